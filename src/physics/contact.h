#pragma once
// Contact with boundaries, before the particles move: the pressure solve pushes a particle only once it is
// compressed, and a lone particle (a splash) never is, so this rule keeps it from flying through a wall. Neither
// the paper's nor an effect: every simulation with boundaries runs it.

#include "core/types.h"

#include <cstdint>
#include <vector>

namespace ganache {

class ParticleSet;
class UniformGrid;
struct StepContext;

class Contact {
public:
    explicit Contact(Real particleRadius) : m_radius(particleRadius) {}
    /// Takes out of each particle's velocity the approach to a boundary that would bring it closer than one
    /// particle radius to its nearest boundary particle (along the wall's normal) or 3/4 of a radius to any, and
    /// gives it to the body. Counts the contacts in ctx.stats.boundaryContacts. `grid` holds the boundary particles
    /// where they are now: particles fast enough to outrun their neighbour lists look for walls in it.
    void apply(StepContext& ctx, ParticleSet& particles, const UniformGrid& grid);

private:
    Real m_radius;
    std::vector<Vec3> m_change;  // scratch, kept between steps
    std::vector<std::uint32_t> m_nearest;
};

}  // namespace ganache
