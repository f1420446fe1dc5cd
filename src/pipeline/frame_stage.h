#pragma once
// What the per-frame stages (surface, render) share: which frames need work, a progress line, frames run in
// parallel, and their failures collected by frame so that every frame that can be done is done.

#include "app/progress.h"

#include <cstdint>
#include <filesystem>
#include <functional>
#include <mutex>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace ganache {

struct OutputLayout;
struct Scene;

/// An output is up to date when it exists and is newer than its input.
bool upToDate(const std::filesystem::path& output, const std::filesystem::path& input);

/// Throws InputError naming the first frame of the range without a particle cache, before a stage does any work.
void requireParticleCaches(const char* stage, const Scene& scene, const OutputLayout& layout,
                           std::pair<std::int64_t, std::int64_t> frames);

/// The frames of a range that a per-frame stage has to do, run in parallel, with their failures.
class FrameJobs {
public:
    /// The frames of the range to do: those whose outputs are not up to date (`fresh` says false), or every frame
    /// with force; the others are counted as skipped. `verb` says what the stage does to a frame ("rendered").
    FrameJobs(std::string stage, std::string verb, std::pair<std::int64_t, std::int64_t> frames, bool force,
              const std::function<bool(std::int64_t)>& fresh);

    const std::vector<std::int64_t>& todo() const { return m_todo; }
    std::size_t skipped() const { return m_skipped; }
    std::size_t done() const { return m_done; }
    bool failed() const { return !m_failures.empty(); }
    /// A SIGINT or SIGTERM arrived (see InterruptGuard): frames not yet started are left alone.
    bool stopped() const;

    /// Runs work(frame) for todo()[begin, end) in parallel. A frame that throws is recorded as
    /// "<stage>: frame F: <what>" and the others go on; once stopped() no further frame starts, and the frames
    /// under way finish.
    void run(std::size_t begin, std::size_t end, const std::function<void(std::int64_t frame)>& work);
    /// Finishes the progress line; then, when a frame failed, throws listing every failure in frame order and
    /// saying that the frames done are complete and kept: InputError when every failure was bad input,
    /// std::runtime_error otherwise (a full disk). When stopped, throws Interrupted saying how many frames are done.
    void finish();

private:
    std::string m_stage, m_verb;
    std::vector<std::int64_t> m_todo;
    std::size_t m_skipped = 0, m_done = 0;
    std::vector<std::pair<std::int64_t, std::string>> m_failures;
    bool m_onlyInputErrors = true;
    std::optional<Progress> m_progress;  // none when there is nothing to do
    std::mutex m_lock;
};

}  // namespace ganache
