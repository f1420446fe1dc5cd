#include "physics/viscosity/coarse_space.h"

#include "core/parallel.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/OrderingMethods>
#include <Eigen/SparseCore>
#include <tbb/parallel_reduce.h>
#include <tbb/parallel_sort.h>
#if defined(__AVX2__) && defined(__FMA__)
#include <immintrin.h>
#endif

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace ganache {

namespace {

/// c -= a b, each entry's six products taken in order by fused multiply-adds. The factorisation spends its time here:
/// with AVX2 a column of c is a vector and a half, and the product takes a third of the time Eigen's took (13 against
/// 35 ns); the loops for targets without it round alike.
inline void subtractProduct(const Mat6& a, const Mat6& b, Mat6& c) {
#if defined(__AVX2__) && defined(__FMA__)
    __m256d top[6];
    __m128d bottom[6];
    for (int k = 0; k < 6; ++k) top[k] = _mm256_loadu_pd(&a(0, k)), bottom[k] = _mm_loadu_pd(&a(4, k));
    for (int j = 0; j < 6; ++j) {
        __m256d ct = _mm256_loadu_pd(&c(0, j));
        __m128d cb = _mm_loadu_pd(&c(4, j));
        for (int k = 0; k < 6; ++k) {
            ct = _mm256_fnmadd_pd(top[k], _mm256_set1_pd(b(k, j)), ct);
            cb = _mm_fnmadd_pd(bottom[k], _mm_set1_pd(b(k, j)), cb);
        }
        _mm256_storeu_pd(&c(0, j), ct);
        _mm_storeu_pd(&c(4, j), cb);
    }
#else
    for (int j = 0; j < 6; ++j)
        for (int k = 0; k < 6; ++k)
            for (int r = 0; r < 6; ++r) c(r, j) = std::fma(-a(r, k), b(k, j), c(r, j));
#endif
}

/// c += t b^T (Sign 1) or c -= t b^T (Sign -1), each entry by one fused multiply-add, as subtractProduct: the coarse
/// system's assembly takes one or two for each pair that crosses clusters.
template <int Sign>
inline void addOuter(const Vec6& t, const Vec6& b, Mat6& c) {
#if defined(__AVX2__) && defined(__FMA__)
    const __m256d top = _mm256_loadu_pd(t.data());
    const __m128d bottom = _mm_loadu_pd(t.data() + 4);
    for (int j = 0; j < 6; ++j) {
        const __m256d ct = _mm256_loadu_pd(&c(0, j));
        const __m128d cb = _mm_loadu_pd(&c(4, j));
        if constexpr (Sign > 0) {
            _mm256_storeu_pd(&c(0, j), _mm256_fmadd_pd(top, _mm256_set1_pd(b[j]), ct));
            _mm_storeu_pd(&c(4, j), _mm_fmadd_pd(bottom, _mm_set1_pd(b[j]), cb));
        } else {
            _mm256_storeu_pd(&c(0, j), _mm256_fnmadd_pd(top, _mm256_set1_pd(b[j]), ct));
            _mm_storeu_pd(&c(4, j), _mm_fnmadd_pd(bottom, _mm_set1_pd(b[j]), cb));
        }
    }
#else
    for (int j = 0; j < 6; ++j)
        for (int r = 0; r < 6; ++r) c(r, j) = std::fma(Sign * t[r], b[j], c(r, j));
#endif
}

Mat3 cross(const Vec3& a) {
    Mat3 m;
    m << 0, -a.z(), a.y(), a.z(), 0, -a.x(), -a.y(), a.x(), 0;
    return m;
}

/// Z_i^T d for a particle with arm a: the force d and its moment about the centre.
inline Vec6 rigidImage(const Vec3& a, const Vec3& d) {
    Vec6 u;
    u.head<3>() = d;
    u.tail<3>() = a.cross(d);
    return u;
}

/// sum_i Z_i^T Z_i for arms a_i: [[n I, -[sum a]x], [[sum a]x, sum (|a|^2 I - a a^T)]].
Mat6 identityPart(Real count, const Vec3& arms, const Mat3& second) {
    Mat6 e;
    e << count * Mat3::Identity(), -cross(arms), cross(arms), second.trace() * Mat3::Identity() - second;
    return e;
}

/// The power of two nearest to s > 0: the arms are offsets times its inverse, exact as a division by it would be, and
/// the CG passes that take each particle's arm multiply instead of dividing.
Real powerOfTwo(Real s) { return std::exp2(std::round(std::log2(s))); }

Mat6 boundaryPart(const Vec3& a, const Mat3& extra) {
    Eigen::Matrix<Real, 3, 6> z;
    z << Mat3::Identity(), -cross(a);
    return z.transpose() * extra * z;
}

constexpr int kAxisBits = 18;

/// The cell of x in a grid from the corner lo, 18 bits an axis, and the particle's group in the low 8 bits.
std::int64_t clusterKey(const Vec3& x, const Vec3& lo, Real cellSize, std::uint8_t group) {
    std::int64_t key = 0;
    for (int a = 0; a < 3; ++a) {
        const std::int64_t c = std::int64_t(std::floor((x[a] - lo[a]) / cellSize));
        if (c < 0 || c >= (std::int64_t(1) << kAxisBits))
            throw std::runtime_error("the fluid spans more than 2^18 cells of the viscosity coarse space");
        key = (key << kAxisBits) | c;
    }
    return (key << 8) | group;
}

/// The cell coordinates a clusterKey holds.
std::array<std::uint64_t, 3> keyCell(std::int64_t key) {
    constexpr std::int64_t kAxis = (std::int64_t(1) << kAxisBits) - 1;
    std::array<std::uint64_t, 3> c{};
    for (int a = 2; a >= 0; --a, key >>= kAxisBits) c[std::size_t(a)] = std::uint64_t(key >> 8 & kAxis);
    return c;
}

}  // namespace

void RigidModes::build(const std::vector<Vec3>& x, const sweeps::BoundaryBlocks& boundary, Real minScale) {
    const std::size_t n = x.size();
    m_centre = deterministicSum<Vec3>(n, [&](std::size_t i) { return x[i]; }, Vec3::Zero()) / Real(n);
    // The offsets from the centre and their second moments in one pass; the arms are those times m_inverseScale.
    using Moments = Eigen::Matrix<Real, 3, 4>;
    const Moments moments = deterministicSum<Moments>(n, [&](std::size_t i) -> Moments {
        const Vec3 d = x[i] - m_centre;
        Moments m;
        m << d * d.transpose(), d;
        return m;
    }, Moments::Zero());
    const Mat3 offsetSquares = moments.leftCols<3>();
    m_inverseScale = 1 / powerOfTwo(std::max(std::sqrt(offsetSquares.trace() / Real(n)), minScale));
    const Vec3 arms = moments.col(3) * m_inverseScale;
    const Mat3 second = offsetSquares * (m_inverseScale * m_inverseScale);
    // E = Z^T M Z = sum_i Z_i^T (I + extra_i) Z_i: the fluid's own coupling has the rigid motions in its null
    // space, so only the block-diagonal boundary part (when there is one) adds to the identity.
    Mat6 e = identityPart(Real(n), arms, second);
    e += deterministicSum<Mat6>(boundary.count, [&](std::size_t k) -> Mat6 {
        return boundaryPart(arm(x[boundary.particle[k]]), boundary.block[k]);
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
    // Once per CG iteration: plain sums over a block, which the compiler keeps in registers.
    return deterministicBlockSum<Vec6>(x.size(), [&](std::size_t begin, std::size_t end) {
        Vec6 y = Vec6::Zero();
        for (std::size_t i = begin; i < end; ++i) {
            const Vec3 m = moment(x[i], r[i]);
            for (int k = 0; k < 3; ++k) y[k] += r[i][k], y[3 + k] += m[k];
        }
        return y;
    }, Vec6::Zero());
}

void BlockLdlt::factor(const std::vector<std::vector<std::pair<std::uint32_t, Mat6>>>& rows) {
    const std::size_t m = rows.size();
    // Each off-diagonal block E[c, o] (c < o) from both ends: later[c] holds (o, E[c, o]), earlier[o] (c, E[c, o]).
    std::vector<std::vector<std::pair<std::uint32_t, const Mat6*>>> later(m), earlier(m);
    for (std::size_t c = 0; c < m; ++c)
        for (const auto& [o, block] : rows[c])
            if (o != c) later[c].emplace_back(o, &block), earlier[o].emplace_back(std::uint32_t(c), &block);

    // The elimination order: approximate minimum degree on the block graph.
    const Eigen::Index size = static_cast<Eigen::Index>(m);
    Eigen::SparseMatrix<Real> graph(size, size);
    std::vector<Eigen::Triplet<Real>> links;
    for (std::size_t c = 0; c < m; ++c) {
        links.emplace_back(int(c), int(c), 1);
        for (const auto& entry : later[c]) {
            links.emplace_back(int(entry.first), int(c), 1);
            links.emplace_back(int(c), int(entry.first), 1);
        }
    }
    graph.setFromTriplets(links.begin(), links.end());
    Eigen::PermutationMatrix<Eigen::Dynamic, Eigen::Dynamic, int> order;
    Eigen::AMDOrdering<int>()(graph, order);
    m_order.resize(m);
    std::vector<std::uint32_t> position(m);
    for (std::size_t k = 0; k < m; ++k) {
        m_order[k] = std::uint32_t(order.indices()[Eigen::Index(k)]);
        position[m_order[k]] = std::uint32_t(k);
    }

    // The elimination tree (Liu's algorithm with path compression).
    constexpr std::uint32_t kRoot = ~std::uint32_t(0);
    std::vector<std::uint32_t> parent(m, kRoot), ancestor(m, kRoot);
    auto earlierNeighbours = [&](std::size_t k, auto&& visit) {
        const std::uint32_t c = m_order[k];
        for (const auto& [o, block] : later[c])
            if (position[o] < k) visit(position[o], block->transpose());  // E[o, c] = E[c, o]^T
        for (const auto& [o, block] : earlier[c])
            if (position[o] < k) visit(position[o], *block);  // E[o, c], stored in o's row
    };
    for (std::size_t k = 0; k < m; ++k)
        earlierNeighbours(k, [&](std::uint32_t i, const auto&) {
            for (std::uint32_t r = i; r != kRoot && r != k;) {
                const std::uint32_t next = ancestor[r];
                ancestor[r] = std::uint32_t(k);
                if (next == kRoot) parent[r] = std::uint32_t(k);
                r = next;
            }
        });

    // Row k of L from E's column k above the diagonal, A_ik (i < k): Z_i = A_ik - sum_j L_ij Z_j in the order of the
    // elimination tree, L_ki = Z_i^T D_i^-1, D_k = A_kk - sum_i L_ki Z_i.
    std::vector<std::vector<std::pair<std::uint32_t, Mat6>>> columns(m);
    m_inverseDiagonal.resize(m);
    std::vector<Mat6> z(m, Mat6::Zero());
    std::vector<std::uint32_t> tag(m, kRoot), pattern(m), path(m);
    for (std::size_t k = 0; k < m; ++k) {
        std::size_t top = m;
        tag[k] = std::uint32_t(k);  // the walks up the tree stop at k
        earlierNeighbours(k, [&](std::uint32_t i, const auto& block) {
            z[i] = block;
            std::size_t length = 0;
            for (std::uint32_t r = i; tag[r] != k; r = parent[r]) path[length++] = r, tag[r] = std::uint32_t(k);
            while (length > 0) pattern[--top] = path[--length];
        });
        const std::uint32_t c = m_order[k];
        Mat6 d = rows[c].front().second;  // the diagonal block comes first: o ascending from c
        for (std::size_t t = top; t < m; ++t) {
            const std::uint32_t i = pattern[t];
            const Mat6 zi = z[i];
            z[i].setZero();
            for (const auto& [row, block] : columns[i]) subtractProduct(block, zi, z[row]);
            const Mat6 l = zi.transpose() * m_inverseDiagonal[i];
            subtractProduct(l, zi, d);
            columns[i].emplace_back(std::uint32_t(k), l);
        }
        // A pivot block of a cluster without rotations (one particle, or particles on a line) holds only the floor
        // there and may come out of round-off slightly indefinite: a pivoting LDL^T of the block keeps it usable.
        m_inverseDiagonal[k] = d.ldlt().solve(Mat6::Identity());
        if (!m_inverseDiagonal[k].allFinite())
            throw std::runtime_error("the viscosity coarse space could not be factored (a non-finite coefficient?); "
                                     "lower simulation.time_step.max");
    }
    m_first.assign(1, 0);
    m_row.clear();
    m_block.clear();
    for (const auto& column : columns) {
        for (const auto& [row, block] : column) m_row.push_back(row), m_block.push_back(block);
        m_first.push_back(std::uint32_t(m_row.size()));
    }
    m_work.resize(m);
}

void BlockLdlt::solve(Eigen::Matrix<Real, Eigen::Dynamic, 1>& b) const {
    const std::size_t m = m_order.size();
    for (std::size_t k = 0; k < m; ++k) m_work[k] = b.segment<6>(Eigen::Index(6 * m_order[k]));
    for (std::size_t k = 0; k < m; ++k)  // L y = b
        for (std::uint32_t e = m_first[k]; e < m_first[k + 1]; ++e)
            m_work[m_row[e]].noalias() -= m_block[e] * m_work[k];
    for (std::size_t k = 0; k < m; ++k) m_work[k] = m_inverseDiagonal[k] * m_work[k];  // D
    for (std::size_t k = m; k-- > 0;)  // L^T x = y
        for (std::uint32_t e = m_first[k]; e < m_first[k + 1]; ++e)
            m_work[k].noalias() -= m_block[e].transpose() * m_work[m_row[e]];
    for (std::size_t k = 0; k < m; ++k) b.segment<6>(Eigen::Index(6 * m_order[k])) = m_work[k];
}

void ClusterModes::build(const std::vector<Vec3>& x, const std::vector<std::uint8_t>* group, Real cellSize,
                         std::size_t maxClusters, const NeighbourList& fluid,
                         const sweeps::PairWeights& pairs, Real dt, const sweeps::BoundaryBlocks& boundary) {
    const std::size_t n = x.size();
    // The clusters: particles sorted by cell and group, then by index, so the order is the same for any thread count.
    // Cells grow until there are at most maxClusters, which bounds the cost of factoring E at high resolution; the
    // grid starts at the fluid's lowest corner, so that growing cells merge clusters.
    using Box = std::pair<Vec3, Vec3>;
    constexpr Real kInfinity = std::numeric_limits<Real>::infinity();
    const Box box = tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(0, n), Box(Vec3::Constant(kInfinity), Vec3::Constant(-kInfinity)),
        [&](const auto& r, Box b) {
            for (std::size_t i = r.begin(); i != r.end(); ++i) b = {b.first.cwiseMin(x[i]), b.second.cwiseMax(x[i])};
            return b;
        },
        [](const Box& a, const Box& b) { return Box(a.first.cwiseMin(b.first), a.second.cwiseMax(b.second)); });
    const Vec3& lo = box.first;
    // The groups present, numbered densely, for counting the occupied (cell, group) pairs.
    std::array<std::uint32_t, 256> groupIndex{};
    std::uint32_t groups = 0;
    {
        std::array<bool, 256> present{};
        if (group)
            for (std::uint8_t g : *group) present[g] = true;
        else
            present[0] = true;
        present[kNoCluster] = false;
        for (std::size_t g = 0; g < 256; ++g) groupIndex[g] = present[g] ? groups++ : 0;
    }
    constexpr std::int64_t kOutside = std::numeric_limits<std::int64_t>::max();  // sorts after every cluster
    std::vector<std::pair<std::int64_t, std::uint32_t>> keyed(n);
    auto computeKeys = [&] {
        forEachParticle(n, [&](std::size_t i) {
            const std::uint8_t g = group ? (*group)[i] : 0;
            keyed[i] = {g == kNoCluster ? kOutside : clusterKey(x[i], lo, cellSize, g), std::uint32_t(i)};
        });
    };
    // How many clusters cells of this size make: the occupied (cell, group) pairs marked on a table over the fluid's
    // box. Sorting the keys to count them, as the final order needs once, took four sorts a step at 1.1M particles
    // (20-25 ms each of a 240-330 ms build). Where the box holds more than a few cells a particle (a spray, fluid far
    // apart), clearing the table would cost more than sorting: there the keys are sorted.
    const std::uint64_t mostTableCells = 8 * std::uint64_t(n) + 65536;
    std::vector<std::uint8_t> occupied;
    auto countClusters = [&]() -> std::size_t {
        std::array<std::uint64_t, 3> cells{};
        std::uint64_t total = groups;  // at most 2^8 2^54: the keys hold 18 bits an axis
        for (std::size_t a = 0; a < 3; ++a) {
            cells[a] = std::uint64_t(std::floor((box.second[int(a)] - lo[int(a)]) / cellSize)) + 1;
            total *= cells[a];
        }
        if (total > mostTableCells) {
            std::vector<std::int64_t> keys(n);
            forEachParticle(n, [&](std::size_t i) { keys[i] = keyed[i].first; });
            tbb::parallel_sort(keys.begin(), keys.end());
            std::size_t count = 0;
            for (std::size_t k = 0; k < n && keys[k] != kOutside; ++k) count += k == 0 || keys[k] != keys[k - 1];
            return count;
        }
        occupied.assign(total, 0);
        for (const auto& [key, i] : keyed) {
            if (key == kOutside) continue;
            const auto c = keyCell(key);
            occupied[((c[0] * cells[1] + c[1]) * cells[2] + c[2]) * groups + groupIndex[std::size_t(key & 0xff)]] = 1;
        }
        return std::size_t(std::count(occupied.begin(), occupied.end(), std::uint8_t(1)));
    };
    for (computeKeys();; computeKeys()) {
        const std::size_t count = countClusters();
        if (count <= maxClusters) break;
        cellSize *= std::max(1.1, std::cbrt(Real(count) / Real(maxClusters)));
    }
    tbb::parallel_sort(keyed.begin(), keyed.end());
    const std::size_t inside = std::size_t(
        std::lower_bound(keyed.begin(), keyed.end(), std::make_pair(kOutside, std::uint32_t(0))) - keyed.begin());
    m_inverseScale = 1 / powerOfTwo(cellSize);  // arms within about +-1: E balanced between translations and rotations
    m_of.assign(n, kNone);
    m_members.resize(inside);
    m_firstMember.clear();
    for (std::size_t k = 0; k < inside; ++k) {
        if (k == 0 || keyed[k].first != keyed[k - 1].first) m_firstMember.push_back(std::uint32_t(k));
        m_members[k] = keyed[k].second;
        m_of[keyed[k].second] = std::uint32_t(m_firstMember.size() - 1);
    }
    const std::size_t clusters = m_firstMember.size();
    m_firstMember.push_back(std::uint32_t(inside));
    m_centre.resize(clusters);
    if (clusters == 0) return;
    forEachParticle(clusters, [&](std::size_t c) {
        Vec3 sum = Vec3::Zero();
        for (std::uint32_t k = m_firstMember[c]; k < m_firstMember[c + 1]; ++k) sum += x[m_members[k]];
        m_centre[c] = sum / Real(m_firstMember[c + 1] - m_firstMember[c]);
    });
    constexpr std::uint32_t kNoBlock = UINT32_MAX;  // each particle's entry in `boundary`
    std::vector<std::uint32_t> blockOf(boundary.count ? n : 0, kNoBlock);
    for (std::size_t k = 0; k < boundary.count; ++k) blockOf[boundary.particle[k]] = std::uint32_t(k);

    // Each cluster's row of E: its diagonal block and its blocks with the adjacent clusters.
    std::vector<std::vector<std::pair<std::uint32_t, Mat6>>> rows(clusters);
    forEachParticle(clusters, [&](std::size_t c) {
        Mat6 diagonal = Mat6::Zero();
        std::vector<std::pair<std::uint32_t, Mat6>> offDiagonal;
        std::size_t last = 0;  // the block of the previous pair, usually the one wanted again
        auto blockWith = [&](std::uint32_t other) -> Mat6& {
            if (last < offDiagonal.size() && offDiagonal[last].first == other) return offDiagonal[last].second;
            for (last = 0; last < offDiagonal.size(); ++last)
                if (offDiagonal[last].first == other) return offDiagonal[last].second;
            offDiagonal.emplace_back(other, Mat6::Zero());
            return offDiagonal.back().second;
        };
        Vec3 arms = Vec3::Zero();
        Mat3 second = Mat3::Zero();
        for (std::uint32_t k = m_firstMember[c]; k < m_firstMember[c + 1]; ++k) {
            const std::uint32_t i = m_members[k];
            const Vec3 ai = arm(c, x[i]);
            arms += ai;
            second += ai * ai.transpose();
            if (!blockOf.empty() && blockOf[i] != kNoBlock) diagonal += boundaryPart(ai, boundary.block[blockOf[i]]);
            for (std::size_t p = fluid.first(i); p < fluid.last(i); ++p) {
                const std::uint32_t j = fluid.indices[p];
                const std::uint32_t cj = m_of[j];
                if (cj == c) continue;  // a cluster's own pairs leave its rigid motions alone
                const Vec3 d = x[i] - x[j];
                const Real weight = -dt * pairs[p];  // the pair's share of (I - dt A), positive
                const Vec6 ui = rigidImage(ai, d), wi = weight * ui;
                addOuter<1>(wi, ui, diagonal);
                // One triangle is kept (BlockLdlt's rows): the blocks with clusters of a higher index.
                if (cj != kNone && cj > c) addOuter<-1>(wi, rigidImage(arm(cj, x[j]), d), blockWith(cj));
            }
        }
        const Real count = Real(m_firstMember[c + 1] - m_firstMember[c]);
        diagonal += identityPart(count, arms, second);
        // A lone particle has no rotations, particles on a line none about it: a floor far below round-off of the
        // rest keeps E definite. Those modes neither take part of r (Z^T r) nor give velocity (Z y), so the floor
        // changes nothing else.
        diagonal.bottomRightCorner<3, 3>().diagonal().array() += 1e-12 * diagonal.trace();
        rows[c].emplace_back(std::uint32_t(c), diagonal);
        rows[c].insert(rows[c].end(), offDiagonal.begin(), offDiagonal.end());
        std::sort(rows[c].begin(), rows[c].end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    });

    m_factor.factor(rows);
    m_rhs.resize(Eigen::Index(6 * clusters));
}

Real ClusterModes::solveFor(const std::vector<Vec3>& x, const std::vector<Vec3>& r) const {
    if (clusters() == 0) return 0;
    const auto rhs = [&](std::size_t c) { return m_rhs.segment<6>(Eigen::Index(6 * c)); };
    forEachParticle(clusters(), [&](std::size_t c) {
        Vec3 total = Vec3::Zero(), moment = Vec3::Zero();
        for (std::uint32_t k = m_firstMember[c]; k < m_firstMember[c + 1]; ++k) {
            const std::uint32_t i = m_members[k];
            total += r[i];
            moment += arm(c, x[i]).cross(r[i]);
        }
        rhs(c).head<3>() = total;
        rhs(c).tail<3>() = moment;
    }, 64);
    m_projection = m_rhs;
    m_factor.solve(m_rhs);
    // (Z^T r) . E^-1 Z^T r, summed over the clusters in a fixed order
    return deterministicSum(clusters(), [&](std::size_t c) {
        return m_projection.segment<6>(Eigen::Index(6 * c)).dot(rhs(c));
    });
}

void ClusterModes::addCorrection(const std::vector<Vec3>& x, const std::vector<Vec3>& r, std::vector<Vec3>& z) const {
    solveFor(x, r);
    forEachParticle(x.size(), [&](std::size_t i) { z[i] += velocity(i, x[i]); });
}

}  // namespace ganache
