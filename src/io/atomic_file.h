#pragma once
// Atomic output: a file appears under its name complete or not at all. Its bytes are written to an unnamed file
// in the target folder (O_TMPFILE; on file systems without it, a hidden temporary name), flushed to the disk, and
// only then given a name and renamed into place. A run killed at any moment leaves every earlier file as it was
// and no half-written file under any name; a full disk is reported as such, with the fix.

#include <filesystem>
#include <functional>
#include <string>
#include <string_view>

namespace ganache {

/// Calls write(path to write to), flushes the file to the disk and renames it to `path`. `write` must throw when
/// its own writing fails. On any failure `path` is left as it was, nothing else is left behind, and
/// std::runtime_error names the file and the cause (a full disk says so and how to fix it).
void writeAtomically(const std::filesystem::path& path, const std::function<void(const std::filesystem::path&)>& write);

/// Writes `bytes` to `path` atomically, checking every write.
void writeBytesAtomically(const std::filesystem::path& path, std::string_view bytes);

/// Writes `text` to `path` atomically.
inline void writeTextAtomically(const std::filesystem::path& path, const std::string& text) {
    writeBytesAtomically(path, text);
}

/// Removes what killed runs on this host left under `folder` (recursively): named temporary files of
/// writeAtomically whose process is gone. Returns how many were removed.
std::size_t removeStaleTemporaries(const std::filesystem::path& folder);

/// Makes the output folder `root` (named by `option` in messages, e.g. "--out") before any work, or throws
/// InputError: a part of the path that exists is a file, or the folder cannot be made. A typo in an output path
/// then never costs a stage's work.
void prepareOutputFolder(const std::filesystem::path& root, const std::string& option);

}  // namespace ganache
