#include "app/interrupt.h"

#include <csignal>

#include <unistd.h>

namespace ganache {

namespace {

volatile std::sig_atomic_t g_received = 0;
struct sigaction g_previous[2];
constexpr int kSignals[2] = {SIGINT, SIGTERM};

extern "C" void onSignal(int signal) {
    g_received = signal;
    // Only async-signal-safe calls here: one write of a fixed text.
    static const char kNote[] = "\nganache: stopping at the next safe point (a step or a frame); signal again to "
                                "stop at once\n";
    [[maybe_unused]] const ssize_t written = write(STDERR_FILENO, kNote, sizeof(kNote) - 1);
}

}  // namespace

InterruptGuard::InterruptGuard() {
    g_received = 0;
    struct sigaction action {};
    action.sa_handler = onSignal;
    sigemptyset(&action.sa_mask);
    action.sa_flags = SA_RESETHAND;  // the second signal takes the default action: the process ends
    for (int k = 0; k < 2; ++k) sigaction(kSignals[k], &action, &g_previous[k]);
}

InterruptGuard::~InterruptGuard() {
    for (int k = 0; k < 2; ++k) sigaction(kSignals[k], &g_previous[k], nullptr);
}

int InterruptGuard::received() { return g_received; }

}  // namespace ganache
