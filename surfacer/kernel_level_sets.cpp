// Level sets from fields gathered over particles' kernels, taken only where the surface can be: Yu & Turk's
// anisotropic kernels (2013), Zhu & Bridson's smooth spheres (2005) and the plain union of spheres.
//
// Visiting every voxel a kernel reaches (about 2,000 per particle) was most of a frame's time. Here a field is
// taken in two passes: first on a coarse lattice of two voxels' spacing, which finds the bricks of 2^3 voxels the
// surface can cross; then on the voxels of those bricks and of the bricks around them, as wide as the narrow band.
// For anisotropic kernels the signed distance is the kernel sum's distance from the iso value over its gradient,
// exact to first order at the surface, so that no level set needs rebuilding from a mesh; the spheres' fields are
// distances near the surface already.

#include "surfacer/level_sets.h"

#include "core/kernels.h"
#include "core/neighbour_search.h"
#include "core/parallel.h"

#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <immintrin.h>
#include <openvdb/tools/Morphology.h>
#include <openvdb/tools/Prune.h>
#include <openvdb/tools/SignedFloodFill.h>
#include <openvdb/tree/LeafManager.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

namespace ganache::surfacing {

namespace {

using openvdb::FloatGrid;

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

// A kernel's shape in single precision (the sums evaluate in it anyway): 72 bytes instead of 120 a particle.
struct Ellipsoid {
    Vec3 centre;
    Eigen::Matrix3f shape;  // A: a point y from the centre counts at distance |A y| (det A = 1)
    Eigen::Vector3f extent;  // half size of its bounding box [m], rounded up
};

// An ellipsoid's box half size in single precision, never smaller than in double.
Eigen::Vector3f extentAbove(const Vec3& extent) {
    Eigen::Vector3f out;
    for (int axis = 0; axis < 3; ++axis)
        out[axis] = std::nextafter(float(extent[axis]), std::numeric_limits<float>::infinity());
    return out;
}

// The shape A of a kernel from its neighbours' covariance C: along C's axes, the inverse of its eigenvalues raised to
// at least 1 / kMaxStretch of the largest, scaled to det A = 1 (the kernel's volume, so the interior's sum, does not
// change). Where no eigenvalue needs raising that is cbrt(det C) C^-1, and no eigenvectors are needed: Gershgorin's
// discs bound the eigenvalues, and in the fluid's inside (most particles) they lie within a factor kMaxStretch.
Mat3 shapeFromSpread(const Mat3& covariance) {
    Real upper = 0, lower = std::numeric_limits<Real>::infinity();
    for (int i = 0; i < 3; ++i) {
        const Real radius = std::abs(covariance(i, (i + 1) % 3)) + std::abs(covariance(i, (i + 2) % 3));
        upper = std::max(upper, covariance(i, i) + radius);
        lower = std::min(lower, covariance(i, i) - radius);
    }
    if (lower > 0 && lower * kMaxStretch >= upper) return std::cbrt(covariance.determinant()) * covariance.inverse();
    Eigen::SelfAdjointEigenSolver<Mat3> eigen;
    eigen.computeDirect(covariance);
    Vec3 scale = eigen.eigenvalues().cwiseMax(eigen.eigenvalues().maxCoeff() / kMaxStretch);
    scale /= std::cbrt(scale.prod());
    const Mat3& axes = eigen.eigenvectors();
    return axes * scale.cwiseInverse().asDiagonal() * axes.transpose();
}

// The 27 cells' points around one cell of a grid, as offsets from that cell's lowest corner in single precision
// (small numbers: float keeps them to a nanometre at a centimetre), padded to a multiple of eight with points too
// far for any kernel, so that the spread's sums take eight at a time without a test per candidate.
struct NearbyOffsets {
    CellCandidates candidates;
    std::vector<float> x, y, z;

    void gather(const UniformGrid& grid, std::size_t cell) {
        candidates.gather(grid, grid.cellCoords(cell));
        const std::size_t n = candidates.count, padded = (n + 7) / 8 * 8;
        x.resize(padded), y.resize(padded), z.resize(padded);
        const Vec3 corner = lowestCorner(grid, cell);
        for (std::size_t k = 0; k < n; ++k) {
            x[k] = float(candidates.x[k] - corner.x());
            y[k] = float(candidates.y[k] - corner.y());
            z[k] = float(candidates.z[k] - corner.z());
        }
        // Far, yet squares and cubes stay finite: such a point weighs max(0, 1 - huge) = 0, and 0 times it is 0.
        std::fill(x.begin() + std::ptrdiff_t(n), x.end(), 1e12f);
        std::fill(y.begin() + std::ptrdiff_t(n), y.end(), 1e12f);
        std::fill(z.begin() + std::ptrdiff_t(n), z.end(), 1e12f);
    }

