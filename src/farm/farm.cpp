#include "farm/farm.h"

#include "farm/slurm.h"

#include "core/errors.h"
#include "io/atomic_file.h"
#include "pipeline/frame_stage.h"

#include <fmt/chrono.h>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <functional>
#include <map>
#include <optional>

#include <sys/statfs.h>
#include <unistd.h>

namespace ganache {

namespace fs = std::filesystem;
using Json = nlohmann::ordered_json;

namespace {

constexpr double kMiB = 1 << 20;
// Seconds before its time limit that the simulate job is warned (Slurm's --signal): time for a step, a checkpoint
// and the requeue.
constexpr int kStopWarningSeconds = 180;
// Measured time limits: twice the measured cost, plus this for starting up and reading inputs.
constexpr double kLimitMarginSeconds = 600;

/// One job of the graph.
struct FarmJob {
    std::string stage;          ///< simulate, surface, render, assemble
    std::int64_t tasks = 0;     ///< an array of this many tasks (one per chunk); 0: a single job
    int cpus = 1;
    double memoryMiB = 0;
    std::optional<int> minutes;  ///< time limit; none: the partition's default
    std::string after;          ///< the stage it waits for ("" none)
    bool perTask = false;       ///< waits for the same task of `after` (aftercorr), not for all of it (afterok)
    std::string id;             ///< once submitted

