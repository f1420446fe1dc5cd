#include "atomic_file.h"

#include <fmt/format.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <stdexcept>
#include <unistd.h>

namespace ganache {

void writeAtomically(const std::filesystem::path& path,
                     const std::function<void(const std::filesystem::path&)>& write) {
    namespace fs = std::filesystem;
    std::error_code ec;
    if (path.has_parent_path()) {
        fs::create_directories(path.parent_path(), ec);
        if (ec) throw std::runtime_error(fmt::format("cannot create folder {}: {}", path.parent_path().string(),
                                                     ec.message()));
    }
    const fs::path tmp = path.string() + fmt::format(".tmp-{}", ::getpid());
    try {
        write(tmp);
    } catch (const std::exception& e) {
        fs::remove(tmp, ec);
        throw std::runtime_error(fmt::format("writing {} failed: {}", path.string(), e.what()));
    }
    fs::rename(tmp, path, ec);
    if (ec) {
        std::error_code ignored;
        fs::remove(tmp, ignored);
        throw std::runtime_error(fmt::format("cannot move {} into place: {}", path.string(), ec.message()));
    }
}

void writeTextAtomically(const std::filesystem::path& path, const std::string& text) {
    writeAtomically(path, [&](const std::filesystem::path& tmp) {
        std::FILE* f = std::fopen(tmp.c_str(), "wb");
        if (!f) throw std::runtime_error(std::strerror(errno));
        const bool ok = std::fwrite(text.data(), 1, text.size(), f) == text.size();
        const int err = errno;
        // fclose flushes: a full disk often shows only here.
        if (std::fclose(f) != 0 || !ok) throw std::runtime_error(std::strerror(ok ? errno : err));
    });
}

}  // namespace ganache
