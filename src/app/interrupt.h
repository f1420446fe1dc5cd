#pragma once
// SIGINT (Ctrl-C) and SIGTERM (a farm scheduler's stop) during a run: the first one asks the run to stop at its next
// safe point (the end of a simulation step, with a checkpoint; the end of the frames being surfaced or rendered;
// the end of the sample), say what is done and how to continue, and exit with 128 + the signal; a second one ends
// the process at once, as it would without ganache's handler. Outside an InterruptGuard the signals act as usual
// (every output is written atomically, so a killed stage leaves complete files only).

namespace ganache {

class InterruptGuard {
public:
    InterruptGuard();
    ~InterruptGuard();
    InterruptGuard(const InterruptGuard&) = delete;
    InterruptGuard& operator=(const InterruptGuard&) = delete;

    /// The signal received since the guard was made; 0 when none.
    static int received();
};

}  // namespace ganache
