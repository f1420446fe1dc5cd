#include "physics/viscosity/viscosity_explicit.h"

#include "core/parallel.h"

#include <fmt/format.h>
#include <tbb/parallel_reduce.h>

#include <cmath>
#include <limits>

namespace ganache {

namespace {
// Of the bound 2 / (Gershgorin radius): a margin for the densities and neighbours that change within a step.
constexpr Real kSafety = 0.9;
}  // namespace

Real ViscosityExplicit::stableStep(const StepContext& ctx, const ParticleSet& particles) const {
    const auto& x = particles.x();
    // The largest Gershgorin radius; a maximum does not depend on the order of the reduction.
    const Real radius = tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(0, particles.size(), 1024), Real(0),
        [&](const tbb::blocked_range<std::size_t>& range, Real worst) {
            for (std::size_t i = range.begin(); i != range.end(); ++i) {
                // Block A_ij = -k_ij x_ij x_ij^T has norm |k_ij| |x_ij|^2; it appears off the diagonal and again in
                // the diagonal block A_ii.
                Real row = 0;
                const auto& f = ctx.fluidNeighbours;
                for (std::size_t p = f.first(i); p < f.last(i); ++p)
                    row += 2 * std::abs(pairs()[p]) * (x[i] - x[f.indices[p]]).squaredNorm();
                if (sticky()) {
                    const auto& b = ctx.boundaryNeighbours;
                    for (std::size_t p = b.first(i); p < b.last(i); ++p)
                        row += std::abs(boundaryPairs()[p]) * (x[i] - ctx.boundary.x[b.indices[p]]).squaredNorm();
                }
                worst = std::max(worst, row);
            }
            return worst;
        },
        [](Real a, Real b) { return std::max(a, b); });
    return radius > 0 ? kSafety * 2 / radius : std::numeric_limits<Real>::infinity();
}

ViscosityPass ViscosityExplicit::solve(StepContext& ctx, const ParticleSet& particles, std::vector<Vec3>& out) {
    const std::size_t n = particles.size();
    const Real stable = stableStep(ctx, particles);
    const Real needed = std::ceil(ctx.dt / stable);
    if (needed > Real(m_params.maxIterations))
        throw std::runtime_error(fmt::format(
            "step {}: explicit viscosity needs {:.0f} sub-steps of {:.3g} s for this {:.3g} s step, more than "
            "effects.viscosity.max_iterations = {}; raise it, lower simulation.time_step.max, or use the implicit "
            "method (weiler2018)",
            ctx.step, needed, stable, ctx.dt, m_params.maxIterations));
    const std::size_t substeps = std::max<std::size_t>(1, std::size_t(needed));
    const Real h = ctx.dt / Real(substeps);
    std::copy(particles.v().begin(), particles.v().end(), out.begin());  // no guess: it starts from v
    m_acceleration.resize(n);
    for (std::size_t s = 0; s < substeps; ++s) {
        forEachParticle(n, [&](std::size_t i) { m_acceleration[i] = laplacian(ctx, particles, out, i, true); });
        forEachParticle(n, [&](std::size_t i) { out[i] += h * m_acceleration[i]; });
    }
    return {substeps, 0};
}

}  // namespace ganache
