#pragma once
// Shared set-up for solver tests: scenes written to a temporary folder and sampled in memory.

#include "sampler.h"
#include "scene.h"
#include "step.h"

#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <string>

namespace ganache::testing {

/// Loads a scene from text (at final quality), written to the temporary folder under `name`.
inline Scene sceneFromText(const std::string& name, const std::string& body) {
    const std::filesystem::path dir = std::filesystem::temp_directory_path() / "ganache_solver_test";
    std::filesystem::create_directories(dir);
    std::ofstream(dir / (name + ".yaml")) << "ganache: 1\n" << body;
    return loadScene(dir / (name + ".yaml"), Quality::parse("final"));
}

/// Samples the scene and starts a simulation of it.
inline Simulation simulationOf(const Scene& scene) {
    Sample s = sampleScene(scene);
    return Simulation(scene, std::move(s.fluid), s.boundaries);
}

inline Real maxSpeed(const ParticleSet& p) {
    Real m = 0;
    for (const Vec3& v : p.v()) m = std::max(m, v.norm());
    return m;
}

}  // namespace ganache::testing
