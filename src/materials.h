#pragma once
// Fluid materials: named presets with cited sources, and user-defined materials built on them.

#include "types.h"

#include <string>
#include <vector>

namespace ganache {

/// Bulk properties of a fluid in SI units.
struct Material {
    std::string name;
    Real density = 1000;  ///< rest density rho_0 [kg/m^3]
    Real mu = 1.0e-3;     ///< dynamic viscosity [Pa s] = [kg/(m s)], as in the paper
    std::string source;   ///< where the numbers come from
};

/// The built-in presets: water, honey, molten_chocolate, solid_chocolate.
const std::vector<Material>& materialPresets();
/// The preset with this name, or nullptr.
const Material* findPreset(const std::string& name);

}  // namespace ganache
