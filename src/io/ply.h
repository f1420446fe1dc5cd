#pragma once
// Binary little-endian PLY files: a text header that names each element and its properties, then the packed records.
// Blender, Houdini and most point and mesh tools read them. No library in Debian writes PLY with extra per-vertex
// properties (assimp's exporter keeps positions, normals, colours and texture coordinates), and the format is this
// simple, so it is written here.

#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

namespace ganache {

class PlyFile {
public:
    /// `comments`: lines for the header's comments.
    explicit PlyFile(const std::string& comments);
    /// Declares an element of `count` records with the properties in order, as PLY writes them ("float x",
    /// "list uchar uint vertex_indices"). Its records follow, value by value, through put().
    void element(const std::string& name, std::size_t count, const std::vector<std::string>& properties);
    /// Appends one value of a record (its type must be the property's).
    template <class T>
    void put(T value) {
        char bytes[sizeof(T)];
        std::memcpy(bytes, &value, sizeof(T));
        m_body.append(bytes, sizeof(T));
    }
    void reserve(std::size_t bytes) { m_body.reserve(bytes); }
    /// Writes the header and the records atomically (see atomic_file.h).
    void write(const std::filesystem::path& path) const;

private:
    std::string m_header, m_body;
};

}  // namespace ganache
