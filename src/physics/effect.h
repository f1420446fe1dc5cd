#pragma once
// Effects: what a simulation does beyond the pressure solve, each only when the scene asks for it. An effect reads
// its own settings, adds its own particle attributes, runs in one stage of the step, keeps its own counters and
// carries its own state into checkpoints. The registry (effect.cpp) is the one place that knows every effect by
// name: an effect a scene does not list is never read, constructed or allocated, and costs nothing.

#include "core/errors.h"
#include "core/particles.h"

#include <cstddef>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace ganache {

class ByteReader;
class ByteWriter;
class Section;
struct SimulationSetup;
struct StepContext;

/// The slots of one step that effects fill, in the order the step runs them (see simulation.h).
enum class Stage {
    Start,      ///< before anything moves (heat: temperatures, hence viscosities, of this step)
    Forces,     ///< explicit forces on the velocities (gravity)
    Emit,       ///< after advection, before the neighbour search (emitters add particles)
    Viscosity,  ///< the implicit viscosity solve
    Count
};
inline constexpr std::size_t kStageCount = std::size_t(Stage::Count);

/// Base of each effect's parameters, read from its section of the scene.
struct EffectParams {
    virtual ~EffectParams() = default;
    /// Checks what needs the rest of the set-up (e.g. that a named body exists); throws SceneError at `at`.
    virtual void check(const SimulationSetup& /*setup*/, const Location& /*at*/) const {}
};

/// A number an effect reports in report.json, as solver.<effect>_<name>.
struct Counter {
    std::string name;
    double value = 0;
};

/// One effect of a simulation step.
class Effect {
public:
    virtual ~Effect() = default;
    virtual void apply(StepContext& ctx, ParticleSet& particles) = 0;
    /// What the effect did over the `steps` steps so far.
    virtual std::vector<Counter> counters(std::size_t /*steps*/) const { return {}; }
    /// What the effect carries from one step to the next beyond its particle attributes (which move with the
    /// particles and are saved with them), so that a restored simulation takes the same steps.
    virtual void save(ByteWriter& /*out*/) const {}
    virtual void restore(ByteReader& /*in*/) {}
};

/// An effect as a scene asks for it.
struct EffectSpec {
    std::string name;
    Location at;
    std::shared_ptr<const EffectParams> params;
};

/// One row of the effect registry: the scene key, its stage, the reader of its section and the factory.
struct EffectEntry {
    std::string_view name;
    Stage stage;
    std::string_view summary;
    std::shared_ptr<const EffectParams> (*read)(Section& s);
    std::unique_ptr<Effect> (*make)(const EffectParams& params, const SimulationSetup& setup, ParticleSet& particles);
};

/// Every effect this build knows.
const std::vector<EffectEntry>& effectTable();
/// Adds a row to the registry (an effect built outside the physics library, e.g. a test's); std::logic_error when
/// the name is taken. Call it before any scene is read.
void registerEffect(const EffectEntry& entry);
/// The registry's row of that name, or null.
const EffectEntry* findEffectEntry(std::string_view name);

/// Reads the `effects:` map: each key must name a known effect; unknown names get a "did you mean".
std::vector<EffectSpec> readEffects(Section& effects);

}  // namespace ganache
