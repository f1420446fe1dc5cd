#include "physics/heat/heat.h"

#include "core/attributes.h"
#include "core/byte_stream.h"
#include "core/memory.h"
#include "core/parallel.h"
#include "physics/setup.h"
#include "physics/simulation.h"
#include "scene/section.h"

#include <fmt/format.h>

#include <cmath>
#include <tuple>

namespace ganache {

namespace {

constexpr std::size_t kMinSurfaceNeighbours = 8;  // fewer: a drop or a thread, all surface

// F_ij = (x_ij . grad W_ij) / (|x_ij|^2 + 0.01 h^2) <= 0 [1/m^5]: the kernel part of the Laplacian of Eq. 16, with
// grad W_ij = g x_ij.
Real laplacianWeight(const Vec3& xij, Real g, Real h2) {
    const Real r2 = xij.squaredNorm();
    return g * r2 / (r2 + 0.01 * h2);
}

HeatSource readSource(Section s, std::size_t index) {
    HeatSource src;
    src.at = s.where();
    src.name = s.name("name", fmt::format("source{}", index));
    const bool sphere = s.has("sphere"), plane = s.has("plane");
    if (sphere == plane)
        s.fail(sphere ? "plane" : "", fmt::format("{} needs exactly one of `sphere` and `plane`", s.path()),
               "e.g. `sphere: {centre: [0, 0.3, 0]}` for a lamp or `plane: {point: [0, 0, 0], normal: [0, 1, 0]}` "
               "for a warm floor");
    if (sphere) {
        Section sp = *s.child("sphere");
        src.point = sp.vec3("centre", std::nullopt, "m");
        sp.rejectUnused();
    } else {
        Section pl = *s.child("plane");
        src.plane = true;
        src.point = pl.vec3("point", src.point, "m");
        src.normal = pl.direction("normal", src.normal);
        pl.rejectUnused();
    }
    src.intensity = s.number("intensity", std::nullopt, "W/m^2 at the source", Bounds::nonNegative());
    src.radius = s.positive("radius", std::nullopt, "m (the intensity halves at this distance)");
    std::tie(src.start, src.end) = readTimeWindow(s, std::nullopt);
    if (auto m = s.child("motion")) src.motion = readMotion(*m);
    s.rejectUnused();
    return src;
}

}  // namespace

Real HeatSource::flux(const Vec3& x, Real t) const {
    if (t < start || t >= end) return 0;
    const Vec3 p = motion.transform(point, t);
    const Real s = plane ? std::abs((motion.rotation(t) * normal).dot(x - p)) : (x - p).norm();
    const Real f = (std::sqrt(Real(2)) - 1) * s / radius + 1;  // [Eq. 17]
    return intensity / (f * f);
}

void HeatParams::check(const SimulationSetup& setup, const Location&) const {
    for (const auto& b : bodies) {
        bool found = false;
        std::vector<std::string> names;
        for (const auto& spec : setup.bodies) {
            found |= spec.name == b.body;
            names.push_back(spec.name);
        }
        if (!found) {
            const std::string guess = closestMatch(b.body, names);
            throw SceneError(b.at, fmt::format("effects.heat.bodies: the scene has no boundary named '{}'", b.body),
                             names.empty() ? "add the body under `boundaries:` first"
                                           : (guess.empty() ? "" : fmt::format("did you mean '{}'? ", guess)) +
                                                 fmt::format("boundaries: {}", joinNames(names)));
        }
    }
}

std::shared_ptr<const EffectParams> readHeat(Section& s) {
    auto p = std::make_shared<HeatParams>();
    p->roomTemperature = s.number("room_temperature", p->roomTemperature, "C", Bounds{-273.15, 1e4});
    p->radiationTime = s.number("radiation_time", p->radiationTime, "s (0: no radiation)", Bounds::nonNegative());
    p->surfaceThreshold = s.number("surface_threshold", p->surfaceThreshold, "h |grad colour|", Bounds{0, 10, true});
    auto sources = s.list("sources");
    for (std::size_t i = 0; i < sources.size(); ++i) p->sources.push_back(readSource(sources[i], i));
    if (auto bodies = s.child("bodies")) {
        for (const std::string& name : bodies->keys()) {
            HeatedBody b;
            b.body = name;
            b.at = bodies->where(name);
            Section bs = *bodies->child(name);
            b.temperature = bs.number("temperature", std::nullopt, "C", Bounds{-273.15, 1e4});
            if (bs.has("conductivity"))
                b.conductivity = bs.number("conductivity", std::nullopt, "W/(m K)", Bounds::nonNegative());
            bs.rejectUnused();
            p->bodies.push_back(b);
        }
        bodies->rejectUnused();
    }
    return p;
}

std::vector<std::uint8_t> surfaceParticles(const ParticleSet& particles, const std::vector<Real>& density,
                                           const NeighbourList& neighbours, const std::vector<Real>& gradients,
                                           Real support, Real threshold) {
    const auto& x = particles.x();
    const auto& m = particles.mass();
    std::vector<std::uint8_t> surface(particles.size(), 0);
    forEachParticle(particles.size(), [&](std::size_t i) {
        // Colour-field normal h sum_j V_j grad W_ij: zero inside a full neighbourhood, about 1 on a flat surface.
        Vec3 n = Vec3::Zero();
        for (std::size_t p = neighbours.first(i); p < neighbours.last(i); ++p) {
            const std::uint32_t j = neighbours.indices[p];
            n += (m[j] / density[j]) * (gradients[p] * (x[i] - x[j]));
        }
        surface[i] = support * n.norm() >= threshold || neighbours.of(i).size() < kMinSurfaceNeighbours;
    });
    return surface;
}

namespace {

class Heat final : public Effect {
public:
    Heat(const HeatParams& params, const SimulationSetup& setup, ParticleSet& particles)
        : m_params(params), m_particleArea(M_PI * setup.particleRadius * setup.particleRadius) {
        for (const FluidSource& s : setup.sources) {
            m_conductivity.push_back(s.material.conductivity);
            m_capacity.push_back(s.material.heatCapacity);
        }
        // Every particle starts at its fluid's (or emitter's) temperature unless the cache already carries one.
        if (!particles.find(attribute::kTemperature)) {
            auto& t = particles.add(attribute::kTemperature);
            const std::vector<Real>* fluid = particles.find(attribute::kFluid);
            for (std::size_t i = 0; i < particles.size(); ++i) t[i] = setup.sources.at(sourceIndex(fluid, i)).temperature;
        }
        m_bodyTemperature.assign(setup.bodies.size(), std::numeric_limits<Real>::quiet_NaN());
        m_bodyConductivity.assign(setup.bodies.size(), -1);
        for (const auto& hb : params.bodies)
            for (std::size_t b = 0; b < setup.bodies.size(); ++b)
                if (setup.bodies[b].name == hb.body) {
                    m_bodyTemperature[b] = hb.temperature;
                    m_bodyConductivity[b] = hb.conductivity;
                }
    }

