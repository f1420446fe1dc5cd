// Long runs survive faults: runs killed at several points resume to the frames of an uninterrupted run, damaged
// checkpoints fall back to the previous one, a full disk stops the run with a clear error, and no half-written
// file ever appears under an output's name. The scene (tests/scenes/resume.yaml) carries every kind of state a
// checkpoint must hold: heat, per-particle viscosity, warm starts, an emitter, a turning paddle.

#include "cli_util.h"
#include "io/checkpoint.h"
#include "io/particle_cache.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <chrono>
#include <csignal>
#include <fstream>
#include <iterator>
#include <thread>

using namespace ganache_test;

namespace {

const std::string kScene = (kSource / "tests/scenes/resume.yaml").string();
constexpr int kFirst = 1, kLast = 9;  // the scene's frames

std::string readBytes(const fs::path& file) {
    std::ifstream in(file, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

fs::path frame(const fs::path& out, int f) { return out / "particles" / ("resume.000" + std::to_string(f) + ".vdb"); }

bool isTemporary(const fs::path& p) { return p.filename().string().find(".ganache-tmp.") != std::string::npos; }

// Every file under a final name reads back whole: particle caches and checkpoints pass their checksums, the
// report parses. Temporary files (named only on file systems without unnamed files) are allowed while a run is
// killed; the next run removes them. Returns how many files it checked.
std::size_t expectOnlyCompleteFiles(const fs::path& out, const std::string& when) {
    std::size_t checked = 0;
    for (const auto& e : fs::recursive_directory_iterator(out)) {
        if (!e.is_regular_file() || isTemporary(e.path())) continue;
        const std::string ext = e.path().extension().string();
        try {
            if (ext == ".vdb") ganache::readParticleCache(e.path());
            else if (ext == ".ckpt") ganache::readCheckpoint(e.path());
            else if (ext == ".json") {
                EXPECT_FALSE(nlohmann::json::parse(readBytes(e.path())).empty());
            }
            ++checked;
        } catch (const std::exception& ex) {
            ADD_FAILURE() << when << ": " << e.path() << " is not complete: " << ex.what();
        }
    }
    return checked;
}

// The frames of one uninterrupted run, made once for the tests that compare against it.
const std::vector<std::string>& referenceFrames() {
    static const std::vector<std::string> frames = [] {
        const fs::path out = freshDir("reliability_reference_" + std::to_string(getpid()));  // one per test process
        const Result r = runGanache("run " + kScene + " --threads 2 --out " + out.string());
        EXPECT_EQ(r.code, 0) << r.output;
        std::vector<std::string> bytes;
        for (int f = kFirst; f <= kLast; ++f) bytes.push_back(readBytes(frame(out, f)));
        return bytes;
    }();
    return frames;
}

void expectReferenceFrames(const fs::path& out) {
    for (int f = kFirst; f <= kLast; ++f) {
        ASSERT_TRUE(fs::exists(frame(out, f))) << f;
        EXPECT_TRUE(readBytes(frame(out, f)) == referenceFrames()[std::size_t(f - kFirst)])
            << "frame " << f << " differs from the uninterrupted run";
    }
}

// Waits until `file` exists (or the process ends); false when it ended first.
bool waitForFile(const fs::path& file, pid_t pid) {
    for (int k = 0; k < 30000; ++k) {  // up to a minute: a loaded machine is slow, not wrong
        if (fs::exists(file)) return true;
        if (waitpid(pid, nullptr, WNOHANG) == pid) return false;
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    return false;
}

}  // namespace

TEST(Reliability, SameSceneGivesBitIdenticalCachesForOneAndTwoThreads) {
    // The README's claim: the same bytes for the same thread count (the reference ran on 2), and for another.
    for (int threads : {2, 1}) {
        const fs::path out = freshDir("reliability_threads_" + std::to_string(threads));
        const Result r = runGanache("run " + kScene + " --threads " + std::to_string(threads) + " --out " + out.string());
        ASSERT_EQ(r.code, 0) << r.output;
        expectReferenceFrames(out);
    }
}

TEST(Reliability, RunsKilledAtSeveralPointsResumeToTheUninterruptedFrames) {
    const fs::path out = freshDir("reliability_killed");
    const std::string args = "run " + kScene + " --threads 2 --resume --out " + out.string();
    // SIGKILL right after the sample, as frame 2 appears, just after frame 4 (mid-step), and as the checkpoint of
    // frame 5 appears; each time the next run resumes from whatever the last one left.
    const std::vector<std::pair<fs::path, int>> killPoints = {
        {out / "sample/resume.vdb", 0},
        {frame(out, 2), 0},
        {frame(out, 4), 30},
        {out / "checkpoints", 400},
    };
    for (std::size_t k = 0; k < killPoints.size(); ++k) {
        const pid_t pid = startGanache(args, out / ("kill" + std::to_string(k) + ".log"));
        if (waitForFile(killPoints[k].first, pid)) {
            std::this_thread::sleep_for(std::chrono::milliseconds(killPoints[k].second));
            kill(pid, SIGKILL);
            waitFor(pid);
        }
        expectOnlyCompleteFiles(out, "after kill " + std::to_string(k));
    }
    const Result r = runGanache(args);
    ASSERT_EQ(r.code, 0) << r.output;
    expectReferenceFrames(out);
    EXPECT_GT(expectOnlyCompleteFiles(out, "at the end"), std::size_t(kLast));
    for (const auto& e : fs::recursive_directory_iterator(out)) EXPECT_FALSE(isTemporary(e.path())) << e.path();
    // The kept checkpoints: the scene's checkpoints_kept default, 2.
    std::size_t checkpoints = 0;
    for (const auto& e : fs::directory_iterator(out / "checkpoints")) checkpoints += e.path().extension() == ".ckpt";
    EXPECT_EQ(checkpoints, 2u);
}

TEST(Reliability, SigtermMidSimulationSavesTheStateAndResumesToTheSameFrames) {
    // A farm scheduler's stop while frames are still to come (frame 2 of 9 has just appeared): a checkpoint of that
    // moment, a message that says where it is and how to go on, exit 143, and a report that says so. Waiting for the
    // frame, not a fixed delay, keeps this right on a loaded machine.
    const fs::path out = freshDir("reliability_term");
    const std::string args = "run " + kScene + " --threads 2 --resume --out " + out.string();
    const pid_t pid = startGanache(args, out / "term.log");
    ASSERT_TRUE(waitForFile(frame(out, 2), pid)) << readBytes(out / "term.log");
    kill(pid, SIGTERM);
    const int code = waitFor(pid);
    const std::string log = readBytes(out / "term.log");
    if (code != 0) {  // 0 only when frames 3-9 were done within the moment the signal took to arrive
        EXPECT_EQ(code, 143) << log;
        EXPECT_NE(log.find("the state is saved in"), std::string::npos) << log;
        EXPECT_NE(log.find("continue: run the same command with --resume"), std::string::npos) << log;
        EXPECT_EQ(nlohmann::json::parse(readBytes(out / "report.json"))["result"]["status"], "interrupted");
    }
    expectOnlyCompleteFiles(out, "after SIGTERM");
    const Result r = runGanache(args);
    ASSERT_EQ(r.code, 0) << r.output;
    expectReferenceFrames(out);
}

TEST(Reliability, ADamagedCheckpointIsRejectedAndThePreviousOneUsed) {
    const fs::path out = freshDir("reliability_damaged");
    ASSERT_EQ(runGanache("run " + kScene + " --threads 2 --out " + out.string()).code, 0);
    std::vector<fs::path> files;
    for (const auto& e : fs::directory_iterator(out / "checkpoints")) files.push_back(e.path());
    std::sort(files.begin(), files.end());
    ASSERT_EQ(files.size(), 2u);  // after frames 7 and 9 (checkpoint_every: 2)
    EXPECT_NE(files[0].filename().string().find("resume.0007."), std::string::npos) << files[0];

    // One flipped byte in the newest: its checksum fails, the one before it is used, frames 8-9 come back the same.
    std::string bytes = readBytes(files[1]);
    bytes[bytes.size() / 2] ^= 0x10;
    std::ofstream(files[1], std::ios::binary) << bytes;
    fs::remove(frame(out, 8));
    fs::remove(frame(out, 9));
    Result r = runGanache("simulate " + kScene + " --threads 2 --resume --out " + out.string());
    ASSERT_EQ(r.code, 0) << r.output;
    EXPECT_NE(r.output.find(files[1].string() + " is unusable: it fails its checksum (corrupt); trying the one before"),
              std::string::npos)
        << r.output;
    EXPECT_NE(r.output.find("resume: from " + files[0].string() + " (frame 7"), std::string::npos) << r.output;
    expectReferenceFrames(out);

    // Truncated: the same fallback; with neither usable the run starts over (and says so).
    for (const fs::path& f : files) {
        const std::string whole = readBytes(f);
        std::ofstream(f, std::ios::binary) << whole.substr(0, whole.size() - 100);
    }
    r = runGanache("simulate " + kScene + " --threads 2 --resume --out " + out.string());
    ASSERT_EQ(r.code, 0) << r.output;
    EXPECT_NE(r.output.find("has no ganache checksum footer (truncated"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("no checkpoint reads back whole: starting from the beginning"), std::string::npos)
        << r.output;
    expectReferenceFrames(out);

    // A checkpoint of another version of the scene is refused, not silently continued.
    fs::create_directories(out / "edit");
    std::ofstream(out / "edit/resume.yaml") << readBytes(kScene) << "# an edit\n";
    r = runGanache("simulate " + (out / "edit/resume.yaml").string() + " --resume --out " + out.string());
    EXPECT_EQ(r.code, 2) << r.output;
    EXPECT_NE(r.output.find("saved from another version of the scene"), std::string::npos) << r.output;
}

TEST(Reliability, AFullDiskStopsWithAClearErrorAndKeepsWhatWasWritten) {
    // A small file system of our own: a tmpfs in a private mount namespace (root, or an unprivileged user
    // namespace). Where neither is allowed, a file size limit (ulimit -f) stands in for it: the write fails the
    // same way, with EFBIG instead of ENOSPC.
    const fs::path dir = freshDir("reliability_full");
    const fs::path small = dir / "small", kept = dir / "kept";
    fs::create_directories(small);
    const std::string ganache = std::string(GANACHE_EXE) + " run " + kScene + " --threads 2 --out " + small.string();
    // First without --skip-resource-check: the guard sees the small disk and refuses before any work, leaving only
    // the report that says why.
    std::ofstream(dir / "tmpfs.sh") << "mount -t tmpfs -o size=640k tmpfs '" << small.string() << "' || exit 99\n"
                                    << ganache << "\necho guard=$?\nls -A '" << small.string() << "'\n"
                                    << ganache << " --skip-resource-check\necho exit=$?\ncp -a '" << small.string()
                                    << "/.' '" << kept.string() << "'\n";
    // The limit (in 512-byte blocks) lets the sample and frame 1 through and stops frame 2, which is larger.
    const std::size_t blocks = (referenceFrames()[0].size() + referenceFrames()[1].size()) / 2 / 512;
    std::ofstream(dir / "ulimit.sh") << "trap '' XFSZ\nulimit -f " << blocks << "\n" << ganache
                                     << " --skip-resource-check\necho exit=$?\n";
    Result r = runShell("unshare -m --propagation private sh " + (dir / "tmpfs.sh").string());
    if (r.output.find("exit=") == std::string::npos) r = runShell("unshare -rm sh " + (dir / "tmpfs.sh").string());
    const bool tmpfs = r.output.find("exit=") != std::string::npos;
    if (!tmpfs) {
        fs::remove_all(small);
        r = runShell("sh " + (dir / "ulimit.sh").string());
        fs::rename(small, kept);
    }
    SCOPED_TRACE(tmpfs ? "tmpfs of 640 KiB" : "ulimit -f");
    if (tmpfs) {
        EXPECT_NE(r.output.find("error: the outputs need about"), std::string::npos) << r.output;
        EXPECT_NE(r.output.find("guard=2\nreport.json\nplan:"), std::string::npos) << r.output;  // refused
    }
    EXPECT_NE(r.output.find("exit=1"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("error: cannot write"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find(tmpfs ? "is full" : "ulimit -f"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("fix: "), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("complete and kept"), std::string::npos) << r.output;
    // What was written before is whole and equal to the uninterrupted run's, and nothing half-written remains.
    ASSERT_TRUE(fs::exists(frame(kept, kFirst))) << r.output;
    expectOnlyCompleteFiles(kept, "after the disk filled");
    for (int f = kFirst; f <= kLast && fs::exists(frame(kept, f)); ++f)
        EXPECT_TRUE(readBytes(frame(kept, f)) == referenceFrames()[std::size_t(f - kFirst)]) << f;
    EXPECT_FALSE(fs::exists(frame(kept, kLast)));
    for (const auto& e : fs::recursive_directory_iterator(kept)) EXPECT_FALSE(isTemporary(e.path())) << e.path();
}

TEST(Reliability, TheResourceGuardPrintsItsEstimateAndRefusesWhatCannotFit) {
    const fs::path out = freshDir("reliability_guard");
    Result r = runGanache("run " + kScene + " --memory 0.001 --out " + out.string());
    EXPECT_EQ(r.code, 2) << r.output;
    EXPECT_NE(r.output.find("plan: about"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("resume.yaml:6:"), std::string::npos) << r.output;  // particles.radius
    EXPECT_NE(r.output.find("more than the 1.0 MiB --memory allows"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("fix: raise particles.radius"), std::string::npos) << r.output;
    // Nothing but the report, which says the run failed and why.
    std::vector<fs::path> written;
    for (const auto& e : fs::recursive_directory_iterator(out)) written.push_back(e.path());
    ASSERT_EQ(written, std::vector<fs::path>{out / "report.json"});
    const auto result = nlohmann::json::parse(readBytes(out / "report.json"))["result"];
    EXPECT_EQ(result["status"], "failed");
    EXPECT_NE(result["error"].get<std::string>().find("--memory allows"), std::string::npos) << result;
    r = runGanache("run " + kScene + " --memory 0.001 --skip-resource-check --frames 1-2 --out " + out.string());
    EXPECT_EQ(r.code, 0) << r.output;
}
