// `ganache study`: what accuracy costs in time. Sweeps, one at a time from ganache's defaults, the settings that
// trade accuracy for speed, on four cases (scenes/study/), and measures for each run the wall time per simulated
// second and the error against an exact answer or a converged reference. Writes study.csv, one chart per case and
// report.md.

#include "tools/study/study.h"

#include "core/errors.h"
#include "io/atomic_file.h"
#include "physics/simulation.h"
#include "physics/viscosity/viscosity.h"
#include "sampler/sampler.h"
#include "scene/scene.h"
#include "tools/study/chart.h"

#include <fmt/format.h>
#include <tbb/global_control.h>
#include <tbb/info.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <functional>
#include <map>
#include <numeric>
#include <sstream>

namespace ganache {

namespace fs = std::filesystem;

namespace {

constexpr Real kPi = 3.14159265358979323846;
constexpr Real kQuickRadius = 1.26, kQuickTime = 0.25;  // --quick: radius factor and fraction of each case's time

// --- the knobs ---------------------------------------------------------------------------------------------

/// One setting of one knob; `apply` edits the simulation's set-up at the point's resolution.
struct Point {
    std::string label;
    bool isDefault = false;
    Real radiusFactor = 1;  ///< times the preview radius
    std::function<void(SimulationSetup&)> apply = [](SimulationSetup&) {};
};

struct Knob {
    std::string name, meaning;
    std::vector<Point> points;  ///< from cheapest (or least accurate) to dearest, the default among them
};

Point viscosityPoint(std::string label, bool isDefault, std::function<void(ViscosityParams&)> edit) {
    return {std::move(label), isDefault, 1, [edit](SimulationSetup& s) { edit(s.editEffect<ViscosityParams>("viscosity")); }};
}

Point pressurePoint(Real densityError, bool isDefault) {
    return {fmt::format("{:g} / {:g}", densityError, 10 * densityError), isDefault, 1, [densityError](SimulationSetup& s) {
                s.pressure.densityError = densityError;
                s.pressure.divergenceError = 10 * densityError;
            }};
}

Point fixedStepPoint(Real dt) {
    return {fmt::format("fixed {:g} ms", dt * 1000), false, 1, [dt](SimulationSetup& s) { s.timeStep.fixedDt = dt; }};
}

Point cflPoint(Real cfl, bool isDefault) {
    return {fmt::format("cfl {:g}", cfl), isDefault, 1, [cfl](SimulationSetup& s) { s.timeStep.cfl = cfl; }};
}

/// The knobs, in the order the report lists them; `quick` keeps two points of each (the default and one more).
std::vector<Knob> knobs(bool quick) {
    using P = ViscosityParams;
    std::vector<Knob> all;
    Knob tol{"viscosity_tolerance", "effects.viscosity.tolerance: CG stops at this residual, relative to the correction", {}};
    for (Real t : {1e-1, 1e-2, 1e-3, 1e-4, 1e-5, 1e-6})
        tol.points.push_back(
            viscosityPoint(fmt::format("{:g}", t), t == P{}.tolerance, [t](P& p) { p.tolerance = t; }));
    all.push_back(tol);
    Knob stiff{"stiff_tolerance",
               "effects.viscosity.stiff_tolerance: where a solve has stiff particles (dt mu / (rho h^2) from 3,000) or "
               "viscosities differ, CG stops at this residual instead of `tolerance` (of the four cases only "
               "stiff_arm's solves are stiff)",
               {}};
    for (Real t : {1e-2, 3e-3, 1e-3, 1e-4, 1e-5})
        stiff.points.push_back(
            viscosityPoint(fmt::format("{:g}", t), t == P{}.stiffTolerance, [t](P& p) { p.stiffTolerance = t; }));
    all.push_back(stiff);
    Knob pressure{"pressure_tolerance",
                  "simulation.pressure.density_error / divergence_error: DFSPH's two solves stop at these", {}};
    for (Real e : {1e-2, 1e-3, 1e-4, 1e-5}) pressure.points.push_back(pressurePoint(e, e == 1e-4));
    all.push_back(pressure);
    Knob step{"time_step", "simulation.time_step: the CFL factor (steps at most 5 ms), or a fixed step", {}};
    step.points = {fixedStepPoint(5e-3), cflPoint(0.8, false), cflPoint(0.4, true), cflPoint(0.2, false),
                   fixedStepPoint(5e-4), fixedStepPoint(5e-5)};
    all.push_back(step);
    Knob resolution{"resolution", "particle radius, as a factor of the preview radius (particles x 0.5, x 1, x 2)", {}};
    for (Real f : {1.26, 1.0, 0.794}) resolution.points.push_back({fmt::format("r x {:g}", f), f == 1.0, f});
    all.push_back(resolution);
    Knob preconditioner{"preconditioner", "effects.viscosity.preconditioner", {}};
    preconditioner.points = {
        viscosityPoint("none", false, [](P& p) { p.preconditioner = P::Preconditioner::None; }),
        viscosityPoint("block_jacobi", false, [](P& p) { p.preconditioner = P::Preconditioner::BlockJacobi; }),
        viscosityPoint("rigid", false, [](P& p) { p.preconditioner = P::Preconditioner::Rigid; }),
        viscosityPoint("clusters", true, [](P& p) { p.preconditioner = P::Preconditioner::Clusters; })};
    all.push_back(preconditioner);
    Knob warm{"warm_start", "effects.viscosity.warm_start", {}};
    warm.points = {viscosityPoint("off", false, [](P& p) { p.warmStart = false; }),
                   viscosityPoint("on", true, [](P& p) { p.warmStart = true; })};
    all.push_back(warm);
    Knob method{"viscosity_method", "effects.viscosity.method (explicit and takahashi2015 exist for comparison)", {}};
    method.points = {viscosityPoint("explicit", false,
                                    [](P& p) {
                                        p.method = P::Method::Explicit;
                                        p.maxIterations = 100'000'000;
                                    }),
                     viscosityPoint("takahashi2015", false,
                                    [](P& p) {
                                        p.method = P::Method::Takahashi2015;
                                        p.preconditioner = P::Preconditioner::BlockJacobi;
                                    }),
                     viscosityPoint("weiler2018", true, [](P&) {})};
    all.push_back(method);
    Knob order{"viscosity_order", "simulation.viscosity_coupling: where the viscosity solve sits in a step", {}};
    auto orderPoint = [](std::string label, bool isDefault, ViscosityOrder o) {
        return Point{std::move(label), isDefault, 1, [o](SimulationSetup& s) { s.viscosityOrder = o; }};
    };
    order.points = {orderPoint("paper", false, {ViscosityOrder::Kind::Paper, 1}),
                    orderPoint("predicted", true, {ViscosityOrder::Kind::Predicted, 1}),
                    orderPoint("coupled 3", false, {ViscosityOrder::Kind::Coupled, 3})};
    all.push_back(order);
    Knob solver{"pressure_solver", "simulation.pressure.solver: how DFSPH's solves reach their tolerance", {}};
    auto solverPoint = [](std::string label, bool isDefault, PressureSettings::Solver which) {
        return Point{std::move(label), isDefault, 1, [which](SimulationSetup& s) { s.pressure.solver = which; }};
    };
    solver.points = {solverPoint("jacobi", false, PressureSettings::Solver::Jacobi),
                     solverPoint("mprgp", true, PressureSettings::Solver::Mprgp)};
    all.push_back(solver);
    Knob divergence{"divergence_minimum",
                    "simulation.pressure.min_divergence_iterations: fewest divergence-free iterations a step (two "
                    "after an impact whatever this says, impact_iterations)",
                    {}};
    auto divergencePoint = [](std::int64_t fewest) {
        return Point{fmt::format("{}", fewest), fewest == PressureSettings{}.minDivergenceIterations, 1,
                     [fewest](SimulationSetup& s) { s.pressure.minDivergenceIterations = fewest; }};
    };
    divergence.points = {divergencePoint(2), divergencePoint(1)};
    all.push_back(divergence);
    if (quick)  // the cheapest setting and the default: every knob, chart and sentence of the report is exercised
        for (Knob& k : all) {
            const Point cheapest = k.points.front();
            const Point defaults = *std::find_if(k.points.begin(), k.points.end(), [](const Point& p) { return p.isDefault; });
            k.points = {cheapest, defaults};
        }
    return all;
}

// --- the cases ---------------------------------------------------------------------------------------------

using Metrics = std::map<std::string, Real>;

struct Case {
    std::string name, file, title, errorMeaning;
    /// Adjusts the scene loaded at a run's resolution (after the knob's setting); may be empty.
    std::function<void(Scene&)> prepare;
    /// Quantities of the finished run, from the particles at t = 0 and the simulation at the end.
    std::function<Metrics(const Scene&, const ParticleSet& initial, const Simulation& end)> measure;
    /// The error of a run; `reference` is empty for cases with an exact answer.
    std::function<Real(const Metrics& run, const Metrics& reference)> error;
    bool needsReference = false;
    /// Settings the case does not run, as "knob=setting", with the reason the report gives.
    std::map<std::string, std::string> notRun = {};
    /// Why the case leaves out this setting of this knob; null where it runs it.
    const std::string* skips(const std::string& knob, const std::string& setting) const {
        const auto it = notRun.find(knob + "=" + setting);
        return it == notRun.end() ? nullptr : &it->second;
    }
};

Real angularMomentumKept(const ParticleSet& initial, const ParticleSet& end) {
    auto momentum = [](const ParticleSet& p) {
        Vec3 centre = Vec3::Zero(), l = Vec3::Zero();
        Real mass = 0;
        for (std::size_t i = 0; i < p.size(); ++i) {
            centre += p.mass()[i] * p.x()[i];
            mass += p.mass()[i];
        }
        centre /= mass;
        for (std::size_t i = 0; i < p.size(); ++i) l += p.mass()[i] * (p.x()[i] - centre).cross(p.v()[i]);
        return l;
    };
    const Vec3 l0 = momentum(initial);
    return momentum(end).dot(l0) / l0.squaredNorm();
}

PlaneBoundary& planeNamed(Scene& scene, const std::string& name) {
    for (auto& b : scene.boundaries)
        if (b.name == name)
            if (auto* plane = std::get_if<PlaneBoundary>(&b.shape)) return *plane;
    throw InputError(fmt::format("{}: the Couette case needs plane boundaries named 'bottom' and 'top'",
                                 scene.file.string()));
}

const PlaneBoundary& planeNamed(const Scene& scene, const std::string& name) {
    return planeNamed(const_cast<Scene&>(scene), name);
}

/// The sampler keeps fluid one lattice spacing d = 2r from a wall (the wall stands in for a layer of fluid), so
/// the plates go one spacing below the layer's lowest row and above its highest, at every resolution; the
/// scene file has them there for the preview radius.
void placeCouettePlates(Scene& scene) {
    const auto& box = std::get<BoxShape>(scene.fluids.front().shape);
    const Real d = 2 * scene.particleRadius;
    const Real rows = std::round((box.max.y() - box.min.y()) / d);
    const Real centre = 0.5 * (box.min.y() + box.max.y());
    planeNamed(scene, "bottom").point.y() = centre - 0.5 * (rows - 1) * d - d;
    planeNamed(scene, "top").point.y() = centre + 0.5 * (rows - 1) * d + d;
}

/// Start-up Couette flow between a wall at y0 and one at y0 + H that moves at U from t = 0: the RMS of
/// (u_x - exact) / U over the particles in the middle third of the layer.
Metrics couetteMetrics(const Scene& scene, const ParticleSet&, const Simulation& sim) {
    const Real y0 = planeNamed(scene, "bottom").point.y();
    const Real height = planeNamed(scene, "top").point.y() - y0;
    const BodyMotion* top = nullptr;
    for (const auto& b : scene.boundaries)
        if (b.name == "top") top = &b.motion;
    const Real t = sim.time();
    const Real speed = top->translationVelocity(0.5 * t).x();
    const auto& viscosity = dynamic_cast<const ViscosityParams&>(*scene.findEffect("viscosity")->params);
    const Material& material = scene.fluids.front().material;
    const Real nu = viscosity.mu.value_or(material.mu) / material.density;
    const auto& box = std::get<BoxShape>(scene.fluids.front().shape);
    const Real centre = 0.5 * (box.min.x() + box.max.x()), third = (box.max.x() - box.min.x()) / 6;
    auto exact = [&](Real y) {
        const Real eta = (y - y0) / height;
        Real u = eta;
        for (int n = 1; n <= 200; ++n)
            u -= 2 * (n % 2 ? 1 : -1) / (n * kPi) * std::sin(n * kPi * eta) *
                 std::exp(-n * n * kPi * kPi * nu * t / (height * height));
        return speed * u;
    };
    Real sum = 0, worst = 0;
    std::size_t count = 0;
    const ParticleSet& p = sim.particles();
    for (std::size_t i = 0; i < p.size(); ++i) {
        if (std::abs(p.x()[i].x() - centre) > third) continue;
        const Real e = (p.v()[i].x() - exact(p.x()[i].y())) / speed;
        sum += e * e;
        worst = std::max(worst, std::abs(e));
        ++count;
    }
    return {{"rms_error", std::sqrt(sum / Real(std::max<std::size_t>(count, 1)))}, {"max_error", worst}};
}

/// Spread (RMS horizontal distance from the centroid's vertical) [m], centroid height [m], and mean compression
/// max(0, rho / rho_0 - 1) over the particles.
Metrics slumpMetrics(const Scene&, const ParticleSet&, const Simulation& sim) {
    const ParticleSet& p = sim.particles();
    const auto& restDensity = sim.restDensity();
    Vec3 c = Vec3::Zero();
    for (const Vec3& x : p.x()) c += x;
    c /= Real(p.size());
    Real spread = 0, compression = 0;
    for (std::size_t i = 0; i < p.size(); ++i) {
        const Vec3 d = p.x()[i] - c;
        spread += d.x() * d.x() + d.z() * d.z();
        compression += std::max<Real>(0, sim.density()[i] / restDensity[i] - 1);
    }
    return {{"spread_m", std::sqrt(spread / Real(p.size()))}, {"centroid_height_m", c.y()},
            {"compression", compression / Real(p.size())}};
}

/// The RMS speed [m/s] of the particles' velocities less the rigid motion (translation and rotation about the centre
/// of mass) that fits them best in the least-squares sense, and that rotation's rate [rad/s].
Metrics deformationMetrics(const Scene&, const ParticleSet&, const Simulation& sim) {
    const ParticleSet& p = sim.particles();
    Real mass = 0;
    Vec3 centre = Vec3::Zero(), momentum = Vec3::Zero();
    for (std::size_t i = 0; i < p.size(); ++i) {
        mass += p.mass()[i];
        centre += p.mass()[i] * p.x()[i];
        momentum += p.mass()[i] * p.v()[i];
    }
    centre /= mass;
    const Vec3 velocity = momentum / mass;
    Mat3 inertia = Mat3::Zero();
    Vec3 angular = Vec3::Zero();
    for (std::size_t i = 0; i < p.size(); ++i) {
        const Vec3 r = p.x()[i] - centre;
        inertia += p.mass()[i] * (r.squaredNorm() * Mat3::Identity() - r * r.transpose());
        angular += p.mass()[i] * r.cross(p.v()[i] - velocity);
    }
    const Vec3 rate = inertia.ldlt().solve(angular);
    Real squares = 0;
    for (std::size_t i = 0; i < p.size(); ++i)
        squares += p.mass()[i] * (p.v()[i] - velocity - rate.cross(p.x()[i] - centre)).squaredNorm();
    return {{"deformation_speed", std::sqrt(squares / mass)}, {"rotation_rate", rate.norm()}};
}

std::vector<Case> cases() {
    Case cube{"spinning_cube", "spinning_cube.yaml",
              "a viscous cube spinning in zero gravity (exact: angular momentum stays)",
              "angular momentum lost or gained, |1 - L(T).L(0) / |L(0)|^2|", nullptr, nullptr, nullptr};
    cube.measure = [](const Scene&, const ParticleSet& initial, const Simulation& sim) {
        return Metrics{{"angular_momentum_kept", angularMomentumKept(initial, sim.particles())}};
    };
    cube.error = [](const Metrics& m, const Metrics&) { return std::abs(1 - m.at("angular_momentum_kept")); };
    Case couette{"couette", "couette.yaml", "start-up of plane Couette flow (exact: a Fourier series)",
                 "RMS velocity error over the middle third, relative to the plate's speed", placeCouettePlates,
                 couetteMetrics,
                 [](const Metrics& m, const Metrics&) { return m.at("rms_error"); }};
    Case bunny{"viscous_bunny", "viscous_bunny.yaml",
               "a viscous bunny slumping on the ground (against a converged reference run)",
               "relative difference of the spread from the reference's", nullptr, slumpMetrics,
               [](const Metrics& m, const Metrics& ref) { return std::abs(m.at("spread_m") / ref.at("spread_m") - 1); },
               true};
    Case stiff{"stiff_arm", "stiff_arm.yaml",
               "a stiff body with a thin arm resting on a slipping floor (exact: it keeps its shape)",
               "RMS speed of the particles less the body's best-fitting rigid motion, in m/s (the exact body creeps at "
               "a few micrometres per second)",
               nullptr, deformationMetrics,
               [](const Metrics& m, const Metrics&) { return m.at("deformation_speed"); }};
    stiff.notRun["viscosity_method=explicit"] =
        "explicit viscosity at 5e6 Pa s needs 2.9e7 sub-steps of 1.7e-10 s a step here, some 3e9 in all";
    return {cube, couette, bunny, stiff};
}

// --- running ---------------------------------------------------------------------------------------------

struct Run {
    std::string caseName, knob, label;
    bool isDefault = false;
    std::size_t particles = 0, steps = 0;
    Real simulated = 0, wall = 0;
    Real cgPerSolve = 0;
    std::size_t capHits = 0;
    Metrics metrics;
    Real error = std::numeric_limits<Real>::quiet_NaN();
    std::string failure;  ///< empty when the run finished
    std::string notRun;   ///< why the case leaves this setting out (then nothing ran)
    Real wallPerSecond() const { return wall / simulated; }
};

class Runner {
public:
    Runner(const fs::path& sceneDir, bool quick, std::function<int()> stopSignal)
        : m_dir(sceneDir), m_quick(quick), m_stopSignal(std::move(stopSignal)) {}

