#pragma once
// The sampler's cache: the points sampled from one mesh input (the sites inside a fluid mesh, the surface of a
// boundary mesh), keyed by the placed mesh's content and the sampling parameters, so a re-run skips the work.

#include "geometry/mesh.h"

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace ganache {

/// Files <folder>/<key>.points, written atomically and sealed with a checksum footer. A file that fails its
/// checksum or does not match its key is a miss (and is rewritten), never an error.
class SampleCache {
public:
    explicit SampleCache(std::filesystem::path folder) : m_folder(std::move(folder)) {}

    std::optional<std::vector<Vec3>> load(std::uint64_t key) const;
    void store(std::uint64_t key, const std::vector<Vec3>& points) const;
    std::filesystem::path fileFor(std::uint64_t key) const;

private:
    std::filesystem::path m_folder;
};

/// Key of what sampling a mesh gives: its vertices and triangles (after placement and repair), what is
/// sampled (`purpose`), the spacing and the method.
std::uint64_t sampleKey(const TriangleMesh& mesh, const std::string& purpose, Real spacing, int method);

}  // namespace ganache
