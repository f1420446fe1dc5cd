#pragma once
// Command-line numbers for the measuring tools (coil_metrics, fold_metrics).

#include "core/types.h"

#include <cmath>
#include <stdexcept>
#include <string>

namespace ganache::tools {

/// The value `text` given to `option`, or a runtime_error naming both when the text is not one finite number.
inline Real number(const std::string& option, const std::string& text) {
    std::size_t used = 0;
    Real v = 0;
    try {
        v = std::stod(text, &used);
    } catch (const std::exception&) {
    }
    if (used == 0 || used != text.size() || !std::isfinite(v))
        throw std::runtime_error(option + ": '" + text + "' is not a number");
    return v;
}

/// The number after option argv[a] (which it steps past), or a runtime_error when it is missing or not a number.
inline Real nextNumber(int argc, char** argv, int& a) {
    const std::string option = argv[a];
    if (a + 1 >= argc) throw std::runtime_error(option + " needs a value");
    return number(option, argv[++a]);
}

}  // namespace ganache::tools
