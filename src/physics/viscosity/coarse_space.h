#pragma once
// Coarse spaces for the implicit viscosity solve (I - dt A) v = b of weiler2018. The viscous coupling between fluid
// particles leaves rigid motion alone (Eq. 7 is zero for it), so a stiff fluid's slowest modes are the rigid
// motions of its parts, which the 3x3 block Jacobi preconditioner barely moves. Solving for them exactly, on the
// whole fluid (RigidModes) or on each cluster of nearby particles (ClusterModes), removes those modes from CG.

#include "core/neighbour_search.h"
#include "physics/pair_sweeps.h"

#include <cstdint>
#include <vector>

namespace ganache {

using Vec6 = Eigen::Matrix<Real, 6, 1>;
using Mat6 = Eigen::Matrix<Real, 6, 6>;

/// The rigid motions of all fluid particles together (three translations, three rotations about their centroid).
/// Within this space the system is the identity plus the (block-diagonal) boundary part.
class RigidModes {
public:
    /// boundary: the boundary part of the system's diagonal block for the particles that have one.
    void build(const std::vector<Vec3>& x, const sweeps::BoundaryBlocks& boundary, Real minScale);
    /// Z^T r: the total of r and its moment about the centroid.
    Vec6 project(const std::vector<Vec3>& x, const std::vector<Vec3>& r) const;
    /// The moment of ri at xi: particle i's share of project()'s last three entries (the first three are ri).
    Vec3 moment(const Vec3& xi, const Vec3& ri) const { return arm(xi).cross(ri); }
    /// (Z^T M Z)^+ y: the rigid motion whose image under the system has the projection y.
    Vec6 solve(const Vec6& y) const { return m_inverse * y; }
    /// The velocity of the rigid motion y at position xi.
    Vec3 velocity(const Vec6& y, const Vec3& xi) const { return y.head<3>() + y.tail<3>().cross(arm(xi)); }

private:
    Vec3 arm(const Vec3& xi) const { return (xi - m_centre) * m_inverseScale; }  // scaled to keep Z^T M Z balanced

    Vec3 m_centre = Vec3::Zero();
    Real m_inverseScale = 1;  // a power of two
    Mat6 m_inverse = Mat6::Zero();
};

/// LDL^T of a symmetric positive definite matrix of 6x6 blocks with a sparse block pattern (the coarse system E):
/// the blocks ordered by approximate minimum degree on the block graph, then factored row by row (up-looking), every
/// operation a product of 6x6 blocks. A scalar sparse Cholesky of the same matrix spent its time on indices.
class BlockLdlt {
public:
    /// rows[c]: the blocks (o, E[c, o]) of row c with o >= c (one triangle; E[o, c] = E[c, o]^T), the diagonal block
    /// first, o ascending. Throws std::runtime_error where a pivot block cannot be inverted (a non-finite coefficient).
    void factor(const std::vector<std::vector<std::pair<std::uint32_t, Mat6>>>& rows);
    /// E^-1 b for b of 6 entries a block, in place.
    void solve(Eigen::Matrix<Real, Eigen::Dynamic, 1>& b) const;

private:
    std::vector<std::uint32_t> m_order;  // the block eliminated k-th
    std::vector<Mat6> m_inverseDiagonal;  // D_k^-1
    // L's blocks below the diagonal by column in elimination order, k ascending: column c's are the entries
    // [m_first[c], m_first[c + 1]) of m_row (k) and m_block (L_kc).
    std::vector<std::uint32_t> m_first, m_row;
    std::vector<Mat6> m_block;
    mutable std::vector<Vec6> m_work;
};

/// The rigid motions of each cluster of fluid particles, the clusters being the cells of a grid (split by group where
/// groups are given). The coarse system E = Z^T M Z has a 6x6 block per pair of adjacent clusters; it is assembled
/// from the pairs that cross clusters (pairs within one cluster do not act on its rigid motions) and factored by
/// BlockLdlt.
class ClusterModes {
public:
    /// A group that keeps its particles out of every cluster (their rows of Z are zero).
    static constexpr std::uint8_t kNoCluster = 255;

    /// Clusters are the cells of side cellSize, larger where that would make more than maxClusters; particles of
    /// different groups (null: one group) never share a cluster. The system (I - dt A): fluid pairs with Eq. 7's
    /// coefficient k_ij in the order of the neighbour lists (the off-diagonal block of pair ij is dt k_ij x_ij x_ij^T),
    /// and the boundary part of the diagonal block for the particles that have one.
    void build(const std::vector<Vec3>& x, const std::vector<std::uint8_t>* group, Real cellSize,
               std::size_t maxClusters, const NeighbourList& fluid, const sweeps::PairWeights& pairs, Real dt,
               const sweeps::BoundaryBlocks& boundary);
    /// Finds the clusters' rigid motions E^-1 Z^T r, the exact answer within them, and returns r . Z E^-1 Z^T r.
    Real solveFor(const std::vector<Vec3>& x, const std::vector<Vec3>& r) const;
    /// The velocity at particle i, at xi, of the motions solveFor() found last (zero outside the clusters).
    Vec3 velocity(std::size_t i, const Vec3& xi) const {
        const std::uint32_t c = m_of[i];
        if (c == kNone) return Vec3::Zero();
        const auto y = m_rhs.segment<6>(Eigen::Index(6 * c));
        return y.head<3>() + y.tail<3>().cross(arm(c, xi));
    }
    /// z += Z E^-1 Z^T r.
    void addCorrection(const std::vector<Vec3>& x, const std::vector<Vec3>& r, std::vector<Vec3>& z) const;
    std::size_t clusters() const { return m_centre.size(); }

private:
    Vec3 arm(std::size_t c, const Vec3& xi) const { return (xi - m_centre[c]) * m_inverseScale; }

    Real m_inverseScale = 1;  // a power of two
    static constexpr std::uint32_t kNone = ~std::uint32_t(0);
    std::vector<std::uint32_t> m_of;                      // each particle's cluster, or kNone
    std::vector<std::uint32_t> m_members, m_firstMember;  // the particles of cluster c, ascending
    std::vector<Vec3> m_centre;
    BlockLdlt m_factor;
    mutable Eigen::Matrix<Real, Eigen::Dynamic, 1> m_rhs;         // Z^T r, then the motions solveFor() found
    mutable Eigen::Matrix<Real, Eigen::Dynamic, 1> m_projection;  // Z^T r, kept for r . Z E^-1 Z^T r
};

}  // namespace ganache
