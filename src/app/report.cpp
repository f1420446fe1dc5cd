#include "app/report.h"

#include "io/atomic_file.h"
#include "physics/emitter.h"
#include "physics/simulation.h"
#include "scene/scene.h"

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <sys/resource.h>

#include <cmath>

namespace ganache {

std::size_t peakMemoryBytes() {
    rusage usage{};
    getrusage(RUSAGE_SELF, &usage);
    return std::size_t(usage.ru_maxrss) * 1024;  // Linux reports kilobytes
}

using Json = nlohmann::ordered_json;

struct RunReport::Data {
    Json simulation;  // empty until the simulate stage ran
    Json bodies = Json::array();
    Json emitters = Json::array();
    Json measurements = Json::object();
};

RunReport::RunReport(const Scene& scene, int threads)
    : m_scene(scene), m_threads(threads), m_data(std::make_unique<Data>()) {}

RunReport::~RunReport() = default;

void RunReport::measure(const std::string& path, double value) {
    m_data->measurements[Json::json_pointer("/" + path)] = value;
}

void RunReport::measureCount(const std::string& path, std::uint64_t value) {
    m_data->measurements[Json::json_pointer("/" + path)] = value;
}

StageRecord& RunReport::addStage(const std::string& name) {
    m_stages.push_back({name, "done", 0, -1, "", {}});
    return m_stages.back();
}

void RunReport::setCounts(std::size_t fluid, std::size_t boundary) {
    m_fluid = fluid;
    m_boundary = boundary;
}

void RunReport::setSimulation(const SolverStats& s, double simulatedTime, const std::vector<EffectSummary>& effects,
                              std::size_t finalFluid) {
    const double steps = double(std::max<std::size_t>(s.steps, 1));
    auto ms = [&](double seconds) { return 1000 * seconds / steps; };
    Json perStep{{"pressure", ms(s.time.pressure)},
                 {"advect", ms(s.time.advect)},
                 {"neighbours", ms(s.time.neighbours)},
                 {"divergence", ms(s.time.divergence)}};
    Json solver{{"pressure_iterations_per_step", double(s.pressureIterations) / steps},
                {"pressure_cap_hits", s.pressureCapHits},
                {"divergence_iterations_per_step", double(s.divergenceIterations) / steps},
                {"divergence_cap_hits", s.divergenceCapHits}};
    Json names = Json::array();
    double total = s.time.total();
    for (const EffectSummary& e : effects) {
        names.push_back(e.name);
        perStep[e.name] = ms(e.seconds);
        total += e.seconds;
        for (const Counter& c : e.counters) {
            // Counts stay whole numbers in the JSON.
            const bool whole = std::floor(c.value) == c.value && std::abs(c.value) < 9e15;
            solver[e.name + "_" + c.name] = whole ? Json(std::int64_t(c.value)) : Json(c.value);
        }
    }
    perStep["total"] = ms(total);
    m_data->simulation = Json{{"steps", s.steps},
                              {"simulated_time_s", simulatedTime},
                              {"effects_ran", names},
                              {"dt_s", {{"min", s.steps ? s.dtMin : 0.0}, {"max", s.dtMax}}},
                              {"per_step_ms", perStep},
                              {"solver", solver},
                              {"particles_removed", s.removedParticles},
                              {"particles_added", s.addedParticles},
                              {"boundary_contacts", s.boundaryContacts},
                              {"steps_past_cfl", s.stepsPastCfl},
                              {"cfl_excess_max", s.cflExcess},
                              {"fluid_particles_at_end", finalFluid},
                              {"warning_count", s.warningCount}};
    m_warnings.insert(m_warnings.end(), s.warnings.begin(), s.warnings.end());
}

void RunReport::setBodies(const std::vector<std::string>& names, const std::vector<BodyReport>& bodies) {
    auto vec = [](const Vec3& v) { return Json::array({v.x(), v.y(), v.z()}); };
    m_data->bodies = Json::array();
    for (std::size_t b = 0; b < bodies.size(); ++b)
        m_data->bodies.push_back({{"name", names[b]},
                            {"mean_force_N", vec(bodies[b].meanForce)},
                            {"mean_torque_Nm", vec(bodies[b].meanTorque)},
                            {"peak_force_N", bodies[b].peakForce}});
}

void RunReport::setEmitters(const std::vector<EmitterReport>& emitters) {
    m_data->emitters = Json::array();
    for (const auto& e : emitters)
        m_data->emitters.push_back({{"name", e.name}, {"particles_emitted", e.emitted}, {"sites_blocked", e.blocked}});
}

std::string RunReport::json() const {
    using json = Json;
    const Json& simulation = m_data->simulation;
    json j;
    j["ganache_version"] = GANACHE_VERSION;
    j["scene"] = {{"name", m_scene.name}, {"file", m_scene.file.string()}, {"hash_fnv1a64", m_scene.hash}};
    j["result"] = {{"status", m_status}, {"error", m_why}};
    j["quality"] = m_scene.quality.str();
    j["particle_radius_m"] = m_scene.particleRadius;
    j["threads"] = m_threads;
    j["settings"] = json::parse(effectiveJson(*m_scene.effective));
    j["particles"] = {{"fluid", m_fluid}, {"boundary", m_boundary}};
    j["frames"] = m_lastFrame >= m_firstFrame ? json{{"first", m_firstFrame}, {"last", m_lastFrame}} : json(nullptr);
    const bool simulated = !simulation.is_null();
    j["steps"] = simulated ? simulation["steps"] : json(0);
    j["simulated_time_s"] = simulated ? simulation["simulated_time_s"] : json(0.0);
    json effects = json::array();
    for (const auto& e : m_scene.effects) effects.push_back(e.name);
    j["effects_requested"] = effects;
    j["effects_ran"] = simulated ? simulation["effects_ran"] : json::array();
    json stages = json::array();
    for (const auto& s : m_stages)
        stages.push_back({{"name", s.name},
                          {"status", s.status},
                          {"wall_s", s.seconds},
                          {"frames_done", s.frames >= 0 ? json(s.frames) : json(nullptr)},
                          {"note", s.note},
                          {"outputs", s.outputs}});
    j["stages"] = stages;
    j["per_step_ms"] = simulated ? simulation["per_step_ms"] : json::object();
    j["solver"] = simulated ? simulation["solver"] : json::object();
    if (simulated)
        j["simulation"] = {{"dt_s", simulation["dt_s"]},
                           {"particles_removed", simulation["particles_removed"]},
                           {"particles_added", simulation["particles_added"]},
                           {"boundary_contacts", simulation["boundary_contacts"]},
                           {"steps_past_cfl", simulation["steps_past_cfl"]},
                           {"cfl_excess_max", simulation["cfl_excess_max"]},
                           {"fluid_particles_at_end", simulation["fluid_particles_at_end"]},
                           {"warning_count", simulation["warning_count"]}};
    j["bodies"] = m_data->bodies;
    j["emitters"] = m_data->emitters;
    j["measurements"] = m_data->measurements;
    j["warnings"] = m_warnings;
    j["wall_s"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - m_start).count();
    j["peak_memory_bytes"] = peakMemoryBytes();
    return j.dump(2) + "\n";
}

std::string RunReport::table() const {
    std::string t = fmt::format("ganache: scene '{}' ({} quality, r = {} m, {} threads)\n", m_scene.name,
                                m_scene.quality.str(), formatNumber(m_scene.particleRadius), m_threads);
    t += fmt::format("  {:<10} {:<14} {:>9}  {}\n", "stage", "status", "wall [s]", "note");
    for (const auto& s : m_stages)
        t += fmt::format("  {:<10} {:<14} {:>9.3f}  {}\n", s.name, s.status, s.seconds, s.note);
    t += fmt::format("  particles: {} fluid, {} boundary; peak memory {:.1f} MiB\n", m_fluid, m_boundary,
                     double(peakMemoryBytes()) / (1024.0 * 1024.0));
    const Json& simulation = m_data->simulation;
    if (!simulation.is_null()) {
        // Per step: the step's own parts, then each effect that ran.
        std::string parts;
        for (const auto& [name, value] : simulation["per_step_ms"].items())
            if (name != "total") parts += fmt::format("{} {:.2f} ms, ", name, value.get<double>());
        t += fmt::format("  {} steps, per step: {}total {:.2f} ms\n", simulation["steps"].get<std::size_t>(), parts,
                         simulation["per_step_ms"]["total"].get<double>());
        const auto& sv = simulation["solver"];
        t += fmt::format("  iterations: pressure {:.1f}/step, divergence {:.1f}/step{}\n",
                         sv["pressure_iterations_per_step"].get<double>(),
                         sv["divergence_iterations_per_step"].get<double>(),
                         sv.contains("viscosity_iterations_per_solve")
                             ? fmt::format(", viscosity {:.1f}/solve (CG; explicit: sub-steps)",
                                           sv["viscosity_iterations_per_solve"].get<double>())
                             : std::string());
    }
    for (const auto& b : m_data->bodies)
        t += fmt::format("  body {}: mean force [{:.3g}, {:.3g}, {:.3g}] N, peak {:.3g} N\n", b["name"].get<std::string>(),
                         b["mean_force_N"][0].get<double>(), b["mean_force_N"][1].get<double>(),
                         b["mean_force_N"][2].get<double>(), b["peak_force_N"].get<double>());
    for (const auto& e : m_data->emitters)
        t += fmt::format("  emitter {}: {} particles emitted, {} sites blocked\n", e["name"].get<std::string>(),
                         e["particles_emitted"].get<std::size_t>(), e["sites_blocked"].get<std::size_t>());
    const std::size_t shown = std::min<std::size_t>(m_warnings.size(), 5);
    for (std::size_t w = 0; w < shown; ++w) t += "  warning: " + m_warnings[w] + "\n";
    if (m_warnings.size() > shown) t += fmt::format("  ... {} more warnings in report.json\n", m_warnings.size() - shown);
    return t;
}

void RunReport::write(const std::filesystem::path& path) const { writeTextAtomically(path, json()); }

}  // namespace ganache
