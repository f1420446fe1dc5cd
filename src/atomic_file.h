#pragma once
// Atomic output: every file is written under a temporary name in its folder and renamed into place, so a
// killed run never leaves a half-written frame and an existing file is only replaced by a complete one.

#include <filesystem>
#include <functional>
#include <string>

namespace ganache {

/// Calls write(temporaryPath), then renames the temporary file to `path`. On any failure the temporary file
/// is removed, `path` is left as it was, and std::runtime_error names the file and the cause.
void writeAtomically(const std::filesystem::path& path, const std::function<void(const std::filesystem::path&)>& write);

/// Writes `text` to `path` atomically.
void writeTextAtomically(const std::filesystem::path& path, const std::string& text);

}  // namespace ganache
