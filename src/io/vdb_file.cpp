#include "io/vdb_file.h"

#include "io/atomic_file.h"
#include "io/checksum.h"

#include <fmt/format.h>
#include <openvdb/io/Archive.h>

#include <cctype>
#include <sstream>
#include <stdexcept>

namespace ganache {

namespace {

// OpenVDB's archive writer is protected; this exposes it for an in-memory stream, whose errors ganache then
// checks itself when the bytes go to the disk (openvdb::io::File does not check its stream after writing).
class ArchiveImage : public openvdb::io::Archive {
public:
    std::string bytes(const openvdb::GridCPtrVec& grids) const {
        std::ostringstream out(std::ios::binary);
        write(out, grids, /*seekable=*/true);
        if (!out) throw std::runtime_error("OpenVDB could not serialise the grids");
        return out.str();
    }
};

// The header holds the UUID as 36 characters (8-4-4-4-12 hex digits) right after the magic number, the file
// version, the library version and the grid-offsets flag.
constexpr std::size_t kUuidOffset = 8 + 4 + 4 + 4 + 1;
constexpr std::size_t kUuidLength = 36;

bool looksLikeUuid(std::string_view s) {
    if (s.size() != kUuidLength) return false;
    for (std::size_t k = 0; k < s.size(); ++k) {
        const bool dash = k == 8 || k == 13 || k == 18 || k == 23;
        if (dash ? s[k] != '-' : !std::isxdigit(static_cast<unsigned char>(s[k]))) return false;
    }
    return true;
}

}  // namespace

void writeVdbAtomically(const std::filesystem::path& path, const openvdb::GridCPtrVec& grids) {
    openvdb::initialize();
    std::string bytes = ArchiveImage().bytes(grids);
    if (bytes.size() < kUuidOffset + kUuidLength || !looksLikeUuid(std::string_view(bytes).substr(kUuidOffset, kUuidLength)))
        throw std::runtime_error("unexpected OpenVDB file header (no UUID where OpenVDB 10 writes it)");
    // The contents' hash (with the UUID blanked) becomes the UUID: same grids, same file.
    std::fill_n(bytes.begin() + kUuidOffset, kUuidLength, '0');
    const std::uint64_t a = fnv1a64(bytes.data(), bytes.size());
    const std::uint64_t b = fnv1a64(&a, sizeof a, a ^ 0x9e3779b97f4a7c15ULL);
    const std::string uuid = fmt::format("{:08x}-{:04x}-{:04x}-{:04x}-{:012x}", a >> 32, (a >> 16) & 0xffff,
                                         a & 0xffff, b >> 48, b & 0xffffffffffffULL);
    bytes.replace(kUuidOffset, kUuidLength, uuid);
    bytes += checksumFooter(bytes);
    writeBytesAtomically(path, bytes);
}

}  // namespace ganache
