#include "physics/contact.h"

#include "core/parallel.h"
#include "physics/simulation.h"

namespace ganache {

void Contact::apply(StepContext& ctx, ParticleSet& particles) {
    // A particle may approach a boundary only to within one particle radius of its nearest boundary particle; the
    // rest of its approach velocity (relative to the wall, along the wall's normal) is taken out, inelastically,
    // and given to the body (all of it, for simplicity, to the body of the nearest boundary particle). Fluid at
    // rest sits two radii from a wall and never meets this; it never pushes, so it adds no energy.
    const Real dt = ctx.dt, r = m_radius;
    const auto& x = particles.x();
    auto& v = particles.v();
    const auto& b = ctx.boundary;
    auto& change = m_change;
    auto& nearest = m_nearest;
    change.assign(x.size(), Vec3::Zero());
    nearest.assign(x.size(), 0);
    forEachParticle(x.size(), [&](std::size_t i) {
        Vec3 towardWall = Vec3::Zero();
        Real closest2 = std::numeric_limits<Real>::infinity();
        const auto& list = ctx.boundaryNeighbours;
        for (std::size_t p = list.first(i); p < list.last(i); ++p) {
            const std::uint32_t k = list.indices[p];
            const Vec3 xik = x[i] - b.x[k];
            towardWall += (b.volume[k] * ctx.gradients.boundary[p]) * xik;  // grad W points from the particle to k
            if (xik.squaredNorm() < closest2) closest2 = xik.squaredNorm(), nearest[i] = k;
        }
        if (towardWall.squaredNorm() == 0) return;
        const Vec3 n = -towardWall.normalized();  // out of the wall
        Vec3 vi = v[i];
        const Real approach = -(vi - b.v[nearest[i]]).dot(n);
        const Real allowed = std::max<Real>(0, std::sqrt(closest2) - r) / dt;
        if (approach > allowed) vi += (approach - allowed) * n;
        // Where walls meet, one normal cannot hold both: no particle may also come nearer than 3/4 r to any single
        // boundary particle. Boundary particles are at most r apart, so every gap between them is narrower
        // (r / sqrt 2 from its centre to its corners): nothing slips through. Fluid sliding along a wall keeps
        // at least r from it and does not meet this.
        for (std::uint32_t k : ctx.boundaryNeighbours.of(i)) {
            const Vec3 xik = x[i] - b.x[k];
            const Real dist = xik.norm();
            if (dist == 0 || dist > r + dt * (vi - b.v[k]).norm()) continue;
            const Vec3 nk = xik / dist;
            const Real closing = -(vi - b.v[k]).dot(nk);
            const Real limit = std::max<Real>(0, dist - 0.75 * r) / dt;
            if (closing > limit) vi += (closing - limit) * nk;
        }
        change[i] = vi - v[i];
    });
    for (std::size_t i = 0; i < x.size(); ++i) {
        if (change[i].squaredNorm() == 0) continue;
        v[i] += change[i];
        ctx.loads.add(b, nearest[i], -particles.mass()[i] * change[i], ctx.time + dt);  // what the body took
        ++ctx.stats.boundaryContacts;
    }
}

}  // namespace ganache
