#include "physics/gravity.h"

#include "core/parallel.h"
#include "physics/simulation.h"
#include "scene/section.h"

namespace ganache {

namespace {

/// v += dt g for every fluid particle.
class Gravity final : public Effect {
public:
    explicit Gravity(const Vec3& g) : m_g(g) {}
    void apply(StepContext& ctx, ParticleSet& particles) override {
        auto& v = particles.v();
        forEachParticle(v.size(), [&](std::size_t i) { v[i] += ctx.dt * m_g; });
    }

private:
    Vec3 m_g;
};

}  // namespace

std::shared_ptr<const EffectParams> readGravity(Section& s) {
    auto p = std::make_shared<GravityParams>();
    p->acceleration = s.vec3("acceleration", p->acceleration, "m/s^2", limits::kAcceleration);
    return p;
}

std::unique_ptr<Effect> makeGravity(const EffectParams& p, const SimulationSetup&, ParticleSet&) {
    return std::make_unique<Gravity>(static_cast<const GravityParams&>(p).acceleration);
}

}  // namespace ganache
