#include "app/report.h"

#include "io/atomic_file.h"
#include "scene/scene.h"
#include "physics/simulation.h"

#include <fmt/format.h>

#include <sys/resource.h>

namespace ganache {

std::size_t peakMemoryBytes() {
    rusage usage{};
    getrusage(RUSAGE_SELF, &usage);
    return std::size_t(usage.ru_maxrss) * 1024;  // Linux reports kilobytes
}

RunReport::RunReport(const Scene& scene, int threads) : m_scene(scene), m_threads(threads) {}

StageRecord& RunReport::addStage(const std::string& name) {
    m_stages.push_back({name, "done", 0, "", {}});
    return m_stages.back();
}

void RunReport::setCounts(std::size_t fluid, std::size_t boundary) {
    m_fluid = fluid;
    m_boundary = boundary;
}

void RunReport::setSimulation(const SolverStats& s, double simulatedTime, const std::vector<std::string>& effects,
                              std::size_t finalFluid) {
    using json = nlohmann::ordered_json;
    const double steps = double(std::max<std::size_t>(s.steps, 1));
    auto ms = [&](double seconds) { return 1000 * seconds / steps; };
    m_simulation = json{
        {"steps", s.steps},
        {"simulated_time_s", simulatedTime},
        {"effects_ran", effects},
        {"dt_s", {{"min", s.steps ? s.dtMin : 0.0}, {"max", s.dtMax}}},
        {"per_step_ms",
         {{"heat", ms(s.time.heat)}, {"forces", ms(s.time.forces)}, {"pressure", ms(s.time.pressure)}, {"advect", ms(s.time.advect)},
          {"emit", ms(s.time.emit)}, {"neighbours", ms(s.time.neighbours)}, {"divergence", ms(s.time.divergence)},
          {"viscosity", ms(s.time.viscosity)}, {"end_of_step", ms(s.time.endOfStep)}, {"total", ms(s.time.total())}}},
        {"solver",
         {{"pressure_iterations_per_step", double(s.pressureIterations) / steps},
          {"pressure_cap_hits", s.pressureCapHits},
          {"divergence_iterations_per_step", double(s.divergenceIterations) / steps},
          {"divergence_cap_hits", s.divergenceCapHits},
          {"viscosity_solves", s.viscositySolves},
          {"viscosity_iterations_per_solve",
           s.viscositySolves ? double(s.viscosityIterations) / double(s.viscositySolves) : 0.0},
          {"viscosity_cap_hits", s.viscosityCapHits},
          {"viscosity_worst_residual", s.viscosityWorstResidual},
          {"heat_substeps_per_step", double(s.heatSubsteps) / steps},
          {"heat_substeps_max", s.heatSubstepsMax}}},
        {"particles_removed", s.removedParticles},
        {"particles_emitted", s.emittedParticles},
        {"boundary_contacts", s.boundaryContacts},
        {"fluid_particles_at_end", finalFluid},
        {"warning_count", s.warningCount}};
    m_warnings.insert(m_warnings.end(), s.warnings.begin(), s.warnings.end());
}

void RunReport::setBodies(const std::vector<std::string>& names, const std::vector<BodyReport>& bodies) {
    auto vec = [](const Vec3& v) { return nlohmann::ordered_json::array({v.x(), v.y(), v.z()}); };
    m_bodies = nlohmann::ordered_json::array();
    for (std::size_t b = 0; b < bodies.size(); ++b)
        m_bodies.push_back({{"name", names[b]},
                            {"mean_force_N", vec(bodies[b].meanForce)},
                            {"mean_torque_Nm", vec(bodies[b].meanTorque)},
                            {"peak_force_N", bodies[b].peakForce}});
}

void RunReport::setEmitters(const std::vector<EmitterReport>& emitters) {
    m_emitters = nlohmann::ordered_json::array();
    for (const auto& e : emitters)
        m_emitters.push_back({{"name", e.name}, {"particles_emitted", e.emitted}, {"sites_blocked", e.blocked}});
}

nlohmann::ordered_json RunReport::toJson() const {
    using json = nlohmann::ordered_json;
    json j;
    j["ganache_version"] = GANACHE_VERSION;
    j["scene"] = {{"name", m_scene.name}, {"file", m_scene.file.string()}, {"hash_fnv1a64", m_scene.hash}};
    j["quality"] = m_scene.quality.str();
    j["particle_radius_m"] = m_scene.particleRadius;
    j["threads"] = m_threads;
    j["settings"] = m_scene.effective->values;
    j["particles"] = {{"fluid", m_fluid}, {"boundary", m_boundary}};
    j["frames"] = m_lastFrame >= m_firstFrame ? json{{"first", m_firstFrame}, {"last", m_lastFrame}} : json(nullptr);
    const bool simulated = !m_simulation.is_null();
    j["steps"] = simulated ? m_simulation["steps"] : json(0);
    j["simulated_time_s"] = simulated ? m_simulation["simulated_time_s"] : json(0.0);
    json effects = json::array();
    for (const auto& e : m_scene.effects) effects.push_back(e.name);
    j["effects_requested"] = effects;
    j["effects_ran"] = simulated ? m_simulation["effects_ran"] : json::array();
    json stages = json::array();
    for (const auto& s : m_stages)
        stages.push_back({{"name", s.name}, {"status", s.status}, {"wall_s", s.seconds}, {"note", s.note},
                          {"outputs", s.outputs}});
    j["stages"] = stages;
    j["per_step_ms"] = simulated ? m_simulation["per_step_ms"] : json::object();
    j["solver"] = simulated ? m_simulation["solver"] : json::object();
    if (simulated)
        j["simulation"] = {{"dt_s", m_simulation["dt_s"]},
                           {"particles_removed", m_simulation["particles_removed"]},
                           {"particles_emitted", m_simulation["particles_emitted"]},
                           {"boundary_contacts", m_simulation["boundary_contacts"]},
                           {"fluid_particles_at_end", m_simulation["fluid_particles_at_end"]},
                           {"warning_count", m_simulation["warning_count"]}};
    j["bodies"] = m_bodies;
    j["emitters"] = m_emitters;
    j["measurements"] = m_measurements;
    j["warnings"] = m_warnings;
    j["wall_s"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - m_start).count();
    j["peak_memory_bytes"] = peakMemoryBytes();
    return j;
}

std::string RunReport::table() const {
    std::string t = fmt::format("ganache: scene '{}' ({} quality, r = {} m, {} threads)\n", m_scene.name,
                                m_scene.quality.str(), formatNumber(m_scene.particleRadius), m_threads);
    t += fmt::format("  {:<10} {:<14} {:>9}  {}\n", "stage", "status", "wall [s]", "note");
    for (const auto& s : m_stages)
        t += fmt::format("  {:<10} {:<14} {:>9.3f}  {}\n", s.name, s.status, s.seconds, s.note);
    t += fmt::format("  particles: {} fluid, {} boundary; peak memory {:.1f} MiB\n", m_fluid, m_boundary,
                     double(peakMemoryBytes()) / (1024.0 * 1024.0));
    if (!m_simulation.is_null()) {
        const auto& ms = m_simulation["per_step_ms"];
        const auto& sv = m_simulation["solver"];
        const double heat = ms["heat"].get<double>();
        t += fmt::format("  {} steps, per step: {}neighbours {:.2f} ms, pressure {:.2f} ms, divergence {:.2f} ms, "
                         "viscosity {:.2f} ms, total {:.2f} ms\n",
                         m_simulation["steps"].get<std::size_t>(),
                         heat > 0 ? fmt::format("heat {:.2f} ms, ", heat) : std::string(),
                         ms["neighbours"].get<double>(), ms["pressure"].get<double>(), ms["divergence"].get<double>(),
                         ms["viscosity"].get<double>(), ms["total"].get<double>());
        t += fmt::format("  iterations: pressure {:.1f}/step, divergence {:.1f}/step, viscosity {:.1f}/solve (CG; explicit: sub-steps)\n",
                         sv["pressure_iterations_per_step"].get<double>(),
                         sv["divergence_iterations_per_step"].get<double>(),
                         sv["viscosity_iterations_per_solve"].get<double>());
    }
    for (const auto& b : m_bodies)
        t += fmt::format("  body {}: mean force [{:.3g}, {:.3g}, {:.3g}] N, peak {:.3g} N\n", b["name"].get<std::string>(),
                         b["mean_force_N"][0].get<double>(), b["mean_force_N"][1].get<double>(),
                         b["mean_force_N"][2].get<double>(), b["peak_force_N"].get<double>());
    for (const auto& e : m_emitters)
        t += fmt::format("  emitter {}: {} particles emitted, {} sites blocked\n", e["name"].get<std::string>(),
                         e["particles_emitted"].get<std::size_t>(), e["sites_blocked"].get<std::size_t>());
    const std::size_t shown = std::min<std::size_t>(m_warnings.size(), 5);
    for (std::size_t w = 0; w < shown; ++w) t += "  warning: " + m_warnings[w] + "\n";
    if (m_warnings.size() > shown) t += fmt::format("  ... {} more warnings in report.json\n", m_warnings.size() - shown);
    return t;
}

void RunReport::write(const std::filesystem::path& path) const { writeTextAtomically(path, toJson().dump(2) + "\n"); }

}  // namespace ganache
