#include "physics/viscosity/coarse_space.h"

#include "core/parallel.h"

#include <Eigen/Eigenvalues>
#include <tbb/parallel_sort.h>

#include <array>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace ganache {

namespace {

Mat3 cross(const Vec3& a) {
    Mat3 m;
    m << 0, -a.z(), a.y(), a.z(), 0, -a.x(), -a.y(), a.x(), 0;
    return m;
}

/// Z_i^T d for a particle with arm a: the force d and its moment about the centre.
Vec6 rigidImage(const Vec3& a, const Vec3& d) {
    Vec6 u;
    u << d, a.cross(d);
    return u;
}

/// sum_i Z_i^T Z_i for arms a_i: [[n I, -[sum a]x], [[sum a]x, sum (|a|^2 I - a a^T)]].
Mat6 identityPart(Real count, const Vec3& arms, const Mat3& second) {
    Mat6 e;
    e << count * Mat3::Identity(), -cross(arms), cross(arms), second.trace() * Mat3::Identity() - second;
    return e;
}

Mat6 boundaryPart(const Vec3& a, const Mat3& extra) {
    Eigen::Matrix<Real, 3, 6> z;
    z << Mat3::Identity(), -cross(a);
    return z.transpose() * extra * z;
}

/// The cell of x in a grid from the corner lo, packed in 21 bits an axis.
std::int64_t packCell(const Vec3& x, const Vec3& lo, Real cellSize) {
    std::int64_t key = 0;
    for (int a = 0; a < 3; ++a) {
        const std::int64_t c = std::int64_t(std::floor((x[a] - lo[a]) / cellSize));
        if (c < 0 || c >= (std::int64_t(1) << 21))
            throw std::runtime_error("the fluid spans more than 2^21 cells of the viscosity coarse space");
        key = (key << 21) | c;
    }
    return key;
}

std::array<std::int64_t, 3> unpackCell(std::int64_t key) {
    constexpr std::int64_t mask = (std::int64_t(1) << 21) - 1;
    return {(key >> 42) & mask, (key >> 21) & mask, key & mask};
}

}  // namespace

void RigidModes::build(const std::vector<Vec3>& x, const std::vector<Mat3>* extra,
                       const std::vector<std::uint32_t>& withExtra, Real minScale) {
    const std::size_t n = x.size();
    m_centre = deterministicSum<Vec3>(n, [&](std::size_t i) { return x[i]; }, Vec3::Zero()) / Real(n);
    const Real spread = deterministicSum(n, [&](std::size_t i) { return (x[i] - m_centre).squaredNorm(); });
    m_scale = std::max(std::sqrt(spread / Real(n)), minScale);
    // E = Z^T M Z = sum_i Z_i^T (I + extra_i) Z_i: the fluid's own coupling has the rigid motions in its null
    // space, so only the block-diagonal boundary part (when there is one) adds to the identity.
    const Vec3 arms = deterministicSum<Vec3>(n, [&](std::size_t i) { return arm(x[i]); }, Vec3::Zero());
    const Mat3 second = deterministicSum<Mat3>(n, [&](std::size_t i) -> Mat3 {
        const Vec3 a = arm(x[i]);
        return a * a.transpose();
    }, Mat3::Zero());
    Mat6 e = identityPart(Real(n), arms, second);
    if (extra)
        e += deterministicSum<Mat6>(withExtra.size(), [&](std::size_t k) -> Mat6 {
            const std::uint32_t i = withExtra[k];
            return boundaryPart(arm(x[i]), (*extra)[i]);
        }, Mat6::Zero());
    // Pseudo-inverse: a lone particle has no rotations, particles on a line none about that line.
    const Eigen::SelfAdjointEigenSolver<Mat6> eigen(e);
    const Vec6 values = eigen.eigenvalues();
    Vec6 inverted = Vec6::Zero();
    for (int k = 0; k < 6; ++k)
        if (values[k] > 1e-10 * values.maxCoeff()) inverted[k] = 1 / values[k];
    m_inverse = eigen.eigenvectors() * inverted.asDiagonal() * eigen.eigenvectors().transpose();
}