    static Vec3 lowestCorner(const UniformGrid& grid, std::size_t cell) {
        const auto& c = grid.cellCoords(cell);
        return Vec3(c[0], c[1], c[2]) * grid.cellSize();
    }
};

// Each particle's kernel from the spread of its neighbours within the support. The sums the spread needs are
// taken in one pass over the 27 grid cells around the particle's own, without storing neighbour lists (which cost
// as much again as the sums at 1M particles): the 27 cells' points are gathered once for the particles of a cell,
// and every particle weighs them eight at a time in single precision, those beyond the support with weight zero (a
// branch per candidate went the wrong way often). The kernels come out in the grid's order, not the particles'.
std::vector<Ellipsoid> anisotropicKernels(const std::vector<Vec3>& x, Real r) {
    const Real support = kKernelSupport * r;
    const Real support2 = support * support;
    const float inverseCube = float(1 / (support2 * support));
    // Z order: the kernel sums walk the level set's leaves, which OpenVDB's tree keeps in blocks of blocks.
    UniformGrid grid(support, UniformGrid::kAlwaysZOrder);
    grid.build(x);
    grid.releaseWorkingMemory();
    const std::vector<Real>& sx = grid.sortedCoords(0);
    const std::vector<Real>& sy = grid.sortedCoords(1);
    const std::vector<Real>& sz = grid.sortedCoords(2);
    std::vector<Ellipsoid> out(x.size());
    tbb::enumerable_thread_specific<NearbyOffsets> scratch;
    forEachBlock(grid.cellCount(), [&](std::size_t begin, std::size_t end) {
        NearbyOffsets& near = scratch.local();
        for (std::size_t c = begin; c != end; ++c) {
            near.gather(grid, c);
            const Vec3 corner = NearbyOffsets::lowestCorner(grid, c);
            for (std::size_t s = grid.cellBegin(c); s != grid.cellBegin(c + 1); ++s) {
                const std::uint32_t i = grid.sortedIndices()[s];
                // Weighted sums over the neighbourhood, itself included (at offset 0, weight 1),
                // w = max(0, 1 - (d / support)^3), of the offsets from the particle and of their products (the
                // covariance about the weighted mean follows).
                const float px = float(sx[s] - corner.x()), py = float(sy[s] - corner.y()),
                            pz = float(sz[s] - corner.z());
                RowOfEight total = RowOfEight::Zero(), m[3], q[6];
                for (auto& sum : m) sum.setZero();
                for (auto& sum : q) sum.setZero();
                // The candidates within the support are found in double, 64 at a time, and counted there: a
                // lattice's points two spacings apart lie at the support itself, where rounding decides, and the
                // count decides whether a kernel may stretch. Eights without one are skipped.
                std::size_t neighbours = 0;
                const CellCandidates& cand = near.candidates;
                for (std::size_t word = 0; word != cand.words(); ++word) {
                    const std::size_t base = 64 * word;
                    const std::uint64_t bits = closer64(cand.x.data() + base, cand.y.data() + base,
                                                        cand.z.data() + base, cand.lanes(word), sx[s], sy[s], sz[s],
                                                        support2);
                    neighbours += std::size_t(__builtin_popcountll(bits));
                    for (std::size_t k = base; k != base + 64; k += 8) {
                        if (!(bits >> (k - base) & 0xffu)) continue;
                        const RowOfEight dx = Eigen::Map<const RowOfEight>(near.x.data() + k) - px;
                        const RowOfEight dy = Eigen::Map<const RowOfEight>(near.y.data() + k) - py;
                        const RowOfEight dz = Eigen::Map<const RowOfEight>(near.z.data() + k) - pz;
                        const RowOfEight d2 = dx * dx + dy * dy + dz * dz;
                        const RowOfEight w = (1.f - d2 * d2.sqrt() * inverseCube).max(0.f);
                        total += w;
                        const RowOfEight wx = w * dx, wy = w * dy, wz = w * dz;
                        m[0] += wx, m[1] += wy, m[2] += wz;
                        q[0] += wx * dx, q[1] += wy * dy, q[2] += wz * dz;
                        q[3] += wx * dy, q[4] += wx * dz, q[5] += wy * dz;
                    }
                }
                const Real weight = total.sum();
                --neighbours;  // itself
                // In the grid's Z order, not the particles': the sums' bins then find a cell's kernels side by side.
                Ellipsoid& e = out[s];
                e.centre = x[i];
                Mat3 shape = Mat3::Identity();
                if (neighbours >= kMinNeighbours) {
                    const Vec3 mean = Vec3(m[0].sum(), m[1].sum(), m[2].sum()) / weight;
                    Mat3 covariance;
                    covariance << q[0].sum(), q[3].sum(), q[4].sum(), q[3].sum(), q[1].sum(), q[5].sum(), q[4].sum(),
                        q[5].sum(), q[2].sum();
                    covariance = covariance / weight - mean * mean.transpose();
                    shape = shapeFromSpread(covariance);
                }
                // The ellipsoid {y : |A y| < support} = A^-1 (ball); its box's half size along axis k is
                // support |row_k A^-1|.
                e.shape = shape.cast<float>();
                const Mat3 inverse = e.shape.cast<Real>().inverse();
                Vec3 extent;
                for (int axis = 0; axis < 3; ++axis) extent[axis] = support * inverse.row(axis).norm();
                e.extent = extentAbove(extent);
            }
        }
    }, 16);
    return out;
}

// A row's points' offsets along z.
const RowOfEight kRowSteps = RowOfEight::LinSpaced(8, 0, 7);

// a b + c, rounded once where the target has FMA (the build leaves no product to the compiler to fuse, so that the
// same code rounds the same way wherever it is inlined; here it is asked for by name).
inline RowOfEight fusedMultiplyAdd(const RowOfEight& a, const RowOfEight& b, const RowOfEight& c) {
#if defined(__FMA__) && defined(__AVX__)
    RowOfEight out;
    _mm256_storeu_ps(out.data(),
                     _mm256_fmadd_ps(_mm256_loadu_ps(a.data()), _mm256_loadu_ps(b.data()), _mm256_loadu_ps(c.data())));
    return out;
#else
    return a * b + c;
#endif
}

// The kernel's profile over s = q^2 (q = distance / support): (1 - s)^3 (1 + a s + b s^2), the cubic spline's
// profile fitted by least squares weighted by q^2 (as volume is). It stays within 0.007 of the spline (peak 1) and
// vanishes at the support with two derivatives, as the spline does, but a row's points need no square root: the two
// kernel sums cost about a fifth less at 1M particles than with the spline itself (docs/benchmarks.md, change 11).
constexpr float kShapeA = -2.0484819f, kShapeB = 1.6913138f;
Real shapeFactor(Real s) { return 1.f + s * (kShapeA + s * kShapeB); }  // 1 + a s + b s^2
// sum + the profile at a row's s, with fused products.
inline RowOfEight addKernelShape(const RowOfEight& sum, const RowOfEight& s) {
    const RowOfEight t = (1.f - s).max(0.f);
    const RowOfEight factor = fusedMultiplyAdd(s, fusedMultiplyAdd(s, RowOfEight::Constant(kShapeB),
                                                                   RowOfEight::Constant(kShapeA)),
                                               RowOfEight::Ones());
    return fusedMultiplyAdd(t * t * t, factor, sum);
}

// The sum of the profile (in double) at a point of a lattice of spacing 2r, support 4r (the points within two
// spacings).
Real latticeShapeSum() {
    Real sum = 0;
    for (int i = -2; i <= 2; ++i)
        for (int j = -2; j <= 2; ++j)
            for (int k = -2; k <= 2; ++k) {
                const Real s = (i * i + j * j + k * k) / 4.0;
                if (s < 1) sum += std::pow(1 - s, 3) * shapeFactor(s);
            }
    return sum;
}

// A leaf of a lattice (8^3 points) and which of its 4^3 bricks of 2^3 points to evaluate (bit 16 i + 4 j + k).
struct LatticeLeaf {
    openvdb::Coord origin;
    std::uint64_t bricks;
};

// The kernels' centres sorted into cells of one leaf of a lattice of spacing h (8 h), how far the largest kernel
// reaches from its centre along each axis, and per cell the box that holds its kernels' boxes (so that a leaf skips
// the cells none of whose kernels reach it: most of those two cells away, where only stretched kernels could).
struct KernelBins {
    struct Box {  // in single precision, rounded outwards
        Eigen::Vector3f lo, hi;
    };
    Real h;
    UniformGrid grid;
    Vec3 reach = Vec3::Zero();
    std::vector<Box> boxes;  // per cell

