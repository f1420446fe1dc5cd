#include "report.h"

#include "atomic_file.h"
#include "scene.h"

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
    // Stepping arrives with the simulate stage; until then no step has run.
    j["steps"] = 0;
    j["simulated_time_s"] = 0.0;
    json effects = json::array();
    for (const auto& e : m_scene.effects) effects.push_back(e.name);
    j["effects_requested"] = effects;
    j["effects_ran"] = json::array();
    json stages = json::array();
    for (const auto& s : m_stages)
        stages.push_back({{"name", s.name}, {"status", s.status}, {"wall_s", s.seconds}, {"note", s.note},
                          {"outputs", s.outputs}});
    j["stages"] = stages;
    j["per_step_ms"] = json::object();
    j["solver"] = json::object();
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
    for (const auto& w : m_warnings) t += "  warning: " + w + "\n";
    return t;
}

void RunReport::write(const std::filesystem::path& path) const { writeTextAtomically(path, toJson().dump(2) + "\n"); }

}  // namespace ganache