    /// Runs the case with the point's settings until the case's end time.
    Run run(const Case& c, const Point& point) {
        if (const int signal = stopSignal()) throw Interrupted(signal, "between two runs");
        // Quick mode: radii 1.26x (half the particles) and a quarter of each case's time.
        const Real factor = point.radiusFactor * (m_quick ? kQuickRadius : 1.0);
        Scene scene = loaded(c, factor);
        if (c.prepare) c.prepare(scene);
        SimulationSetup setup = simulationSetup(scene);
        point.apply(setup);
        Run r;
        r.caseName = c.name;
        r.label = point.label;
        r.isDefault = point.isDefault;
        const std::string key = fmt::format("{}@{}", c.name, scene.particleRadius);
        auto sample = m_samples.find(key);
        if (sample == m_samples.end()) sample = m_samples.emplace(key, sampleScene(scene)).first;
        const Real end = scene.frames.timeOf(scene.frames.end) * (m_quick ? kQuickTime : 1.0);
        try {
            Simulation sim(setup, sample->second.fluid, sample->second.boundaries);
            const ParticleSet initial = sim.particles();
            const auto start = std::chrono::steady_clock::now();
            if (!sim.advanceTo(end, [&] { return stopSignal() == 0; }))
                throw Interrupted(stopSignal(), "during a run");
            r.wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
            r.simulated = end;
            r.particles = sim.particles().size();
            r.steps = sim.stats().steps;
            r.cgPerSolve = sim.counter("viscosity", "iterations_per_solve");
            r.capHits = std::size_t(sim.counter("viscosity", "cap_hits"));
            r.metrics = c.measure(scene, initial, sim);
        } catch (const InputError&) {
            throw;
        } catch (const Interrupted&) {
            throw;
        } catch (const std::exception& e) {
            r.failure = e.what();
            r.simulated = end;
        }
        return r;
    }

private:
    int stopSignal() const { return m_stopSignal ? m_stopSignal() : 0; }