    fs::path script(const fs::path& root) const { return root / "farm" / (stage + ".sbatch"); }
};

struct FarmPlan {
    fs::path exe, scene, root;
    std::string quality, sceneName;
    double programMiB = 0;  ///< of each job's memory, what the program takes before any particle
    std::int64_t first = 0, last = 0, chunk = 1;
    std::vector<FarmJob> jobs;
    std::int64_t chunks() const { return (last - first + chunk) / chunk; }
    const FarmJob* find(const std::string& stage) const {
        for (const FarmJob& j : jobs)
            if (j.stage == stage) return &j;
        return nullptr;
    }
};

std::string quote(const std::string& text) {  // for a POSIX shell
    if (!text.empty() && text.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-+=./:,@%") ==
                             std::string::npos)
        return text;
    std::string out = "'";
    for (char c : text) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
    return out + "'";
}

std::string thisHost() {
    char name[256] = {};
    ::gethostname(name, sizeof name - 1);
    const std::string full = name;
    return full.substr(0, full.find('.'));
}

// File systems that several machines mount as one (network and cluster file systems; FUSE may be one).
bool sharedFileSystem(const fs::path& path) {
    struct statfs info {};
    if (::statfs(path.c_str(), &info) != 0) return true;  // cannot tell: do not refuse
    switch (static_cast<unsigned long>(info.f_type)) {
    case 0x6969UL:      // NFS
    case 0x517BUL:      // SMB
    case 0xFF534D42UL:  // CIFS
    case 0xFE534D42UL:  // SMB2
    case 0x0BD00BD0UL:  // Lustre
    case 0x47504653UL:  // GPFS / Spectrum Scale
    case 0x00C36400UL:  // CephFS
    case 0x19830326UL:  // BeeGFS
    case 0xAAD7AAEAUL:  // PanFS
    case 0x5346414FUL:  // AFS
    case 0x01021997UL:  // 9p
    case 0x65735546UL:  // FUSE (sshfs, GlusterFS, ...)
        return true;
    default:
        return false;
    }
}

// Per-frame cost [core-seconds] of each stage measured by an earlier run of the same scene at the same quality
// (<out>/report.json, from `ganache run` or an earlier farm's assemble job).
std::map<std::string, double> measuredCosts(const fs::path& report, const std::string& quality, Real radius) {
    std::map<std::string, double> costs;
    std::ifstream in(report);
    if (!in) return costs;
    try {
        const Json r = Json::parse(in);
        if (r.at("quality") != quality || std::abs(r.at("particle_radius_m").get<double>() - radius) > 1e-9 * radius)
            return costs;
        const double threads = std::max(1.0, r.value("threads", 1.0));
        for (const Json& s : r.at("stages")) {
            const auto& frames = s.at("frames_done");
            if (s.at("status") == "done" && frames.is_number() && frames.get<double>() > 0)  // a farm's: its tasks'
                costs[s.at("name")] = s.value("threads", threads) * s.at("wall_s").get<double>() / frames.get<double>();
        }
    } catch (const std::exception&) {  // an unreadable or older report measures nothing
        costs.clear();
    }
    return costs;
}

FarmPlan planFarm(const RunOptions& run, const FarmOptions& options, const Scene& scene,
                  std::pair<std::int64_t, std::int64_t> frames, const slurm::Partition& partition) {
    FarmPlan plan;
    plan.exe = fs::read_symlink("/proc/self/exe");
    plan.scene = fs::absolute(run.scene).lexically_normal();
    plan.root = fs::absolute(run.out.empty() ? fs::path("out") / scene.name : run.out).lexically_normal();
    plan.quality = run.quality;
    plan.sceneName = scene.name;
    plan.first = frames.first;
    plan.last = frames.second;
    plan.chunk = std::min(options.chunk, frames.second - frames.first + 1);

    int nodeCpus = 1;
    double nodeMiB = 0;
    for (const slurm::Node& n : partition.nodes) nodeCpus = std::max(nodeCpus, n.cpus), nodeMiB = std::max(nodeMiB, n.memoryMiB);
    const int taskCpus = options.cpus > 0 ? options.cpus : std::min(nodeCpus, 4);
    if (taskCpus > nodeCpus)
        throw InputError(fmt::format("--cpus {}: the largest node of partition '{}' has {} CPUs\n  fix: ask for at most "
                                     "{}",
                                     options.cpus, partition.name, nodeCpus, nodeCpus));

    const std::vector<StageId> all = {StageId::Sample, StageId::Simulate, StageId::Surface, StageId::Render};
    const ResourceEstimate e = estimateResources(scene, frames, all);
    plan.programMiB = e.programBytes / kMiB;
    const auto costs = measuredCosts(plan.root / "report.json", run.quality, scene.particleRadius);
    auto limit = [&](const char* stage, double frameCount, int cpus) -> std::optional<int> {
        const auto it = costs.find(stage);
        if (it == costs.end()) return std::nullopt;
        return int(std::ceil((2 * it->second * frameCount / cpus + kLimitMarginSeconds) / 60));
    };
    auto mib = [&](double bytes) { return std::max(256.0, 64 * std::ceil((e.programBytes + bytes) / kMiB / 64)); };

    // The simulation runs from t = 0 to the last frame, however few frames are written.
    plan.jobs.push_back({"simulate", 0, nodeCpus, mib(e.simulateBytes),
                         limit("simulate", double(frames.second - scene.frames.start), nodeCpus), "", false, ""});
    const double chunkFrames = double(plan.chunk);
    if (scene.surface.requested)
        plan.jobs.push_back({"surface", plan.chunks(), taskCpus,
                             mib(e.surfaceFrameBytes * double(std::min<std::int64_t>(taskCpus, plan.chunk))),
                             limit("surface", chunkFrames, taskCpus), "simulate", false, ""});
    // A renderer per thread: the estimate's two, and one more for each further CPU.
    const double renderBytes = e.renderBytes + std::max(0, taskCpus - 2) * e.renderContextBytes;
    if (scene.render.requested)
        plan.jobs.push_back({"render", plan.chunks(), taskCpus, mib(renderBytes), limit("render", chunkFrames, taskCpus),
                             scene.surface.requested ? "surface" : "simulate", scene.surface.requested, ""});
    plan.jobs.push_back({"assemble", 0, taskCpus, mib(renderBytes), std::nullopt, plan.jobs.back().stage, false, ""});

    for (const FarmJob& j : plan.jobs)
        if (nodeMiB > 0 && j.memoryMiB > nodeMiB)
            throw SceneError(j.stage == "surface" ? scene.surface.at : scene.radiusAt,
                             fmt::format("the {} job needs about {:.0f} MiB of memory, more than the largest node of "
                                         "partition '{}' has ({:.0f} MiB)",
                                         j.stage, j.memoryMiB, partition.name, nodeMiB),
                             j.stage == "surface" ? "raise surface.voxel_size, or ask for fewer CPUs per task (--cpus)"
                                                  : "raise particles.radius or use a coarser --quality");
    return plan;
}

// The sbatch options of a job, dependencies aside: these go into its script.
std::vector<std::string> scriptOptions(const FarmPlan& plan, const FarmJob& job, const FarmOptions& options) {
    const fs::path logs = plan.root / "farm" / "logs";
    std::vector<std::string> o = {
        fmt::format("--job-name=ganache:{}:{}", plan.sceneName, job.stage),
        "--nodes=1",
        "--ntasks=1",
        fmt::format("--cpus-per-task={}", job.cpus),
        fmt::format("--mem={:.0f}M", job.memoryMiB),
        fmt::format("--output={}", (logs / (job.stage + (job.tasks ? ".%A_%a.log" : ".%j.log"))).string()),
    };
    if (!options.partition.empty()) o.push_back("--partition=" + options.partition);
    if (job.tasks) o.push_back(fmt::format("--array=0-{}", job.tasks - 1));
    if (job.minutes) o.push_back(fmt::format("--time={}", *job.minutes));
    if (job.stage == "simulate") {
        o.push_back("--requeue");
        o.push_back("--open-mode=append");  // a requeued run adds to its log
        o.push_back(fmt::format("--signal=B:USR1@{}", kStopWarningSeconds));
    }
    o.insert(o.end(), options.sbatch.begin(), options.sbatch.end());
    return o;
}

std::string scriptText(const FarmPlan& plan, const FarmJob& job, const FarmOptions& options, bool resume) {
    const std::string root = quote(plan.root.string()), scene = quote(plan.scene.string());
    const std::string common = fmt::format("{} --out {} --quality {}", scene, root, quote(plan.quality));
    const std::string reports = quote((plan.root / "farm" / "reports").string());
    std::string s = fmt::format("#!/bin/bash\n# ganache farm: the {} {} of scene '{}' ({}), written by `ganache farm`.\n"
                                "# Submit again by hand with `sbatch{} {}`.\n",
                                job.stage, job.tasks ? "tasks" : "job", plan.sceneName, plan.scene.string(),
                                job.tasks ? " --array=K" : "", job.script(plan.root).string());
    for (const std::string& o : scriptOptions(plan, job, options)) s += "#SBATCH " + o + "\n";
    s += fmt::format("set -euo pipefail\nganache={}\n", quote(plan.exe.string()));
    if (job.tasks)
        s += fmt::format("# Task K does the {2} frames from {0} + K * {2} on, up to frame {1}.\n"
                         "first=$(({0} + SLURM_ARRAY_TASK_ID * {2}))\nlast=$((first + {2} - 1))\n"
                         "if ((last > {1})); then last={1}; fi\n",
                         plan.first, plan.last, plan.chunk);
    const std::string threads = fmt::format("--threads {}", job.cpus);
    if (job.stage == "simulate") {
        s += fmt::format("# A requeued run (preemption, node failure, scontrol requeue) continues from its newest "
                         "checkpoint.\nresume={}\nif [ \"${{SLURM_RESTART_COUNT:-0}}\" -gt 0 ]; then "
                         "resume=--resume; fi\n",
                         resume ? "--resume" : "");
        s += fmt::format("\"$ganache\" sample {} {} --report {}/sample.json\n", common, threads, reports);
        s += fmt::format(
            "# Slurm warns this shell {0} s before the time limit (USR1): ganache stops after its current step with a "
            "checkpoint\n# and the job requeues itself, so that a long simulation goes on in a new allocation. "
            "Slurm's own TERM\n# (scancel, scontrol requeue, preemption) reaches ganache directly; the shell lets it "
            "pass.\nrequeue=0\ntrap 'requeue=1; kill -TERM \"$pid\" 2>/dev/null' USR1\ntrap 'true' TERM\n"
            "\"$ganache\" simulate {1} --frames {2}-{3} {4} $resume --report {5}/simulate.json &\npid=$!\n"
            "while true; do  # a trapped signal ends `wait` early\n  status=0\n  wait \"$pid\" || status=$?\n"
            "  kill -0 \"$pid\" 2>/dev/null || break\ndone\n"
            "if [ \"$requeue\" = 1 ] && [ \"$status\" = 143 ]; then\n"
            "  echo \"ganache farm: stopped before the time limit with a checkpoint; requeued to go on from it\" >&2\n"
            "  exec scontrol requeue \"$SLURM_JOB_ID\"\nfi\nexit \"$status\"\n",
            kStopWarningSeconds, common, plan.first, plan.last, threads, reports);
    } else if (job.stage == "surface") {
        s += fmt::format("exec \"$ganache\" surface {} --frames \"$first-$last\" {} --memory {:.3f} "
                         "--report {}/surface.\"$first-$last\".json\n",
                         common, threads, (job.memoryMiB - plan.programMiB) / 1024, reports);
    } else if (job.stage == "render") {
        s += fmt::format("exec \"$ganache\" render {} --frames \"$first-$last\" --frames-only {} "
                         "--report {}/render.\"$first-$last\".json\n",
                         common, threads, reports);
    } else {
        if (plan.find("render"))
            s += fmt::format("# The contact sheet and the video, from every frame.\n\"$ganache\" render {} --frames "
                             "{}-{} {} --report {}/assemble.json\n",
                             common, plan.first, plan.last, threads, reports);
        s += fmt::format("exec \"$ganache\" farm report {}\n", root);
    }
    return s;
}

std::vector<std::string> dependency(const FarmPlan& plan, const FarmJob& job) {
    if (job.after.empty()) return {};
    return {fmt::format("--dependency={}:{}", job.perTask ? "aftercorr" : "afterok", plan.find(job.after)->id)};
}

fs::path planFile(const fs::path& root) { return root / "farm" / "farm.json"; }

void writePlan(const FarmPlan& plan) {
    Json jobs = Json::array();
    for (const FarmJob& j : plan.jobs)
        jobs.push_back({{"stage", j.stage},
                        {"id", j.id},
                        {"tasks", j.tasks},
                        {"cpus", j.cpus},
                        {"memory_mib", j.memoryMiB},
                        {"time_limit_min", j.minutes ? Json(*j.minutes) : Json(nullptr)},
                        {"after", j.after},
                        {"script", j.script(plan.root).string()}});
    const Json j = {{"scene", plan.scene.string()},
                    {"scene_name", plan.sceneName},
                    {"out", plan.root.string()},
                    {"quality", plan.quality},
                    {"frames", {{"first", plan.first}, {"last", plan.last}}},
                    {"chunk", plan.chunk},
                    {"submitted_unix", std::chrono::duration<double>(
                                           std::chrono::system_clock::now().time_since_epoch()).count()},
                    {"jobs", jobs}};
    writeTextAtomically(planFile(plan.root), j.dump(2) + "\n");
}

FarmPlan readPlan(const fs::path& out, Json* raw = nullptr) {
    std::ifstream in(planFile(out));
    if (!in)
        throw InputError(fmt::format("{}: no farm submission here (no {})\n  fix: name the --out folder that "
                                     "`ganache farm` submitted to",
                                     out.string(), planFile(out).string()));
    try {
        const Json j = Json::parse(in);
        FarmPlan plan;
        plan.scene = j.at("scene").get<std::string>();
        plan.sceneName = j.at("scene_name");
        plan.root = j.at("out").get<std::string>();
        plan.quality = j.at("quality");
        plan.first = j.at("frames").at("first");
        plan.last = j.at("frames").at("last");
        plan.chunk = j.at("chunk");
        for (const Json& job : j.at("jobs"))
            plan.jobs.push_back({job.at("stage"), job.at("tasks"), job.at("cpus"), job.at("memory_mib"), std::nullopt,
                                 job.at("after"), false, job.at("id")});
        if (raw) *raw = j;
        return plan;
    } catch (const std::exception& e) {
        throw InputError(fmt::format("{}: not a farm plan ganache can read: {}\n  fix: submit again with `ganache "
                                     "farm`",
                                     planFile(out).string(), e.what()));
    }
}

std::string chunkRange(const FarmPlan& plan, std::int64_t k) {
    const std::int64_t a = plan.first + k * plan.chunk;
    return fmt::format("{}-{}", a, std::min(plan.last, a + plan.chunk - 1));
}

}  // namespace

void farmSubmitCommand(const RunOptions& run, const FarmOptions& options) {
    if (options.chunk < 1) throw InputError(fmt::format("--chunk {}: must be at least 1 frame", options.chunk));
    const Scene scene = loadScene(run.scene, Quality::parse(run.quality));
    const auto frames = run.frames.empty() ? std::make_pair(scene.frames.start, scene.frames.end)
                                           : parseFrameRange(run.frames, scene.frames);
    slurm::requireClients();
    slurm::requireController();
    const slurm::Partition partition = slurm::partition(options.partition);
    const FarmPlan plan = planFarm(run, options, scene, frames, partition);
    if (fs::exists(planFile(plan.root))) {  // two graphs must not write one folder at once
        std::vector<std::string> earlier;
        try {
            for (const FarmJob& j : readPlan(plan.root).jobs)
                if (!j.id.empty()) earlier.push_back(j.id);
        } catch (const InputError&) {  // a damaged plan names no jobs; this submission replaces it
        }
        if (const auto queued = slurm::queue(earlier); !queued.empty()) {
            std::vector<std::string> ids;
            for (const auto& [id, state] : queued) ids.push_back(id);
            throw InputError(fmt::format(
                "ganache farm: jobs of an earlier submission into {} are still in the queue ({})\n  fix: wait for "
                "them (`ganache farm status {}`), or cancel them (`scancel {}`) and submit again (--resume continues "
                "the simulation from its newest checkpoint)",
                plan.root.string(), joinNames(ids), plan.root.string(), fmt::join(earlier, " ")));
        }
    }

    // Every job reads the scene and the program and writes the output folder: on another node they must be there.
    std::vector<std::string> others;
    for (const slurm::Node& n : partition.nodes)
        if (n.name != thisHost()) others.push_back(n.name);
    prepareOutputFolder(plan.root, "--out");
    if (!others.empty() && !options.assumeShared)
        for (const auto& [what, path] : {std::pair<const char*, fs::path>{"the output folder", plan.root},
                                         {"the scene file", plan.scene},
                                         {"the ganache program", plan.exe}})
            if (!sharedFileSystem(path))
                throw InputError(fmt::format(
                    "ganache farm: {} {} is on a file system local to this machine ({}), but partition '{}' runs jobs "
                    "on {}: they would not see it\n  fix: put it on the farm's shared file system (NFS, Lustre, ...), "
                    "or pass --assume-shared if the same path holds the same files on every node",
                    what, path.string(), thisHost(), partition.name, joinNames(others)));

    const fs::path folder = plan.root / "farm";
    fs::create_directories(folder / "logs");
    for (const FarmJob& j : plan.jobs) {
        writeTextAtomically(j.script(plan.root), scriptText(plan, j, options, run.resume));
        fs::permissions(j.script(plan.root), fs::perms::owner_exec | fs::perms::group_exec | fs::perms::others_exec,
                        fs::perm_options::add);
    }

    fmt::print("farm: scene '{}' frames {}-{} at {} quality (about {:.0f} fluid particles), partition '{}' ({} node(s))\n",
               scene.name, plan.first, plan.last, scene.quality.str(), estimateFluidParticles(scene, scene.particleRadius),
               partition.name, partition.nodes.size());
    for (const FarmJob& j : plan.jobs)
        fmt::print("  {:<9} {:<25} {} CPU(s), {:.0f} MiB, time limit {}{}\n", j.stage,
                   j.tasks ? fmt::format("{} task(s) of {} frame(s)", j.tasks, plan.chunk) : std::string("1 job"),
                   j.cpus, j.memoryMiB,
                   j.minutes ? fmt::format("{} min (measured)", *j.minutes) : std::string("the partition's default"),
                   j.after.empty() ? "" : fmt::format(", after {}{}", j.after, j.perTask ? " (same chunk)" : ""));
    bool measured = false;
    for (const FarmJob& j : plan.jobs) measured |= bool(j.minutes);
    if (!measured)
        fmt::print("  (no report.json of this scene and quality in {} to measure time limits from; a local run of a "
                   "few frames, e.g. `ganache run {} --frames {}-{}`, gives one)\n",
                   plan.root.string(), run.scene.string(), plan.first, std::min(plan.last, plan.first + 2));
    fmt::print("scripts in {}\n", folder.string());
    if (options.dryRun) {
        writePlan(plan);
        fmt::print("dry run: nothing submitted; `ganache farm {} --out {}` without --dry-run submits them\n",
                   run.scene.string(), plan.root.string());
        return;
    }

    // Every job must be acceptable before the first is submitted; a refusal after that takes back what was.
    for (const FarmJob& j : plan.jobs)
        if (const std::string why = slurm::testSubmit({}, j.script(plan.root).string()); !why.empty())
            throw InputError(fmt::format("ganache farm: Slurm would refuse the {} job ({}): {}\n  fix: change the "
                                         "request (--partition, --cpus, --sbatch) or the scene; nothing was submitted",
                                         j.stage, j.script(plan.root).string(), why));
    // The reports of an earlier submission must not be merged with this one's.
    fs::remove_all(folder / "reports");
    fs::create_directories(folder / "reports");
    FarmPlan submitted = plan;
    std::vector<std::string> ids;
    try {
        for (FarmJob& j : submitted.jobs) {
            j.id = slurm::submit(dependency(submitted, j), j.script(plan.root).string());
            ids.push_back(j.id);
        }
    } catch (const std::exception& e) {
        slurm::cancel(ids);
        throw std::runtime_error(fmt::format("{}\n  the jobs submitted before it ({}) were cancelled: nothing is "
                                             "left submitted",
                                             e.what(), ids.empty() ? "none" : joinNames(ids)));
    }
    writePlan(submitted);
    for (const FarmJob& j : submitted.jobs) fmt::print("submitted {:<9} job {}\n", j.stage, j.id);
    fmt::print("watch: `ganache farm status {0}` (or `squeue -j {1}`); logs in {2}; when the assemble job is done, "
               "{0}/report.json has every task's report\n",
               plan.root.string(), fmt::join(ids, ","), (folder / "logs").string());
}

void farmStatusCommand(const fs::path& out) {
    Json raw;
    const FarmPlan plan = readPlan(out, &raw);
    const OutputLayout layout{plan.root, plan.sceneName};
    std::vector<std::string> ids;
    for (const FarmJob& j : plan.jobs)
        if (!j.id.empty()) ids.push_back(j.id);
    std::map<std::string, std::string> queue;
    std::string queueNote;
    try {
        queue = slurm::queue(ids);
    } catch (const std::exception& e) {
        queueNote = fmt::format(" (the queue is unknown: {})", e.what());
    }
    const std::int64_t total = plan.last - plan.first + 1;
    auto count = [&](const std::function<bool(std::int64_t)>& done) {
        std::int64_t n = 0;
        for (std::int64_t f = plan.first; f <= plan.last; ++f) n += done(f);
        return n;
    };
    fmt::print("farm: scene '{}' in {}, frames {}-{} in chunks of {}{}\n", plan.sceneName, plan.root.string(),
               plan.first, plan.last, plan.chunk, queueNote);
    std::vector<std::string> failures;
    for (const FarmJob& j : plan.jobs) {
        std::map<std::string, int> counts;  // an array's tasks by state
        for (const auto& [id, state] : queue)
            if (id == j.id || id.rfind(j.id + "_", 0) == 0) ++counts[state];
        std::vector<std::string> states;
        for (const auto& [state, n] : counts)
            states.push_back(j.tasks ? fmt::format("{} task(s) {}", n, state) : state);
        std::string done;
        if (j.stage == "simulate")
            done = fmt::format("{}/{} frames simulated", count([&](std::int64_t f) { return fs::exists(layout.particles(f)); }), total);
        else if (j.stage == "surface")
            done = fmt::format("{}/{} frames surfaced", count([&](std::int64_t f) {
                                   return upToDate(layout.surface(f), layout.particles(f));
                               }), total);
        else if (j.stage == "render")
            done = fmt::format("{}/{} frames rendered", count([&](std::int64_t f) {
                                   return upToDate(layout.preview(f), layout.particles(f));
                               }), total);
        else
            done = fs::exists(plan.root / "report.json") ? "report.json written" : "not done";
        fmt::print("  {:<9} job {:<8} {}; {}\n", j.stage, j.id.empty() ? "(dry run)" : j.id, done,
                   states.empty() ? std::string("not in the queue") : joinNames(states));

        // Failed tasks, from their own reports, unless Slurm runs them again: each can be rerun alone (frames
        // already done are skipped).
        const fs::path reports = plan.root / "farm" / "reports";
        auto queued = [&](std::int64_t k) {
            return queue.count(j.id) || queue.count(fmt::format("{}_{}", j.id, k));
        };
        for (std::int64_t k = 0; k < std::max<std::int64_t>(j.tasks, 1); ++k) {
            if (queued(k)) continue;
            const std::string name = j.tasks ? fmt::format("{}.{}.json", j.stage, chunkRange(plan, k)) : j.stage + ".json";
            std::ifstream in(reports / name);
            if (!in) continue;
            try {
                const Json r = Json::parse(in);
                const std::string status = r.at("result").at("status");
                if (status == "done") continue;
                std::string why = r.at("result").at("error");
                why = why.substr(0, why.find('\n'));
                // The jobs after a failed simulation wait for good (Slurm never re-tests a failed dependency).
                const std::string rerun =
                    j.stage == "simulate"
                        ? fmt::format("scancel {}; ganache farm {} --out {} --quality {} --frames {}-{} --resume",
                                      fmt::join(ids, " "), plan.scene.string(), plan.root.string(), plan.quality,
                                      plan.first, plan.last)
                        : fmt::format("sbatch{} {}", j.tasks ? fmt::format(" --array={}", k) : "",
                                      j.script(plan.root).string());
                failures.push_back(fmt::format("{} {}{}: {}: {}\n    rerun: {}", j.stage, j.tasks ? "frames " : "",
                                               j.tasks ? chunkRange(plan, k) : "", status, why, rerun));
            } catch (const std::exception&) {
            }
        }
    }
    for (const std::string& f : failures) fmt::print("  not done: {}\n", f);
}

void farmReportCommand(const fs::path& out) {
    Json raw;
    const FarmPlan plan = readPlan(out, &raw);
    const fs::path reports = plan.root / "farm" / "reports";
    Json merged, tasks = Json::array(), stages = Json::array(), warnings = Json::array();
    std::vector<std::string> problems;
    double peak = 0;
    auto read = [&](const std::string& stage, const std::string& jobId, const std::string& frames,
                    const std::string& file) -> std::optional<Json> {
        std::ifstream in(reports / file);
        if (!in) {
            problems.push_back(fmt::format("{} {}: no report ({} is missing)", stage, frames, (reports / file).string()));
            return std::nullopt;
        }
        Json r;
        try {
            r = Json::parse(in);
        } catch (const std::exception& e) {
            problems.push_back(fmt::format("{} {}: unreadable report {}: {}", stage, frames, file, e.what()));
            return std::nullopt;
        }
        const std::string status = r["result"].value("status", "unknown");
        if (status != "done")
            problems.push_back(fmt::format("{} {}: {}: {}", stage, frames, status, r["result"].value("error", "")));
        tasks.push_back({{"stage", stage},
                         {"job", jobId},
                         {"frames", frames},
                         {"status", status},
                         {"wall_s", r.value("wall_s", 0.0)},
                         {"threads", r.value("threads", 0)},
                         {"peak_memory_bytes", r.value("peak_memory_bytes", 0.0)},
                         {"report", (reports / file).string()}});
        peak = std::max(peak, r.value("peak_memory_bytes", 0.0));
        for (const Json& w : r.value("warnings", Json::array())) warnings.push_back(w);
        return r;
    };
    // One stage record from its tasks' records of it: times and frames add up.
    auto addStage = [&](const std::string& name, const std::vector<Json>& records, int threads) {
        if (records.empty()) return;
        Json s = {{"name", name}, {"status", "done"}, {"wall_s", 0.0},        {"threads", threads},
                  {"frames_done", nullptr}, {"note", ""}, {"outputs", Json::array()}};
        std::int64_t frames = 0;
        bool counted = false;
        for (const Json& r : records) {
            if (r.value("status", "") != "done" && r.value("status", "") != "skipped") s["status"] = r["status"];
            s["wall_s"] = s["wall_s"].get<double>() + r.value("wall_s", 0.0);
            if (r["frames_done"].is_number()) frames += r["frames_done"].get<std::int64_t>(), counted = true;
            for (const Json& o : r.value("outputs", Json::array())) s["outputs"].push_back(o);
        }
        if (counted) s["frames_done"] = frames;
        s["note"] = records.size() == 1 ? records.front().value("note", "")
                                        : fmt::format("{} farm tasks (their own notes are in farm.tasks)", records.size());
        stages.push_back(s);
    };
    auto stageOf = [](const std::optional<Json>& r, const std::string& name) -> std::vector<Json> {
        if (!r) return {};
        for (const Json& s : r->value("stages", Json::array()))
            if (s.value("name", "") == name) return {s};
        return {};
    };

    const FarmJob* simulate = plan.find("simulate");
    const auto sample = read("sample", simulate->id, "", "sample.json");
    const auto simulation = read("simulate", simulate->id, fmt::format("{}-{}", plan.first, plan.last), "simulate.json");
    addStage("sample", stageOf(sample, "sample"), simulate->cpus);
    addStage("simulate", stageOf(simulation, "simulate"), simulate->cpus);
    for (const char* stage : {"surface", "render"}) {
        const FarmJob* job = plan.find(stage);
        if (!job) continue;
        std::vector<Json> records;
        for (std::int64_t k = 0; k < job->tasks; ++k) {
            const std::string frames = chunkRange(plan, k);
            const auto r = read(stage, fmt::format("{}_{}", job->id, k), frames, fmt::format("{}.{}.json", stage, frames));
            for (const Json& s : stageOf(r, stage)) records.push_back(s);
        }
        addStage(stage, records, job->cpus);
    }
    if (plan.find("render")) {
        const auto r = read("assemble", plan.find("assemble")->id, "", "assemble.json");
        std::vector<Json> records = stageOf(r, "render");
        if (!records.empty()) records.front()["name"] = "assemble";
        addStage("assemble", records, plan.find("assemble")->cpus);
    }

    // The simulation's report carries the scene, its settings and the solver's figures; the rest is the farm's.
    merged = simulation ? *simulation : Json::object();
    merged["result"] = {{"status", problems.empty() ? "done" : "failed"},
                        {"error", problems.empty() ? std::string() : joinNames(problems)}};
    merged["stages"] = stages;
    merged["warnings"] = warnings;
    merged["wall_s"] = std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count() -
                       raw.value("submitted_unix", 0.0);
    merged["peak_memory_bytes"] = peak;
    Json jobs = Json::object();
    for (const FarmJob& j : plan.jobs) jobs[j.stage] = j.id;
    merged["farm"] = {{"jobs", jobs}, {"chunk", plan.chunk}, {"tasks", tasks}};
    writeTextAtomically(plan.root / "report.json", merged.dump(2) + "\n");
    fmt::print("farm report: {} ({} task reports{})\n", (plan.root / "report.json").string(), tasks.size(),
               problems.empty() ? "" : fmt::format("; not done: {}", joinNames(problems)));
    if (!problems.empty())
        throw std::runtime_error(fmt::format("the farm's work is not complete: {}", joinNames(problems)));
}

}  // namespace ganache
