#include "checksum.h"

#include <array>
#include <cstdio>
#include <cstring>
#include <stdexcept>
#include <vector>

namespace ganache {

namespace {

constexpr char kMagic[8] = {'G', 'N', 'C', 'H', 'S', 'U', 'M', '1'};
constexpr std::size_t kFooterSize = kChecksumFooterSize;

struct File {
    std::FILE* f;
    ~File() {
        if (f) std::fclose(f);
    }
};

// Hashes the first `length` bytes of an open file.
std::uint64_t hashPrefix(std::FILE* f, std::uint64_t length) {
    std::vector<unsigned char> buf(1 << 20);
    std::uint64_t hash = kFnvOffset, left = length;
    std::fseek(f, 0, SEEK_SET);
    while (left > 0) {
        const std::size_t n = std::fread(buf.data(), 1, std::size_t(std::min<std::uint64_t>(left, buf.size())), f);
        if (n == 0) throw std::runtime_error("read error");
        hash = fnv1a64(buf.data(), n, hash);
        left -= n;
    }
    return hash;
}

}  // namespace

std::uint64_t fnv1a64(const void* data, std::size_t size, std::uint64_t hash) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (std::size_t i = 0; i < size; ++i) {
        hash ^= p[i];
        hash *= 0x100000001b3ULL;
    }
    return hash;
}

std::string checksumFooter(std::string_view payload) {
    const std::uint64_t length = payload.size();
    const std::uint64_t hash = fnv1a64(payload.data(), payload.size());
    std::string footer(kFooterSize, '\0');
    std::memcpy(footer.data(), kMagic, 8);
    std::memcpy(footer.data() + 8, &length, 8);
    std::memcpy(footer.data() + 16, &hash, 8);
    return footer;
}

bool checksumFooterMatches(std::string_view bytes, std::string& why) {
    if (bytes.size() < kFooterSize || std::memcmp(bytes.data() + bytes.size() - kFooterSize, kMagic, 8) != 0) {
        why = "has no ganache checksum footer (truncated, or not written by ganache)";
        return false;
    }
    std::uint64_t length, hash;
    std::memcpy(&length, bytes.data() + bytes.size() - 16, 8);
    std::memcpy(&hash, bytes.data() + bytes.size() - 8, 8);
    if (length != bytes.size() - kFooterSize) {
        why = "has the wrong length for its checksum footer (truncated or extended)";
        return false;
    }
    if (fnv1a64(bytes.data(), length) != hash) {
        why = "fails its checksum (corrupt)";
        return false;
    }
    return true;
}

bool verifyChecksumFooter(const std::filesystem::path& file, std::string& why) {
    File f{std::fopen(file.c_str(), "rb")};
    if (!f.f) {
        why = "cannot be opened";
        return false;
    }
    std::fseek(f.f, 0, SEEK_END);
    const long size = std::ftell(f.f);
    std::array<unsigned char, kFooterSize> footer{};
    if (size < long(kFooterSize) || std::fseek(f.f, size - long(kFooterSize), SEEK_SET) != 0 ||
        std::fread(footer.data(), 1, kFooterSize, f.f) != kFooterSize || std::memcmp(footer.data(), kMagic, 8) != 0) {
        why = "has no ganache checksum footer (truncated, or not written by ganache)";
        return false;
    }
    std::uint64_t length, hash;
    std::memcpy(&length, footer.data() + 8, 8);
    std::memcpy(&hash, footer.data() + 16, 8);
    if (length != std::uint64_t(size) - kFooterSize) {
        why = "has the wrong length for its checksum footer";
        return false;
    }
    if (hashPrefix(f.f, length) != hash) {
        why = "fails its checksum (corrupt)";
        return false;
    }
    return true;
}

}  // namespace ganache