    /// The case's scene at `factor` times its preview radius, read (meshes included) once per case and factor.
    const Scene& loaded(const Case& c, Real factor) {
        const std::string key = fmt::format("{}@{}", c.name, factor);
        auto it = m_scenes.find(key);
        if (it != m_scenes.end()) return it->second;
        const fs::path file = m_dir / c.file;
        Scene scene = loadScene(file, Quality::parse("preview"));
        if (factor != 1) scene = loadScene(file, Quality::parse(fmt::format("{:.6g}", scene.previewScale * factor)));
        return m_scenes.emplace(key, std::move(scene)).first->second;
    }

    fs::path m_dir;
    bool m_quick;
    std::function<int()> m_stopSignal;
    std::map<std::string, Scene> m_scenes;    // by case and radius factor
    std::map<std::string, Sample> m_samples;  // by case and particle radius
};

// --- reporting ---------------------------------------------------------------------------------------------

std::string csvField(const std::string& s) {
    return s.find_first_of(",\"") == std::string::npos ? s : "\"" + s + "\"";
}

void writeCsv(const fs::path& path, const std::vector<Run>& runs, int threads) {
    std::set<std::string> metricNames;
    for (const Run& r : runs)
        for (const auto& [k, v] : r.metrics) metricNames.insert(k);
    std::ostringstream out;
    out << "case,knob,setting,default,threads,particles,steps,simulated_s,wall_s,wall_per_simulated_s,"
           "viscosity_iterations_per_solve,viscosity_cap_hits,error";
    for (const auto& m : metricNames) out << "," << m;
    out << ",failure\n";
    for (const Run& r : runs) {
        out << fmt::format("{},{},{},{},{},{},{},{:g},{:.6g},{:.6g},{:.3g},{},{:.6g}", r.caseName, r.knob,
                           csvField(r.label), r.isDefault ? 1 : 0, threads, r.particles, r.steps, r.simulated, r.wall,
                           r.failure.empty() && r.notRun.empty() ? r.wallPerSecond()
                                                                  : std::numeric_limits<Real>::quiet_NaN(),
                           r.cgPerSolve, r.capHits, r.error);
        for (const auto& m : metricNames) {
            const auto it = r.metrics.find(m);
            out << "," << (it == r.metrics.end() ? std::string() : fmt::format("{:.6g}", it->second));
        }
        out << "," << csvField(r.notRun.empty() ? r.failure : "not run: " + r.notRun) << "\n";
    }
    writeTextAtomically(path, out.str());
}

/// Errors below this are round-off (a method that keeps a quantity exactly): reported and plotted at it.
constexpr Real kRoundOff = 1e-12;

bool usable(const Run& r) { return r.failure.empty() && r.notRun.empty() && std::isfinite(r.error); }
Real shownError(const Run& r) { return std::max(r.error, kRoundOff); }

/// "halving the error costs x N time" between successive runs of one knob, ordered by time, where more time
/// bought less error.
std::string halvingSentence(const std::vector<const Run*>& runs) {
    std::vector<const Run*> sorted;
    for (const Run* r : runs)
        if (usable(*r)) sorted.push_back(r);
    std::sort(sorted.begin(), sorted.end(),
              [](const Run* a, const Run* b) { return a->wallPerSecond() < b->wallPerSecond(); });
    std::vector<std::string> parts;
    for (std::size_t k = 1; k < sorted.size(); ++k) {
        const Run& a = *sorted[k - 1];
        const Run& b = *sorted[k];
        const Real timeRatio = b.wallPerSecond() / a.wallPerSecond();
        const Real errorRatio = shownError(b) / shownError(a);
        if (a.error <= kRoundOff && b.error <= kRoundOff) {
            parts.push_back(fmt::format("{} -> {}: time x{:.2f}, both exact to round-off", a.label, b.label, timeRatio));
        } else if (errorRatio < 0.98 && timeRatio > 1.02) {
            const Real perHalving = std::pow(timeRatio, std::log(2.0) / std::log(1 / errorRatio));
            parts.push_back(fmt::format("{} -> {}: error x{:.2g} for time x{:.2f} (halving the error costs x{:.3g} "
                                        "time)",
                                        a.label, b.label, errorRatio, timeRatio, perHalving));
        } else {
            parts.push_back(fmt::format("{} -> {}: time x{:.2f}, error x{:.2g}: {}", a.label, b.label, timeRatio,
                                        errorRatio,
                                        errorRatio < 0.98    ? "more accurate for no more time"
                                        : errorRatio <= 1.02 ? "the same accuracy"
                                                             : "slower and less accurate"));
        }
    }
    return parts.empty() ? "too few finished runs to compare" : fmt::format("{}", fmt::join(parts, "; "));
}

std::string errorText(Real e) {
    if (std::isnan(e)) return "(reference)";
    return e <= kRoundOff ? "< 1e-12" : fmt::format("{:.3g}", e);
}

std::string formatMetric(const std::string& name, Real v) {
    if (name.size() > 2 && name.substr(name.size() - 2) == "_m") return fmt::format("{:.2f} mm", v * 1000);
    return fmt::format("{:.4g}", v);
}

void writeReport(const fs::path& dir, const std::vector<Case>& studied, const std::vector<Knob>& knobList,
                 const std::vector<Run>& runs, const std::map<std::string, Run>& references, bool quick, int threads) {
    std::ostringstream md;
    md << "# What accuracy costs in time\n\n";
    md << fmt::format("Written by `ganache study{}` ({} thread{}); every figure below comes from the runs in "
                      "`study.csv`. Each knob is moved on its own from ganache's defaults (marked *), which run again "
                      "beside each knob's other settings; time is wall time of the simulation per simulated second "
                      "(sampling excluded), on this machine.\n\n",
                      quick ? " --quick" : "", threads, threads == 1 ? "" : "s");
    if (quick) md << "**Quick mode**: radii 1.26 times larger (half the particles), a quarter of each case's time, "
                     "and two settings per knob; the "
                     "figures show the shape of the trade-offs, not their final values.\n\n";
    md << "Knobs:\n\n";
    for (const Knob& k : knobList) md << fmt::format("- `{}`: {}\n", k.name, k.meaning);
    for (const Case& c : studied) {
        md << fmt::format("\n## {}: {}\n\n", c.name, c.title);
        md << fmt::format("Scene `scenes/study/{}`. Error: {}.", c.file, c.errorMeaning);
        const auto ref = references.find(c.name);
        if (ref != references.end()) {
            md << " Reference run: viscosity tolerance 1e-6, DFSPH 1e-5 / 1e-4, fixed "
               << fmt::format("{:g} ms steps ({} particles, {} steps, {:.1f} s of wall time per simulated second)",
                              quick ? 0.5 : 0.05, ref->second.particles, ref->second.steps,
                              ref->second.wallPerSecond());
            if (!ref->second.failure.empty()) md << "; it failed: " << ref->second.failure;
            md << "; `resolution` compares with the finest run instead, since the reference has the base resolution";
        }
        md << fmt::format("\n\n![{} chart]({}.png)\n\n", c.name, c.name);
        md << "| knob | setting | particles | steps | time per sim. s | viscosity iter. per pass (explicit: sub-steps) | error | metrics |\n";
        md << "|---|---|---|---|---|---|---|---|\n";
        for (const Knob& k : knobList)
            for (const Run& r : runs)
                if (r.caseName == c.name && r.knob == k.name) {
                    std::vector<std::string> metrics;
                    for (const auto& [name, v] : r.metrics) metrics.push_back(name + " " + formatMetric(name, v));
                    if (!r.notRun.empty())
                        md << fmt::format("| {} | {} | | | | | not run | {} |\n", k.name, r.label, r.notRun);
                    else if (!r.failure.empty())
                        md << fmt::format("| {} | {}{} | | | | | failed | {} |\n", k.name, r.label,
                                          r.isDefault ? "*" : "", r.failure);
                    else
                        md << fmt::format("| {} | {}{} | {} | {} | {:.3g} s | {:.1f} | {} | {} |\n", k.name,
                                          r.label, r.isDefault ? "*" : "", r.particles, r.steps, r.wallPerSecond(),
                                          r.cgPerSolve, errorText(r.error), fmt::join(metrics, ", "));
                }
        md << "\nWhat each knob buys, between its settings ordered by time:\n\n";
        for (const Knob& k : knobList) {
            std::vector<const Run*> mine;
            for (const Run& r : runs)
                if (r.caseName == c.name && r.knob == k.name) mine.push_back(&r);
            md << fmt::format("- `{}`: {}\n", k.name, halvingSentence(mine));
        }
        // Pareto front: runs no other run beats in both time and error.
        std::vector<std::string> front;
        for (const Run& a : runs) {
            if (a.caseName != c.name || !usable(a)) continue;
            bool dominated = false;
            for (const Run& b : runs)
                if (&a != &b && b.caseName == c.name && usable(b) && b.wallPerSecond() <= a.wallPerSecond() &&
                    shownError(b) <= shownError(a) &&
                    (b.wallPerSecond() < a.wallPerSecond() || shownError(b) < shownError(a)))
                    dominated = true;
            if (!dominated)
                front.push_back(fmt::format("{} = {} ({:.3g} s, error {})", a.knob, a.label, a.wallPerSecond(),
                                            errorText(a.error)));
        }
        md << fmt::format("\nPareto front (no other run is both faster and more accurate): {}.\n",
                          fmt::join(front, "; "));
    }
    writeTextAtomically(dir / "report.md", md.str());
}

void writeChart(const fs::path& dir, const Case& c, const std::vector<Knob>& knobList, const std::vector<Run>& runs) {
    Chart chart;
    chart.title = c.name + ": error against time";
    chart.xLabel = "wall seconds per simulated second";
    chart.yLabel = "error (1e-12: exact to round-off)";
    for (std::size_t k = 0; k < knobList.size(); ++k) {
        ChartSeries s;
        s.label = knobList[k].name;
        s.colour = seriesColour(k);
        for (const Run& r : runs)
            if (r.caseName == c.name && r.knob == knobList[k].name) {
                s.points.emplace_back(usable(r) ? r.wallPerSecond() : Real(-1), shownError(r));
                // Every knob passes through the defaults: label that point once.
                s.pointLabels.push_back(r.isDefault ? (k == 0 ? "defaults" : "") : r.label);
            }
        chart.series.push_back(s);
    }
    writePng(dir / (c.name + ".png"), logLogChart(chart));
}

}  // namespace

void studyCommand(const StudyOptions& options) {
    if (options.threads < 0) throw InputError("--threads must be 0 (every core) or a positive number");
    const std::vector<Case> known = cases();
    std::vector<std::string> names, files;
    for (const Case& c : known) names.push_back(c.name), files.push_back(c.file);
    if (!fs::is_directory(options.scenes))
        throw InputError(fmt::format("{}: the study's scenes are not there\n  fix: run from the repository root, or "
                                     "pass --scenes DIR (the folder with {})",
                                     options.scenes.string(), fmt::join(files, ", ")));
    std::vector<Case> studied;
    for (const Case& c : known)
        if (options.cases.empty() || std::count(options.cases.begin(), options.cases.end(), c.name))
            studied.push_back(c);
    for (const std::string& name : options.cases)
        if (std::none_of(studied.begin(), studied.end(), [&](const Case& c) { return c.name == name; }))
            throw InputError(fmt::format("--case: no case '{}'\n  fix: one of {}", name, fmt::join(names, ", ")));
    const int threads = options.threads > 0 ? options.threads : tbb::info::default_concurrency();
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::size_t(threads));
    prepareOutputFolder(options.out, "--out");

