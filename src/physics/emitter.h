#pragma once
// Emitters: nozzles that add fluid while a simulation runs. Built only for scenes that list emitters.

#include "core/kernels.h"
#include "scene/scene.h"

#include <cstdint>
#include <vector>

namespace ganache {

class ParticleSet;
struct SolverStats;

/// Offsets from the nozzle centre of one emitted layer's particles at t = 0: a square lattice of spacing 2r in
/// the plane across the emitter's direction, every particle (a sphere of radius r) inside the opening. Empty
/// when the opening is narrower than one particle.
std::vector<Vec3> nozzleSites(const EmitterSpec& emitter, Real particleRadius);

/// Volume the emitter adds per second of emission [m^3/s]: its layers of sites, 2r apart, leave at its speed.
Real emitterFlowRate(const EmitterSpec& emitter, Real particleRadius);

/// What one emitter did over a run.
struct EmitterReport {
    std::string name;
    std::size_t emitted = 0;  ///< particles added
    std::size_t blocked = 0;  ///< sites skipped because fluid still sat there
};

/// What one emitter carries from one step to the next: the distance its fluid has travelled since its last layer
/// [m], and its report so far. Checkpoints save it.
struct EmitterState {
    Real travelled = 0;
    EmitterReport report;
};

/// Every emitter of a scene. A layer of particles leaves a nozzle each time the emitted fluid has travelled one
/// lattice spacing 2r, so layers stack into the same lattice (and rest density) the sampler builds.
class Emitters {
public:
    Emitters(const Scene& scene, Real particleRadius);

    /// Adds the layers that left the nozzles between t0 and t0 + dt, at their positions at t0 + dt. New particles
    /// get ids from nextId onwards, the `fluid` attribute and their emitter's temperature when the set has those
    /// attributes, and zero in every other attribute.
    void emit(Real t0, Real dt, ParticleSet& particles, std::uint64_t& nextId, SolverStats& stats);

    const std::vector<EmitterReport>& reports() const { return m_reports; }

    std::vector<EmitterState> state() const;
    /// Continues from a saved state; std::runtime_error when it is not of these emitters.
    void restore(const std::vector<EmitterState>& state);

private:
    struct Nozzle {
        EmitterSpec spec;
        std::vector<Vec3> sites;  // at t = 0
        Real reach = 0;           // of the farthest site from the centre [m]
        Real mass = 0;
        Real travelled = 0;       // distance the fluid has left the nozzle since the last layer [m]
        std::uint32_t sourceIndex = 0;  // in Scene::sourceMaterials()
    };
    // Adds the layer that left at time t, `age` seconds before the end of the step.
    void emitLayer(Nozzle& n, std::size_t index, Real t, Real age, ParticleSet& particles, std::uint64_t& nextId,
                   SolverStats& stats);

    Real m_spacing;
    std::vector<Nozzle> m_nozzles;
    std::vector<EmitterReport> m_reports;
};

}  // namespace ganache