Vec6 RigidModes::project(const std::vector<Vec3>& x, const std::vector<Vec3>& r) const {
    return deterministicSum<Vec6>(x.size(), [&](std::size_t i) -> Vec6 { return rigidImage(arm(x[i]), r[i]); },
                                  Vec6::Zero());
}

void ClusterModes::build(const std::vector<Vec3>& x, Real cellSize, std::size_t maxClusters, const NeighbourList& fluid,
                         const std::vector<Real>& pairs, Real dt, const std::vector<Mat3>* extra,
                         const std::vector<std::uint32_t>& withExtra) {
    const std::size_t n = x.size();
    // The clusters: particles sorted by cell, then by index, so the order is the same for any thread count. Cells
    // grow until there are at most maxClusters, which bounds the cost of factoring E at high resolution.
    // The grid starts at the fluid's lowest corner, so that growing cells merge clusters.
    const Vec3 lo = tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(0, n), Vec3(Vec3::Constant(std::numeric_limits<Real>::infinity())),
        [&](const auto& r, Vec3 m) {
            for (std::size_t i = r.begin(); i != r.end(); ++i) m = m.cwiseMin(x[i]);
            return m;
        },
        [](const Vec3& a, const Vec3& b) -> Vec3 { return a.cwiseMin(b); });
    std::vector<std::pair<std::int64_t, std::uint32_t>> keyed(n);
    for (;;) {
        forEachParticle(n, [&](std::size_t i) { keyed[i] = {packCell(x[i], lo, cellSize), std::uint32_t(i)}; });
        tbb::parallel_sort(keyed.begin(), keyed.end());
        std::size_t count = n > 0 ? 1 : 0;
        for (std::size_t k = 1; k < n; ++k) count += keyed[k].first != keyed[k - 1].first;
        if (count <= maxClusters) break;
        cellSize *= std::max(1.1, std::cbrt(Real(count) / Real(maxClusters)));
    }
    m_scale = cellSize;  // arms within +-1 keep E balanced between translations and rotations
    m_of.resize(n);
    m_members.resize(n);
    m_firstMember.clear();
    m_cell.clear();
    for (std::size_t k = 0; k < n; ++k) {
        if (k == 0 || keyed[k].first != keyed[k - 1].first) {
            m_firstMember.push_back(std::uint32_t(k));
            m_cell.push_back(keyed[k].first);
        }
        m_members[k] = keyed[k].second;
        m_of[keyed[k].second] = std::uint32_t(m_cell.size() - 1);
    }
    m_firstMember.push_back(std::uint32_t(n));
    const std::size_t clusters = m_cell.size();
    m_centre.resize(clusters);
    forEachParticle(clusters, [&](std::size_t c) {
        Vec3 sum = Vec3::Zero();
        for (std::uint32_t k = m_firstMember[c]; k < m_firstMember[c + 1]; ++k) sum += x[m_members[k]];
        m_centre[c] = sum / Real(m_firstMember[c + 1] - m_firstMember[c]);
    });
    std::vector<char> hasExtra;
    if (extra) {
        hasExtra.assign(n, 0);
        for (std::uint32_t i : withExtra) hasExtra[i] = 1;
    }

    // Each cluster's row of E: its 6x6 blocks with the up to 26 adjacent clusters, kept by cell offset (slot 13 is
    // the cluster itself). Only the lower triangle (neighbours with a higher index) is stored.
    struct Row {
        std::array<std::uint32_t, 27> neighbour;
        std::array<Mat6, 27> block;
    };
    constexpr std::uint32_t kNone = ~std::uint32_t(0);
    std::vector<std::vector<std::pair<std::uint32_t, Mat6>>> rows(clusters);
    forEachParticle(clusters, [&](std::size_t c) {
        Row row;
        row.neighbour.fill(kNone);
        for (Mat6& b : row.block) b.setZero();
        row.neighbour[13] = std::uint32_t(c);
        const auto cell = unpackCell(m_cell[c]);
        Vec3 arms = Vec3::Zero();
        Mat3 second = Mat3::Zero();
        for (std::uint32_t k = m_firstMember[c]; k < m_firstMember[c + 1]; ++k) {
            const std::uint32_t i = m_members[k];
            const Vec3 ai = arm(c, x[i]);
            arms += ai;
            second += ai * ai.transpose();
            if (extra && hasExtra[i]) row.block[13] += boundaryPart(ai, (*extra)[i]);
            for (std::size_t p = fluid.first(i); p < fluid.last(i); ++p) {
                const std::uint32_t j = fluid.indices[p];
                const std::uint32_t cj = m_of[j];
                if (cj == c) continue;  // a cluster's own pairs leave its rigid motions alone
                const auto other = unpackCell(m_cell[cj]);
                int slot = 0;
                for (int a = 0; a < 3; ++a) {
                    const std::int64_t step = other[a] - cell[a];
                    if (step < -1 || step > 1)
                        throw std::logic_error("viscosity coarse space: a pair spans more than one cluster cell");
                    slot = 3 * slot + int(step + 1);
                }
                row.neighbour[slot] = cj;
                const Vec3 d = x[i] - x[j];
                const Real weight = -dt * pairs[p];  // the pair's share of (I - dt A), positive
                const Vec6 ui = rigidImage(ai, d);
                row.block[13].noalias() += (weight * ui) * ui.transpose();
                row.block[slot].noalias() -= (weight * ui) * rigidImage(arm(cj, x[j]), d).transpose();
            }
        }
        const Real count = Real(m_firstMember[c + 1] - m_firstMember[c]);
        row.block[13] += identityPart(count, arms, second);
        // A lone particle has no rotations, particles on a line none about it: a floor far below round-off of the
        // rest keeps E definite. Those modes neither take part of r (Z^T r) nor give velocity (Z y), so the floor
        // changes nothing else.
        row.block[13].bottomRightCorner<3, 3>().diagonal().array() += 1e-12 * row.block[13].trace();
        for (int s = 0; s < 27; ++s)
            if (row.neighbour[s] != kNone && row.neighbour[s] >= c) rows[c].emplace_back(row.neighbour[s], row.block[s]);
        std::sort(rows[c].begin(), rows[c].end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    });

    // Column c of the lower triangle holds E[other, c] = E[c, other]^T for the stored blocks of row c; filled in order,
    // so every insertion appends.
    const Eigen::Index size = Eigen::Index(6 * clusters);
    Eigen::SparseMatrix<Real> e(size, size);
    Eigen::VectorXi perColumn(size);
    for (std::size_t c = 0; c < clusters; ++c) perColumn.segment<6>(Eigen::Index(6 * c)).setConstant(int(6 * rows[c].size()));
    e.reserve(perColumn);
    for (std::size_t c = 0; c < clusters; ++c)
        for (int col = 0; col < 6; ++col)
            for (const auto& [other, block] : rows[c])
                for (int r = 0; r < 6; ++r) {
                    if (other == c && r < col) continue;
                    e.insert(Eigen::Index(6 * other + r), Eigen::Index(6 * c + col)) = block(col, r);
                }
    e.makeCompressed();
    m_factor.compute(e);
    if (m_factor.info() != Eigen::Success)
        throw std::runtime_error("the viscosity coarse space could not be factored (a non-finite coefficient?); "
                                 "lower simulation.time_step.max");
    m_rhs.resize(size);
}

void ClusterModes::addCorrection(const std::vector<Vec3>& x, const std::vector<Vec3>& r, std::vector<Vec3>& z) const {
    forEachParticle(clusters(), [&](std::size_t c) {
        Vec6 y = Vec6::Zero();
        for (std::uint32_t k = m_firstMember[c]; k < m_firstMember[c + 1]; ++k) {
            const std::uint32_t i = m_members[k];
            y += rigidImage(arm(c, x[i]), r[i]);
        }
        m_rhs.segment<6>(Eigen::Index(6 * c)) = y;
    }, 64);
    const Eigen::Matrix<Real, Eigen::Dynamic, 1> motion = m_factor.solve(m_rhs);
    forEachParticle(x.size(), [&](std::size_t i) {
        const std::size_t c = m_of[i];
        const Vec6 y = motion.segment<6>(Eigen::Index(6 * c));
        z[i] += y.head<3>() + y.tail<3>().cross(arm(c, x[i]));
    });
}

}  // namespace ganache
