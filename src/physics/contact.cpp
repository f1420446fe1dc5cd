#include "physics/contact.h"

#include "core/neighbour_search.h"
#include "core/parallel.h"
#include "physics/simulation.h"

namespace ganache {

namespace {

// Calls visit(k) for every point k of the grid in the cube of half-width `radius` about c, in a fixed order.
template <class Visit>
void forEachPointWithin(const UniformGrid& grid, const Vec3& c, Real radius, Visit&& visit) {
    const Real inv = 1 / grid.cellSize();
    const Eigen::Array<Real, 3, 1> lo = ((c.array() - radius) * inv).floor(), hi = ((c.array() + radius) * inv).floor();
    const auto& sorted = grid.sortedIndices();
    const auto visitCell = [&](std::size_t cell) {
        for (std::size_t s = grid.cellBegin(cell); s < grid.cellBegin(cell + 1); ++s) visit(sorted[s]);
    };
    const Real cells = (hi - lo + 1).prod();
    if (cells > Real(grid.cellCount())) {  // a very long reach: fewer occupied cells than cells in the cube
        for (std::size_t cell = 0; cell < grid.cellCount(); ++cell) {
            const auto& cc = grid.cellCoords(cell);
            bool inside = true;
            for (int a = 0; a < 3; ++a) inside = inside && cc[a] >= lo[a] && cc[a] <= hi[a];
            if (inside) visitCell(cell);
        }
        return;
    }
    for (auto cz = std::int64_t(lo[2]); cz <= std::int64_t(hi[2]); ++cz)
        for (auto cy = std::int64_t(lo[1]); cy <= std::int64_t(hi[1]); ++cy)
            for (auto cx = std::int64_t(lo[0]); cx <= std::int64_t(hi[0]); ++cx)
                if (const std::int64_t cell = grid.findCell(cx, cy, cz); cell >= 0) visitCell(std::size_t(cell));
}

}  // namespace

void Contact::apply(StepContext& ctx, ParticleSet& particles, const UniformGrid& grid) {
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
    const Real h = ctx.kernel.supportRadius();
    Real bodySpeed = 0;  // the fastest boundary particle: how far a wall may come towards a particle in one step
    if (b.anyMoving)
        for (const Vec3& vk : b.v) bodySpeed = std::max(bodySpeed, vk.norm());
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
        Vec3 vi = v[i];
        if (towardWall.squaredNorm() > 0) {
            const Vec3 n = -towardWall.normalized();  // out of the wall
            const Real approach = -(vi - b.v[nearest[i]]).dot(n);
            const Real allowed = std::max<Real>(0, std::sqrt(closest2) - r) / dt;
            if (approach > allowed) vi += (approach - allowed) * n;
        }
        // Where walls meet, one normal cannot hold both: no particle may also come nearer than 3/4 r to any single
        // boundary particle. Boundary particles are at most r apart, so every gap between them is narrower
        // (r / sqrt 2 from its centre to its corners): nothing slips through. Fluid sliding along a wall keeps
        // at least r from it and does not meet this.
        const auto closeIn = [&](std::uint32_t k) {
            const Vec3 xik = x[i] - b.x[k];
            const Real dist = xik.norm();
            if (dist == 0 || dist > r + dt * (vi - b.v[k]).norm()) return;
            const Vec3 nk = xik / dist;
            const Real closing = -(vi - b.v[k]).dot(nk);
            const Real limit = std::max<Real>(0, dist - 0.75 * r) / dt;
            if (closing <= limit) return;
            vi += (closing - limit) * nk;
            if (dist * dist < closest2) closest2 = dist * dist, nearest[i] = k;  // the body that takes the change
        };
        // The neighbour list holds the boundary particles within one support; a particle that can travel further
        // in this step (a splash thrown hard at a wall from a support away: 5 ms steps past the CFL limit shot one
        // through a tank's floor at 5 m/s) looks for them in the boundary grid along its whole reach.
        const Real reach = r + dt * (vi.norm() + bodySpeed);
        if (reach < h)
            for (std::uint32_t k : ctx.boundaryNeighbours.of(i)) closeIn(k);
        else
            forEachPointWithin(grid, x[i], reach, closeIn);
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
