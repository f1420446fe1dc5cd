#pragma once
// `ganache farm`: a scene as a Slurm job graph. One simulate job (sample, then simulate: sequential in time, on one
// node), an array of surface tasks over chunks of frames after it, an array of render tasks each after its surface
// chunk, and an assemble job (contact sheet, video, one report.json). The batch scripts are written to
// <out>/farm/ and stay there, readable and re-submittable by hand; the shared output folder is the only thing the
// jobs share.

#include "pipeline/pipeline.h"

#include <filesystem>
#include <string>
#include <vector>

namespace ganache {

struct FarmOptions {
    std::int64_t chunk = 10;           ///< frames per surface / render task
    std::string partition;             ///< empty: the cluster's default
    int cpus = 0;                      ///< CPUs of each surface / render task; 0: a node's, at most 4
    std::vector<std::string> sbatch;   ///< further sbatch options for every job (e.g. --account=vfx)
    bool dryRun = false;               ///< write the scripts and print the plan; submit nothing
    bool assumeShared = false;         ///< trust that the output folder is the same on every node
};

/// `ganache farm SCENE`: plans, writes and (unless dryRun) submits the job graph. Nothing is left submitted when
/// any job is refused. InputError for bad input (no Slurm clients, no such partition, a job no node can hold, an
/// output folder the nodes cannot see), std::runtime_error when the controller does not answer.
void farmSubmitCommand(const RunOptions& run, const FarmOptions& farm);

/// `ganache farm status OUT`: per stage, the frames done and the jobs running, pending or failed, with the
/// command that reruns a failed task.
void farmStatusCommand(const std::filesystem::path& out);

/// `ganache farm report OUT` (the assemble job's last step): merges the tasks' reports into <out>/report.json.
void farmReportCommand(const std::filesystem::path& out);

}  // namespace ganache