    void apply(StepContext& ctx, ParticleSet& particles) override {
        const std::size_t n = particles.size();
        if (n == 0) return;
        auto& T = *particles.find(attribute::kTemperature);
        const auto& x = particles.x();
        const auto& m = particles.mass();
        const auto& rho = ctx.density;
        const std::vector<Real>* fluid = particles.find(attribute::kFluid);
        auto source = [fluid](std::size_t i) { return sourceIndex(fluid, i); };

        // Conduction [Eq. 15-16], written per pair so that the heat one particle gains the other loses:
        // m_i c_i dT_i/dt = 2 sum_j k_ij V_i V_j (T_i - T_j) F_ij, with F_ij <= 0 and k_ij the mean conductivity;
        // bodies at a set temperature T_b join the sum with their boundary volumes V_k.
        // The pair coefficients depend on the positions only: taken once a step, every sub-step reuses them.
        const auto& f = ctx.fluidNeighbours;
        const auto& b = ctx.boundaryNeighbours;
        const auto conducts = [&](std::uint32_t k) { return !std::isnan(m_bodyTemperature[ctx.boundary.body[k]]); };
        m_rate.resize(n);
        m_diagonal.resize(n);
        resizeForRefill(m_pair, f.pairs());
        resizeForRefill(m_boundaryPair, b.pairs());
        const Real h2 = ctx.kernel.supportRadius() * ctx.kernel.supportRadius();
        forEachParticle(n, [&](std::size_t i) {
            const std::size_t si = source(i);
            const Real vi = m[i] / rho[i];
            Real diagonal = 0;
            for (std::size_t p = f.first(i); p < f.last(i); ++p) {
                const std::uint32_t j = f.indices[p];
                const Real kij = 0.5 * (m_conductivity[si] + m_conductivity[source(j)]);
                m_pair[p] = 2 * kij * vi * (m[j] / rho[j]) * laplacianWeight(x[i] - x[j], ctx.gradients.fluid[p], h2);
                diagonal -= m_pair[p];
            }
            for (std::size_t p = b.first(i); p < b.last(i); ++p) {
                const std::uint32_t k = b.indices[p];
                if (!conducts(k)) continue;
                const std::uint32_t body = ctx.boundary.body[k];
                const Real kib = m_bodyConductivity[body] >= 0 ? m_bodyConductivity[body] : m_conductivity[si];
                m_boundaryPair[p] = 2 * kib * vi * ctx.boundary.volume[k] *
                                    laplacianWeight(x[i] - ctx.boundary.x[k], ctx.gradients.boundary[p], h2);
                diagonal -= m_boundaryPair[p];
            }
            m_diagonal[i] = diagonal / (m[i] * m_capacity[si]);
        });
        auto rates = [&] {
            forEachParticle(n, [&](std::size_t i) {
                Real sum = 0;
                for (std::size_t p = f.first(i); p < f.last(i); ++p) sum += m_pair[p] * (T[i] - T[f.indices[p]]);
                for (std::size_t p = b.first(i); p < b.last(i); ++p) {
                    const std::uint32_t k = b.indices[p];
                    if (conducts(k)) sum += m_boundaryPair[p] * (T[i] - m_bodyTemperature[ctx.boundary.body[k]]);
                }
                m_rate[i] = sum / (m[i] * m_capacity[source(i)]);
            });
        };
        rates();
        // Explicit steps are monotone (each new temperature a weighted mean of the old ones) while
        // dt * diagonal <= 1; longer steps are split into equal sub-steps that respect it.
        Real largest = 0;
        for (Real d : m_diagonal) largest = std::max(largest, d);
        const std::size_t substeps = std::max<std::size_t>(1, std::size_t(std::ceil(ctx.dt * largest)));
        const Real h = ctx.dt / Real(substeps);
        for (std::size_t s = 0; s < substeps; ++s) {
            if (s > 0) rates();
            forEachParticle(n, [&](std::size_t i) { T[i] += h * m_rate[i]; });
        }
        m_substeps += substeps;
        if (substeps > 1 && m_substepsMax <= 1)
            ctx.stats.warn(fmt::format("step {}: conduction needs {} sub-steps of {:.3g} s for stability (reported "
                                       "once; the count is in the report)",
                                       ctx.step, substeps, h));
        m_substepsMax = std::max(m_substepsMax, substeps);

        // Sources and radiation act on the surface only.
        if (m_params.sources.empty() && m_params.radiationTime <= 0) return;
        const auto surface =
            surfaceParticles(particles, rho, ctx.fluidNeighbours, ctx.gradients.fluid, ctx.kernel.supportRadius(),
                             m_params.surfaceThreshold);
        const Real t = ctx.time + 0.5 * ctx.dt;
        const Real decay = m_params.radiationTime > 0 ? std::exp(-ctx.dt / m_params.radiationTime) : 1;
        forEachParticle(n, [&](std::size_t i) {
            if (!surface[i]) return;
            // [Eq. 18]: the power a particle's cross-section A_p catches, turned into kelvin by m c.
            Real q = 0;
            for (const HeatSource& src : m_params.sources) q += src.flux(x[i], t);
            T[i] += ctx.dt * m_particleArea * q / (m[i] * m_capacity[source(i)]);
            // [Eq. 14], integrated exactly: T relaxes towards the room over t_r, for any dt.
            if (m_params.radiationTime > 0)
                T[i] = m_params.roomTemperature + (T[i] - m_params.roomTemperature) * decay;
        });
    }

    /// Conduction sub-steps: per step on average, and the most in one step.
    std::vector<Counter> counters(std::size_t steps) const override {
        return {{"substeps_per_step", steps ? double(m_substeps) / double(steps) : 0.0},
                {"substeps_max", double(m_substepsMax)}};
    }
    void save(ByteWriter& out) const override { out(m_substeps), out(m_substepsMax); }
    void restore(ByteReader& in) override { in(m_substeps), in(m_substepsMax); }

private:
    HeatParams m_params;
    Real m_particleArea;
    std::vector<Real> m_conductivity, m_capacity;  // per source of fluid
    std::vector<Real> m_bodyTemperature;           // per boundary body; NaN: does not conduct
    std::vector<Real> m_bodyConductivity;
    std::vector<Real> m_rate, m_diagonal;
    std::vector<Real> m_pair, m_boundaryPair;  // conduction coefficients of the step's fluid and boundary pairs
    std::size_t m_substeps = 0, m_substepsMax = 0;  // over the run
};

}  // namespace

std::unique_ptr<Effect> makeHeat(const EffectParams& params, const SimulationSetup& setup, ParticleSet& particles) {
    return std::make_unique<Heat>(static_cast<const HeatParams&>(params), setup, particles);
}

}  // namespace ganache
