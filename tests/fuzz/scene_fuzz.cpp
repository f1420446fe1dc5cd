// Fuzz target: the scene loader. Any bytes as a scene file must give a scene or an InputError (the message with
// file, line and column); anything else (another exception, a crash, a sanitizer report) is a finding.

#include "core/errors.h"
#include "fuzz_input.h"
#include "scene/scene.h"

#include <cstdio>
#include <cstdlib>
#include <typeinfo>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const auto file = ganache_fuzz::writeInput(data, size, "scene.yaml");
    for (const char* quality : {"preview", "final"}) {
        try {
            const ganache::Scene scene = ganache::loadScene(file, ganache::Quality::parse(quality));
            (void)ganache::explainScene(scene);
        } catch (const ganache::InputError&) {
        } catch (const std::exception& e) {
            std::fprintf(stderr, "scene loader threw a %s that is not an InputError: %s\n", typeid(e).name(), e.what());
            std::abort();
        }
    }
    return 0;
}
