#pragma once
// report.json and the closing table on stderr: what a command did, how long each stage took, and what it cost.

#include "core/timing.h"

#include <chrono>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

namespace ganache {

struct Scene;
struct SolverStats;
struct BodyReport;
struct EffectSummary;
struct EmitterReport;

/// One pipeline stage as it ran (or did not).
struct StageRecord {
    std::string name;
    std::string status;  ///< "done", "skipped" (up to date or not asked for), "not available"
    double seconds = 0;
    std::int64_t frames = -1;  ///< frames the stage made (simulate: simulated), for costs per frame; -1: not per frame
    std::string note;
    std::vector<std::string> outputs;
};

class RunReport {
public:
    explicit RunReport(const Scene& scene, int threads);
    ~RunReport();

    StageRecord& addStage(const std::string& name);
    void setCounts(std::size_t fluid, std::size_t boundary);
    void setFrames(std::int64_t first, std::int64_t last) { m_firstFrame = first, m_lastFrame = last; }
    void addWarning(const std::string& text) { m_warnings.push_back(text); }
    /// How the run ended: "done", "failed" or "interrupted", and why (empty when done). report.json's `result`.
    void setOutcome(std::string status, std::string why) { m_status = std::move(status), m_why = std::move(why); }
    /// What the simulate stage did: steps, time, the effects that ran with their times and counters, solver
    /// statistics and warnings.
    void setSimulation(const SolverStats& stats, double simulatedTime, const std::vector<EffectSummary>& effects,
                       std::size_t finalFluid);
    /// The fluid's force and torque on each boundary body.
    void setBodies(const std::vector<std::string>& names, const std::vector<BodyReport>& bodies);
    /// What each emitter added.
    void setEmitters(const std::vector<EmitterReport>& emitters);
    /// A fact a stage measured, at a path of names under `measurements` (e.g. "sample/mesh_cache/hits").
    void measure(const std::string& path, double value);
    void measureCount(const std::string& path, std::uint64_t value);

    /// report.json's text.
    std::string json() const;
    /// A short table for stderr.
    std::string table() const;
    void write(const std::filesystem::path& path) const;

private:
    struct Data;  // the JSON parts
    const Scene& m_scene;
    int m_threads;
    std::chrono::steady_clock::time_point m_start = std::chrono::steady_clock::now();
    std::vector<StageRecord> m_stages;
    std::size_t m_fluid = 0, m_boundary = 0;
    std::int64_t m_firstFrame = 0, m_lastFrame = -1;
    std::vector<std::string> m_warnings;
    std::string m_status = "running", m_why;
    std::unique_ptr<Data> m_data;
};

/// Peak resident memory of this process so far [bytes].
std::size_t peakMemoryBytes();

}  // namespace ganache
