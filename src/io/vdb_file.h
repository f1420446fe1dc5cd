#pragma once
// Writing OpenVDB files the way every ganache output is written: atomically, sealed with a checksum footer (which
// OpenVDB readers ignore), and reproducibly: OpenVDB stamps each file with a random UUID, which ganache replaces
// by one derived from the file's contents, so the same grids give the same bytes. Include only where OpenVDB's
// headers are already included (cache.cpp, surfacer.cpp): they are slow to compile.

#include <openvdb/openvdb.h>

#include <filesystem>

namespace ganache {

/// Writes the grids to `path` as one OpenVDB file (with grid offsets, as openvdb::io::File writes it).
void writeVdbAtomically(const std::filesystem::path& path, const openvdb::GridCPtrVec& grids);

}  // namespace ganache
