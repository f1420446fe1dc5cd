#pragma once
// The stages of a ganache run and the commands that drive them: sample -> simulate -> surface -> render.
// Each stage reads the files the previous one wrote, so any stage can be rerun on its own.

#include "scene/scene.h"

#include <filesystem>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace ganache {

enum class StageId { Sample, Simulate, Surface, Render };

/// Options shared by the commands (the CLI's flags).
struct RunOptions {
    std::filesystem::path scene;
    std::filesystem::path out;                       ///< empty: out/<scene name>
    std::filesystem::path report;                    ///< empty: <out>/report.json
    std::string frames;                              ///< "A-B" or "A"; empty: the scene's frames
    int threads = 0;                                 ///< 0: every core
    std::string quality = "preview";
    bool resume = false;
    bool force = false;                              ///< redo frames whose outputs are up to date
    bool framesOnly = false;                         ///< render: no contact sheet or video (a farm task's part)
    double memoryGiB = 0;                            ///< memory a stage may plan for; 0: what is free
    bool skipResourceCheck = false;                  ///< run even when the estimates exceed what the machine has
};

/// The inclusive frame range "A-B" (or "A") within the scene's frames; InputError when malformed or outside.
std::pair<std::int64_t, std::int64_t> parseFrameRange(const std::string& text, const FrameRange& scene);

/// Output locations of a scene: <out>/sample/<name>.vdb, <out>/particles/<name>.NNNN.vdb, <out>/report.json,
/// <out>/cache/ (the sampler's mesh cache), <out>/checkpoints/.
struct OutputLayout {
    std::filesystem::path root;
    std::string name;
    std::string meshExtension = "obj";  ///< the scene's surface.mesh_format
    std::filesystem::path sample() const { return root / "sample" / (name + ".vdb"); }
    std::filesystem::path sampleCache() const { return root / "cache"; }  ///< sampled mesh inputs, by key
    std::filesystem::path particles(std::int64_t frame) const;
    std::filesystem::path points(std::int64_t frame) const;   ///< <out>/points/<name>.NNNN.ply (particles.export)
    std::filesystem::path surface(std::int64_t frame) const;  ///< <out>/surface/<name>.NNNN.vdb
    std::filesystem::path mesh(std::int64_t frame) const;     ///< <out>/mesh/<name>.NNNN.obj (or .ply)
    std::filesystem::path preview(std::int64_t frame) const;  ///< <out>/preview/<name>.NNNN.png
    std::filesystem::path sheet() const { return root / "preview" / (name + ".sheet.png"); }
    std::filesystem::path video() const { return root / "preview" / (name + ".mp4"); }
    std::filesystem::path report() const { return root / "report.json"; }
    std::filesystem::path checkpoints() const { return root / "checkpoints"; }
    /// <out>/checkpoints/<name>.FFFF.SSSSSSS.ckpt: saved after frame F was written, at step S.
    std::filesystem::path checkpoint(std::int64_t frame, std::uint64_t step) const;
};

/// What a scene will need, estimated from the scene before anything runs (resources.cpp). The resource guard
/// compares it with what the machine has; the farm turns it into each job's request.
struct ResourceEstimate {
    double fluid = 0, boundary = 0;  ///< particles
    double programBytes = 0;         ///< memory of the program itself, before any particle
    /// Memory on top of the program [bytes]: sample and simulate; one frame surfaced; the render stage with two
    /// threads, of which each thread's renderer takes renderContextBytes. 0 for a stage not asked for.
    double simulateBytes = 0, surfaceFrameBytes = 0, renderBytes = 0, renderContextBytes = 0;
    /// Disk the outputs of the frame range take [bytes].
    double sampleDisk = 0, particleDisk = 0, checkpointDisk = 0, levelSetDisk = 0, meshDisk = 0, previewDisk = 0;
    double disk() const { return sampleDisk + particleDisk + checkpointDisk + levelSetDisk + meshDisk + previewDisk; }
};
ResourceEstimate estimateResources(const Scene& scene, std::pair<std::int64_t, std::int64_t> frames,
                                   const std::vector<StageId>& stages);

/// `ganache run` (every stage the scene asks for) or one stage on its own. Throws InputError for bad input,
/// std::runtime_error for run-time failures. Progress and the closing table go to stderr.
void runCommand(const RunOptions& options, const std::vector<StageId>& stages);

/// `ganache sample --check`: the pre-flight facts of every mesh of the scene, to stdout.
void meshCheckCommand(const RunOptions& options);

/// `ganache scene`: validates the scene; with explain, prints the effective scene to stdout.
void sceneCommand(const RunOptions& options, bool explain);

}  // namespace ganache
