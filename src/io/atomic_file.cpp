#include "io/atomic_file.h"

#include "core/errors.h"

#include <fmt/format.h>

#include <atomic>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <stdexcept>
#include <system_error>

#include <fcntl.h>
#include <signal.h>
#include <sys/statvfs.h>
#include <unistd.h>

namespace ganache {

namespace fs = std::filesystem;

namespace {

constexpr std::string_view kTemporaryTag = ".ganache-tmp.";

// This machine's name as it appears in temporary names: a shared output folder may be written by several hosts,
// and only this host's processes can be checked for being alive.
const std::string& hostTag() {
    static const std::string tag = [] {
        char name[256] = {};
        if (::gethostname(name, sizeof name - 1) != 0) return std::string("host");
        std::string out(name);
        for (char& c : out)
            if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-') c = '_';
        return out.empty() ? std::string("host") : out;
    }();
    return tag;
}

fs::path temporaryName(const fs::path& path) {
    static std::atomic<unsigned> counter{0};
    return path.parent_path() / fmt::format(".{}{}{}.{}.{}", path.filename().string(), kTemporaryTag, hostTag(),
                                            ::getpid(), counter++);
}

// The error a failed write ends with: the cause, and when the disk (or the file size limit) is what stopped it,
// how much is left and what to do.
[[noreturn]] void fail(const fs::path& path, const std::string& cause, int err) {
    std::string text = fmt::format("cannot write {}: {}", path.string(), cause);
    const fs::path folder = path.has_parent_path() ? path.parent_path() : fs::path(".");
    struct statvfs disk {};
    const bool known = ::statvfs(folder.c_str(), &disk) == 0;
    const double freeBytes = known ? double(disk.f_bavail) * double(disk.f_frsize) : -1;
    const bool full = err == ENOSPC || err == EDQUOT || (known && freeBytes < 1 << 20);
    if (full)
        text += fmt::format("\n  the disk holding {} is full ({:.1f} MiB free)\n  fix: free space there, or write the "
                            "outputs elsewhere with --out; every file written before this one is complete and kept",
                            folder.string(), std::max(0.0, freeBytes) / (1 << 20));
    else if (err == EFBIG)
        text += "\n  fix: the file is larger than this process may write (`ulimit -f`); raise the limit; every file "
                "written before this one is complete and kept";
    throw std::runtime_error(text);
}

// Flushes a written file to the disk: a full disk often shows only here (delayed allocation).
int syncFile(int fd) { return ::fsync(fd) == 0 ? 0 : errno; }

int syncPath(const fs::path& file) {
    const int fd = ::open(file.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) return errno;
    const int err = syncFile(fd);
    ::close(fd);
    return err;
}

// Makes a rename durable; failure here loses nothing already written, so it is not an error.
void syncFolder(const fs::path& folder) {
    const int fd = ::open(folder.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (fd < 0) return;
    ::fsync(fd);
    ::close(fd);
}

}  // namespace

void writeAtomically(const fs::path& path, const std::function<void(const fs::path&)>& write) {
    const fs::path folder = path.has_parent_path() ? path.parent_path() : fs::path(".");
    std::error_code ec;
    fs::create_directories(folder, ec);
    if (ec) fail(path, fmt::format("cannot create the folder {}: {}", folder.string(), ec.message()), ec.value());

    // The bytes go to an unnamed file of the folder when the file system allows it: a killed run leaves nothing.
    // Its /proc path (by process id, so a child process such as ffmpeg can open it too) is what `write` opens.
    const int unnamed = ::open(folder.c_str(), O_TMPFILE | O_WRONLY | O_CLOEXEC, 0644);
    const fs::path proc = unnamed >= 0 ? fs::path(fmt::format("/proc/{}/fd/{}", ::getpid(), unnamed)) : fs::path();
    const bool useUnnamed = unnamed >= 0 && fs::exists(proc, ec);
    if (unnamed >= 0 && !useUnnamed) ::close(unnamed);
    const fs::path temporary = temporaryName(path);
    auto cleanUp = [&] {
        if (useUnnamed) ::close(unnamed);
        std::error_code ignored;
        fs::remove(temporary, ignored);
    };

    try {
        write(useUnnamed ? proc : temporary);
    } catch (const std::system_error& e) {
        cleanUp();
        fail(path, e.what(), e.code().value());
    } catch (const std::exception& e) {
        cleanUp();
        fail(path, e.what(), 0);
    }
    if (const int err = useUnnamed ? syncFile(unnamed) : syncPath(temporary)) {
        cleanUp();
        fail(path, std::strerror(err), err);
    }
    // Named only now that it is complete and on the disk; the rename replaces `path` in one step.
    if (useUnnamed && ::linkat(AT_FDCWD, proc.c_str(), AT_FDCWD, temporary.c_str(), AT_SYMLINK_FOLLOW) != 0) {
        const int err = errno;
        cleanUp();
        fail(path, fmt::format("cannot name the written file: {}", std::strerror(err)), err);
    }
    if (::rename(temporary.c_str(), path.c_str()) != 0) {
        const int err = errno;
        cleanUp();
        fail(path, fmt::format("cannot move it into place: {}", std::strerror(err)), err);
    }
    if (useUnnamed) ::close(unnamed);
    syncFolder(folder);
}

void writeBytesAtomically(const fs::path& path, std::string_view bytes) {
    writeAtomically(path, [&](const fs::path& target) {
        const int fd = ::open(target.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
        if (fd < 0) throw std::system_error(errno, std::generic_category(), "cannot open it");
        std::size_t done = 0;
        while (done < bytes.size()) {
            const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
            if (n < 0 && errno == EINTR) continue;
            if (n <= 0) {
                const int err = n < 0 ? errno : ENOSPC;
                ::close(fd);
                throw std::system_error(err, std::generic_category(), fmt::format("wrote {} of {} bytes", done,
                                                                                   bytes.size()));
            }
            done += std::size_t(n);
        }
        if (::close(fd) != 0) throw std::system_error(errno, std::generic_category(), "closing it failed");
    });
}

std::size_t removeStaleTemporaries(const fs::path& folder) {
    std::error_code ec;
    if (!fs::is_directory(folder, ec)) return 0;
    std::size_t removed = 0;
    const std::string mine = std::string(kTemporaryTag) + hostTag() + ".";
    for (auto it = fs::recursive_directory_iterator(folder, ec); !ec && it != fs::recursive_directory_iterator();
         it.increment(ec)) {
        const std::string name = it->path().filename().string();
        const std::size_t at = name.find(mine);
        if (at == std::string::npos || !it->is_regular_file(ec)) continue;
        const long pid = std::strtol(name.c_str() + at + mine.size(), nullptr, 10);
        if (pid > 0 && ::kill(pid_t(pid), 0) != 0 && errno == ESRCH) {
            std::error_code ignored;
            if (fs::remove(it->path(), ignored)) ++removed;
        }
    }
    return removed;
}

void prepareOutputFolder(const std::filesystem::path& root, const std::string& option) {
    namespace fs = std::filesystem;
    std::error_code ec;
    for (fs::path p = root; !p.empty(); p = p.parent_path()) {
        if (fs::exists(p, ec) && !fs::is_directory(p, ec))
            throw InputError(fmt::format("{} {}: {} is a file, not a folder\n  fix: give {} a folder (it is made "
                                         "when missing) that no file stands in the way of",
                                         option, root.string(), p.string(), option));
        if (p == p.parent_path()) break;
    }
    fs::create_directories(root, ec);
    if (ec)
        throw InputError(fmt::format("{} {}: the folder cannot be made: {}\n  fix: choose a folder this user may "
                                     "write to",
                                     option, root.string(), ec.message()));
}

}  // namespace ganache
