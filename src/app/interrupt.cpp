#include "app/interrupt.h"

#include <csignal>

namespace ganache {

namespace {

volatile std::sig_atomic_t g_received = 0;
struct sigaction g_previous[2];
constexpr int kSignals[2] = {SIGINT, SIGTERM};

extern "C" void onSignal(int signal) { g_received = signal; }

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
