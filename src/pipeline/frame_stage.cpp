#include "pipeline/frame_stage.h"

#include "app/interrupt.h"
#include "core/errors.h"
#include "pipeline/pipeline.h"

#include <fmt/format.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cstring>

namespace ganache {

FrameJobs::FrameJobs(std::string stage, std::string verb, std::pair<std::int64_t, std::int64_t> frames, bool force,
                     const std::function<bool(std::int64_t)>& fresh)
    : m_stage(std::move(stage)), m_verb(std::move(verb)) {
    for (std::int64_t f = frames.first; f <= frames.second; ++f) {
        if (!force && fresh(f)) ++m_skipped;
        else m_todo.push_back(f);
    }
    if (!m_todo.empty()) m_progress.emplace(m_stage, m_todo.size());
}

void FrameJobs::run(std::size_t begin, std::size_t end, const std::function<void(std::int64_t frame)>& work) {
    tbb::parallel_for(begin, end, std::size_t(1), [&](std::size_t k) {
        if (stopped()) return;
        const std::int64_t f = m_todo[k];
        std::string failure;
        bool input = true;
        try {
            work(f);
        } catch (const InputError& e) {
            failure = e.what();
        } catch (const std::exception& e) {
            failure = e.what();
            input = false;
        }
        const std::lock_guard<std::mutex> guard(m_lock);
        if (!failure.empty()) {
            m_failures.emplace_back(f, fmt::format("{}: frame {}: {}", m_stage, f, failure));
            m_onlyInputErrors &= input;
            return;
        }
        ++m_done;
        m_progress->update(m_done);
    });
}

bool FrameJobs::stopped() const { return InterruptGuard::received() != 0; }

void FrameJobs::finish() {
    if (m_progress) m_progress->finish(m_done);
    if (m_failures.empty()) {
        if (stopped() && m_done < m_todo.size())
            throw Interrupted(InterruptGuard::received(),
                              fmt::format("{} during the {} stage: {} of {} frames {} (complete and kept), {} not "
                                          "started",
                                          strsignal(InterruptGuard::received()), m_stage, m_done, m_todo.size(),
                                          m_verb, m_todo.size() - m_done));
        return;
    }
    std::sort(m_failures.begin(), m_failures.end());
    std::string text;
    for (const auto& [frame, what] : m_failures) text += (text.empty() ? "" : "\n") + what;
    text += fmt::format("\n  ({} other frames were {}; they are complete and kept)", m_done, m_verb);
    if (m_onlyInputErrors) throw InputError(text);
    throw std::runtime_error(text);
}

bool upToDate(const std::filesystem::path& output, const std::filesystem::path& input) {
    std::error_code ec;
    const auto out = std::filesystem::last_write_time(output, ec);
    if (ec) return false;
    return out >= std::filesystem::last_write_time(input, ec) && !ec;
}

void requireParticleCaches(const char* stage, const Scene& scene, const OutputLayout& layout,
                           std::pair<std::int64_t, std::int64_t> frames) {
    for (std::int64_t f = frames.first; f <= frames.second; ++f)
        if (!std::filesystem::exists(layout.particles(f)))
            throw InputError(fmt::format("{}: frame {} has no particle cache ({})\n  fix: simulate frames {}-{} "
                                         "first (`ganache simulate {} --frames {}-{}`), or pick frames that were "
                                         "simulated with --frames",
                                         stage, f, layout.particles(f).string(), frames.first, frames.second,
                                         scene.file.string(), frames.first, frames.second));
}

}  // namespace ganache
