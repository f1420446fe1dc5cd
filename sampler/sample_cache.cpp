#include "sampler/sample_cache.h"

#include "io/atomic_file.h"
#include "io/checksum.h"

#include <fmt/format.h>

#include <cstring>
#include <fstream>

namespace ganache {

namespace {

constexpr char kMagic[8] = {'G', 'N', 'C', 'H', 'P', 'T', 'S', '1'};

}  // namespace

std::uint64_t sampleKey(const TriangleMesh& mesh, const std::string& purpose, Real spacing, int method) {
    std::uint64_t h = fnv1a64(purpose.data(), purpose.size());
    h = fnv1a64(mesh.vertices.data(), mesh.vertices.size() * sizeof(Vec3), h);
    h = fnv1a64(mesh.triangles.data(), mesh.triangles.size() * sizeof(mesh.triangles[0]), h);
    h = fnv1a64(&spacing, sizeof spacing, h);
    return fnv1a64(&method, sizeof method, h);
}

std::filesystem::path SampleCache::fileFor(std::uint64_t key) const {
    return m_folder / fmt::format("{:016x}.points", key);
}

std::optional<std::vector<Vec3>> SampleCache::load(std::uint64_t key) const {
    const std::filesystem::path file = fileFor(key);
    std::error_code ec;
    if (!std::filesystem::exists(file, ec)) return std::nullopt;
    std::string why;
    if (!verifyChecksumFooter(file, why)) return std::nullopt;
    std::ifstream in(file, std::ios::binary);
    char magic[8];
    std::uint64_t storedKey = 0, count = 0;
    in.read(magic, 8);
    in.read(reinterpret_cast<char*>(&storedKey), sizeof storedKey);
    in.read(reinterpret_cast<char*>(&count), sizeof count);
    const auto size = std::filesystem::file_size(file, ec);
    if (!in || std::memcmp(magic, kMagic, 8) != 0 || storedKey != key || ec || count > size / sizeof(Vec3))
        return std::nullopt;
    std::vector<Vec3> points(count);
    in.read(reinterpret_cast<char*>(points.data()), std::streamsize(count * sizeof(Vec3)));
    if (!in) return std::nullopt;
    return points;
}

void SampleCache::store(std::uint64_t key, const std::vector<Vec3>& points) const {
    const std::uint64_t count = points.size();
    std::string bytes(kMagic, 8);
    bytes.append(reinterpret_cast<const char*>(&key), sizeof key);
    bytes.append(reinterpret_cast<const char*>(&count), sizeof count);
    bytes.append(reinterpret_cast<const char*>(points.data()), points.size() * sizeof(Vec3));
    bytes += checksumFooter(bytes);
    writeBytesAtomically(fileFor(key), bytes);
}

}  // namespace ganache
