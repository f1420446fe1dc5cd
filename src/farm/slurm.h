#pragma once
// The Slurm client programs (sbatch, scontrol, sinfo, squeue, scancel) as ganache uses them. Every call has a time
// limit, and every failure becomes a message that names the program and what it said. They talk to the cluster
// that SLURM_CONF (or /etc/slurm/slurm.conf) names.

#include <map>
#include <string>
#include <vector>

namespace ganache::slurm {

struct Node {
    std::string name;
    int cpus = 0;
    double memoryMiB = 0;
    std::string state;
};

struct Partition {
    std::string name;
    bool isDefault = false;
    std::vector<Node> nodes;
};

/// InputError naming the first client program that is not on the PATH and how to get it.
void requireClients();

/// std::runtime_error when the controller does not answer (with what scontrol said and what to check).
void requireController();

/// The partition jobs go to: `name`, or the cluster's default when empty; InputError when there is no such
/// partition (listing those there are) or no default.
Partition partition(const std::string& name);

/// `sbatch --parsable ARGS SCRIPT`: the job id; std::runtime_error with sbatch's message when it refuses.
std::string submit(const std::vector<std::string>& args, const std::string& script);

/// `sbatch --test-only ARGS SCRIPT`: empty when Slurm would accept the job, else its message.
std::string testSubmit(const std::vector<std::string>& args, const std::string& script);

/// Cancels jobs (errors ignored: used to take back a graph submitted in part).
void cancel(const std::vector<std::string>& jobIds);

/// Jobs of `jobIds` still in the queue, by id ("12", or "12_3" for task 3 of an array): "STATE" or
/// "STATE (reason)". std::runtime_error when the controller does not answer.
std::map<std::string, std::string> queue(const std::vector<std::string>& jobIds);

}  // namespace ganache::slurm
