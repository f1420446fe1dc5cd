#include "app/progress.h"

#include <fmt/format.h>

#include <algorithm>
#include <cstdio>
#include <unistd.h>

namespace ganache {

namespace {
constexpr double kLineInterval = 5.0;   // seconds between lines when stderr is a file or pipe
constexpr double kRedrawInterval = 0.2;  // seconds between bar redraws on a terminal
}  // namespace

std::string formatDuration(double s) {
    if (s < 60) return fmt::format("{:.1f}s", s);
    const long t = long(s + 0.5);
    if (t < 3600) return fmt::format("{}m{:02}s", t / 60, t % 60);
    return fmt::format("{}h{:02}m", t / 3600, (t % 3600) / 60);
}

Progress::Progress(std::string label, std::size_t total)
    : m_label(std::move(label)), m_total(std::max<std::size_t>(total, 1)), m_isTerminal(::isatty(STDERR_FILENO)),
      m_start(std::chrono::steady_clock::now()), m_lastPrint(m_start) {}

Progress::~Progress() {
    if (m_isTerminal && !m_finished) std::fputc('\n', stderr);
}

void Progress::update(std::size_t done) {
    const auto now = std::chrono::steady_clock::now();
    const double sinceLast = std::chrono::duration<double>(now - m_lastPrint).count();
    if (sinceLast < (m_isTerminal ? kRedrawInterval : kLineInterval)) return;
    m_lastPrint = now;
    print(done, false);
}

void Progress::finish(std::size_t done) {
    if (m_finished) return;
    print(std::min(done, m_total), true);
    m_finished = true;
}

void Progress::print(std::size_t done, bool final) {
    const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - m_start).count();
    const double fraction = std::min(1.0, double(done) / double(m_total));
    const std::string eta = final ? (done < m_total ? "stopped after " : "done in ") + formatDuration(elapsed)
                            : fraction > 0 ? "ETA " + formatDuration(elapsed * (1 - fraction) / fraction)
                                           : "ETA --";
    if (m_isTerminal) {
        constexpr int kWidth = 30;
        const int filled = int(fraction * kWidth);
        fmt::print(stderr, "\r{:<10} [{}{}] {:5.1f}% {}/{}  {}\x1b[K{}", m_label, std::string(filled, '#'),
                   std::string(kWidth - filled, '.'), 100 * fraction, done, m_total, eta, final ? "\n" : "");
    } else {
        fmt::print(stderr, "{}: {:5.1f}% ({}/{})  {}\n", m_label, 100 * fraction, done, m_total, eta);
    }
    std::fflush(stderr);
}

}  // namespace ganache
