#pragma once
// A test-only effect, written the way a new effect is added to ganache (docs/architecture.md): its parameters, its
// reader, its class and one registry row, all in this file. Linear drag: dv/dt = -rate v, integrated exactly.

#include "core/byte_stream.h"
#include "core/parallel.h"
#include "physics/effect.h"
#include "physics/simulation.h"
#include "scene/section.h"

#include <cmath>

namespace ganache::testing {

struct DragParams : EffectParams {
    Real rate = 1;  ///< [1/s]
};

class Drag final : public Effect {
public:
    explicit Drag(const DragParams& p) : m_rate(p.rate) {}
    void apply(StepContext& ctx, ParticleSet& particles) override {
        const Real factor = std::exp(-m_rate * ctx.dt);
        auto& v = particles.v();
        forEachParticle(v.size(), [&](std::size_t i) { v[i] *= factor; });
        ++m_applied;
    }
    std::vector<Counter> counters(std::size_t) const override { return {{"applied", double(m_applied)}}; }
    void save(ByteWriter& out) const override { out(m_applied); }
    void restore(ByteReader& in) override { in(m_applied); }

private:
    Real m_rate;
    std::uint64_t m_applied = 0;
};

inline std::shared_ptr<const EffectParams> readDrag(Section& s) {
    auto p = std::make_shared<DragParams>();
    p->rate = s.positive("rate", p->rate, "1/s");
    return p;
}

inline std::unique_ptr<Effect> makeDrag(const EffectParams& p, const SimulationSetup&, ParticleSet&) {
    return std::make_unique<Drag>(static_cast<const DragParams&>(p));
}

/// The registry row; a real effect's row goes into the table in src/physics/effect.cpp instead.
inline void registerDrag() {
    if (!findEffectEntry("drag")) registerEffect({"drag", Stage::Forces, "linear drag (tests only)", &readDrag, &makeDrag});
}

}  // namespace ganache::testing
