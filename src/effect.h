#pragma once
// The effects a scene can ask for, and the one table that knows them all by name. An effect a scene does
// not list is never read, constructed or allocated.

#include "scene_section.h"
#include "types.h"

#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace ganache {

/// Slots of one time step that effects fill, in this order (Algorithm 1 of Weiler et al. 2018).
enum class Stage { Forces, Viscosity, EndOfStep };

/// Base of each effect's parameters, read from its section of the scene.
struct EffectParams {
    virtual ~EffectParams() = default;
};

/// Uniform gravitational acceleration [m/s^2].
struct GravityParams : EffectParams {
    Vec3 acceleration{0, -9.81, 0};
};

/// An effect as a scene asks for it.
struct EffectSpec {
    std::string name;
    Stage stage = Stage::Forces;
    Location at;
    std::shared_ptr<const EffectParams> params;
};

/// One row of the effect table: the scene key, its stage, and the reader of its section.
struct EffectEntry {
    std::string_view name;
    Stage stage;
    std::string_view summary;
    std::shared_ptr<const EffectParams> (*read)(Section& s);
};

/// Every effect this build knows.
const std::vector<EffectEntry>& effectTable();

/// Reads the `effects:` map: each key must name a known effect; unknown names get a "did you mean".
std::vector<EffectSpec> readEffects(Section& effects);

}  // namespace ganache
