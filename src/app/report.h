#pragma once
// report.json and the closing table on stderr: what a command did, how long each stage took, and what it cost.

#include <nlohmann/json.hpp>

#include <chrono>
#include <filesystem>
#include <string>
#include <vector>

namespace ganache {

struct Scene;
struct SolverStats;
struct BodyReport;
struct EmitterReport;

/// One pipeline stage as it ran (or did not).
struct StageRecord {
    std::string name;
    std::string status;  ///< "done", "skipped" (up to date or not asked for), "not available"
    double seconds = 0;
    std::string note;
    std::vector<std::string> outputs;
};

class RunReport {
public:
    explicit RunReport(const Scene& scene, int threads);

    StageRecord& addStage(const std::string& name);
    void setCounts(std::size_t fluid, std::size_t boundary);
    void setFrames(std::int64_t first, std::int64_t last) { m_firstFrame = first, m_lastFrame = last; }
    void addWarning(const std::string& text) { m_warnings.push_back(text); }
    /// What the simulate stage did: steps, time, the effects that ran, solver statistics and warnings.
    void setSimulation(const SolverStats& stats, double simulatedTime, const std::vector<std::string>& effects,
                       std::size_t finalFluid);
    /// The fluid's force and torque on each boundary body.
    void setBodies(const std::vector<std::string>& names, const std::vector<BodyReport>& bodies);
    /// What each emitter added.
    void setEmitters(const std::vector<EmitterReport>& emitters);
    /// Free-form facts a stage measured (e.g. the initial density error of the sample).
    nlohmann::ordered_json& measurements() { return m_measurements; }

    nlohmann::ordered_json toJson() const;
    /// A short table for stderr.
    std::string table() const;
    void write(const std::filesystem::path& path) const;

private:
    const Scene& m_scene;
    int m_threads;
    std::chrono::steady_clock::time_point m_start = std::chrono::steady_clock::now();
    std::vector<StageRecord> m_stages;
    std::size_t m_fluid = 0, m_boundary = 0;
    std::int64_t m_firstFrame = 0, m_lastFrame = -1;
    std::vector<std::string> m_warnings;
    nlohmann::ordered_json m_simulation;  // empty until the simulate stage ran
    nlohmann::ordered_json m_bodies = nlohmann::ordered_json::array();
    nlohmann::ordered_json m_emitters = nlohmann::ordered_json::array();
    nlohmann::ordered_json m_measurements = nlohmann::ordered_json::object();
};

/// Peak resident memory of this process so far [bytes].
std::size_t peakMemoryBytes();

/// Measures wall time from construction; seconds() reads it.
class Stopwatch {
public:
    double seconds() const {
        return std::chrono::duration<double>(std::chrono::steady_clock::now() - m_start).count();
    }

private:
    std::chrono::steady_clock::time_point m_start = std::chrono::steady_clock::now();
};

/// Adds the wall time of its scope to `total` [s].
class ScopedTimer {
public:
    explicit ScopedTimer(double& total) : m_total(total) {}
    ~ScopedTimer() { m_total += m_clock.seconds(); }

private:
    double& m_total;
    Stopwatch m_clock;
};

}  // namespace ganache
