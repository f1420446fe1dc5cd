#pragma once
// The boundary model of Akinci et al. 2012: a solid's surface as a sheet of particles, each with the volume that
// makes a flat wall stand in for the missing layer of fluid. Samplers of the simplest solids (box walls, planes)
// live here too, so that tests and tools can make walls without a scene.

#include "core/kernels.h"
#include "core/types.h"

#include <vector>

namespace ganache {

/// The walls of the box [min, max] with spacing <= r: every point of a regular grid on a face; the top face (max y)
/// left out when openTop (the rim of the side walls stays).
std::vector<Vec3> boxWallPoints(const Vec3& min, const Vec3& max, bool openTop, Real r);

/// The plane through `point` with unit `normal`, sampled with spacing r where it passes within h of the box [lo, hi].
std::vector<Vec3> planePoints(const Vec3& point, const Vec3& normal, const Vec3& lo, const Vec3& hi, Real r, Real h);

/// Boundary volumes V_k = gamma / sum_l W(x_k - x_l) over one body's particles (Akinci et al. 2012, Eq. 4),
/// with gamma = flatWallCalibration(w).
std::vector<Real> boundaryVolumes(const std::vector<Vec3>& x, const CubicSpline& w);

/// The factor gamma that makes a flat wall (sampled with spacing r) one lattice spacing 2r from a resting fluid
/// lattice give that fluid exactly its rest density; Akinci's 1/delta alone overshoots by about 6 %.
Real flatWallCalibration(const CubicSpline& w);
}  // namespace ganache