    KernelBins(const std::vector<Ellipsoid>& kernels, Real spacing)
        : h(spacing), grid(8 * spacing, UniformGrid::kAlwaysZOrder) {  // Z order, as the kernels' grid
        std::vector<Vec3> centres(kernels.size());
        for (std::size_t i = 0; i < kernels.size(); ++i)
            reach = reach.cwiseMax(kernels[i].extent.cast<Real>()), centres[i] = kernels[i].centre;
        grid.build(centres);
        grid.releaseWorkingMemory();
        boxes.resize(grid.cellCount());
        forEachBlock(grid.cellCount(), [&](std::size_t begin, std::size_t end) {
            for (std::size_t c = begin; c != end; ++c) {
                Vec3 lo = Vec3::Constant(std::numeric_limits<Real>::infinity()), hi = -lo;
                for (std::size_t k = grid.cellBegin(c); k < grid.cellBegin(c + 1); ++k) {
                    const Ellipsoid& e = kernels[grid.sortedIndices()[k]];
                    // As the leaves' test computes them, so that a cell is skipped only where each kernel would be.
                    const Vec3 extent = e.extent.cast<Real>();
                    lo = lo.cwiseMin(e.centre - extent), hi = hi.cwiseMax(e.centre + extent);
                }
                for (int axis = 0; axis < 3; ++axis) {
                    boxes[c].lo[axis] = std::nextafter(float(lo[axis]), -std::numeric_limits<float>::infinity());
                    boxes[c].hi[axis] = std::nextafter(float(hi[axis]), std::numeric_limits<float>::infinity());
                }
            }
        }, 256);
    }
};

// The 4 bits of the bricks along z under the row (a, b) of a leaf (a, b in 0..7).
inline unsigned rowBricks(std::uint64_t bricks, int a, int b) {
    return unsigned(bricks >> ((a >> 1) * 16 + (b >> 1) * 4)) & 0xFu;
}

// Visits, for each target leaf of a lattice of spacing h [m] (point ijk at h ijk), every row along z of its chosen
// bricks that a kernel reaches: field.add(kernel, a, b, q2) with q2 the row's points' squared distances in the
// kernel's own coordinates (|A y| / support; inside where q2 < 1; rounding may leave it a little below 0 at the
// centre), after field.start(leaf's lowest point [m]); field.value(n) then gives each chosen point's value. Each leaf
// gathers the kernels whose boxes reach it from a grid of their centres, in that grid's fixed order: deterministic for
// any thread count. A field whose kernels add nothing outside (Field::kNothingOutside) also takes the rows of a
// kernel's box that miss the ellipsoid; for the others those rows are skipped. A leaf stops taking kernels once
// field.settled(): its values are decided as far as they are asked for. A field that may take its kernels in any
// order (field.orderFree()) takes the leaf's own cell first. Returns the grid of the leaves made (background
// `background`).
template <class Field>
FloatGrid::Ptr gatherRows(const std::vector<Ellipsoid>& kernels, const KernelBins& binned,
                          const std::vector<LatticeLeaf>& targets, Real support, float background,
                          const Field& prototype) {
    const Real h = binned.h, cell = 8 * h, inverseH = 1 / h;
    const float stepInSupports = float(h / support);
    const Vec3& reach = binned.reach;
    const UniformGrid& bins = binned.grid;
    std::vector<FloatLeaf*> made(targets.size(), nullptr);
    forEachBlock(targets.size(), [&](std::size_t begin, std::size_t end) {
        Field field = prototype;
        for (std::size_t t = begin; t != end; ++t) {
            const LatticeLeaf& target = targets[t];
            const openvdb::Coord o = target.origin;
            const Vec3 lo = Vec3(o.x(), o.y(), o.z()) * h, hi = lo + Vec3::Constant(7 * h);
            field.start(lo);
            const Vec3 cellLo = ((lo - reach) / cell).array().floor(), cellHi = ((hi + reach) / cell).array().floor();
            // The kernels of one cell of the bins.
            const auto visit = [&](std::int64_t ca, std::int64_t cb, std::int64_t cc) {
                const std::int64_t found = bins.findCell(ca, cb, cc);
                if (found < 0) return;
                const std::size_t ci = std::size_t(found);
                const KernelBins::Box& box = binned.boxes[ci];
                if ((((box.lo.cast<Real>() - lo) * inverseH).array().ceil() > 7).any() ||
                    (((box.hi.cast<Real>() - lo) * inverseH).array().floor() < 0).any())
                    return;
                for (std::size_t k = bins.cellBegin(ci); k < bins.cellBegin(ci + 1); ++k) {
                    const Ellipsoid& e = kernels[bins.sortedIndices()[k]];
                    // The kernel's box in the leaf's point indices (0..7).
                    const Vec3 extent = e.extent.cast<Real>();
                    // (A box a point wider where a product rounds the other way adds only zeros: the kernel vanishes
                    // at its box's faces, which lie outside its ellipsoid.)
                    const Vec3 boxLo = ((e.centre - extent - lo) * inverseH).array().ceil();
                    const Vec3 boxHi = ((e.centre + extent - lo) * inverseH).array().floor();
                    if ((boxLo.array() > 7).any() || (boxHi.array() < 0).any()) continue;
                    const int aLo = std::max(0, int(boxLo.x())), aHi = std::min(7, int(boxHi.x()));
                    const int bLo = std::max(0, int(boxLo.y())), bHi = std::min(7, int(boxHi.y()));
                    // A y in supports at point (a, b, c) of the leaf: u0 + a dx + b dy + c dz, with (dx dy dz) =
                    // A h / support and u0 = A (lo - centre) / support, in single precision as the rows are.
                    const float steps[3] = {float((lo.x() - e.centre.x()) * inverseH),
                                            float((lo.y() - e.centre.y()) * inverseH),
                                            float((lo.z() - e.centre.z()) * inverseH)};
                    float u0[3], dx[3], dy[3], dz[3];
                    for (int d = 0; d < 3; ++d) {  // written out: Eigen called functions here
                        dx[d] = e.shape(d, 0) * stepInSupports, dy[d] = e.shape(d, 1) * stepInSupports,
                        dz[d] = e.shape(d, 2) * stepInSupports;
                        u0[d] = dx[d] * steps[0] + dy[d] * steps[1] + dz[d] * steps[2];
                    }
                    const float inverseStep = 1.f / (dz[0] * dz[0] + dz[1] * dz[1] + dz[2] * dz[2]);
                    const RowOfEight dy2 = RowOfEight::Constant(dy[0] * dy[0] + dy[1] * dy[1] + dy[2] * dy[2]);
                    for (int a = aLo; a <= aHi; ++a) {
                        float ua[3];
                        for (int d = 0; d < 3; ++d) ua[d] = u0[d] + float(a) * dx[d];
                        // A row at once (one vector), at the row's points p + b dy with p = ua + c dz, c = 0..7:
                        // |p + b dy|^2 = |p|^2 + b (2 p.dy + b |dy|^2), the slab's two vectors taken once for its rows.
                        RowOfEight p[3];
                        for (int d = 0; d < 3; ++d)
                            p[d] = fusedMultiplyAdd(kRowSteps, RowOfEight::Constant(dz[d]),
                                                    RowOfEight::Constant(ua[d]));
                        const RowOfEight pp = fusedMultiplyAdd(p[2], p[2], fusedMultiplyAdd(p[1], p[1], p[0] * p[0]));
                        const RowOfEight pdy =
                            2.f * fusedMultiplyAdd(p[2], RowOfEight::Constant(dy[2]),
                                                   fusedMultiplyAdd(p[1], RowOfEight::Constant(dy[1]), p[0] * dy[0]));
                        const auto row = [&](int b) {
                            if (!rowBricks(target.bricks, a, b)) return;
                            // Rows that miss the ellipsoid (|u + c dz| < 1 for no c, a quadratic's roots)
                            // are skipped where adding them would change the field. Where it would not,
                            // the test costs more than the rows it saves (a quarter more rows evaluated,
                            // but the branch is mispredicted, and without it two rows' work overlaps).
                            if constexpr (!Field::kNothingOutside) {
                                float u[3];
                                for (int d = 0; d < 3; ++d) u[d] = ua[d] + float(b) * dy[d];
                                const float middle = (u[0] * dz[0] + u[1] * dz[1] + u[2] * dz[2]) * inverseStep;
                                const float discriminant = middle * middle - (u[0] * u[0] + u[1] * u[1] +
                                                                              u[2] * u[2] - 1) * inverseStep;
                                if (discriminant <= 0) return;
                            }
                            const RowOfEight fb = RowOfEight::Constant(float(b));
                            field.add(e, a, b, fusedMultiplyAdd(fb, fusedMultiplyAdd(fb, dy2, pdy), pp));
                        };
#pragma GCC unroll 2
                        for (int b = bLo; b <= bHi; ++b) row(b);
                    }
                }
            };
            const auto visitAll = [&] {
                const std::int64_t own[3] = {std::int64_t(std::floor(lo.x() / cell)),
                                             std::int64_t(std::floor(lo.y() / cell)),
                                             std::int64_t(std::floor(lo.z() / cell))};
                // Where the order is free, the cells nearest the leaf's own first (by their distance in cells
                // summed over the axes, up to 3): their kernels cover most of the leaf, so an inside leaf settles
                // sooner. Else one pass in the grid's order.
                const int rings = field.orderFree() ? 4 : 1;
                for (int ring = 0; ring < rings; ++ring)
                    for (std::int64_t ca = std::int64_t(cellLo.x()); ca <= std::int64_t(cellHi.x()); ++ca)
                        for (std::int64_t cb = std::int64_t(cellLo.y()); cb <= std::int64_t(cellHi.y()); ++cb)
                            for (std::int64_t cc = std::int64_t(cellLo.z()); cc <= std::int64_t(cellHi.z()); ++cc) {
                                const std::int64_t away =
                                    std::abs(ca - own[0]) + std::abs(cb - own[1]) + std::abs(cc - own[2]);
                                if (rings > 1 && std::min<std::int64_t>(away, rings - 1) != ring) continue;
                                if (field.settled()) return;
                                visit(ca, cb, cc);
                            }
            };
            visitAll();
            auto* leaf = new FloatLeaf(o, background, false);
            float* values = leaf->buffer().data();
            for (int n = 0; n < 512; ++n)
                if (rowBricks(target.bricks, n >> 6, (n >> 3) & 7) >> ((n & 7) >> 1) & 1u) {
                    values[n] = field.value(n);
                    leaf->setValueOn(openvdb::Index(n));
                }
            made[t] = leaf;
        }
    }, 8);
    FloatGrid::Ptr grid = FloatGrid::create(background);
    grid->setTransform(openvdb::math::Transform::createLinearTransform(h));
    for (FloatLeaf* leaf : made) grid->tree().addLeaf(leaf);
    return grid;
}

// Yu & Turk's field: iso minus the kernels' sum (the profile, scaled to the cubic spline's peak), each particle
// weighing one lattice cell (2r)^3. With settleBelow, only how the values lie against it and other such thresholds is
// asked for: the order of the kernels, which moves a sum's last bits, is free, and since the sums only grow (the shape
// is never negative), a leaf whose values all lie at or below settleBelow has settled.
class ShapeSum {
public:
    static constexpr bool kNothingOutside = true;  // the kernel is zero there
    ShapeSum(float scale, float iso, float settleBelow = -std::numeric_limits<float>::infinity())
        : m_scale(scale), m_iso(iso), m_settleBelow(settleBelow) {}
    void start(const Vec3&) { std::fill(m_sum, m_sum + 512, 0.f); }
    void add(const Ellipsoid&, int a, int b, const RowOfEight& q2) {
        Eigen::Map<RowOfEight> row(m_sum + a * 64 + b * 8);
        row = addKernelShape(row, q2);
    }
    float value(int n) const { return valueOf(m_sum[n]); }
    bool orderFree() const { return m_settleBelow > -std::numeric_limits<float>::infinity(); }
    bool settled() const {
        return orderFree() && valueOf(Eigen::Map<const Eigen::Array<float, 512, 1>>(m_sum).minCoeff()) <= m_settleBelow;
    }

private:
    float valueOf(float sum) const { return m_iso - m_scale * sum; }

