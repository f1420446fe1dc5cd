#include "physics/simulation.h"

#include "core/parallel.h"
#include "physics/pressure/pressure_dfsph.h"
#include "app/report.h"
#include "scene/scene.h"

#include <fmt/format.h>
#include <tbb/parallel_reduce.h>

namespace ganache {

namespace {

// Reorder the particles along the grid's Z curve this often, to keep neighbours close in memory.
constexpr std::size_t kReorderInterval = 50;

}  // namespace

void SolverStats::warn(std::string text) {
    ++warningCount;
    if (warnings.size() < kMaxWarnings) warnings.push_back(std::move(text));
}

Simulation::Simulation(const Scene& scene, ParticleSet fluid, const std::vector<BoundaryBody>& bodies)
    : m_particleRadius(scene.particleRadius),
      m_kernel(supportRadiusFor(scene.particleRadius)),
      m_latticeSum(latticeKernelSum(2 * scene.particleRadius, m_kernel)),
      m_domainMin(scene.domainMin),
      m_domainMax(scene.domainMax),
      m_timeStep(scene.timeStep),
      m_pressureSettings(scene.pressure),
      m_coupling(scene.viscosityCoupling),
      m_fluid(std::move(fluid)),
      m_fluidGrid(m_kernel.supportRadius()),
      m_boundaryGrid(m_kernel.supportRadius()) {
    // Every particle was sampled on the lattice of spacing 2r, so its mass says its rest density.
    m_restDensity = &m_fluid.addScalar("_rest_density", 0, false);
    for (std::size_t i = 0; i < m_fluid.size(); ++i) (*m_restDensity)[i] = m_fluid.mass()[i] * m_latticeSum;

    for (std::size_t b = 0; b < bodies.size(); ++b) {
        m_boundary.names.push_back(bodies[b].name);
        m_boundary.x.insert(m_boundary.x.end(), bodies[b].x.begin(), bodies[b].x.end());
        m_boundary.volume.insert(m_boundary.volume.end(), bodies[b].volume.begin(), bodies[b].volume.end());
        m_boundary.body.insert(m_boundary.body.end(), bodies[b].x.size(), std::uint32_t(b));
        // Caches name their bodies; the scene's motion goes with the body of the same name.
        BodyMotion motion;
        for (const auto& spec : scene.boundaries)
            if (spec.name == bodies[b].name) motion = spec.motion;
        m_boundary.anyMoving |= !motion.isStatic();
        m_boundary.motion.push_back(motion);
    }
    m_boundary.x0 = m_boundary.x;
    m_boundary.v.assign(m_boundary.x.size(), Vec3::Zero());
    m_loads.clear(bodies.size());
    m_totalImpulse.assign(bodies.size(), Vec3::Zero());
    m_totalAngular.assign(bodies.size(), Vec3::Zero());
    m_peakForce.assign(bodies.size(), 0);
    moveBoundaries(0);

    m_pressure = std::make_unique<PressureDFSPH>(m_pressureSettings, m_fluid);
    m_effects = makeEffects(scene, m_fluid);
    for (const auto& e : scene.effects) m_effectNames.push_back(e.name);
    if (!scene.emitters.empty()) {
        m_emitters = std::make_unique<Emitters>(scene, m_particleRadius);
        m_effectNames.push_back("emitters");
        for (std::uint64_t id : m_fluid.id()) m_nextId = std::max(m_nextId, id + 1);
    }

    updateNeighbours(true);
    computeDensities();
    m_pressure->computeFactors(context(0), m_fluid);
}

Simulation::~Simulation() = default;

SimulationState Simulation::state() const {
    SimulationState s;
    s.time = m_time;
    s.step = m_step;
    s.nextId = m_nextId;
    s.fluid = m_fluid;
    if (m_emitters) s.emitters = m_emitters->state();
    s.totalImpulse = m_totalImpulse;
    s.totalAngular = m_totalAngular;
    s.peakForce = m_peakForce;
    s.stats = m_stats;
    return s;
}

void Simulation::restore(const SimulationState& s) {
    const std::size_t bodies = m_boundary.names.size();
    if (s.totalImpulse.size() != bodies || s.totalAngular.size() != bodies || s.peakForce.size() != bodies)
        throw std::runtime_error(fmt::format("the saved state has {} boundary bodies, the scene {}",
                                             s.totalImpulse.size(), bodies));
    if (m_emitters) m_emitters->restore(s.emitters);
    else if (!s.emitters.empty()) throw std::runtime_error("the saved state has emitters, the scene none");
    m_fluid.assignValues(s.fluid);  // in place: the effects hold their attributes by address
    m_time = s.time;
    m_step = s.step;
    m_nextId = s.nextId;
    m_totalImpulse = s.totalImpulse;
    m_totalAngular = s.totalAngular;
    m_peakForce = s.peakForce;
    m_stats = s.stats;
    // What the saved simulation computed at the end of its last step, from the same positions and order.
    moveBoundaries(m_time);
    updateNeighbours(false);
    computeDensities();
    m_pressure->computeFactors(context(0), m_fluid);
}

StepContext Simulation::context(Real dt) {
    return StepContext{dt, m_time, m_step, m_kernel, m_fluidNeighbours, m_boundaryNeighbours,
                       m_density, *m_restDensity, m_boundary, m_stats, m_loads};
}

void Simulation::moveBoundaries(Real t) {
    if (!m_boundary.anyMoving) {
        if (m_boundaryGrid.pointCount() != m_boundary.x.size()) m_boundaryGrid.build(m_boundary.x);
        return;
    }
    auto& b = m_boundary;
    for (std::size_t k = 0; k < b.x.size(); ++k) {
        const BodyMotion& m = b.motion[b.body[k]];
        if (m.isStatic()) continue;
        b.x[k] = m.transform(b.x0[k], t);
        b.v[k] = m.velocity(b.x[k], t);
    }
    m_boundaryGrid.build(b.x);
}

std::vector<EmitterReport> Simulation::emitterReports() const {
    return m_emitters ? m_emitters->reports() : std::vector<EmitterReport>{};
}

std::vector<BodyReport> Simulation::bodyReports() const {
    std::vector<BodyReport> out(m_totalImpulse.size());
    for (std::size_t b = 0; b < out.size(); ++b) {
        if (m_time > 0) {
            out[b].meanForce = m_totalImpulse[b] / m_time;
            out[b].meanTorque = m_totalAngular[b] / m_time;
        }
        out[b].peakForce = m_peakForce[b];
    }
    return out;
}

void Simulation::updateNeighbours(bool mayReorder) {
    const Real h = m_kernel.supportRadius();
    m_fluidGrid.build(m_fluid.x());
    if (mayReorder && m_step % kReorderInterval == 0) {
        // The one place particles are reordered: every attribute moves together.
        m_fluid.reorder(m_fluidGrid.sortedIndices());
        m_fluidGrid.build(m_fluid.x());
    }
    findNeighbours(m_fluidGrid, m_fluid.x(), m_fluidGrid, m_fluid.x(), h, true, m_fluidNeighbours);
    findNeighbours(m_fluidGrid, m_fluid.x(), m_boundaryGrid, m_boundary.x, h, false, m_boundaryNeighbours);
}

void Simulation::computeDensities() {
    const std::size_t n = m_fluid.size();
    m_density.resize(n);
    const auto& x = m_fluid.x();
    const auto& m = m_fluid.mass();
    const auto& rho0 = *m_restDensity;
    forEachParticle(n, [&](std::size_t i) {
        // rho_i = sum_j m_j W_ij + sum_k Psi_k W_ik, with Psi_k = rho_0 V_k [AIA+12]
        Real rho = m[i] * m_kernel.W0();
        for (std::uint32_t j : m_fluidNeighbours.of(i)) rho += m[j] * m_kernel.W(x[i] - x[j]);
        for (std::uint32_t k : m_boundaryNeighbours.of(i))
            rho += rho0[i] * m_boundary.volume[k] * m_kernel.W(x[i] - m_boundary.x[k]);
        m_density[i] = rho;
    });
}

Real Simulation::chooseDt(Real maxDt) const {
    Real dt = m_timeStep.fixedDt;
    if (dt <= 0) {
        const auto& v = m_fluid.v();
        const Real maxSpeed = std::sqrt(tbb::parallel_reduce(
            tbb::blocked_range<std::size_t>(0, v.size(), 4096), Real(0),
            [&](const auto& r, Real s) {
                for (std::size_t i = r.begin(); i != r.end(); ++i) s = std::max(s, v[i].squaredNorm());
                return s;
            },
            [](Real a, Real b) { return std::max(a, b); }));
        // [WKBB18 Alg. 1] dt <= 0.4 d / max|v|, d the particle diameter
        dt = maxSpeed > 0 ? m_timeStep.cfl * 2 * m_particleRadius / maxSpeed : m_timeStep.dtMax;
        dt = std::clamp(dt, m_timeStep.dtMin, m_timeStep.dtMax);
    }
    return std::min(dt, maxDt);
}

void Simulation::keepOffBoundaries(StepContext& ctx) {
    // The pressure solve only pushes a particle once it is compressed, and a lone particle (a splash) is not:
    // even touching a wall, the wall and its own mass give it less than rest density, so it would fly through.
    // Before moving, a particle may approach a boundary only to within one particle radius of its nearest
    // boundary particle; the rest of its approach velocity (relative to the wall, along the wall's normal) is
    // taken out, inelastically, and given to the body (all of it, for simplicity, to the body of the nearest
    // boundary particle). Fluid at rest sits two radii from a wall and never
    // meets this; it never pushes, so it adds no energy.
    const Real dt = ctx.dt, r = m_particleRadius;
    const auto& x = m_fluid.x();
    auto& v = m_fluid.v();
    const auto& b = m_boundary;
    auto& change = m_contactChange;
    auto& nearest = m_contactNearest;
    change.assign(x.size(), Vec3::Zero());
    nearest.assign(x.size(), 0);
    forEachParticle(x.size(), [&](std::size_t i) {
        Vec3 towardWall = Vec3::Zero();
        Real closest2 = std::numeric_limits<Real>::infinity();
        for (std::uint32_t k : m_boundaryNeighbours.of(i)) {
            const Vec3 xik = x[i] - b.x[k];
            towardWall += b.volume[k] * m_kernel.gradW(xik);  // grad W points from the particle to k
            if (xik.squaredNorm() < closest2) closest2 = xik.squaredNorm(), nearest[i] = k;
        }
        if (towardWall.squaredNorm() == 0) return;
        const Vec3 n = -towardWall.normalized();  // out of the wall
        Vec3 vi = v[i];
        const Real approach = -(vi - b.v[nearest[i]]).dot(n);
        const Real allowed = std::max<Real>(0, std::sqrt(closest2) - r) / dt;
        if (approach > allowed) vi += (approach - allowed) * n;
        // Where walls meet, one normal cannot hold both: no particle may also come nearer than 3/4 r to any single
        // boundary particle. Boundary particles are at most r apart, so every gap between them is narrower
        // (r / sqrt 2 from its centre to its corners): nothing slips through. Fluid sliding along a wall keeps
        // at least r from it and does not meet this.
        for (std::uint32_t k : m_boundaryNeighbours.of(i)) {
            const Vec3 xik = x[i] - b.x[k];
            const Real dist = xik.norm();
            if (dist == 0 || dist > r + dt * (vi - b.v[k]).norm()) continue;
            const Vec3 nk = xik / dist;
            const Real closing = -(vi - b.v[k]).dot(nk);
            const Real limit = std::max<Real>(0, dist - 0.75 * r) / dt;
            if (closing > limit) vi += (closing - limit) * nk;
        }
        change[i] = vi - v[i];
    });
    for (std::size_t i = 0; i < x.size(); ++i) {
        if (change[i].squaredNorm() == 0) continue;
        v[i] += change[i];
        const Vec3 j = -m_fluid.mass()[i] * change[i];  // what the body took
        const std::uint32_t body = b.body[nearest[i]];
        const BodyMotion& motion = b.motion[body];
        m_loads.impulse[body] += j;
        m_loads.angularImpulse[body] += (b.x[nearest[i]] - (motion.centre + motion.offset(ctx.time + dt))).cross(j);
        ++m_stats.boundaryContacts;
    }
}

void Simulation::removeEscaped() {
    const auto& x = m_fluid.x();
    std::vector<std::uint8_t> out(x.size());
    std::size_t count = 0, first = x.size();
    for (std::size_t i = 0; i < x.size(); ++i) {
        out[i] = (x[i].array() < m_domainMin.array()).any() || (x[i].array() > m_domainMax.array()).any();
        count += out[i];
        if (out[i] && first == x.size()) first = i;
    }
    if (count == 0) return;
    std::string side;
    for (int a = 0; a < 3 && side.empty(); ++a) {
        if (x[first][a] < m_domainMin[a]) side = fmt::format("{} min", "xyz"[a]);
        if (x[first][a] > m_domainMax[a]) side = fmt::format("{} max", "xyz"[a]);
    }
    m_stats.warn(fmt::format("step {} (t = {:.4f} s): {} particle(s) left the domain and were removed (the first, id "
                             "{}, through the {} side at [{:.4g}, {:.4g}, {:.4g}] m)",
                             m_step, m_time, count, m_fluid.id()[first], side, x[first].x(), x[first].y(),
                             x[first].z()));
    m_fluid.removeIf(out);
    m_stats.removedParticles += count;
}

void Simulation::checkFinite(const char* stage) {
    const auto& x = m_fluid.x();
    const auto& v = m_fluid.v();
    const std::size_t bad = tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(0, x.size(), 4096), x.size(),
        [&](const auto& r, std::size_t first) {
            for (std::size_t i = r.begin(); i != r.end() && i < first; ++i)
                if (!x[i].allFinite() || !v[i].allFinite()) return i;
            return first;
        },
        [](std::size_t a, std::size_t b) { return std::min(a, b); });
    if (bad == x.size()) return;
    throw std::runtime_error(fmt::format(
        "step {} (t = {:.6f} s): particle id {} has a non-finite {} after the {} stage\n  fix: lower "
        "simulation.time_step.max, or check the scene for extreme values",
        m_step, m_time, m_fluid.id()[bad], x[bad].allFinite() ? "velocity" : "position", stage));
}

