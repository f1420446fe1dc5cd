#include "physics/simulation.h"

#include "core/attributes.h"
#include "core/byte_stream.h"
#include "core/memory.h"
#include "core/parallel.h"
#include "core/timing.h"
#include "physics/gravity.h"
#include "physics/pressure/pressure_dfsph.h"

#include <fmt/format.h>

namespace ganache {

namespace {

// Reorder the particles in the grid's cell order this often, to keep neighbours close in memory.
constexpr std::size_t kReorderInterval = 50;

}  // namespace

void SolverStats::warn(std::string text) {
    ++warningCount;
    if (warnings.size() < kMaxWarnings) warnings.push_back(std::move(text));
}

Simulation::Simulation(const SimulationSetup& setup, ParticleSet fluid, const std::vector<BoundaryBody>& bodies)
    : m_particleRadius(setup.particleRadius),
      m_kernel(supportRadiusFor(setup.particleRadius)),
      m_latticeSum(latticeKernelSum(2 * setup.particleRadius, m_kernel)),
      m_domainMin(setup.domainMin),
      m_domainMax(setup.domainMax),
      m_timeStep(setup.timeStep),
      m_pressureSettings(setup.pressure),
      m_order(setup.viscosityOrder),
      m_fluid(std::move(fluid)),
      m_boundary(bodies, setup.bodies),
      m_fluidGrid(m_kernel.supportRadius()),
      m_boundaryGrid(m_kernel.supportRadius()),
      m_contact(setup.particleRadius) {
    // Every particle was sampled on the lattice of spacing 2r, so its mass says its rest density.
    m_restDensity = &m_fluid.add(attribute::kRestDensity);
    for (std::size_t i = 0; i < m_fluid.size(); ++i) (*m_restDensity)[i] = m_fluid.mass()[i] * m_latticeSum;

    m_loads.clear(bodies.size());
    m_totalImpulse.assign(bodies.size(), Vec3::Zero());
    m_totalAngular.assign(bodies.size(), Vec3::Zero());
    m_peakForce.assign(bodies.size(), 0);
    moveBoundaries(0);

    if (const EffectSpec* gravity = setup.findEffect("gravity"))
        m_gravity = static_cast<const GravityParams&>(*gravity->params).acceleration.norm();
    m_pressure = std::make_unique<PressureDFSPH>(m_pressureSettings, m_fluid);
    for (const EffectSpec& spec : setup.effects) {
        const EffectEntry* entry = findEffectEntry(spec.name);
        if (!entry) throw std::logic_error("no effect named '" + spec.name + "' is registered");
        m_effects.push_back({spec.name, entry->stage, entry->make(*spec.params, setup, m_fluid)});
    }
    if (!setup.emitters.empty()) m_effects.push_back({"emitters", Stage::Emit, std::make_unique<Emitters>(setup, m_fluid)});
    for (std::size_t e = 0; e < m_effects.size(); ++e) m_stages[std::size_t(m_effects[e].stage)].push_back(e);

    updateNeighbours(true);
    computeDensities();
    m_pressure->computeFactors(context(0), m_fluid);
}

Simulation::~Simulation() = default;

SimulationState Simulation::state() const {
    SimulationState s;
    s.time = m_time;
    s.step = m_step;
    s.fluid = m_fluid;
    for (const RunningEffect& e : m_effects) {
        ByteWriter out;
        e.effect->save(out);
        s.effects.push_back({e.name, e.seconds, std::move(out.bytes)});
    }
    ByteWriter pressure;
    m_pressure->save(pressure);
    s.pressure = std::move(pressure.bytes);
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
    if (s.effects.size() != m_effects.size())
        throw std::runtime_error(fmt::format("the saved state has {} effects, the scene {}", s.effects.size(),
                                             m_effects.size()));
    for (std::size_t e = 0; e < m_effects.size(); ++e) {
        if (s.effects[e].name != m_effects[e].name)
            throw std::runtime_error(fmt::format("the saved state's effect {} is '{}', the scene's '{}'", e,
                                                 s.effects[e].name, m_effects[e].name));
        ByteReader in(s.effects[e].bytes);
        m_effects[e].effect->restore(in);
        if (!in.atEnd()) throw std::runtime_error("the saved state of effect '" + m_effects[e].name + "' is too long");
        m_effects[e].seconds = s.effects[e].seconds;
    }
    m_fluid.assignValues(s.fluid);  // in place: the effects hold their attributes by address
    m_time = s.time;
    m_step = s.step;
    m_totalImpulse = s.totalImpulse;
    m_totalAngular = s.totalAngular;
    m_peakForce = s.peakForce;
    m_stats = s.stats;
    ByteReader pressure(s.pressure);
    m_pressure->restore(pressure);
    if (!pressure.atEnd()) throw std::runtime_error("the saved state of the pressure solver is too long");
    // What the saved simulation computed at the end of its last step, from the same positions and order; the pressure
    // solver's coarse space is the saved one.
    moveBoundaries(m_time);
    updateNeighbours(false);
    computeDensities();
    m_pressure->computeFactors(context(0), m_fluid, false);
}

StepContext Simulation::context(Real dt) {
    return StepContext{dt,          m_time,          m_step,    m_kernel,       m_fluidNeighbours,
                       m_boundaryNeighbours, m_gradients, m_positionRows, m_density, *m_restDensity,
                       m_boundary,  m_stats,         m_loads};
}

std::vector<std::string> Simulation::effectNames() const {
    std::vector<std::string> names;
    for (const RunningEffect& e : m_effects) names.push_back(e.name);
    return names;
}

std::vector<EffectSummary> Simulation::effectSummaries() const {
    std::vector<EffectSummary> out;
    for (const RunningEffect& e : m_effects) out.push_back({e.name, e.seconds, e.effect->counters(m_stats.steps)});
    return out;
}

double Simulation::counter(std::string_view effect, std::string_view name) const {
    for (const RunningEffect& e : m_effects)
        if (e.name == effect)
            for (const Counter& c : e.effect->counters(m_stats.steps))
                if (c.name == name) return c.value;
    return 0;
}

void Simulation::moveBoundaries(Real t) {
    if (!m_boundary.anyMoving) {
        if (m_boundaryGrid.pointCount() != m_boundary.x.size()) m_boundaryGrid.build(m_boundary.x);
        return;
    }
    m_boundary.moveTo(t);
    m_boundaryGrid.build(m_boundary.x);
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
    m_positionRows.resize(n);
    resizeForRefill(m_gradients.fluid, m_fluidNeighbours.pairs());
    resizeForRefill(m_gradients.boundary, m_boundaryNeighbours.pairs());
    const auto& x = m_fluid.x();
    const auto& m = m_fluid.mass();
    const auto& rho0 = *m_restDensity;
    const auto& f = m_fluidNeighbours;
    const auto& b = m_boundaryNeighbours;
    forEachBlock(n, [&](std::size_t begin, std::size_t end) {
        sweeps::toRows(begin, end, x.data(), m_positionRows.data());
    });
    forEachBlock(n, [&](std::size_t begin, std::size_t end) {
        // The squared distances of the block's pairs first, then the kernel on all of them in one vectorised pass,
        // then the sums: rho_i = sum_j m_j W_ij + sum_k Psi_k W_ik, with Psi_k = rho_0 V_k [AIA+12].
        const std::size_t f0 = f.first(begin), nf = f.first(end) - f0, b0 = b.first(begin), nb = b.first(end) - b0;
        thread_local std::vector<Real> wf, wb;
        wf.resize(nf), wb.resize(nb);
        Real* gf = m_gradients.fluid.data() + f0;
        Real* gb = m_gradients.boundary.data() + b0;
        sweeps::squaredDistances(begin, end, f, m_positionRows.data(), gf);
        for (std::size_t i = begin; i < end; ++i)
            for (std::size_t p = b.first(i); p < b.last(i); ++p)
                gb[p - b0] = (x[i] - m_boundary.x[b.indices[p]]).squaredNorm();
        m_kernel.valuesAndGradients(nf, gf, wf.data());
        m_kernel.valuesAndGradients(nb, gb, wb.data());
        for (std::size_t i = begin; i < end; ++i) {
            Real rho = m[i] * m_kernel.W0();
            for (std::size_t p = f.first(i); p < f.last(i); ++p) rho += m[f.indices[p]] * wf[p - f0];
            for (std::size_t p = b.first(i); p < b.last(i); ++p)
                rho += rho0[i] * m_boundary.volume[b.indices[p]] * wb[p - b0];
            m_density[i] = rho;
        }
    });
}

Real Simulation::cflStep() const {
    const auto& v = m_fluid.v();
    const Real maxSpeed = std::sqrt(deterministicBlockReduce<Real>(
        v.size(),
        [&](std::size_t begin, std::size_t end) {
            Real s = 0;
            for (std::size_t i = begin; i != end; ++i) s = std::max(s, v[i].squaredNorm());
            return s;
        },
        Real(0), [](Real a, Real b) { return std::max(a, b); }));
    // [WKBB18 Alg. 1] dt <= 0.4 d / max|v|, d the particle diameter
    return maxSpeed > 0 ? m_timeStep.cfl * 2 * m_particleRadius / maxSpeed : std::numeric_limits<Real>::infinity();
}

Real Simulation::chooseDt(Real maxDt, Real cflStep) const {
    Real dt = m_timeStep.fixedDt;
    if (dt <= 0) dt = std::clamp(cflStep, m_timeStep.dtMin, m_timeStep.dtMax);
    return std::min(dt, maxDt);
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
    const std::size_t bad = deterministicBlockReduce<std::size_t>(
        x.size(),
        [&](std::size_t begin, std::size_t end) {
            for (std::size_t i = begin; i != end; ++i)
                if (!x[i].allFinite() || !v[i].allFinite()) return i;
            return x.size();
        },
        x.size(), [](std::size_t a, std::size_t b) { return std::min(a, b); });
    if (bad == x.size()) return;
    throw std::runtime_error(fmt::format(
        "step {} (t = {:.6f} s): particle id {} has a non-finite {} after the {} stage\n  fix: lower "
        "simulation.time_step.max, or check the scene for extreme values",
        m_step, m_time, m_fluid.id()[bad], x[bad].allFinite() ? "velocity" : "position", stage));
}

void Simulation::runStage(Stage stage, StepContext& ctx, const char* checkName) {
    const auto& effects = m_stages[std::size_t(stage)];
    for (std::size_t e : effects) {
        ScopedTimer t(m_effects[e].seconds);
        m_effects[e].effect->apply(ctx, m_fluid);
    }
    if (!effects.empty()) checkFinite(checkName);
}

void Simulation::step(Real maxDt) {
    const Real limit = cflStep();
    const Real dt = chooseDt(maxDt, limit);
    StepContext ctx = context(dt);
    if (dt > limit) {
        // Said once a run, then counted (report.json: simulation.steps_past_cfl, cfl_excess_max).
        if (m_stats.stepsPastCfl++ == 0)
            m_stats.warn(fmt::format("step {}: the time step {:.3g} s is {:.2g} times what the CFL condition allows at "
                                     "the fastest particle's {:.3g} m/s; particles outrun their neighbourhoods and the "
                                     "pressure solves lose accuracy; lower simulation.time_step.{}",
                                     m_step, dt, dt / limit, m_timeStep.cfl * 2 * m_particleRadius / limit,
                                     m_timeStep.fixedDt > 0 ? "fixed" : "min"));
        m_stats.cflExcess = std::max(m_stats.cflExcess, dt / limit);
    }
    m_loads.clear(m_boundary.names.size());
    runStage(Stage::Start, ctx, "start-of-step");
    const bool viscous = !m_stages[std::size_t(Stage::Viscosity)].empty();
    const ViscosityOrder::Kind order = viscous ? m_order.kind : ViscosityOrder::Kind::Predicted;
    const bool predicted = order == ViscosityOrder::Kind::Predicted;
    // Predicted: the divergence-free solve ends the previous step's motion at the start of this one, so that the
    // velocity carried between steps (and written to caches) is the one the particles moved with.
    if (predicted) divergenceFree(ctx);
    runStage(Stage::Forces, ctx, "forces");
    {
        ScopedTimer t(m_stats.time.pressure);
        // The warm start carries last step's pressures into this step's neighbourhoods. Beyond the CFL limit (a
        // fixed or minimum step the scene chose) particles outrun them: whole, they threw single particles out of a
        // honey block landing at 1 m/s at 5-20 m/s, one through the tank's floor (5 ms steps at r = 2.5 mm, 2.5x
        // the limit). There the warm start shrinks with the excess. Within the limit it stays whole: halved always,
        // as SPlisHSPlasH does, it cost the anchors 15-30 % more pressure iterations a step.
        m_pressure->applyWarmStart(ctx, m_fluid, dt > limit ? limit / dt : 1, m_gravity * dt);
    }
    // Predicted: viscosity acts on the velocity that already carries this step's forces and the pressure that held
    // them last step, so the constant-density solve after it only adds what changed. With the paper's order the
    // pressure's answer to gravity is advected before viscosity sees it: a honey blob on a floor spread 12 % further
    // at 5 ms steps than at 0.05 ms (0.7 % in this order), and a viscous column at rest crept at up to 2.7 cm/s
    // (0.2 cm/s in this order; both with DFSPH's Jacobi solver). Three coupled passes were as accurate, for three viscosity solves a step.
    if (viscous && predicted) runStage(Stage::Viscosity, ctx, "viscosity");
    const std::int64_t passes = order == ViscosityOrder::Kind::Coupled ? m_order.passes : 1;
    for (std::int64_t pass = 0; pass < passes; ++pass) {
        {
            ScopedTimer t(m_stats.time.pressure);
            m_pressure->solveDensity(ctx, m_fluid);
            checkFinite("constant-density");
        }
        if (order == ViscosityOrder::Kind::Coupled) runStage(Stage::Viscosity, ctx, "viscosity");
    }
    {
        ScopedTimer t(m_stats.time.advect);
        if (!m_boundary.x.empty()) m_contact.apply(ctx, m_fluid, m_boundaryGrid);
        auto& x = m_fluid.x();
        const auto& v = m_fluid.v();
        forEachParticle(x.size(), [&](std::size_t i) { x[i] += dt * v[i]; });
        removeEscaped();
    }
    const std::size_t before = m_fluid.size();
    runStage(Stage::Emit, ctx, "emit");
    // Added particles sit on the sampler's lattice, so their masses say their rest density, as at the start.
    for (std::size_t i = before; i < m_fluid.size(); ++i) (*m_restDensity)[i] = m_fluid.mass()[i] * m_latticeSum;
    m_stats.addedParticles += m_fluid.size() - before;
    {
        ScopedTimer t(m_stats.time.neighbours);
        moveBoundaries(m_time + dt);
        updateNeighbours(true);
        computeDensities();
        m_pressure->computeFactors(ctx, m_fluid);
    }
    if (!predicted) divergenceFree(ctx);
    if (order == ViscosityOrder::Kind::Paper) runStage(Stage::Viscosity, ctx, "viscosity");  // Algorithm 1
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

void Simulation::divergenceFree(StepContext& ctx) {
    ScopedTimer t(m_stats.time.divergence);
    m_pressure->solveDivergence(ctx, m_fluid);
    checkFinite("divergence-free");
}

bool Simulation::advancePast(Real t, const std::function<bool()>& keepGoing) {
    const bool viscous = !m_stages[std::size_t(Stage::Viscosity)].empty();
    if (viscous && m_order.kind != ViscosityOrder::Kind::Predicted) return advanceTo(t, keepGoing);
    // Ending a step on every frame cost buckling's anchor 235 steps a second instead of 219 (24 frames).
    while (!reached(t)) {
        if (keepGoing && !keepGoing()) return false;
        step();
    }
    return true;
}

void Simulation::writeAt(Real t, const FrameWriter& write) {
    const Real back = m_time - t;
    if (!(back > 0)) {
        write(m_fluid, m_boundary.movingBodies());
        return;
    }
    // The positions at t in place of the step's end for the write, then the end's restored to the bit.
    auto& x = m_fluid.x();
    const auto& v = m_fluid.v();
    std::vector<Vec3> end = x;
    struct Restore {
        std::vector<Vec3>& x;
        std::vector<Vec3>& end;
        ~Restore() { x.swap(end); }
    } restore{x, end};
    forEachParticle(x.size(), [&](std::size_t i) { x[i] -= back * v[i]; });
    write(m_fluid, m_boundary.movingBodies(t));
}

bool Simulation::advanceTo(Real t, const std::function<bool()>& keepGoing) {
    while (!reached(t)) {
        if (keepGoing && !keepGoing()) return false;
        const Real left = t - m_time;
        const Real dt = chooseDt(left, cflStep());
        // Never end on a sliver: the constant-density solve removes the leftover compression within one step, so
        // a step of a microsecond before a frame turned a normal residual into a 9 MN push on the tank (and the
        // warm start carried that pressure on). Between one and two steps left, take two halves.
        step(left > dt && left < 2 * dt ? left / 2 : left);
    }
    return true;
}

}  // namespace ganache
