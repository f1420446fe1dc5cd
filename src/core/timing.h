#pragma once
// Wall-clock timing of stages and solver parts.

#include <chrono>

namespace ganache {

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
