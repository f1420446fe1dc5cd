#include "farm/slurm.h"

#include "app/process.h"
#include "core/errors.h"

#include <fmt/format.h>

#include <sstream>

namespace ganache::slurm {

namespace {

// Long enough for a controller under load (Slurm's own message timeout is 10 s, with retries), short enough that a
// dead one is reported within a minute.
constexpr double kTimeoutSeconds = 45;

ProcessResult call(std::vector<std::string> argv) {
    ProcessResult r = runProcess(argv, kTimeoutSeconds);
    if (r.timedOut)
        throw std::runtime_error(fmt::format("`{}` did not answer within {:.0f} s: the Slurm controller is not "
                                             "reachable\n  fix: check that slurmctld runs and that SLURM_CONF names "
                                             "this cluster's slurm.conf",
                                             argv[0], kTimeoutSeconds));
    return r;
}

std::vector<std::string> lines(const std::string& text) {
    std::vector<std::string> out;
    std::istringstream in(text);
    for (std::string line; std::getline(in, line);)
        if (line.find_first_not_of(" \t") != std::string::npos) out.push_back(line);
    return out;
}

}  // namespace

void requireClients() {
    for (const char* program : {"sbatch", "scontrol", "sinfo", "squeue", "scancel"})
        if (!onPath(program))
            throw InputError(fmt::format("ganache farm: `{}` is not on the PATH, so there is no Slurm to submit to\n  "
                                         "fix: run on a machine of the farm that has Slurm's client programs "
                                         "(Debian: apt-get install slurm-client), or add their folder to PATH",
                                         program));
}

void requireController() {
    const ProcessResult r = call({"scontrol", "ping"});
    if (r.exitCode != 0 || r.out.find("UP") == std::string::npos)
        throw std::runtime_error(fmt::format("the Slurm controller does not answer (`scontrol ping`: {})\n  fix: "
                                             "check that slurmctld runs and that SLURM_CONF names this cluster's "
                                             "slurm.conf; nothing was submitted",
                                             r.message().substr(0, r.message().find('\n'))));
}

Partition partition(const std::string& name) {
    // sinfo -N: one line per node and partition; the default partition's name carries a '*'.
    const ProcessResult r = call({"sinfo", "-h", "-N", "-o", "%P|%N|%c|%m|%T"});
    if (r.exitCode != 0) throw std::runtime_error(fmt::format("`sinfo` failed: {}", r.message()));
    std::map<std::string, Partition> all;
    for (const std::string& line : lines(r.out)) {
        std::vector<std::string> f;
        std::istringstream in(line);
        for (std::string field; std::getline(in, field, '|');) f.push_back(field);
        if (f.size() != 5) continue;
        const bool isDefault = !f[0].empty() && f[0].back() == '*';
        const std::string partitionName = isDefault ? f[0].substr(0, f[0].size() - 1) : f[0];
        Partition& p = all[partitionName];
        p.name = partitionName;
        p.isDefault |= isDefault;
        Node n{f[1], 0, 0, f[4]};
        try {
            n.cpus = std::stoi(f[2]);
            n.memoryMiB = std::stod(f[3]);
        } catch (const std::exception&) {
        }
        p.nodes.push_back(n);
    }
    std::vector<std::string> names;
    for (const auto& [n, p] : all) names.push_back(n + (p.isDefault ? " (default)" : ""));
    const std::string there = names.empty() ? "none" : fmt::format("{}", fmt::join(names, ", "));
    if (name.empty()) {
        for (const auto& [n, p] : all)
            if (p.isDefault) return p;
        throw InputError(fmt::format("ganache farm: the cluster has no default partition (partitions: {})\n  fix: "
                                     "name one with --partition",
                                     there));
    }
    const auto it = all.find(name);
    if (it == all.end())
        throw InputError(fmt::format("--partition {}: the cluster has no such partition (partitions: {})\n  fix: "
                                     "pick one of those (`sinfo` lists them)",
                                     name, there));
    return it->second;
}

std::string submit(const std::vector<std::string>& args, const std::string& script) {
    std::vector<std::string> argv{"sbatch", "--parsable"};
    argv.insert(argv.end(), args.begin(), args.end());
    argv.push_back(script);
    const ProcessResult r = call(argv);
    const std::string id = r.out.substr(0, r.out.find_first_of(";\n"));  // "ID" or "ID;CLUSTER"
    if (r.exitCode != 0 || id.empty() || id.find_first_not_of("0123456789") != std::string::npos)
        throw std::runtime_error(fmt::format("sbatch refused {}: {}", script, r.message()));
    return id;
}

std::string testSubmit(const std::vector<std::string>& args, const std::string& script) {
    std::vector<std::string> argv{"sbatch", "--test-only"};
    argv.insert(argv.end(), args.begin(), args.end());
    argv.push_back(script);
    const ProcessResult r = call(argv);
    return r.exitCode == 0 ? std::string() : r.message();
}

void cancel(const std::vector<std::string>& jobIds) {
    if (jobIds.empty()) return;
    std::vector<std::string> argv{"scancel"};
    argv.insert(argv.end(), jobIds.begin(), jobIds.end());
    runProcess(argv, kTimeoutSeconds);
}

std::map<std::string, std::string> queue(const std::vector<std::string>& jobIds) {
    std::map<std::string, std::string> out;
    if (jobIds.empty()) return out;
    const ProcessResult r = call({"squeue", "-h", "-r", "-j", fmt::format("{}", fmt::join(jobIds, ",")), "-o", "%i|%T|%r"});
    // A job the controller has forgotten (finished long ago) makes squeue fail with "Invalid job id".
    if (r.exitCode != 0 && r.err.find("Invalid job id") == std::string::npos)
        throw std::runtime_error(fmt::format("`squeue` failed: {}", r.message()));
    for (const std::string& line : lines(r.out)) {
        const std::size_t a = line.find('|'), b = line.find('|', a + 1);
        if (a == std::string::npos || b == std::string::npos) continue;
        const std::string reason = line.substr(b + 1);
        out[line.substr(0, a)] =
            line.substr(a + 1, b - a - 1) + (reason.empty() || reason == "None" ? "" : " (" + reason + ")");
    }
    return out;
}

}  // namespace ganache::slurm
