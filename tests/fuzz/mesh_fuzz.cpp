// Fuzz target: the mesh loader (assimp behind readMeshFile) and the mesh repair and check that follow it. The
// first byte picks the format the rest is read as. A mesh or an InputError are the only allowed outcomes.

#include "core/errors.h"
#include "fuzz_input.h"
#include "geometry/mesh.h"

#include <cstdio>
#include <cstdlib>
#include <typeinfo>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    if (size == 0) return 0;
    static const char* const kFormats[] = {"obj", "ply", "stl", "off", "gltf"};
    const auto file = ganache_fuzz::writeInput(data + 1, size - 1, std::string("mesh.") + kFormats[data[0] % 5]);
    try {
        ganache::TriangleMesh mesh = ganache::readMeshFile(file);
        ganache::repairMesh(mesh);
        (void)mesh.signedVolume();
    } catch (const ganache::InputError&) {
    } catch (const std::exception& e) {
        std::fprintf(stderr, "mesh loader threw a %s that is not an InputError: %s\n", typeid(e).name(), e.what());
        std::abort();
    }
    return 0;
}
