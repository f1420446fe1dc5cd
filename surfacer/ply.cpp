// Binary PLY files of surface meshes (`surface.mesh_format: ply`): under a third of the OBJ text's bytes, written
// and read without formatting numbers. Blender and Houdini read them natively. The reader takes binary little-endian
// triangle meshes with any scalar property types, as ganache and most tools write them.

#include "surfacer/surfacer.h"

#include "core/errors.h"
#include "io/ply.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>

namespace ganache {

namespace {

// The PLY scalar types, by name.
enum class Scalar { None, I8, U8, I16, U16, I32, U32, F32, F64 };

Scalar scalarType(const std::string& name) {
    static const std::map<std::string, Scalar> types = {
        {"char", Scalar::I8},    {"int8", Scalar::I8},     {"uchar", Scalar::U8},   {"uint8", Scalar::U8},
        {"short", Scalar::I16},  {"int16", Scalar::I16},   {"ushort", Scalar::U16}, {"uint16", Scalar::U16},
        {"int", Scalar::I32},    {"int32", Scalar::I32},   {"uint", Scalar::U32},   {"uint32", Scalar::U32},
        {"float", Scalar::F32},  {"float32", Scalar::F32}, {"double", Scalar::F64}, {"float64", Scalar::F64}};
    const auto it = types.find(name);
    return it == types.end() ? Scalar::None : it->second;
}

std::size_t typeSize(Scalar type) {
    switch (type) {
    case Scalar::I8: case Scalar::U8: return 1;
    case Scalar::I16: case Scalar::U16: return 2;
    case Scalar::I32: case Scalar::U32: case Scalar::F32: return 4;
    case Scalar::F64: return 8;
    default: return 0;
    }
}

// The value of a scalar of `type` at `p` (little-endian).
double scalar(Scalar type, const char* p) {
    auto get = [p](auto value) {
        std::memcpy(&value, p, sizeof value);
        return double(value);
    };
    switch (type) {
    case Scalar::I8: return get(std::int8_t());
    case Scalar::U8: return get(std::uint8_t());
    case Scalar::I16: return get(std::int16_t());
    case Scalar::U16: return get(std::uint16_t());
    case Scalar::I32: return get(std::int32_t());
    case Scalar::U32: return get(std::uint32_t());
    case Scalar::F32: return get(float());
    default: return get(double());
    }
}

struct Property {
    std::string name;
    Scalar type = Scalar::None, count = Scalar::None;  // count: the list's length, for a list property
};

struct Element {
    std::string name;
    std::size_t count = 0;
    std::vector<Property> properties;
};

}  // namespace

void writePly(const std::filesystem::path& path, const SurfaceMesh& mesh, const std::string& header) {
    const bool withT = !mesh.temperature.empty();
    PlyFile ply(header);
    std::vector<std::string> vertex = {"float x", "float y", "float z", "float nx", "float ny", "float nz"};
    if (withT) vertex.push_back("float temperature");
    ply.element("vertex", mesh.points.size(), vertex);
    ply.element("face", mesh.triangles.size(), {"list uchar uint vertex_indices"});
    ply.reserve(mesh.points.size() * 4 * vertex.size() + mesh.triangles.size() * 13);
    for (std::size_t v = 0; v < mesh.points.size(); ++v) {
        for (int k = 0; k < 3; ++k) ply.put(float(mesh.points[v][k]));
        for (int k = 0; k < 3; ++k) ply.put(float(mesh.normals[v][k]));
        if (withT) ply.put(mesh.temperature[v]);
    }
    for (const auto& t : mesh.triangles) {
        ply.put(std::uint8_t(3));
        for (std::uint32_t v : t) ply.put(v);
    }
    ply.write(path);
}

SurfaceMesh readPly(const std::filesystem::path& path) {
    auto bad = [&](const std::string& what) {
        return InputError(fmt::format("{}: {}\n  fix: surface the frame again (`ganache surface SCENE --frames N "
                                      "--force`)",
                                      path.string(), what));
    };
    std::ifstream in(path, std::ios::binary);
    if (!in) throw InputError(fmt::format("{}: cannot open the mesh", path.string()));
    std::string line;
    if (!std::getline(in, line) || line != "ply") throw bad("not a PLY file (no `ply` on its first line)");
    std::vector<Element> elements;
    bool binaryLittleEndian = false;
    while (std::getline(in, line) && line != "end_header") {
        std::istringstream s(line);
        std::string word;
        s >> word;
        if (word == "format") {
            std::string format;
            s >> format;
            binaryLittleEndian = format == "binary_little_endian";
        } else if (word == "element") {
            Element e;
            if (!(s >> e.name >> e.count)) throw bad("malformed header line '" + line + "'");
            elements.push_back(e);
        } else if (word == "property") {
            if (elements.empty()) throw bad("a property before any element");
            Property p;
            std::string type, count;
            s >> type;
            if (type == "list") s >> count >> type;
            s >> p.name;
            p.type = scalarType(type);
            p.count = count.empty() ? Scalar::None : scalarType(count);
            if (p.type == Scalar::None || (!count.empty() && p.count == Scalar::None))
                throw bad("unknown property type in '" + line + "'");
            elements.back().properties.push_back(p);
        }
    }
    if (line != "end_header") throw bad("the header never ends (no end_header)");
    if (!binaryLittleEndian) throw bad("only binary little-endian PLY is read (as ganache writes it)");
    const std::string body((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    std::size_t at = 0;
    auto need = [&](std::size_t bytes) {
        if (at + bytes > body.size()) throw bad("the file ends before its last element");
    };

    SurfaceMesh mesh;
    bool normals = false;
    for (const Element& e : elements) {
        const bool vertex = e.name == "vertex", face = e.name == "face";
        if (vertex) mesh.points.assign(e.count, Vec3::Zero()), mesh.normals.assign(e.count, Vec3::Zero());
        // Where each vertex property goes: 0-2 the position, 3-5 the normal, 6 the temperature, -1 nowhere.
        std::vector<int> slot;
        for (const Property& p : e.properties) {
            static const std::vector<std::string> names = {"x", "y", "z", "nx", "ny", "nz", "temperature"};
            const auto it = std::find(names.begin(), names.end(), p.name);
            slot.push_back(vertex && it != names.end() ? int(it - names.begin()) : -1);
            normals |= slot.back() == 3;
            if (slot.back() == 6) mesh.temperature.assign(e.count, 0.f);
        }
        for (std::size_t i = 0; i < e.count; ++i)
            for (std::size_t k = 0; k < e.properties.size(); ++k) {
                const Property& p = e.properties[k];
                const std::size_t size = typeSize(p.type);
                if (p.count != Scalar::None) {
                    need(typeSize(p.count));
                    const auto n = std::size_t(scalar(p.count, body.data() + at));
                    at += typeSize(p.count);
                    need(n * size);
                    if (face && p.name == "vertex_indices") {
                        if (n != 3) throw bad(fmt::format("face {} has {} corners; faces must be triangles", i, n));
                        std::array<std::uint32_t, 3> t{};
                        for (std::size_t c = 0; c < 3; ++c) {
                            const double v = scalar(p.type, body.data() + at + c * size);
                            if (v < 0 || v >= double(mesh.points.size()))
                                throw bad(fmt::format("face {} uses vertex {}, which does not exist", i, v));
                            t[c] = std::uint32_t(v);
                        }
                        mesh.triangles.push_back(t);
                    }
                    at += n * size;
                    continue;
                }
                need(size);
                const int to = slot[k];
                const double value = to >= 0 ? scalar(p.type, body.data() + at) : 0;
                at += size;
                if (to < 0) continue;
                if (!std::isfinite(value)) throw bad(fmt::format("vertex {} has a non-finite {}", i, p.name));
                if (to < 6) (to < 3 ? mesh.points : mesh.normals)[i][to % 3] = value;
                else mesh.temperature[i] = float(value);
            }
    }
    if (!normals) mesh.normalsFromFaces();
    return mesh;
}

void writeSurfaceMesh(const std::filesystem::path& path, const SurfaceMesh& mesh, const std::string& header) {
    if (path.extension() == ".ply") writePly(path, mesh, header);
    else writeObj(path, mesh, header);
}

SurfaceMesh readSurfaceMesh(const std::filesystem::path& path) {
    return path.extension() == ".ply" ? readPly(path) : readObj(path);
}

}  // namespace ganache