    float m_scale, m_iso, m_settleBelow;
    alignas(32) float m_sum[512];
};

// The kernel sum on the chosen bricks of the target leaves, as iso minus the sum (negative inside) on active
// voxels; background iso. Where only whether a value lies at or below settleBelow is asked for, it may stop there.
FloatGrid::Ptr kernelSum(const std::vector<Ellipsoid>& kernels, const KernelBins& binned,
                         const std::vector<LatticeLeaf>& targets, Real r, Real iso,
                         float settleBelow = -std::numeric_limits<float>::infinity()) {
    const CubicSpline w(kKernelSupport * r);
    const float scale = float(8 * r * r * r * w.W0());
    return gatherRows(kernels, binned, targets, w.supportRadius(), float(iso),
                      ShapeSum(scale, float(iso), settleBelow));
}

// Zhu & Bridson's field: the distance to the weighted mean of the particles within the search radius, less the
// particle radius, with weights (1 - (d / search)^2)^3 (no square root); `far` where no particle is that close.
class AveragedSpheres {
public:
    static constexpr bool kNothingOutside = true;  // the weights are zero there
    AveragedSpheres(float spacing, float radius, float far) : m_h(spacing), m_radius(radius), m_far(far) {}
    void start(const Vec3& lo) {
        m_lo = lo;
        for (float* channel : {m_w, m_x, m_y, m_z}) std::fill(channel, channel + 512, 0.f);
    }
    void add(const Ellipsoid& e, int a, int b, const RowOfEight& q2) {
        const RowOfEight t = (1.f - q2).max(0.f), w = t * t * t;
        const Vec3 c = e.centre - m_lo;  // small numbers: float keeps them to a micrometre
        const int row = a * 64 + b * 8;
        Eigen::Map<RowOfEight>(m_w + row) += w;
        for (auto [channel, coordinate] : {std::pair{m_x, c.x()}, {m_y, c.y()}, {m_z, c.z()}}) {
            Eigen::Map<RowOfEight> sum(channel + row);
            sum = fusedMultiplyAdd(w, RowOfEight::Constant(float(coordinate)), sum);
        }
    }
    float value(int n) const {
        if (!(m_w[n] > 0)) return m_far;
        const float x = m_x[n] / m_w[n] - m_h * float(n >> 6), y = m_y[n] / m_w[n] - m_h * float((n >> 3) & 7),
                    z = m_z[n] / m_w[n] - m_h * float(n & 7);
        return std::sqrt(x * x + y * y + z * z) - m_radius;
    }
    bool orderFree() const { return false; }  // a sum: its last bits depend on the order
    bool settled() const { return false; }    // a weighted mean may move either way

private:
    float m_h, m_radius, m_far;
    Vec3 m_lo = Vec3::Zero();
    alignas(32) float m_w[512], m_x[512], m_y[512], m_z[512];
};

// The union of spheres: the distance to the nearest sphere's surface (negative inside), `far` where no sphere's
// support reaches. Below settleBelow it only matters that a value lies below it (on the coarse lattice only the sign
// matters, and past the band's inner edge every value ends as its half width): a leaf whose values all lie below it
// has settled, and its other kernels are left out (the fluid's inside, most of the coarse lattice's leaves).
class NearestSphere {
public:
    static constexpr bool kNothingOutside = false;  // a distance beyond the support is no sphere's
    NearestSphere(float support, float radius, float far, float settleBelow)
        : m_support(support), m_radius(radius), m_far(far), m_settleBelow(settleBelow) {}
    void start(const Vec3&) { std::fill(m_nearest2, m_nearest2 + 512, std::numeric_limits<float>::infinity()); }
    // Only the nearest centre's squared distance (in supports): the distance grows with it, so its square root is
    // taken once per point, in value(), instead of once per sphere.
    void add(const Ellipsoid&, int a, int b, const RowOfEight& q2) {
        Eigen::Map<RowOfEight> row(m_nearest2 + a * 64 + b * 8);
        row = row.min(q2);
    }
    float value(int n) const { return distance(m_nearest2[n]); }
    bool orderFree() const { return true; }  // a minimum: any order gives the same values
    // More spheres can only lower the values (the distance never falls as its square grows).
    bool settled() const {
        return distance(Eigen::Map<const Eigen::Array<float, 512, 1>>(m_nearest2).maxCoeff()) < m_settleBelow;
    }

private:
    float distance(float nearest2) const {
        return std::min(m_far, std::sqrt(std::max(nearest2, 0.f)) * m_support - m_radius);
    }

