#pragma once
// What the fuzz targets share: the input bytes as a file (the loaders read files, as ganache does), in a folder
// of this process's own.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>

#include <unistd.h>

namespace ganache_fuzz {

inline std::filesystem::path writeInput(const std::uint8_t* data, std::size_t size, const std::string& name) {
    static const std::filesystem::path folder = [] {
        const auto d = std::filesystem::temp_directory_path() / ("ganache_fuzz_" + std::to_string(getpid()));
        std::filesystem::create_directories(d);
        return d;
    }();
    const std::filesystem::path file = folder / name;
    std::ofstream(file, std::ios::binary | std::ios::trunc).write(reinterpret_cast<const char*>(data),
                                                                   std::streamsize(size));
    return file;
}

}  // namespace ganache_fuzz
