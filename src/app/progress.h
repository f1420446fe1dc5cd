#pragma once
// Progress with an ETA on stderr: a redrawn bar on a terminal, a line every few seconds otherwise (farm logs).

#include <chrono>
#include <cstddef>
#include <string>

namespace ganache {

class Progress {
public:
    Progress(std::string label, std::size_t total);
    ~Progress();
    /// Reports that `done` of the total units are finished.
    void update(std::size_t done);
    /// Prints the final state: `done` units (default: all of them) and the elapsed time.
    void finish(std::size_t done = std::size_t(-1));

private:
    void print(std::size_t done, bool final);

    std::string m_label;
    std::size_t m_total;
    bool m_isTerminal;
    bool m_finished = false;
    std::chrono::steady_clock::time_point m_start, m_lastPrint;
};

/// "1h02m", "3m05s", "12.3s"
std::string formatDuration(double seconds);

}  // namespace ganache
