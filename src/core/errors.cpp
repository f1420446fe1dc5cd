#include "core/errors.h"

namespace ganache {

std::string Location::str() const {
    if (line <= 0) return file;
    return file + ":" + std::to_string(line) + ":" + std::to_string(column);
}

static std::string formatSceneError(const Location& at, const std::string& what, const std::string& fix) {
    std::string s = at.str() + ": " + what;
    if (!fix.empty()) s += "\n  fix: " + fix;
    return s;
}

SceneError::SceneError(Location at, const std::string& what, const std::string& fix)
    : InputError(formatSceneError(at, what, fix)), m_at(std::move(at)) {}

}  // namespace ganache