void Simulation::step(Real maxDt) {
    const Real dt = chooseDt(maxDt);
    StepContext ctx = context(dt);
    m_loads.clear(m_boundary.names.size());
    if (!m_effects[std::size_t(Stage::Heat)].empty()) {
        ScopedTimer t(m_stats.time.heat);
        for (auto& e : m_effects[std::size_t(Stage::Heat)]) e->apply(ctx, m_fluid);
    }
    {
        ScopedTimer t(m_stats.time.forces);
        for (auto& e : m_effects[std::size_t(Stage::Forces)]) e->apply(ctx, m_fluid);
        checkFinite("forces");
    }
    auto applyViscosity = [&] {
        ScopedTimer t(m_stats.time.viscosity);
        for (auto& e : m_effects[std::size_t(Stage::Viscosity)]) e->apply(ctx, m_fluid);
        checkFinite("viscosity");
    };
    const bool viscous = !m_effects[std::size_t(Stage::Viscosity)].empty();
    // Coupled (n >= 1): viscosity alternates with the constant-density solve before advection, so the motion
    // that moves the particles has seen both. A lone pressure solve answers gravity with an inviscid flow;
    // advected for a whole step before viscosity acts, that flow made a stiff blob (1e4 Pa s) slump to 60 % of
    // its height in 0.3 s at dt = 5 ms where smaller steps kept 98 %, and let a 1e6 Pa s block sink through a
    // floor. A single pass ends on viscous velocities the pressure has not seen (they pressed walls by 13 % with
    // the boundary weighting of that time); three passes keep the stability suite within its bounds.
    const std::int64_t passes = viscous ? std::max<std::int64_t>(m_coupling, 1) : 1;
    for (std::int64_t pass = 0; pass < passes; ++pass) {
        {
            ScopedTimer t(m_stats.time.pressure);
            m_pressure->solveDensity(ctx, m_fluid, pass == 0);
            checkFinite("constant-density");
        }
        if (viscous && m_coupling > 0) applyViscosity();
    }
    {
        ScopedTimer t(m_stats.time.advect);
        if (!m_boundary.x.empty()) keepOffBoundaries(ctx);
        auto& x = m_fluid.x();
        const auto& v = m_fluid.v();
        forEachParticle(x.size(), [&](std::size_t i) { x[i] += dt * v[i]; }, 4096);
        removeEscaped();
    }
    if (m_emitters) {
        ScopedTimer t(m_stats.time.emit);
        const std::size_t before = m_fluid.size();
        m_emitters->emit(m_time, dt, m_fluid, m_nextId, m_stats);
        // Emitted layers sit on the sampler's lattice, so their masses say their rest density, as at the start.
        for (std::size_t i = before; i < m_fluid.size(); ++i) (*m_restDensity)[i] = m_fluid.mass()[i] * m_latticeSum;
        m_stats.emittedParticles += m_fluid.size() - before;
    }
    {
        ScopedTimer t(m_stats.time.neighbours);
        moveBoundaries(m_time + dt);
        updateNeighbours(true);
        computeDensities();
        m_pressure->computeFactors(ctx, m_fluid);
    }
    {
        ScopedTimer t(m_stats.time.divergence);
        m_pressure->solveDivergence(ctx, m_fluid);
        checkFinite("divergence-free");
    }
    if (viscous && m_coupling == 0) applyViscosity();  // Algorithm 1 of the paper
    {
        ScopedTimer t(m_stats.time.endOfStep);
        for (auto& e : m_effects[std::size_t(Stage::EndOfStep)]) e->apply(ctx, m_fluid);
        checkFinite("end-of-step");
    }
    for (std::size_t b = 0; b < m_loads.impulse.size(); ++b) {
        m_totalImpulse[b] += m_loads.impulse[b];
        m_totalAngular[b] += m_loads.angularImpulse[b];
        m_peakForce[b] = std::max(m_peakForce[b], m_loads.impulse[b].norm() / dt);
    }
    m_time += dt;
    ++m_step;
    ++m_stats.steps;
    m_stats.dtMin = std::min(m_stats.dtMin, dt);
    m_stats.dtMax = std::max(m_stats.dtMax, dt);
}

bool Simulation::advanceTo(Real t, const std::function<bool()>& keepGoing) {
    while (t - m_time > 1e-12 * std::max<Real>(1, std::abs(t))) {
        if (keepGoing && !keepGoing()) return false;
        const Real left = t - m_time;
        const Real dt = chooseDt(left);
        // Never end on a sliver: the constant-density solve removes the leftover compression within one step, so
        // a step of a microsecond before a frame turned a normal residual into a 9 MN push on the tank (and the
        // warm start carried that pressure on). Between one and two steps left, take two halves.
        step(left > dt && left < 2 * dt ? left / 2 : left);
    }
    return true;
}

}  // namespace ganache
