#include "io/checksum.h"

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

namespace {

// Reads a footer; false with `why` set when it is missing or does not fit a file of `size` bytes.
bool readFooter(const unsigned char* footer, std::uint64_t size, std::uint64_t& length, std::uint64_t& hash,
                std::string& why) {
    if (size < kFooterSize || std::memcmp(footer, kMagic, 8) != 0) {
        why = "has no ganache checksum footer (truncated, or not written by ganache)";
        return false;
    }
    std::memcpy(&length, footer + 8, 8);
    std::memcpy(&hash, footer + 16, 8);
    if (length != size - kFooterSize) {
        why = "has the wrong length for its checksum footer (truncated or extended)";
        return false;
    }
    return true;
}

}  // namespace

bool checksumFooterMatches(std::string_view bytes, std::string& why) {
    std::uint64_t length = 0, hash = 0;
    const auto* footer = bytes.size() < kFooterSize
                             ? nullptr
                             : reinterpret_cast<const unsigned char*>(bytes.data()) + bytes.size() - kFooterSize;
    if (!readFooter(footer, bytes.size(), length, hash, why)) return false;
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
    const bool read = size >= long(kFooterSize) && std::fseek(f.f, size - long(kFooterSize), SEEK_SET) == 0 &&
                      std::fread(footer.data(), 1, kFooterSize, f.f) == kFooterSize;
    std::uint64_t length = 0, hash = 0;
    if (!readFooter(footer.data(), read ? std::uint64_t(size) : 0, length, hash, why)) return false;
    if (hashPrefix(f.f, length) != hash) {
        why = "fails its checksum (corrupt)";
        return false;
    }
    return true;
}

}  // namespace ganache
