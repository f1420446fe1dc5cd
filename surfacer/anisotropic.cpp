// Anisotropic kernels (Yu & Turk 2013) summed only where the surface can be.
//
// The kernel sum over every voxel a kernel reaches (about 2,000 per particle) was most of a frame's time, and the
// level set rebuilt from it (mesh to volume) most of the rest. Here the sum is taken in two passes: first on a
// coarse lattice of two voxels' spacing, which finds the bricks of 2^3 voxels the surface can cross; then on the
// voxels of those bricks and of the bricks around them, as wide as the narrow band. The signed distance is the
// kernel sum's distance from the iso value over its gradient, exact to first order at the surface, so that no
// rebuild is needed.

#include "surfacer/level_sets.h"

#include "core/kernels.h"
#include "core/neighbour_search.h"
#include "core/parallel.h"

#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <openvdb/tools/Morphology.h>
#include <openvdb/tools/Prune.h>
#include <openvdb/tools/SignedFloodFill.h>
#include <openvdb/tree/LeafManager.h>

#include <algorithm>
#include <cmath>

namespace ganache::surfacing {

namespace {

using openvdb::FloatGrid;
using FloatLeaf = openvdb::FloatTree::LeafNodeType;

constexpr Real kKernelSupport = 4;  // support in particle radii (two lattice spacings)
// Largest to smallest axis of a kernel (Yu & Turk's k_r is 4). Squashed surface kernels pull the surface of a
// flat layer down: 0.97 r above the top row at 2, 0.91 r at 4. Yu & Turk also move each kernel towards its
// neighbours' mean; that pulled the flat surface down to 0.67 r (lambda 0.5) and is not done here.
constexpr Real kMaxStretch = 2;
constexpr std::size_t kMinNeighbours = 12;  // fewer: the spread says little, the kernel stays round
// A brick of the coarse lattice whose corners' kernel sums lie between these fractions of the lattice interior's
// value may hold the surface (at one half); so may one with corners above the upper and below the lower. The
// margin keeps thin sheets, whose sum peaks a little above one half between two coarse points.
constexpr Real kSeedLow = 0.35, kSeedHigh = 0.65;

struct Ellipsoid {
    Vec3 centre;
    Mat3 shape;    // A: a point y from the centre counts at distance |A y| (det A = 1)
    Vec3 extent;   // half size of its bounding box [m]
};

std::vector<Ellipsoid> anisotropicKernels(const std::vector<Vec3>& x, Real r) {
    const Real support = kKernelSupport * r;
    UniformGrid grid(support);
    NeighbourList neighbours;
    findFluidNeighbours(grid, x, support, neighbours);
    std::vector<Ellipsoid> out(x.size());
    forEachParticle(x.size(), [&](std::size_t i) {
        // Weighted mean and covariance of the neighbourhood, itself included, w = 1 - (d / support)^3.
        auto weight = [&](std::uint32_t j) {
            const Real q = (x[j] - x[i]).norm() / support;
            return 1 - q * q * q;
        };
        Real total = 1;
        Vec3 mean = x[i];
        for (std::uint32_t j : neighbours.of(i)) {
            const Real w = weight(j);
            total += w;
            mean += w * x[j];
        }
        mean /= total;
        Ellipsoid& e = out[i];
        e.centre = x[i];
        e.shape = Mat3::Identity();
        if (neighbours.of(i).size() >= kMinNeighbours) {
            Mat3 c = (x[i] - mean) * (x[i] - mean).transpose();
            for (std::uint32_t j : neighbours.of(i)) c += weight(j) * (x[j] - mean) * (x[j] - mean).transpose();
            Eigen::SelfAdjointEigenSolver<Mat3> eigen;
            eigen.computeDirect(c / total);
            Vec3 s = eigen.eigenvalues().cwiseMax(eigen.eigenvalues().maxCoeff() / kMaxStretch);
            s /= std::cbrt(s.prod());  // keep the kernel's volume: the field's interior value does not change
            e.shape = eigen.eigenvectors() * s.cwiseInverse().asDiagonal() * eigen.eigenvectors().transpose();
        }
        // The ellipsoid {y : |A y| < support} = A^-1 (ball); its box's half size along axis k is support |row_k A^-1|.
        const Mat3 inverse = e.shape.inverse();
        for (int k = 0; k < 3; ++k) e.extent[k] = support * inverse.row(k).norm();
    }, 256);
    return out;
}

// A row of a leaf along z, one SIMD vector, and its points' offsets.
using RowOfEight = Eigen::Array<float, 8, 1>;
const RowOfEight kRowSteps = RowOfEight::LinSpaced(8, 0, 7);

// The cubic spline in q = distance / support without branches (2 (1-q)^3 - 8 (1/2-q)^3 equals 1 - 6q^2 + 6q^3
// below one half), for a whole row at once.
inline RowOfEight splineShape(const RowOfEight& q) {
    const RowOfEight a = (1.f - q).max(0.f), b = (0.5f - q).max(0.f);
    return 2 * a * a * a - 8 * b * b * b;
}

// A leaf of a lattice (8^3 points) and which of its 4^3 bricks of 2^3 points to evaluate (bit 16 i + 4 j + k).
struct LatticeLeaf {
    openvdb::Coord origin;
    std::uint64_t bricks;
};

// The kernels' centres sorted into cells of one leaf of a lattice of spacing h (8 h), and how far the largest
// kernel reaches from its centre along each axis.
struct KernelBins {
    Real h;
    UniformGrid grid;
    Vec3 reach = Vec3::Zero();