    float m_support, m_radius, m_far, m_settleBelow;
    alignas(32) float m_nearest2[512];
};

// Every leaf of the binned lattice that some kernel reaches (a cell of the bins is a leaf), all bricks chosen.
std::vector<LatticeLeaf> leavesReached(const KernelBins& binned) {
    const UniformGrid& bins = binned.grid;
    const int around = int(std::ceil(binned.reach.maxCoeff() / (8 * binned.h)));
    const std::size_t side = std::size_t(2 * around + 1), perCell = side * side * side;
    std::vector<openvdb::Coord> origins(bins.cellCount() * perCell);
    forEachBlock(bins.cellCount(), [&](std::size_t begin, std::size_t end) {
        for (std::size_t c = begin; c != end; ++c) {
            const auto& k = bins.cellCoords(c);
            openvdb::Coord* out = origins.data() + c * perCell;
            for (int a = -around; a <= around; ++a)
                for (int b = -around; b <= around; ++b)
                    for (int d = -around; d <= around; ++d) *out++ = {8 * (k[0] + a), 8 * (k[1] + b), 8 * (k[2] + d)};
        }
    });
    tbb::parallel_sort(origins.begin(), origins.end());
    origins.erase(std::unique(origins.begin(), origins.end()), origins.end());
    std::vector<LatticeLeaf> out;
    out.reserve(origins.size());
    for (const openvdb::Coord& o : origins) out.push_back({o, ~std::uint64_t(0)});
    return out;
}

// The bricks (cells of the coarse lattice, named by their lowest corner) the surface may cross: a corner whose value
// lies between insideBelow and outsideAbove, or corners on both sides of them. Each coarse leaf is read from its
// buffer with a layer of its neighbours' points on every side (no accessor per corner), and decides the bricks
// whose lowest corner it holds, and those one point below it whose own leaf the coarse grid lacks.
openvdb::MaskGrid::Ptr bricksCrossed(const FloatGrid& coarse, float insideBelow, float outsideAbove) {
    using MaskLeaf = openvdb::MaskTree::LeafNodeType;
    std::vector<const FloatLeaf*> leaves;
    leaves.reserve(coarse.tree().leafCount());
    coarse.tree().getNodes(leaves);
    std::vector<MaskLeaf*> own(leaves.size(), nullptr);
    std::vector<std::vector<openvdb::Coord>> below(leaves.size());
    forEachBlock(leaves.size(), [&](std::size_t begin, std::size_t end) {
        // Per point of the leaf and the layer around it (index +1): 1 outside, 2 between, 4 inside.
        LeafNeighbourhood values(coarse.tree());
        std::uint8_t kind[10][10][10];
        for (std::size_t l = begin; l != end; ++l) {
            const openvdb::Coord o = leaves[l]->origin();
            values.gather(*leaves[l]);
            unsigned seen = 0;
            for (int i = -1; i <= 8; ++i)
                for (int j = -1; j <= 8; ++j)
                    for (int k = -1; k <= 8; ++k) {
                        const float value = values(i, j, k);
                        const std::uint8_t bits = value >= outsideAbove ? 1 : value <= insideBelow ? 4 : 2;
                        kind[i + 1][j + 1][k + 1] = bits;
                        seen |= bits;
                    }
            if (seen == 1 || seen == 4) continue;  // all outside or all inside
            bool leafBelow[2][2][2];  // whether the grid has the leaf 8 points lower along the axes marked 0
            for (int a = 0; a < 2; ++a)
                for (int b = 0; b < 2; ++b)
                    for (int c = 0; c < 2; ++c)
                        leafBelow[a][b][c] =
                            coarse.tree().probeConstLeaf(o.offsetBy(8 * (a - 1), 8 * (b - 1), 8 * (c - 1)));
            for (int i = -1; i < 8; ++i)
                for (int j = -1; j < 8; ++j)
                    for (int k = -1; k < 8; ++k) {
                        const bool ownBrick = i >= 0 && j >= 0 && k >= 0;
                        if (!ownBrick && leafBelow[i >= 0][j >= 0][k >= 0]) continue;  // its own leaf decides
                        unsigned bits = 0;
                        for (int corner = 0; corner < 8; ++corner)
                            bits |= kind[i + 1 + (corner >> 2)][j + 1 + ((corner >> 1) & 1)][k + 1 + (corner & 1)];
                        if (!(bits & 2u) && (bits & 5u) != 5u) continue;
                        if (!ownBrick) {
                            below[l].push_back(o.offsetBy(i, j, k));
                            continue;
                        }
                        if (!own[l]) own[l] = new MaskLeaf(o, false);
                        own[l]->setValueOn(openvdb::Index(i * 64 + j * 8 + k));
                    }
        }
    }, 8);
    openvdb::MaskGrid::Ptr mask = openvdb::MaskGrid::create();
    for (MaskLeaf* leaf : own)
        if (leaf) mask->tree().addLeaf(leaf);
    auto acc = mask->getAccessor();
    for (const auto& coords : below)
        for (const openvdb::Coord& m : coords) acc.setValueOn(m);
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

// A narrow band of half width `band` [m] from a grid of signed distances: voxels at or past it leave the band, and
// the inactive ones read as inside or outside by flood fill.
void keepBand(FloatGrid& grid, float band) {
    openvdb::tree::LeafManager<openvdb::FloatTree> leaves(grid.tree());
    leaves.foreach([&](FloatLeaf& leaf, std::size_t) { trimLeaf(leaf, band); });
    grid.tree().root().setBackground(band, false);
    openvdb::tools::pruneInactive(grid.tree());
    openvdb::tools::signedFloodFill(grid.tree());
}

// The fine leaves (lattice of spacing voxel) to evaluate: the coarse lattice's crossed bricks (bricksCrossed) and
// around them as far as the band reaches (its half width and one voxel for a gradient, in bricks of two voxels).
std::vector<LatticeLeaf> bricksNearSurface(const FloatGrid& coarse, float insideBelow, float outsideAbove,
                                           Real halfBand) {
    const openvdb::MaskGrid::Ptr bricks = bricksCrossed(coarse, insideBelow, outsideAbove);
    openvdb::tools::dilateActiveValues(bricks->tree(), int(std::ceil((halfBand + 1) / 2)),
                                       openvdb::tools::NN_FACE_EDGE_VERTEX, openvdb::tools::IGNORE_TILES);
    return fineLeaves(*bricks);
}

// The signed distance from a field g (iso minus kernel sum) on its active voxels: g over the length of its
// gradient, the distance to the surface to first order. Voxels within the half band stay active; the others take
// the background with their sign.
void fieldToDistance(FloatGrid& field, Real voxel, Real halfBand) {
    const float band = float(halfBand * voxel), inv2h = float(0.5 / voxel);
    openvdb::tree::LeafManager<openvdb::FloatTree> leaves(field.tree(), 1);
    forEachBlock(leaves.leafCount(), [&](std::size_t begin, std::size_t end) {
        LeafNeighbourhood g(field.tree());  // inactive points read NaN: no value there
        for (std::size_t l = begin; l != end; ++l) {
            const FloatLeaf& leaf = leaves.leaf(l);
            g.gather(leaf, true);
            float* out = leaves.getBuffer(l, 1).data();
            const float* in = leaf.buffer().data();
            for (int n = 0; n < 512; ++n) out[n] = in[n] < 0 ? -band : band;
#if defined(__AVX2__)
            // The same arithmetic as below, a row of eight at a time (the compiler left the loop scalar).
            const __m256 two = _mm256_set1_ps(2.f), halfStep = _mm256_set1_ps(inv2h), zero = _mm256_setzero_ps();
            const __m256 upper = _mm256_set1_ps(band), lower = _mm256_set1_ps(-band);
            const __m256i lanes = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
            for (int i = 0; i < 8; ++i)
                for (int j = 0; j < 8; ++j) {
                    const int active = leaf.getValueMask().getWord<std::uint8_t>(openvdb::Index(8 * i + j));
                    if (!active) continue;
                    const __m256 here = _mm256_loadu_ps(in + 64 * i + 8 * j);
                    const auto derivative = [&](const float* upRow, const float* downRow) {
                        const __m256 up = _mm256_loadu_ps(upRow), down = _mm256_loadu_ps(downRow);
                        const __m256 hasUp = _mm256_cmp_ps(up, up, _CMP_ORD_Q);
                        const __m256 hasDown = _mm256_cmp_ps(down, down, _CMP_ORD_Q);
                        const __m256 central = _mm256_mul_ps(_mm256_sub_ps(up, down), halfStep);
                        const __m256 forward = _mm256_mul_ps(_mm256_mul_ps(_mm256_sub_ps(up, here), two), halfStep);
                        const __m256 backward = _mm256_mul_ps(_mm256_mul_ps(_mm256_sub_ps(here, down), two), halfStep);
                        const __m256 oneSided = _mm256_blendv_ps(_mm256_and_ps(hasDown, backward), forward, hasUp);
                        return _mm256_blendv_ps(oneSided, central, _mm256_and_ps(hasUp, hasDown));
                    };
                    const __m256 dx = derivative(g.row(i + 1, j) + 1, g.row(i - 1, j) + 1);
                    const __m256 dy = derivative(g.row(i, j + 1) + 1, g.row(i, j - 1) + 1);
                    const __m256 dz = derivative(g.row(i, j) + 2, g.row(i, j));
                    const __m256 gradient2 = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(dx, dx), _mm256_mul_ps(dy, dy)),
                                                           _mm256_mul_ps(dz, dz));
                    const __m256 outside = _mm256_blendv_ps(upper, lower, _mm256_cmp_ps(here, zero, _CMP_LT_OQ));
                    __m256 distance = _mm256_blendv_ps(outside, _mm256_div_ps(here, _mm256_sqrt_ps(gradient2)),
                                                       _mm256_cmp_ps(gradient2, zero, _CMP_GT_OQ));
                    distance = _mm256_min_ps(_mm256_max_ps(distance, lower), upper);
                    const __m256 on = _mm256_castsi256_ps(
                        _mm256_cmpeq_epi32(_mm256_and_si256(_mm256_set1_epi32(active), lanes), lanes));
                    float* to = out + 64 * i + 8 * j;
                    _mm256_storeu_ps(to, _mm256_blendv_ps(_mm256_loadu_ps(to), distance, on));
                }
#else
            for (auto it = leaf.cbeginValueOn(); it; ++it) {
                const openvdb::Index n = it.pos();
                const int i = int(n >> 6), j = int((n >> 3) & 7), k = int(n & 7);
                const float here = in[n];
                // Central differences where both neighbours have values, one-sided where one has.
                auto derivative = [&](float up, float down) {
                    const bool hasUp = !std::isnan(up), hasDown = !std::isnan(down);
                    return hasUp && hasDown ? (up - down) * inv2h
                         : hasUp           ? (up - here) * 2 * inv2h
                         : hasDown         ? (here - down) * 2 * inv2h
                                           : 0.f;
                };
                const float dx = derivative(g(i + 1, j, k), g(i - 1, j, k));
                const float dy = derivative(g(i, j + 1, k), g(i, j - 1, k));
                const float dz = derivative(g(i, j, k + 1), g(i, j, k - 1));
                const float gradient2 = dx * dx + dy * dy + dz * dz;
                const float distance = gradient2 > 0 ? here / std::sqrt(gradient2) : (here < 0 ? -band : band);
                out[n] = std::clamp(distance, -band, band);
            }
#endif
        }
    }, 16);
    leaves.swapLeafBuffer(1);
    keepBand(field, band);
}

}  // namespace

