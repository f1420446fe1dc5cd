#pragma once
// Scalar and vector types shared by every ganache module. Double precision throughout: the paper's
// rigid-rotation test needs |lap v| below 1e-12, which single precision cannot reach.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>

namespace ganache {

using Real = double;
using Vec3 = Eigen::Matrix<Real, 3, 1>;
using Mat3 = Eigen::Matrix<Real, 3, 3>;

}  // namespace ganache