    KernelBins(const std::vector<Ellipsoid>& kernels, Real spacing) : h(spacing), grid(8 * spacing) {
        std::vector<Vec3> centres(kernels.size());
        for (std::size_t i = 0; i < kernels.size(); ++i)
            reach = reach.cwiseMax(kernels[i].extent), centres[i] = kernels[i].centre;
        grid.build(centres);
    }
};

// The 4 bits of the bricks along z under the row (a, b) of a leaf (a, b in 0..7).
inline unsigned rowBricks(std::uint64_t bricks, int a, int b) {
    return unsigned(bricks >> ((a >> 1) * 16 + (b >> 1) * 4)) & 0xFu;
}

// The kernel sum on a lattice of spacing h [m] (point ijk at h ijk), at the points of the chosen bricks of each
// target leaf, stored as iso minus the sum (negative inside) on active voxels; background iso. Each leaf gathers
// the kernels whose boxes reach it from a grid of their centres, in that grid's fixed order: deterministic for
// any thread count. Along a row of z the ellipsoid is an interval, found from a quadratic, so only points inside
// a kernel are visited.
FloatGrid::Ptr kernelSum(const std::vector<Ellipsoid>& kernels, const KernelBins& binned,
                         const std::vector<LatticeLeaf>& targets, Real r, Real iso) {
    const CubicSpline w(kKernelSupport * r);
    const Real support = w.supportRadius();
    const float scale = float(8 * r * r * r * w.W0());  // each particle weighs one lattice cell (2r)^3
    const Real h = binned.h, cell = 8 * h;
    const Vec3& reach = binned.reach;
    const UniformGrid& bins = binned.grid;
    std::vector<FloatLeaf*> made(targets.size(), nullptr);
    forEachBlock(targets.size(), [&](std::size_t begin, std::size_t end) {
        alignas(32) float sum[512];
        for (std::size_t t = begin; t != end; ++t) {
            const LatticeLeaf& target = targets[t];
            const openvdb::Coord o = target.origin;
            std::fill(sum, sum + 512, 0.f);
            const Vec3 lo = Vec3(o.x(), o.y(), o.z()) * h, hi = lo + Vec3::Constant(7 * h);
            const Vec3 cellLo = ((lo - reach) / cell).array().floor(), cellHi = ((hi + reach) / cell).array().floor();
            for (std::int64_t ca = std::int64_t(cellLo.x()); ca <= std::int64_t(cellHi.x()); ++ca)
                for (std::int64_t cb = std::int64_t(cellLo.y()); cb <= std::int64_t(cellHi.y()); ++cb)
                    for (std::int64_t cc = std::int64_t(cellLo.z()); cc <= std::int64_t(cellHi.z()); ++cc) {
                        const std::int64_t found = bins.findCell(ca, cb, cc);
                        if (found < 0) continue;
                        const std::size_t ci = std::size_t(found);
                        for (std::size_t k = bins.cellBegin(ci); k < bins.cellBegin(ci + 1); ++k) {
                            const Ellipsoid& e = kernels[bins.sortedIndices()[k]];
                            // The kernel's box in the leaf's point indices (0..7).
                            const Vec3 boxLo = ((e.centre - e.extent - lo) / h).array().ceil();
                            const Vec3 boxHi = ((e.centre + e.extent - lo) / h).array().floor();
                            if ((boxLo.array() > 7).any() || (boxHi.array() < 0).any()) continue;
                            const int aLo = std::max(0, int(boxLo.x())), aHi = std::min(7, int(boxHi.x()));
                            const int bLo = std::max(0, int(boxLo.y())), bHi = std::min(7, int(boxHi.y()));
                                                        // A y in supports at point (a, b, c) of the leaf: u0 + a dx + b dy + c dz.
                            const Mat3 m = e.shape * (h / support);
                            const Vec3 u0d = e.shape * (lo - e.centre) / support;
                            const float u0[3] = {float(u0d.x()), float(u0d.y()), float(u0d.z())};
                            const float dx[3] = {float(m(0, 0)), float(m(1, 0)), float(m(2, 0))};
                            const float dy[3] = {float(m(0, 1)), float(m(1, 1)), float(m(2, 1))};
                            const float dz[3] = {float(m(0, 2)), float(m(1, 2)), float(m(2, 2))};
                            const float inverseStep = 1.f / (dz[0] * dz[0] + dz[1] * dz[1] + dz[2] * dz[2]);
                            for (int a = aLo; a <= aHi; ++a)
                                for (int b = bLo; b <= bHi; ++b) {
                                    const unsigned bits = rowBricks(target.bricks, a, b);
                                    if (!bits) continue;
                                    float u[3];
                                    for (int d = 0; d < 3; ++d) u[d] = u0[d] + float(a) * dx[d] + float(b) * dy[d];
                                    // |u + c dz| < 1: c between the roots of a quadratic.
                                    const float half = (u[0] * dz[0] + u[1] * dz[1] + u[2] * dz[2]) * inverseStep;
                                    const float discriminant =
                                        half * half - (u[0] * u[0] + u[1] * u[1] + u[2] * u[2] - 1) * inverseStep;
                                    if (discriminant <= 0) continue;
                                    // The whole row at once (one vector): the spline is zero outside.
                                    const RowOfEight px = u[0] + kRowSteps * dz[0], py = u[1] + kRowSteps * dz[1],
                                                     pz = u[2] + kRowSteps * dz[2];
                                    Eigen::Map<RowOfEight>(sum + a * 64 + b * 8) +=
                                        splineShape((px * px + py * py + pz * pz).sqrt());
                                }
                        }
                    }
            auto* leaf = new FloatLeaf(o, float(iso), false);
            float* values = leaf->buffer().data();
            for (int n = 0; n < 512; ++n)
                if (rowBricks(target.bricks, n >> 6, (n >> 3) & 7) >> ((n & 7) >> 1) & 1u) {
                    values[n] = float(iso) - scale * sum[n];
                    leaf->setValueOn(openvdb::Index(n));
                }
            made[t] = leaf;
        }
    }, 8);
    FloatGrid::Ptr grid = FloatGrid::create(float(iso));
    grid->setTransform(openvdb::math::Transform::createLinearTransform(h));
    for (FloatLeaf* leaf : made) grid->tree().addLeaf(leaf);
    return grid;
}

// Every leaf of the binned lattice that some kernel reaches (a cell of the bins is a leaf), all bricks chosen.
std::vector<LatticeLeaf> leavesReached(const KernelBins& binned) {
    const UniformGrid& bins = binned.grid;
    const int around = int(std::ceil(binned.reach.maxCoeff() / (8 * binned.h)));
    std::vector<openvdb::Coord> origins;
    for (std::size_t c = 0; c < bins.cellCount(); ++c) {
        const auto& k = bins.cellCoords(c);
        for (int a = -around; a <= around; ++a)
            for (int b = -around; b <= around; ++b)
                for (int d = -around; d <= around; ++d)
                    origins.emplace_back(8 * (k[0] + a), 8 * (k[1] + b), 8 * (k[2] + d));
    }
    std::sort(origins.begin(), origins.end());
    origins.erase(std::unique(origins.begin(), origins.end()), origins.end());
    std::vector<LatticeLeaf> out;
    out.reserve(origins.size());
    for (const openvdb::Coord& o : origins) out.push_back({o, ~std::uint64_t(0)});
    return out;
}

// The bricks (cells of the coarse lattice, named by their lowest corner) the surface may cross: a corner's kernel
// sum between kSeedLow and kSeedHigh of the interior's, or corners on both sides of them.
openvdb::MaskGrid::Ptr bricksCrossed(const FloatGrid& coarse, Real interior) {
    const float low = float(kSeedLow * interior), high = float(kSeedHigh * interior);
    const float iso = coarse.background();
    openvdb::MaskGrid::Ptr mask = openvdb::MaskGrid::create();
    mask->tree().topologyUnion(coarse.tree());
    // A brick whose lowest corner lies outside the coarse grid's leaves may still be crossed.
    openvdb::tools::dilateActiveValues(mask->tree(), 1, openvdb::tools::NN_FACE_EDGE_VERTEX,
                                       openvdb::tools::IGNORE_TILES);
    openvdb::tree::LeafManager<openvdb::MaskTree> leaves(mask->tree());
    leaves.foreach([&](openvdb::MaskTree::LeafNodeType& leaf, std::size_t) {
        const auto acc = coarse.getConstAccessor();
        for (auto it = leaf.beginValueOn(); it; ++it) {
            const openvdb::Coord m = it.getCoord();
            bool inside = false, outside = false, between = false;
            for (int corner = 0; corner < 8; ++corner) {
                const float f = iso - acc.getValue(m.offsetBy(corner >> 2, (corner >> 1) & 1, corner & 1));
                inside = inside || f >= high;
                outside = outside || f <= low;
                between = between || (f > low && f < high);
            }
            if (!between && !(inside && outside)) leaf.setValueOff(it.pos());
        }
    });
    openvdb::tools::pruneInactive(mask->tree());
    return mask;
}

// The fine leaves under the bricks of `bricks` (a mask on the coarse lattice: brick m covers voxels 2m, 2m+1).
std::vector<LatticeLeaf> fineLeaves(const openvdb::MaskGrid& bricks) {
    std::vector<LatticeLeaf> out;
    for (auto leaf = bricks.tree().cbeginLeaf(); leaf; ++leaf) {
        LatticeLeaf part[8] = {};
        for (auto it = leaf->cbeginValueOn(); it; ++it) {
            const openvdb::Coord m = it.getCoord() - leaf->origin();  // 0..7 within the coarse leaf
            const int octant = (m.x() >> 2) * 4 + (m.y() >> 2) * 2 + (m.z() >> 2);
            part[octant].bricks |= std::uint64_t(1) << ((m.x() & 3) * 16 + (m.y() & 3) * 4 + (m.z() & 3));
        }
        for (int octant = 0; octant < 8; ++octant)
            if (part[octant].bricks) {
                const openvdb::Coord offset(((octant >> 2) & 1) * 8, ((octant >> 1) & 1) * 8, (octant & 1) * 8);
                out.push_back({openvdb::Coord(leaf->origin().asVec3i() * 2) + offset, part[octant].bricks});
            }
    }
    return out;
}

// The signed distance from a field g (iso minus kernel sum) on its active voxels: g over the length of its
// gradient, the distance to the surface to first order. Voxels within the half band stay active; the others take
// the background with their sign.
void fieldToDistance(FloatGrid& field, Real voxel, Real halfBand) {
    const float band = float(halfBand * voxel), inv2h = float(0.5 / voxel);
    openvdb::tree::LeafManager<openvdb::FloatTree> leaves(field.tree(), 1);
    leaves.foreach([&](FloatLeaf& leaf, std::size_t index) {
        const auto acc = field.getConstAccessor();
        float* out = leaves.getBuffer(index, 1).data();
        const float* in = leaf.buffer().data();
        for (int n = 0; n < 512; ++n) out[n] = in[n] < 0 ? -band : band;
        const auto& active = leaf.getValueMask();
        for (auto it = leaf.beginValueOn(); it; ++it) {
            const openvdb::Index n = it.pos();
            const int ijk[3] = {int(n >> 6), int((n >> 3) & 7), int(n & 7)};
            const float g = in[n];
            float gradient2 = 0;
            for (int axis = 0; axis < 3; ++axis) {
                // A neighbour inside the leaf is read from its buffer, one outside through the accessor.
                const int stride = 1 << (3 * (2 - axis));
                auto neighbour = [&](int side, float& value) {
                    if (ijk[axis] + side >= 0 && ijk[axis] + side < 8) {
                        const openvdb::Index m = openvdb::Index(int(n) + side * stride);
                        value = in[m];
                        return active.isOn(m);
                    }
                    openvdb::Coord c = it.getCoord();
                    c[axis] += side;
                    return acc.probeValue(c, value);
                };
                float gu, gd;
                const bool hasUp = neighbour(1, gu), hasDown = neighbour(-1, gd);
                const float d = hasUp && hasDown ? (gu - gd) * inv2h
                              : hasUp           ? (gu - g) * 2 * inv2h
                              : hasDown         ? (g - gd) * 2 * inv2h
                                                : 0.f;
                gradient2 += d * d;
            }
            const float distance = gradient2 > 0 ? g / std::sqrt(gradient2) : (g < 0 ? -band : band);
            out[it.pos()] = std::clamp(distance, -band, band);
        }
    });
    leaves.swapLeafBuffer(1);
    leaves.foreach([&](FloatLeaf& leaf, std::size_t) {
        for (auto it = leaf.beginValueOn(); it; ++it)
            if (std::abs(*it) >= band) leaf.setValueOff(it.pos());
    });
    field.tree().root().setBackground(band, false);
    openvdb::tools::pruneInactive(field.tree());
    openvdb::tools::signedFloodFill(field.tree());
}

}  // namespace

FloatGrid::Ptr anisotropicLevelSet(const std::vector<Vec3>& x, Real r, Real voxel, Real halfBand) {
    // Half the value deep inside a lattice of spacing 2r: the surface lies midway between the last row of
    // particles and the next, unfilled one, i.e. where the lattice cells end, as for the other methods.
    const CubicSpline w(kKernelSupport * r);
    const Real interior = latticeKernelSum(2 * r, w) * 8 * r * r * r;
    const std::vector<Ellipsoid> kernels = anisotropicKernels(x, r);
    const KernelBins coarseBins(kernels, 2 * voxel);
    const FloatGrid::Ptr coarse = kernelSum(kernels, coarseBins, leavesReached(coarseBins), r, 0.5 * interior);
    // The bricks the surface may cross, and around them as far as the band reaches (its half width and one voxel
    // for the gradient, in bricks of two voxels).
    const openvdb::MaskGrid::Ptr bricks = bricksCrossed(*coarse, interior);
    openvdb::tools::dilateActiveValues(bricks->tree(), int(std::ceil((halfBand + 1) / 2)),
                                       openvdb::tools::NN_FACE_EDGE_VERTEX, openvdb::tools::IGNORE_TILES);
    const FloatGrid::Ptr field = kernelSum(kernels, KernelBins(kernels, voxel), fineLeaves(*bricks), r, 0.5 * interior);
    fieldToDistance(*field, voxel, halfBand);
    field->setGridClass(openvdb::GRID_LEVEL_SET);
    return field;
}

}  // namespace ganache::surfacing
