#pragma once
// What the cross-stage tests share: running the real `ganache` program and fresh folders for its outputs.

#include <array>
#include <cstdio>
#include <filesystem>
#include <string>

#include <sys/wait.h>
#include <unistd.h>

namespace ganache_test {

namespace fs = std::filesystem;

inline const fs::path kSource = GANACHE_SOURCE_DIR;

struct Result {
    int code;            // exit status; 128 + the signal when a signal ended it
    std::string output;  // stdout and stderr together
};

// Runs a shell command line, stderr joined to stdout.
inline Result runShell(const std::string& command) {
    FILE* pipe = popen((command + " 2>&1").c_str(), "r");
    std::string out;
    std::array<char, 4096> buf;
    while (std::size_t n = std::fread(buf.data(), 1, buf.size(), pipe)) out.append(buf.data(), n);
    const int status = pclose(pipe);
    return {WIFEXITED(status) ? WEXITSTATUS(status) : WIFSIGNALED(status) ? 128 + WTERMSIG(status) : -1, out};
}

// Runs ganache with these arguments; `environment` (e.g. "PATH=/x:$PATH") is put before the command.
inline Result runGanache(const std::string& args, const std::string& environment = "") {
    return runShell(environment + " " + std::string(GANACHE_EXE) + " " + args);
}

// Starts ganache in the background (its output to `log`) and returns its process id: signals sent to it reach
// ganache itself, not a shell.
inline pid_t startGanache(const std::string& args, const fs::path& log) {
    const std::string command = "exec " + std::string(GANACHE_EXE) + " " + args + " > '" + log.string() + "' 2>&1";
    const pid_t pid = fork();
    if (pid == 0) {
        execl("/bin/sh", "sh", "-c", command.c_str(), static_cast<char*>(nullptr));
        _exit(127);
    }
    return pid;
}

// Waits for a started process; returns its exit status as Result::code does.
inline int waitFor(pid_t pid) {
    int status = 0;
    waitpid(pid, &status, 0);
    return WIFEXITED(status) ? WEXITSTATUS(status) : WIFSIGNALED(status) ? 128 + WTERMSIG(status) : -1;
}

inline fs::path freshDir(const std::string& name) {
    const fs::path d = fs::temp_directory_path() / "ganache_cli_test" / name;
    fs::remove_all(d);
    fs::create_directories(d);
    return d;
}

}  // namespace ganache_test
