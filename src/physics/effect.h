#pragma once
// The effects a scene can ask for, and the one table that knows them all by name. An effect a scene does
// not list is never read, constructed or allocated.

#include "scene/section.h"
#include "core/types.h"

#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace ganache {

/// Slots of one time step that effects fill, in this order (Algorithm 1 of Weiler et al. 2018).
enum class Stage { Heat, Forces, Viscosity, EndOfStep };

/// Base of each effect's parameters, read from its section of the scene.
struct Scene;

struct EffectParams {
    virtual ~EffectParams() = default;
    /// Checks what needs the whole scene (e.g. that a named body exists); throws SceneError at `at`.
    virtual void check(const Scene& /*scene*/, const Location& /*at*/) const {}
};

/// Uniform gravitational acceleration [m/s^2].
struct GravityParams : EffectParams {
    Vec3 acceleration{0, -9.81, 0};
};

/// Viscosity: the method and the settings of its solve (see viscosity.h).
struct ViscosityParams : EffectParams {
    /// weiler2018: the implicit solver of Weiler et al. 2018 that ganache is built on; explicit and takahashi2015
    /// are there to compare against it (ganache study).
    enum class Method { Weiler2018, Explicit, Takahashi2015 };
    Method method = Method::Weiler2018;
    std::optional<Real> mu;      ///< dynamic viscosity for every fluid [Pa s]; unset: each fluid's material
    Real boundaryMu = 0;         ///< boundary viscosity mu_b [Pa s]: 0 slips, large sticks
    /// CG stops when |r| <= tolerance |b - (I - dt A) v_df|, the residual relative to the correction the solve
    /// has to make. At 1e-3 the warm start's leftover added 2.4 % angular momentum to a spinning cube in 0.5 s;
    /// at 1e-4 it keeps it to 0.01 %.
    Real tolerance = 1e-4;
    std::int64_t maxIterations = 100;  ///< CG iterations per solve; explicit: sub-steps per step (default 10,000)
    /// none, 3x3 block Jacobi, or block Jacobi plus the fluid's rigid motions as a coarse space (two-level;
    /// weiler2018 only, its default; takahashi2015 defaults to block Jacobi)
    enum class Preconditioner { None, BlockJacobi, Rigid };
    Preconditioner preconditioner = Preconditioner::Rigid;
    bool warmStart = true;       ///< initial guess v_df + dv of the previous step (false: v_df)
};

struct StepContext;
class ParticleSet;

/// One effect of a simulation step. Effects are built only for scenes that ask for them; each adds the
/// particle attributes it needs when it is built and reads dt, kernel and neighbours from the StepContext.
class Effect {
public:
    virtual ~Effect() = default;
    virtual void apply(StepContext& ctx, ParticleSet& particles) = 0;
};

/// An effect as a scene asks for it.
struct EffectSpec {
    std::string name;
    Stage stage = Stage::Forces;
    Location at;
    std::shared_ptr<const EffectParams> params;
};

struct Scene;

/// One row of the effect table: the scene key, its stage, the reader of its section and the factory.
struct EffectEntry {
    std::string_view name;
    Stage stage;
    std::string_view summary;
    std::shared_ptr<const EffectParams> (*read)(Section& s);
    std::unique_ptr<Effect> (*make)(const EffectParams& params, const Scene& scene, ParticleSet& particles);
};

/// Every effect this build knows.
const std::vector<EffectEntry>& effectTable();

/// Builds the effects a scene asks for, grouped by stage.
std::vector<std::vector<std::unique_ptr<Effect>>> makeEffects(const Scene& scene, ParticleSet& particles);

/// Reads the `effects:` map: each key must name a known effect; unknown names get a "did you mean".
std::vector<EffectSpec> readEffects(Section& effects);

}  // namespace ganache
