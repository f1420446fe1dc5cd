#include "io/ply.h"

#include "io/atomic_file.h"

#include <sstream>

namespace ganache {

static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "PLY records are written as the machine lays them out");

PlyFile::PlyFile(const std::string& comments) : m_header("ply\nformat binary_little_endian 1.0\n") {
    std::istringstream lines(comments);
    for (std::string line; std::getline(lines, line);) m_header += "comment " + line + "\n";
}

void PlyFile::element(const std::string& name, std::size_t count, const std::vector<std::string>& properties) {
    m_header += "element " + name + " " + std::to_string(count) + "\n";
    for (const std::string& p : properties) m_header += "property " + p + "\n";
}

void PlyFile::write(const std::filesystem::path& path) const {
    writeBytesAtomically(path, m_header + "end_header\n" + m_body);
}

}  // namespace ganache
