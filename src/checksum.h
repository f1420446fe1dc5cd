#pragma once
// FNV-1a 64-bit hashing: scene hashes in reports, and the footer that guards every cache file.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>

namespace ganache {

constexpr std::uint64_t kFnvOffset = 0xcbf29ce484222325ULL;

/// FNV-1a 64 of `size` bytes, continuing from `hash`.
std::uint64_t fnv1a64(const void* data, std::size_t size, std::uint64_t hash = kFnvOffset);

/// Appends a footer (magic, payload length, FNV-1a 64 of the payload) to the file.
void appendChecksumFooter(const std::filesystem::path& file);

/// True when the file ends in a footer whose length and checksum match the bytes before it.
/// `why` says what is wrong otherwise (no footer, length mismatch, checksum mismatch).
bool verifyChecksumFooter(const std::filesystem::path& file, std::string& why);

}  // namespace ganache
