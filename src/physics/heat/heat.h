#pragma once
// Heat and melting (Weiler et al. 2018, Sec. 5): a temperature per particle, conduction between particles
// (Eq. 15-16) and from bodies held at a set temperature, radiation of surface particles towards the room
// (Eq. 14), and heat sources shining on surface particles (Eq. 17-18). Built only for scenes with `heat:`;
// the viscosity effect turns each particle's temperature into its viscosity through its material's law.

#include "core/errors.h"
#include "core/kernels.h"
#include "core/neighbour_search.h"
#include "core/particles.h"
#include "physics/bodies.h"
#include "physics/effect.h"

#include <limits>
#include <string>
#include <vector>

namespace ganache {

/// A heat source: a point (`sphere`) or a plane (`plane`, e.g. a warm floor). The flux it gives a surface
/// particle at distance s is Q(s) = intensity ((sqrt 2 - 1) s / radius + 1)^-2 [W/m^2] (Eq. 17): Q(0) is the
/// intensity and Q(radius) half of it.
struct HeatSource {
    std::string name;
    bool plane = false;
    Vec3 point = Vec3::Zero();    ///< the sphere's centre, or a point of the plane, at t = 0 [m]
    Vec3 normal = Vec3::UnitY();  ///< of the plane
    Real intensity = 0;           ///< [W/m^2]
    Real radius = 0;              ///< [m]
    Real start = 0, end = std::numeric_limits<Real>::infinity();  ///< when it shines [s]
    BodyMotion motion;            ///< moves and turns it, as for bodies
    Location at;

    /// Q at x and time t [W/m^2] (0 outside [start, end)).
    Real flux(const Vec3& x, Real t) const;
};

/// A boundary body held at a set temperature that conducts into the fluid touching it.
struct HeatedBody {
    std::string body;
    Real temperature = 0;  ///< [C]
    Real conductivity = -1;  ///< [W/(m K)] of the contact; < 0: the fluid's own
    Location at;
};

struct HeatParams : EffectParams {
    Real roomTemperature = 20;  ///< [C]
    Real radiationTime = 0;     ///< t_r [s] of Eq. 14; 0: no radiation
    /// A particle is on the surface when h |grad c| >= this, c the colour field of the fluid around it (1.02 on
    /// a flat surface of the sampling lattice, 0 inside), or when it has fewer than 8 fluid neighbours.
    Real surfaceThreshold = 0.5;
    std::vector<HeatSource> sources;
    std::vector<HeatedBody> bodies;
    void check(const SimulationSetup& setup, const Location& at) const override;
};

std::shared_ptr<const EffectParams> readHeat(Section& s);
std::unique_ptr<Effect> makeHeat(const EffectParams& params, const SimulationSetup& setup, ParticleSet& particles);

/// Which particles are on the surface, as the heat effect decides it (exposed for tests): from the step's kernel
/// gradient factors of the neighbour pairs (PairGradients::fluid) and the kernel's support [m].
std::vector<std::uint8_t> surfaceParticles(const ParticleSet& particles, const std::vector<Real>& density,
                                           const NeighbourList& neighbours, const std::vector<Real>& gradients,
                                           Real support, Real threshold);

}  // namespace ganache