FloatGrid::Ptr anisotropicLevelSet(const std::vector<Vec3>& x, Real r, Real voxel, Real halfBand) {
    // Half the value deep inside a lattice of spacing 2r: the surface lies midway between the last row of
    // particles and the next, unfilled one, i.e. where the lattice cells end, as for the other methods.
    const CubicSpline w(kKernelSupport * r);
    const Real interior = latticeShapeSum() * w.W0() * 8 * r * r * r;
    const std::vector<Ellipsoid> kernels = anisotropicKernels(x, r);
    const KernelBins coarseBins(kernels, 2 * voxel);
    // The coarse lattice only tells inside, outside and between apart: a leaf all inside is decided.
    const float insideBelow = float((0.5 - kSeedHigh) * interior), outsideAbove = float((0.5 - kSeedLow) * interior);
    const FloatGrid::Ptr coarse =
        kernelSum(kernels, coarseBins, leavesReached(coarseBins), r, 0.5 * interior, insideBelow);
    const std::vector<LatticeLeaf> fine = bricksNearSurface(*coarse, insideBelow, outsideAbove, halfBand);
    const FloatGrid::Ptr field = kernelSum(kernels, KernelBins(kernels, voxel), fine, r, 0.5 * interior);
    fieldToDistance(*field, voxel, halfBand);
    field->setGridClass(openvdb::GRID_LEVEL_SET);
    return field;
}

