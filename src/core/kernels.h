#pragma once
// SPH smoothing kernels.

#include "core/types.h"

#include <cmath>

namespace ganache {

/// Cubic spline kernel in 3D (Monaghan 1992) with compact support radius h: W(r) = 0 for |r| >= h.
/// Normalised so that its integral over space is 1. Units: W in 1/m^3, gradW in 1/m^4.
class CubicSpline {
public:
    explicit CubicSpline(Real supportRadius);

    Real supportRadius() const { return m_h; }

    /// W as a function of the distance r >= 0.
    Real W(Real r) const {
        const Real q = r * m_invH;
        if (q >= 1) return 0;
        if (q <= Real(0.5)) return m_k * (6 * q * q * (q - 1) + 1);
        const Real a = 1 - q;
        return 2 * m_k * a * a * a;
    }
    Real W(const Vec3& r) const { return W(r.norm()); }

    /// Gradient of W with respect to the first particle's position, for r = x_i - x_j.
    /// Zero at r = 0 (the kernel is flat there) and outside the support; grad W(-r) = -grad W(r).
    Vec3 gradW(const Vec3& r) const { return gradFactor(r.norm()) * r; }
    /// The factor g <= 0 with grad W(r) = g r, for |r| = rl [1/m^5]: what solvers keep per neighbour pair, so that
    /// no sweep evaluates the kernel again.
    Real gradFactor(Real rl) const {
        const Real q = rl * m_invH;
        if (q >= 1 || rl < Real(1e-12) * m_h) return 0;
        const Real dWdq = q <= Real(0.5) ? m_l * q * (3 * q - 2) : -m_l * (1 - q) * (1 - q);
        return dWdq * m_invH / rl;
    }

    Real W0() const { return m_k; }  ///< W at r = 0

    /// W and gradFactor of n distances at once, without branches so that the loop vectorises: takes the squared
    /// distances in r2 and leaves the gradient factors there, the values in w. Bit for bit what W and gradFactor
    /// give for r = sqrt(r2).
    void valuesAndGradients(std::size_t n, Real* r2, Real* w) const;

private:
    Real m_h;
    Real m_invH;  // 1 / h: W and its gradient multiply by it, leaving one division a pair
    Real m_k;     // 8 / (pi h^3)
    Real m_l;     // 48 / (pi h^3): dW/dq prefactor
};

/// The kernel support radius ganache uses for a particle radius r: h = 4 r (two particle diameters),
/// about 30 neighbours per particle on a lattice of spacing 2 r, as in the paper and SPlisHSPlasH.
inline Real supportRadiusFor(Real particleRadius) { return 4 * particleRadius; }

/// Sum of W over an infinite cubic lattice of this spacing around one of its sites [1/m^3]: a particle of mass
/// m on such a lattice has density m times this.
Real latticeKernelSum(Real spacing, const CubicSpline& w);

/// Mass that gives a particle of an infinite lattice of this spacing the density rho0 with kernel w [kg].
inline Real latticeMass(Real spacing, Real rho0, const CubicSpline& w) { return rho0 / latticeKernelSum(spacing, w); }

}  // namespace ganache
