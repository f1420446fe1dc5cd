#pragma once
// Physics tests build what they simulate in code: fluid blocks on the sampling lattice, box walls and planes as
// Akinci boundaries, and the effects' typed parameters. No scene file, no YAML, no sampler.

#include "core/attributes.h"
#include "core/kernels.h"
#include "physics/boundary.h"
#include "physics/simulation.h"

#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace ganache::testing {

inline Material preset(const std::string& name) { return *findPreset(name); }

/// A test's simulation set-up: blocks of fluid, walls and effects, made the way the sampler makes them.
class World {
public:
    /// Particle radius r [m] and the domain (particles leaving it are removed; planes are sampled across it).
    explicit World(Real radius, const Vec3& domainMin = Vec3::Constant(-1), const Vec3& domainMax = Vec3::Constant(1)) {
        setup.particleRadius = radius;
        setup.domainMin = domainMin;
        setup.domainMax = domainMax;
    }

    /// A block of fluid on the lattice of spacing d = 2r: round(extent / d) sites per axis, centred in the box.
    /// Sites an earlier block holds, or closer than d to a wall, are left out (as the sampler carves them).
    World& block(const Vec3& min, const Vec3& max, const Material& material = preset("water"), Real temperature = 20,
                 const Vec3& velocity = Vec3::Zero()) {
        m_blocks.push_back({min, max, {material, temperature}, velocity});
        return *this;
    }
    /// The walls of a box; with openTop, no face at max y.
    World& box(const std::string& name, const Vec3& min, const Vec3& max, bool openTop = false,
               const BodyMotion& motion = {}) {
        m_walls.push_back({name, boxWallPoints(min, max, openTop, setup.particleRadius), {}});
        setup.bodies.push_back({name, motion});
        return *this;
    }
    /// A solid box (a paddle, an obstacle): the walls of a closed box, and no fluid sampled inside it. Fluid sites are
    /// otherwise only kept a spacing from walls, which leaves the inside of a box thicker than two spacings filled.
    World& solid(const std::string& name, const Vec3& min, const Vec3& max, const BodyMotion& motion = {}) {
        m_solids.push_back({min, max});
        return box(name, min, max, false, motion);
    }
    /// A plane through `point`, sampled across the domain.
    World& plane(const std::string& name, const Vec3& point = Vec3::Zero(), const Vec3& normal = Vec3::UnitY()) {
        m_walls.push_back({name, planePoints(point, normal.normalized(), setup.domainMin, setup.domainMax,
                                             setup.particleRadius, supportRadiusFor(setup.particleRadius)),
                           {}});
        setup.bodies.push_back({name, {}});
        return *this;
    }
    World& emitter(const EmitterSpec& spec) {
        setup.emitters.push_back(spec);
        return *this;
    }
    /// Asks for the effect `name` (a row of the registry) with default parameters and returns them to change.
    template <class P>
    P& effect(const std::string& name) {
        auto params = std::make_shared<P>();
        setup.effects.push_back({name, {}, params});
        return *params;
    }

    /// The set-up with its sources of fluid: the blocks, then the emitters.
    SimulationSetup finalSetup() const {
        SimulationSetup s = setup;
        s.sources.clear();
        for (const Block& b : m_blocks) s.sources.push_back(b.source);
        for (const EmitterSpec& e : setup.emitters) s.sources.push_back({e.material, e.temperature});
        return s;
    }

    ParticleSet particles() const {
        const Real d = 2 * setup.particleRadius;
        const CubicSpline w(supportRadiusFor(setup.particleRadius));
        std::vector<Vec3> walls;
        for (const BoundaryBody& b : m_walls) walls.insert(walls.end(), b.x.begin(), b.x.end());
        ParticleSet p;
        std::vector<Real>* source = m_blocks.size() + setup.emitters.size() > 1 ? &p.add(attribute::kFluid) : nullptr;
        for (std::size_t f = 0; f < m_blocks.size(); ++f) {
            const Block& b = m_blocks[f];
            Eigen::Vector3i n;
            for (int a = 0; a < 3; ++a) n[a] = std::max(1, int(std::lround((b.max[a] - b.min[a]) / d)));
            const Vec3 first = Real(0.5) * (b.min + b.max) - Real(0.5) * d * (n.cast<Real>() - Vec3::Ones());
            const Real mass = latticeMass(d, b.source.material.density, w);
            for (int k = 0; k < n.z(); ++k)
                for (int j = 0; j < n.y(); ++j)
                    for (int i = 0; i < n.x(); ++i) {
                        const Vec3 x = first + d * Vec3(i, j, k);
                        if (heldByEarlierBlock(x, f) || insideSolid(x) || nearWall(x, walls, d)) continue;
                        p.add(x, b.velocity, mass, p.size());
                        if (source) source->back() = Real(f);
                    }
        }
        return p;
    }

    std::vector<BoundaryBody> bodies() const {
        const CubicSpline w(supportRadiusFor(setup.particleRadius));
        std::vector<BoundaryBody> out = m_walls;
        for (BoundaryBody& b : out) b.volume = boundaryVolumes(b.x, w);
        return out;
    }

    Simulation simulation() const { return Simulation(finalSetup(), particles(), bodies()); }
    /// With the particles changed first (velocities, temperatures, positions).
    Simulation simulation(const std::function<void(ParticleSet&)>& prepare) const {
        ParticleSet p = particles();
        prepare(p);
        return Simulation(finalSetup(), std::move(p), bodies());
    }

    SimulationSetup setup;  ///< time step, pressure, coupling, bodies, emitters, effects: change them freely

private:
    struct Block {
        Vec3 min, max;
        FluidSource source;
        Vec3 velocity;
    };
    bool heldByEarlierBlock(const Vec3& x, std::size_t f) const {
        for (std::size_t e = 0; e < f; ++e)
            if ((x.array() >= m_blocks[e].min.array()).all() && (x.array() <= m_blocks[e].max.array()).all()) return true;
        return false;
    }
    bool insideSolid(const Vec3& x) const {
        for (const auto& [lo, hi] : m_solids)
            if ((x.array() > lo.array()).all() && (x.array() < hi.array()).all()) return true;
        return false;
    }
    static bool nearWall(const Vec3& x, const std::vector<Vec3>& walls, Real d) {
        const Real keep = d * (1 - 1e-6);
        for (const Vec3& y : walls)
            if ((y - x).squaredNorm() < keep * keep) return true;
        return false;
    }

    std::vector<Block> m_blocks;
    std::vector<BoundaryBody> m_walls;
    std::vector<std::pair<Vec3, Vec3>> m_solids;  // the solid boxes' corners at t = 0
};

/// Sets every velocity from the position.
inline std::function<void(ParticleSet&)> withVelocity(std::function<Vec3(const Vec3&)> velocity) {
    return [velocity](ParticleSet& p) {
        for (std::size_t i = 0; i < p.size(); ++i) p.v()[i] = velocity(p.x()[i]);
    };
}

inline Real maxSpeed(const ParticleSet& p) {
    Real m = 0;
    for (const Vec3& v : p.v()) m = std::max(m, v.norm());
    return m;
}

inline Vec3 linearMomentum(const ParticleSet& p) {
    Vec3 s = Vec3::Zero();
    for (std::size_t i = 0; i < p.size(); ++i) s += p.mass()[i] * p.v()[i];
    return s;
}

inline Vec3 angularMomentum(const ParticleSet& p) {
    Vec3 s = Vec3::Zero();
    for (std::size_t i = 0; i < p.size(); ++i) s += p.mass()[i] * p.x()[i].cross(p.v()[i]);
    return s;
}

}  // namespace ganache::testing
