#pragma once
// Emitters: nozzles that add fluid while a simulation runs. An effect of the Emit stage, built only for scenes that
// list emitters.

#include "core/errors.h"
#include "physics/bodies.h"
#include "physics/effect.h"
#include "physics/materials.h"

#include <cstdint>
#include <string>
#include <variant>
#include <vector>

namespace ganache {

/// The opening of an emitter, in the plane across its direction.
struct CircleNozzle {
    Real radius = 0;  ///< [m]
};
/// width runs along x (along z when the emitter points along x), height across both [m].
struct RectangleNozzle {
    Real width = 0, height = 0;
};
using NozzleShape = std::variant<CircleNozzle, RectangleNozzle>;

/// A nozzle that adds fluid between `start` and `end`: layers of particles (lattice spacing 2r) leave the
/// opening at `speed` along `direction`. Its position and direction follow `motion` (rotation and keyframes,
/// as for boundary bodies); the emitted fluid also takes the nozzle's own velocity.
struct EmitterSpec {
    std::string name;
    Material material;
    NozzleShape nozzle;
    Vec3 position = Vec3::Zero();     ///< centre of the opening at t = 0 [m]
    Vec3 direction = -Vec3::UnitY();  ///< unit length
    Real speed = 0;                   ///< [m/s], > 0
    Real start = 0, end = 0;          ///< emission times [s]; end defaults to the last frame's time
    Real temperature = 20;            ///< of the emitted fluid [C], used with the heat effect
    BodyMotion motion;
    Location at;
};

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

/// Every emitter of a scene. A layer of particles leaves a nozzle each time the emitted fluid has travelled one
/// lattice spacing 2r, so layers stack into the same lattice (and rest density) the sampler builds. New particles
/// get ids after the largest one so far, attribute::kFluid and their emitter's temperature when the set has those
/// attributes, and zero in every other attribute.
class Emitters final : public Effect {
public:
    Emitters(const SimulationSetup& setup, const ParticleSet& particles);

    /// Adds the layers that left the nozzles during the step, at their positions at its end.
    void apply(StepContext& ctx, ParticleSet& particles) override;
    std::vector<Counter> counters(std::size_t steps) const override;
    void save(ByteWriter& out) const override;
    void restore(ByteReader& in) override;

    const std::vector<EmitterReport>& reports() const { return m_reports; }

private:
    struct Nozzle {
        EmitterSpec spec;
        std::vector<Vec3> sites;  // at t = 0
        Real reach = 0;           // of the farthest site from the centre [m]
        Real mass = 0;
        Real travelled = 0;       // distance the fluid has left the nozzle since the last layer [m]
        std::uint32_t sourceIndex = 0;  // in SimulationSetup::sources
    };
    // Adds the layer that left at time t, `age` seconds before the end of the step.
    void emitLayer(Nozzle& n, std::size_t index, Real t, Real age, ParticleSet& particles, StepContext& ctx);

    Real m_spacing;
    std::vector<Nozzle> m_nozzles;
    std::vector<EmitterReport> m_reports;
    std::uint64_t m_nextId = 0;  // id of the next emitted particle
};

}  // namespace ganache
