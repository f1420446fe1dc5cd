// OBJ files of surface meshes: written by the surface stage, read back by the render stage. OpenVDB-free.

#include "surfacer/surfacer.h"

#include "core/errors.h"
#include "io/atomic_file.h"

#include <fmt/format.h>

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <charconv>
#include <cstring>
#include <fstream>
#include <string_view>
#include <system_error>

namespace ganache {

namespace {

// OBJ text written through a small buffer: numbers by std::to_chars, several times faster than an ostream and the
// same characters; the buffer is reused, so that no fresh memory is touched for a frame's tens of megabytes.
class ObjWriter {
public:
    explicit ObjWriter(std::ofstream& file) : m_file(file) { m_buffer.reserve(kFlushAt + 256); }
    ~ObjWriter() { flush(); }
    void text(std::string_view s) {
        m_buffer.append(s);
        if (m_buffer.size() >= kFlushAt) flush();
    }
    /// Nine significant digits, as an ostream at precision 9 writes them (%.9g): floats round-trip, doubles to 1e-9.
    void number(double x) {
        char digits[32];
        text({digits, std::size_t(std::to_chars(digits, digits + sizeof digits, x, std::chars_format::general, 9).ptr -
                                  digits)});
    }
    void index(std::uint64_t i) {
        char digits[24];
        text({digits, std::size_t(std::to_chars(digits, digits + sizeof digits, i).ptr - digits)});
    }
    void flush() {
        m_file.write(m_buffer.data(), std::streamsize(m_buffer.size()));
        m_buffer.clear();
    }

private:
    static constexpr std::size_t kFlushAt = std::size_t(1) << 20;
    std::ofstream& m_file;
    std::string m_buffer;
};

// Calls f(line) for each line of `text`, without its newline.
template <class F>
void eachLine(std::string_view text, F&& f) {
    for (std::size_t start = 0; start < text.size();) {
        const std::size_t end = std::min(text.find('\n', start), text.size());
        f(text.substr(start, end - start));
        start = end + 1;
    }
}

}  // namespace

void writeObj(const std::filesystem::path& path, const SurfaceMesh& mesh, const std::string& header) {
    writeAtomically(path, [&](const std::filesystem::path& tmp) {
        std::ofstream file(tmp, std::ios::binary);
        {
            ObjWriter out(file);
            eachLine(header, [&](std::string_view line) { out.text("# "), out.text(line), out.text("\n"); });
            const auto triple = [&](std::string_view tag, const Vec3& p) {
                out.text(tag), out.number(p.x()), out.text(" "), out.number(p.y()), out.text(" "), out.number(p.z());
                out.text("\n");
            };
            for (const auto& p : mesh.points) triple("v ", p);
            for (const auto& n : mesh.normals) triple("vn ", n);
            for (float t : mesh.temperature) out.text("vt "), out.number(t), out.text(" 0\n");
            const bool withT = !mesh.temperature.empty();
            for (const auto& t : mesh.triangles) {
                out.text("f");
                for (std::uint32_t v : t) {
                    out.text(" "), out.index(v + 1), out.text(withT ? "/" : "//");
                    if (withT) out.index(v + 1), out.text("/");
                    out.index(v + 1);
                }
                out.text("\n");
            }
        }
        file.close();
        if (!file) throw std::system_error(errno, std::generic_category(), "writing the mesh failed");
    });
}

namespace {

// A line of an OBJ file, read token by token without copies.
class LineReader {
public:
    explicit LineReader(std::string_view line) : m_rest(line) {}
    /// The next run of non-blank characters ("" at the end).
    std::string_view token() {
        std::size_t a = 0;
        while (a < m_rest.size() && (m_rest[a] == ' ' || m_rest[a] == '\t' || m_rest[a] == '\r')) ++a;
        std::size_t b = a;
        while (b < m_rest.size() && m_rest[b] != ' ' && m_rest[b] != '\t' && m_rest[b] != '\r') ++b;
        const std::string_view t = m_rest.substr(a, b - a);
        m_rest.remove_prefix(b);
        return t;
    }
    /// The next token as a number, false when it is missing or is not one whole number.
    template <class T>
    bool number(T& value) {
        std::string_view t = token();
        if (!t.empty() && t[0] == '+') t.remove_prefix(1);
        const auto [end, error] = std::from_chars(t.data(), t.data() + t.size(), value);
        return !t.empty() && error == std::errc() && end == t.data() + t.size();
    }

private:
    std::string_view m_rest;
};

// A file mapped read-only: its pages come straight from the page cache, where reading it into a string first zeroed
// and then copied tens of megabytes.
class MappedFile {
public:
    explicit MappedFile(const std::filesystem::path& path) : m_fd(::open(path.c_str(), O_RDONLY | O_CLOEXEC)) {
        struct stat info {};
        const auto fail = [&](const std::string& what) {
            if (m_fd >= 0) ::close(m_fd);
            return InputError(fmt::format("{}: {}", path.string(), what));
        };
        if (m_fd < 0 || ::fstat(m_fd, &info) != 0 || !S_ISREG(info.st_mode)) throw fail("cannot open the mesh");
        m_size = std::size_t(info.st_size);
        if (m_size == 0) return;
        m_data = ::mmap(nullptr, m_size, PROT_READ, MAP_PRIVATE, m_fd, 0);
        if (m_data == MAP_FAILED) throw fail(fmt::format("cannot read the mesh: {}", std::strerror(errno)));
    }
    ~MappedFile() {
        if (m_data) ::munmap(m_data, m_size);
        if (m_fd >= 0) ::close(m_fd);
    }
    MappedFile(const MappedFile&) = delete;
    MappedFile& operator=(const MappedFile&) = delete;
    std::string_view text() const { return m_data ? std::string_view(static_cast<const char*>(m_data), m_size) : ""; }

private:
    int m_fd;
    void* m_data = nullptr;
    std::size_t m_size = 0;
};

}  // namespace

SurfaceMesh readObj(const std::filesystem::path& path) {
    const MappedFile file(path);
    const std::string_view text = file.text();
    SurfaceMesh mesh;
    std::vector<Vec3> normals;
    std::vector<float> temperatures;
    std::vector<std::array<std::array<std::int64_t, 3>, 3>> faces;  // per corner: v, vt, vn (0: absent)
    // Sized before the parse: the faces alone take 72 bytes each, and growing them copied them over and over.
    {
        std::size_t v = 0, vn = 0, vt = 0, f = 0;
        eachLine(text, [&](std::string_view line) {
            if (line.size() >= 2 && line[0] == 'f') ++f;
            if (line.size() >= 2 && line[0] == 'v') ++(line[1] == 'n' ? vn : line[1] == 't' ? vt : v);
        });
        mesh.points.reserve(v), normals.reserve(vn), temperatures.reserve(vt), faces.reserve(f);
    }
    std::size_t lineNumber = 0;
    auto bad = [&](const std::string& what) {
        return InputError(fmt::format("{}:{}: {}\n  fix: surface the frame again (`ganache surface SCENE --frames "
                                      "N --force`)",
                                      path.string(), lineNumber, what));
    };
    eachLine(text, [&](std::string_view line) {
        LineReader s(line);
        ++lineNumber;
        const std::string_view tag = s.token();
        if (tag.empty() || tag[0] == '#') return;
        if (tag == "v" || tag == "vn") {
            Vec3 p;
            if (!s.number(p.x()) || !s.number(p.y()) || !s.number(p.z()) || !p.allFinite())
                throw bad(fmt::format("a {} line needs three numbers", tag));
            (tag == "v" ? mesh.points : normals).push_back(p);
        } else if (tag == "vt") {
            float t = 0;
            if (!s.number(t)) throw bad("a vt line needs a number");
            temperatures.push_back(t);
        } else if (tag == "f") {
            std::array<std::array<std::int64_t, 3>, 3> face{};
            int n = 0;
            for (std::string_view corner = s.token(); !corner.empty(); corner = s.token(), ++n) {
                if (n == 3) throw bad("faces must be triangles");
                std::array<std::int64_t, 3> ids{0, 0, 0};
                std::size_t from = 0;
                for (std::size_t k = 0; k < 3 && from <= corner.size(); ++k) {
                    const std::size_t to = std::min(corner.find('/', from), corner.size());
                    if (to > from) {
                        const auto [last, error] = std::from_chars(corner.data() + from, corner.data() + to, ids[k]);
                        if (error != std::errc() || last != corner.data() + to)
                            throw bad(fmt::format("'{}' is not a face corner (v/vt/vn)", corner));
                    }
                    from = to + 1;
                }
                face[std::size_t(n)] = ids;
            }
            if (n != 3) throw bad("faces must be triangles");
            faces.push_back(face);
        }
    });
    const bool withNormals = !normals.empty(), withT = !temperatures.empty();
    mesh.normals.assign(mesh.points.size(), Vec3::Zero());
    if (withT) mesh.temperature.assign(mesh.points.size(), 0.f);
    mesh.triangles.reserve(faces.size());
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
