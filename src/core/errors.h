#pragma once
// The kinds of failure a ganache library reports. Only main() prints them and picks the exit code:
// InputError (and SceneError, derived from it) -> exit 2, Interrupted -> 128 + the signal (130 for SIGINT, 143 for
// SIGTERM, as shells report them), any other std::exception -> exit 1.

#include <stdexcept>
#include <string>

namespace ganache {

/// Bad input from the user: a scene value, a command-line option, a missing or unreadable file.
class InputError : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

/// Where a value came from: file, 1-based line and column (0 when unknown).
struct Location {
    std::string file;
    int line = 0;
    int column = 0;
    std::string str() const;  ///< "file:line:col", or just "file" when the position is unknown
};

/// Bad scene input; the message reads "file:line:col: what\n  fix: how".
class SceneError : public InputError {
public:
    SceneError(Location at, const std::string& what, const std::string& fix);
    const Location& location() const { return m_at; }

private:
    Location m_at;
};

/// A run that stopped on SIGINT or SIGTERM after saving what it had (see interrupt.h).
class Interrupted : public std::runtime_error {
public:
    Interrupted(int signal, const std::string& what) : std::runtime_error(what), m_signal(signal) {}
    int signal() const { return m_signal; }

private:
    int m_signal;
};

}  // namespace ganache