namespace {

// The narrow band of a field that is a distance near the surface, from round kernels of radius `support` around
// the particles: the field (field(spacing, far, settleBelow) for a lattice's spacing, the value where no kernel
// reaches, and the value below which it only matters that a value lies below it) on the coarse lattice, where only
// the sign matters, then on the fine one near the bricks whose corners lie on both sides of the surface, where every
// value past the band's inner edge ends as its half width. (Inside, these fields stay near minus a particle's size
// instead of growing like a distance, so the band cannot be chosen by their values.)
template <class MakeField>
FloatGrid::Ptr bandNearSurface(const std::vector<Vec3>& x, Real support, Real voxel, Real halfBand, MakeField&& field) {
    std::vector<Ellipsoid> kernels(x.size());
    const Eigen::Vector3f extent = extentAbove(Vec3::Constant(support));
    for (std::size_t i = 0; i < x.size(); ++i) kernels[i] = {x[i], Eigen::Matrix3f::Identity(), extent};
    const float band = float(halfBand * voxel), far = 2 * band;
    const KernelBins coarseBins(kernels, 2 * voxel);
    const FloatGrid::Ptr coarse =
        gatherRows(kernels, coarseBins, leavesReached(coarseBins), support, far, field(2 * voxel, far, 0.f));
    const std::vector<LatticeLeaf> targets = bricksNearSurface(*coarse, 0.f, 0.f, halfBand);  // on the sign alone
    const FloatGrid::Ptr fine =
        gatherRows(kernels, KernelBins(kernels, voxel), targets, support, far, field(voxel, far, -band));
    keepBand(*fine, band);
    fine->setGridClass(openvdb::GRID_LEVEL_SET);
    return fine;
}

}  // namespace

FloatGrid::Ptr smoothSpheresLevelSet(const std::vector<Vec3>& x, Real radius, Real search, Real voxel, Real halfBand) {
    return bandNearSurface(x, search, voxel, halfBand, [&](Real spacing, float far, float) {
        return AveragedSpheres(float(spacing), float(radius), far);
    });
}

FloatGrid::Ptr sphereUnionLevelSet(const std::vector<Vec3>& x, Real radius, Real voxel, Real halfBand) {
    const Real support = radius + halfBand * voxel;  // where a sphere's own distance leaves the band
    return bandNearSurface(x, support, voxel, halfBand, [&](Real, float far, float settleBelow) {
        return NearestSphere(float(support), float(radius), far, settleBelow);
    });
}

}  // namespace ganache::surfacing
