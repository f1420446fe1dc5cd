#pragma once
// Other programs ganache runs (ffmpeg for videos, Slurm's clients for the farm): found on the PATH, run with their
// output captured and a time limit, so that a tool that hangs (a Slurm controller that does not answer) becomes an
// error message instead of a hung command.

#include <string>
#include <vector>

namespace ganache {

/// Whether an executable `program` is in a folder of the PATH.
bool onPath(const std::string& program);

struct ProcessResult {
    int exitCode = -1;        ///< the program's exit status; 128 + the signal that ended it; -1 when it did not start
    bool timedOut = false;    ///< killed after the time limit
    std::string out, err;     ///< what it wrote to stdout and stderr
    /// stderr (else stdout), trimmed: what to show when it failed.
    std::string message() const;
};

/// Runs argv[0] (looked up on the PATH) with argv[1...], no shell, stdin from /dev/null; kills it (SIGKILL) after
/// timeoutSeconds.
ProcessResult runProcess(const std::vector<std::string>& argv, double timeoutSeconds);

}  // namespace ganache
