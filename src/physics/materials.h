#pragma once
// Fluid materials: named presets with cited sources, and user-defined materials built on them.

#include "core/types.h"

#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace ganache {

class Section;

/// How a material's viscosity follows its temperature (used only in scenes with the heat effect).
struct ViscosityLaw {
    enum class Kind { Reynolds, Ramp } kind = Kind::Reynolds;
    // Reynolds' law mu(T) = mu0 exp(-alpha (T - t0)), clamped to [muMin, muMax].
    Real mu0 = 0;     ///< [Pa s] at t0
    Real t0 = 20;     ///< [C]
    Real alpha = 0;   ///< [1/K]; > 0: warmer is runnier
    Real muMin = 0, muMax = 0;  ///< [Pa s]
    /// Ramp: (temperature [C], mu [Pa s]) points, temperatures increasing; log mu is interpolated linearly and
    /// held beyond the ends.
    std::vector<std::pair<Real, Real>> ramp;

    Real at(Real temperature) const;
};

/// Bulk properties of a fluid in SI units (temperatures in degrees Celsius).
struct Material {
    std::string name;
    Real density = 1000;  ///< rest density rho_0 [kg/m^3]
    Real mu = 1.0e-3;     ///< dynamic viscosity [Pa s] = [kg/(m s)], as in the paper
    std::string source;   ///< where the numbers come from
    Real conductivity = 0.6;     ///< thermal conductivity k [W/(m K)]
    Real heatCapacity = 4180;    ///< specific heat capacity c [J/(kg K)]
    std::optional<ViscosityLaw> law;  ///< temperature-dependent viscosity; mu is used where no temperature exists
    Vec3 colour = Vec3(0.6, 0.75, 0.9);  ///< preview colour, sRGB in [0, 1]
};

/// The built-in presets: water, honey, molten_chocolate, solid_chocolate, chocolate (melting).
const std::vector<Material>& materialPresets();
/// The preset with this name, or nullptr.
const Material* findPreset(const std::string& name);

/// Reads the scene's `materials:` map (absent: none): each of the user's names starts from a preset (`base`) and
/// changes its values.
std::vector<Material> readMaterials(std::optional<Section> section);
/// Reads the `material` key of a fluid or emitter: a preset's name or one of `custom` (default water).
Material readMaterialChoice(Section& s, const std::vector<Material>& custom);

}  // namespace ganache
