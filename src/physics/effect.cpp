#include "physics/effect.h"

#include "physics/heat/heat.h"
#include "core/parallel.h"
#include "physics/simulation.h"
#include "physics/viscosity/viscosity.h"

#include <fmt/format.h>

namespace ganache {

namespace {

std::shared_ptr<const EffectParams> readGravity(Section& s) {
    auto p = std::make_shared<GravityParams>();
    p->acceleration = s.vec3("acceleration", p->acceleration, "m/s^2");
    return p;
}

/// v += dt g for every fluid particle.
class Gravity final : public Effect {
public:
    explicit Gravity(const Vec3& g) : m_g(g) {}
    void apply(StepContext& ctx, ParticleSet& particles) override {
        auto& v = particles.v();
        forEachParticle(v.size(), [&](std::size_t i) { v[i] += ctx.dt * m_g; }, 4096);
    }

private:
    Vec3 m_g;
};

std::unique_ptr<Effect> makeGravity(const EffectParams& p, const Scene&, ParticleSet&) {
    return std::make_unique<Gravity>(dynamic_cast<const GravityParams&>(p).acceleration);
}

std::shared_ptr<const EffectParams> readViscosity(Section& s) {
    using Method = ViscosityParams::Method;
    using Preconditioner = ViscosityParams::Preconditioner;
    auto p = std::make_shared<ViscosityParams>();
    const std::string method = s.choice("method", "weiler2018", {"weiler2018", "explicit", "takahashi2015"});
    p->method = method == "explicit" ? Method::Explicit : method == "takahashi2015" ? Method::Takahashi2015
                                                                                     : Method::Weiler2018;
    if (s.has("mu")) p->mu = s.number("mu", std::nullopt, "Pa s", Bounds::nonNegative());
    p->boundaryMu = s.number("boundary_mu", p->boundaryMu, "Pa s", Bounds::nonNegative());
    if (p->method == Method::Explicit) {
        // Forward Euler has no solve: its only setting is how many sub-steps one step may take.
        for (const char* key : {"tolerance", "preconditioner", "warm_start"})
            if (s.has(key))
                s.failAtKey(key, fmt::format("{}.{} is a setting of the implicit solvers; method 'explicit' has no "
                                             "solve",
                                             s.path(), key),
                            "remove it, or choose method: weiler2018");
        p->maxIterations = s.integer("max_iterations", 10000, 1, 100000000);
        return p;
    }
    p->tolerance = s.number("tolerance", p->tolerance, "relative residual", Bounds{0, 1, true, true});
    p->maxIterations = s.integer("max_iterations", p->maxIterations, 1, 100000);
    const bool weiler = p->method == Method::Weiler2018;
    const std::string preconditioner =
        s.choice("preconditioner", weiler ? "rigid" : "block_jacobi", {"rigid", "block_jacobi", "none"});
    if (preconditioner == "rigid" && !weiler)
        s.fail("preconditioner",
               fmt::format("{}.preconditioner 'rigid' works on the system of weiler2018 only: the rigid motions are "
                           "not free of viscous forces in {}'s",
                           s.path(), method),
               "use block_jacobi or none");
    p->preconditioner = preconditioner == "none"           ? Preconditioner::None
                        : preconditioner == "block_jacobi" ? Preconditioner::BlockJacobi
                                                           : Preconditioner::Rigid;
    p->warmStart = s.boolean("warm_start", p->warmStart);
    return p;
}

std::vector<std::string> effectNames() {
    std::vector<std::string> names;
    for (const auto& e : effectTable()) names.emplace_back(e.name);
    return names;
}

}  // namespace

const std::vector<EffectEntry>& effectTable() {
    static const std::vector<EffectEntry> table = {
        {"gravity", Stage::Forces, "uniform acceleration of every fluid particle", &readGravity, &makeGravity},
        {"viscosity", Stage::Viscosity,
         "viscosity: the implicit solver of Weiler et al. 2018, or (for comparison) explicit or takahashi2015",
         &readViscosity, &makeViscosity},
        {"heat", Stage::Heat, "temperature: conduction, radiation, heat sources; melting through viscosity laws",
         &readHeat, &makeHeat},
    };
    return table;
}

std::vector<std::vector<std::unique_ptr<Effect>>> makeEffects(const Scene& scene, ParticleSet& particles) {
    std::vector<std::vector<std::unique_ptr<Effect>>> byStage(4);
    for (const auto& spec : scene.effects)
        for (const auto& e : effectTable())
            if (e.name == spec.name) byStage[std::size_t(e.stage)].push_back(e.make(*spec.params, scene, particles));
    return byStage;
}

std::vector<EffectSpec> readEffects(Section& effects) {
    std::vector<EffectSpec> specs;
    for (const std::string& key : effects.keys()) {
        const EffectEntry* entry = nullptr;
        for (const auto& e : effectTable())
            if (e.name == key) entry = &e;
        if (!entry) {
            const std::string guess = closestMatch(key, effectNames());
            effects.failAtKey(key, fmt::format("unknown effect '{}'", key),
                         (guess.empty() ? "" : fmt::format("did you mean '{}'? ", guess)) +
                             fmt::format("effects in this build: {}", joinNames(effectNames())));
        }
        const Location at = effects.where(key);
        // `gravity: {}` or a bare `gravity:` asks for the effect with all its defaults.
        Section s = *effects.child(key);
        specs.push_back({key, entry->stage, at, entry->read(s)});
        s.rejectUnused();
    }
    effects.rejectUnused();
    return specs;
}

}  // namespace ganache
