#pragma once
// A coarse space for the pressure solves: pressures constant over each cell of a grid a few particles across. The
// diagonally preconditioned solve moves a pressure about one particle layer per iteration, so a body landing needs
// more iterations the more layers it has; solving exactly for the cells' pressures carries the correction across the
// body at once.

#include "core/byte_stream.h"
#include "core/neighbour_search.h"
#include "physics/pair_sweeps.h"

#include <Eigen/SparseCholesky>

#include <array>
#include <cstdint>
#include <vector>

namespace ganache {

/// The pressure system's product (without its dt^2) is A s = C B s, with -dt B s the velocity change of the pressures
/// s and C u the density rate of the velocities u, both made of the pairs' pushes a_ij = w_ij x_ij and each particle's
/// G_i = sum_j a_ij plus its boundary sum. The coarse system is R A R^T, R summing the particles of each cell.
class PressureCoarseSpace {
public:
    static constexpr std::uint32_t kNone = ~std::uint32_t(0);

    /// Cells of side cellSize, at least two supports (then two neighbours' neighbours lie in the same or adjacent
    /// cells), larger where that would make more than maxCells; the pushes those of the pressure sweeps (pair weights
    /// w in the order of the fluid lists, positions as rows, G from gradientSum). Throws std::runtime_error where the
    /// coarse system cannot be factored (a non-finite weight).
    void build(const std::vector<Vec3>& x, const std::vector<Real>& mass, const NeighbourList& fluid,
               const sweeps::PairWeights& weights, const sweeps::Rows& xRows, const std::vector<Vec3>& gradientSum,
               Real cellSize, Real support, std::size_t maxCells);
    /// The particles' cells anew, for the system of the last build (a preconditioner need not follow every step):
    /// particles outside its cells get none.
    void assign(const std::vector<Vec3>& x);
    /// No coarse system.
    void clear();

    /// Whether there is a coarse system.
    bool active() const { return !m_coords.empty(); }
    std::size_t cells() const { return m_coords.size(); }
    /// Particle i's cell, or kNone.
    std::uint32_t cellOf(std::size_t i) const { return m_cellOf[i]; }
    /// b := (R A R^T)^-1 b, b holding a value per cell.
    void solve(Eigen::VectorXd& b) const { b = m_factor.solve(b); }

    /// The system as built (its cells and their rows), so that a resumed run solves with the same one.
    void save(ByteWriter& out) const;
    /// Throws std::runtime_error where the bytes cannot be a saved system.
    void restore(ByteReader& in);

private:
    // Factors the symmetric part of m_rows; a failure leaves no system.
    void factor();

    UniformGrid m_grid{1};
    std::vector<std::uint32_t> m_cellOf;
    std::vector<std::array<std::int32_t, 3>> m_coords;  // each cell's grid coordinates, in the grid's order
    std::vector<std::array<Real, 27>> m_rows;           // A_c by row, its columns by offset (-1, 0, 1 an axis)
    Eigen::SimplicialLDLT<Eigen::SparseMatrix<Real>, Eigen::Lower> m_factor;
};

}  // namespace ganache
