// OBJ files of surface meshes: written by the surface stage, read back by the render stage. OpenVDB-free.

#include "surfacer/surfacer.h"

#include "core/errors.h"
#include "io/atomic_file.h"

#include <fmt/format.h>

#include <cerrno>
#include <fstream>
#include <sstream>
#include <system_error>

namespace ganache {

void writeObj(const std::filesystem::path& path, const SurfaceMesh& mesh, const std::string& header) {
    writeAtomically(path, [&](const std::filesystem::path& tmp) {
        std::ofstream out(tmp);
        out.precision(9);
        std::size_t start = 0;
        while (start < header.size()) {
            const std::size_t end = header.find('\n', start);
            out << "# " << header.substr(start, end - start) << '\n';
            if (end == std::string::npos) break;
            start = end + 1;
        }
        const bool withT = !mesh.temperature.empty();
        for (const auto& p : mesh.points) out << "v " << p.x() << ' ' << p.y() << ' ' << p.z() << '\n';
        for (const auto& n : mesh.normals) out << "vn " << n.x() << ' ' << n.y() << ' ' << n.z() << '\n';
        if (withT)
            for (float t : mesh.temperature) out << "vt " << t << " 0\n";
        for (const auto& t : mesh.triangles) {
            out << 'f';
            for (std::uint32_t v : t) {
                if (withT) out << ' ' << v + 1 << '/' << v + 1 << '/' << v + 1;
                else out << ' ' << v + 1 << "//" << v + 1;
            }
            out << '\n';
        }
        out.close();
        if (!out) throw std::system_error(errno, std::generic_category(), "writing the mesh failed");
    });
}

SurfaceMesh readObj(const std::filesystem::path& path) {
    std::ifstream in(path);
    if (!in) throw InputError(fmt::format("{}: cannot open the mesh", path.string()));
    SurfaceMesh mesh;
    std::vector<Vec3> normals;
    std::vector<float> temperatures;
    std::vector<std::array<std::array<std::int64_t, 3>, 3>> faces;  // per corner: v, vt, vn (0: absent)
    std::string line;
    std::size_t lineNumber = 0;
    auto bad = [&](const std::string& what) {
        return InputError(fmt::format("{}:{}: {}\n  fix: surface the frame again (`ganache surface SCENE --frames "
                                      "N --force`)",
                                      path.string(), lineNumber, what));
    };
    while (std::getline(in, line)) {
        ++lineNumber;
        std::istringstream s(line);
        std::string tag;
        if (!(s >> tag) || tag[0] == '#') continue;
        if (tag == "v" || tag == "vn") {
            Vec3 p;
            if (!(s >> p.x() >> p.y() >> p.z()) || !p.allFinite()) throw bad("a " + tag + " line needs three numbers");
            (tag == "v" ? mesh.points : normals).push_back(p);
        } else if (tag == "vt") {
            float t = 0;
            if (!(s >> t)) throw bad("a vt line needs a number");
            temperatures.push_back(t);
        } else if (tag == "f") {
            std::array<std::array<std::int64_t, 3>, 3> face{};
            std::string corner;
            int n = 0;
            for (; s >> corner; ++n) {
                if (n == 3) throw bad("faces must be triangles");
                std::array<std::int64_t, 3> ids{0, 0, 0};
                std::size_t start = 0;
                for (int k = 0; k < 3 && start <= corner.size(); ++k) {
                    const std::size_t end = std::min(corner.find('/', start), corner.size());
                    if (end > start) {
                        try {
                            ids[std::size_t(k)] = std::stoll(corner.substr(start, end - start));
                        } catch (const std::exception&) {
                            throw bad("'" + corner + "' is not a face corner (v/vt/vn)");
                        }
                    }
                    start = end + 1;
                }
                face[std::size_t(n)] = ids;
            }
            if (n != 3) throw bad("faces must be triangles");
            faces.push_back(face);
        }
    }
    const bool withNormals = !normals.empty(), withT = !temperatures.empty();
    mesh.normals.assign(mesh.points.size(), Vec3::Zero());
    if (withT) mesh.temperature.assign(mesh.points.size(), 0.f);
    for (const auto& face : faces) {
        std::array<std::uint32_t, 3> t{};
        for (std::size_t k = 0; k < 3; ++k) {
            const auto& [v, vt, vn] = face[k];
            if (v < 1 || std::size_t(v) > mesh.points.size()) throw bad(fmt::format("a face uses vertex {}, which does not exist", v));
            t[k] = std::uint32_t(v - 1);
            if (withNormals && vn >= 1 && std::size_t(vn) <= normals.size()) mesh.normals[t[k]] = normals[std::size_t(vn - 1)];
            if (withT && vt >= 1 && std::size_t(vt) <= temperatures.size()) mesh.temperature[t[k]] = temperatures[std::size_t(vt - 1)];
        }
        mesh.triangles.push_back(t);
    }
    if (!withNormals) mesh.normalsFromFaces();
    return mesh;
}

void SurfaceMesh::normalsFromFaces() {
    normals.assign(points.size(), Vec3::Zero());
    for (const auto& t : triangles) {
        const Vec3 n = (points[t[1]] - points[t[0]]).cross(points[t[2]] - points[t[0]]);
        for (std::uint32_t v : t) normals[v] += n;
    }
    for (auto& n : normals) n = n.norm() > 0 ? Vec3(n.normalized()) : Vec3(0, 1, 0);
}

}  // namespace ganache
