#pragma once
// FNV-1a 64-bit hashing: scene hashes in reports, and the footer that guards every cache file.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>

namespace ganache {

constexpr std::uint64_t kFnvOffset = 0xcbf29ce484222325ULL;
constexpr std::size_t kChecksumFooterSize = 24;  ///< magic, payload length, hash

/// FNV-1a 64 of `size` bytes, continuing from `hash`.
std::uint64_t fnv1a64(const void* data, std::size_t size, std::uint64_t hash = kFnvOffset);

/// The footer that seals `payload` when appended to it: magic, payload length, FNV-1a 64 of the payload.
std::string checksumFooter(std::string_view payload);

/// True when `bytes` (a payload followed by its footer) ends in a footer that matches the payload; otherwise `why`
/// says what is wrong (no footer, length mismatch, checksum mismatch).
bool checksumFooterMatches(std::string_view bytes, std::string& why);

/// True when the file ends in a footer whose length and checksum match the bytes before it.
/// `why` says what is wrong otherwise (no footer, length mismatch, checksum mismatch).
bool verifyChecksumFooter(const std::filesystem::path& file, std::string& why);

}  // namespace ganache