    const std::vector<Knob> knobList = knobs(options.quick);
    std::size_t total = 0;
    for (const Case& c : studied) {
        total += c.needsReference ? 1 : 0;
        for (const Knob& k : knobList) total += k.points.size();
        for (const Knob& k : knobList)
            for (const Point& p : k.points) total -= c.skips(k.name, p.label) ? 1 : 0;
    }
    Runner runner(options.scenes, options.quick, options.stopSignal);
    std::vector<Run> runs;
    std::map<std::string, Run> references;
    std::size_t done = 0;
    auto note = [&](const Run& r) {
        ++done;
        if (r.failure.empty())
            fmt::print(stderr, "study [{}/{}] {} {} = {}: {:.2f} s wall for {:g} s ({} particles, {} steps)\n", done,
                       total, r.caseName, r.knob, r.label, r.wall, r.simulated, r.particles, r.steps);
        else
            fmt::print(stderr, "study [{}/{}] {} {} = {}: failed: {}\n", done, total, r.caseName, r.knob, r.label,
                       r.failure);
    };
    try {
        for (const Case& c : studied) {
            if (c.needsReference) {
                const Point tight{"reference", false, 1, [&](SimulationSetup& s) {
                                      s.editEffect<ViscosityParams>("viscosity").tolerance = 1e-6;
                                      s.pressure.densityError = 1e-5;
                                      s.pressure.divergenceError = 1e-4;
                                      s.timeStep.fixedDt = options.quick ? 5e-4 : 5e-5;
                                  }};
                Run ref = runner.run(c, tight);
                ref.knob = "reference";
                note(ref);
                references[c.name] = ref;
            }
            // Each knob runs the defaults again beside its other settings: this machine's speed drifts by tens of
            // percent within minutes, and a default timed once at the start of a case set every knob's ratios
            // against that moment (the stiff body's preconditioners read 1.8x apart in one such study, 1.3x side by
            // side).
            for (const Knob& k : knobList)
                for (const Point& p : k.points) {
                    Run r;
                    if (const std::string* why = c.skips(k.name, p.label)) {
                        r.caseName = c.name;
                        r.notRun = *why;
                    } else {
                        r = runner.run(c, p);
                        r.knob = k.name;
                        note(r);
                    }
                    r.knob = k.name;
                    r.label = p.label;
                    r.isDefault = p.isDefault;
                    runs.push_back(r);
                }
            // Errors: exact answers, or the reference (the finest run for the resolution knob).
            const Run* finest = nullptr;
            for (const Run& r : runs)
                if (r.caseName == c.name && r.knob == "resolution" && r.failure.empty() &&
                    (!finest || r.particles > finest->particles))
                    finest = &r;
            for (Run& r : runs) {
                if (r.caseName != c.name || !r.failure.empty() || !r.notRun.empty()) continue;
                if (!c.needsReference) {
                    r.error = c.error(r.metrics, {});
                } else {
                    const Run* ref = r.knob == "resolution" ? finest : &references[c.name];
                    if (ref && ref->failure.empty() && ref != &r) r.error = c.error(r.metrics, ref->metrics);
                }
            }
            writeChart(options.out, c, knobList, runs);
        }
    } catch (const Interrupted& e) {
        throw Interrupted(e.signal(),
                          fmt::format("study: {} {} after {} of {} runs; the charts of the cases finished are in {}, "
                                      "study.csv and report.md need every run and were not written\n  continue: run "
                                      "the same command again (the study starts over)",
                                      strsignal(e.signal()), e.what(), done, total, options.out.string()));
    }
    std::vector<Run> all = runs;
    for (const auto& [name, r] : references) all.push_back(r);
    writeCsv(options.out / "study.csv", all, threads);
    writeReport(options.out, studied, knobList, runs, references, options.quick, threads);
    fmt::print(stderr, "study: {} runs; wrote {}, {} and one chart per case\n", done,
               (options.out / "study.csv").string(), (options.out / "report.md").string());
}

}  // namespace ganache
