#pragma once
// The surfacer's own level-set builders, shared between its .cpp files (OpenVDB stays inside the surfacer).

#include "core/types.h"

#include <openvdb/openvdb.h>

#include <vector>

namespace ganache::surfacing {

/// Yu & Turk's anisotropic kernels (see surfacer.h): the narrow-band level set of half-width halfBand voxels
/// where the particles' kernel sum falls to half its value inside a lattice of spacing 2r.
openvdb::FloatGrid::Ptr anisotropicLevelSet(const std::vector<Vec3>& x, Real r, Real voxel, Real halfBand);

}  // namespace ganache::surfacing
