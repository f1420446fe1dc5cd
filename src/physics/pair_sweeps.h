#pragma once
// The sweeps over neighbour pairs that every solver iteration makes. Each pair's geometry is computed once per step:
// the solvers pass per-pair weights in the order of the neighbour lists, and the sweeps only combine them with the
// current vectors. The boundary stands still during a solve and its particles carry no unknowns, so it enters as one
// sum per fluid particle, taken once a step, instead of its pairs.
//
// The sweeps read positions and inputs as Rows (four doubles, 32-byte aligned): one aligned load per neighbour brings
// its row. The viscous product takes four pairs at a time, their rows transposed into one vector per coordinate; the
// pressure sweeps one pair per vector, its lanes the coordinates. Vectors are AVX2's in the default build, with fused
// multiply-adds where a sum takes a product; elsewhere the same four lanes in plain C++ (std::fma for those), which
// round alike, so that both builds give the same bytes. A particle's sum is always taken in the same order, so
// results do not depend on the thread count.

#include "core/neighbour_search.h"
#include "core/types.h"

#include <cstddef>
#include <cstdint>
#include <vector>

namespace ganache::sweeps {

/// A particle's three components and a zero.
using Row = Eigen::Matrix<Real, 4, 1>;
using Rows = std::vector<Row>;

/// A pair's weight, stored in single precision: the sweeps stream a weight and an index a pair from memory at every
/// solver iteration, and the weights' last digits are far below any solver tolerance. The sweeps compute in double.
using PairWeight = float;
using PairWeights = std::vector<PairWeight>;

/// rows[i] = (v_i, 0) for i in [begin, end).
void toRows(std::size_t begin, std::size_t end, const Vec3* v, Row* rows);

/// Whether the sweeps over `list` that read `rows` arrays of rows at the neighbours prefetch them a few dozen pairs
/// ahead: only where those rows outgrow the caches (from about 130k particles for two arrays).
bool prefetches(const NeighbourList& list, int rows);

/// One neighbour list with a weight per pair (nullptr: the list takes no part).
struct Pairs {
    const NeighbourList* list = nullptr;
    const PairWeight* weight = nullptr;
};

/// The boundary's parts of the viscous operator's diagonal blocks, B_k = -dt sum_q kb_q x_ik x_ik^T, summed once a
/// step (the boundary stands still during a solve), for the particles that have one: particle[k] ascending, block[k]
/// its B. Only a fluid's layers next to a wall have one: a block for every particle would stream 72 bytes a particle
/// through each product for those few.
struct BoundaryBlocks {
    const std::uint32_t* particle = nullptr;
    const Mat3* block = nullptr;
    std::size_t count = 0;
};

/// For i in [begin, end): out_i = in_i - dt sum_p k_p (x_ij . (in_i - in_j)) x_ij + B_i in_i, the product
/// (I - dt A) in of the implicit viscosity [WKBB18 Eq. 7-11] with the bodies' velocities left out, B_i the boundary's
/// part of particle i's diagonal block (zero for a particle not in `boundary`).
void viscousProduct(std::size_t begin, std::size_t end, Pairs fluid, const BoundaryBlocks& boundary, const Row* x,
                    const Row* in, Real dt, Vec3* out);

/// viscousProduct for two inputs at once (one pass over the pairs): out1 = (I - dt A) in1, out2 = (I - dt A) in2.
void viscousProducts(std::size_t begin, std::size_t end, Pairs fluid, const BoundaryBlocks& boundary, const Row* x,
                     const Row* in1, const Row* in2, Real dt, Vec3* out1, Vec3* out2);
/// The same for three inputs.
void viscousProducts(std::size_t begin, std::size_t end, Pairs fluid, const BoundaryBlocks& boundary, const Row* x,
                     const Row* in1, const Row* in2, const Row* in3, Real dt, Vec3* out1, Vec3* out2, Vec3* out3);

/// For the pairs p of particles [begin, end): d2[p - list.first(begin)] = |x_ij|^2.
void squaredDistances(std::size_t begin, std::size_t end, const NeighbourList& list, const Row* x, Real* d2);

/// What a viscous pair's weight is made of [WKBB18 Eq. 7, 9]: k_ij = c (mu_i + mu_j) (m_i + m_j) g_ij shape /
/// ((d2 + eps) rho_i rho_j), with d2 = |x_ij|^2, shape = 1 + u (linear + u quadratic) and u = d2 inverseSpacing2 - 1.
struct ViscousWeightTerms {
    const Real* gradient = nullptr;        ///< g of each pair of the list, in its order
    const Real* mass = nullptr;            ///< m_i
    const Real* inverseDensity = nullptr;  ///< 1 / rho_i
    const Real* mu = nullptr;              ///< mu_i, or null: muConstant for every particle
    Real muConstant = 0;
    Real c = 0, eps = 0, inverseSpacing2 = 0, linear = 0, quadratic = 0;
};

/// For i in [begin, end): the weights k_p of its pairs, stored in single precision (pair p at weights[p]), and
/// blocks_i = sum_p k_p x_ij x_ij^T from the stored weights (the fluid's part of particle i's diagonal block of the
/// viscous operator, as the products apply it), in one pass over the pairs.
void viscousWeights(std::size_t begin, std::size_t end, const NeighbourList& list, const Row* x,
                    const ViscousWeightTerms& terms, PairWeight* weights, Mat3* blocks);

/// For i in [begin, end): the pressure pairs' weights w_p = m_j g_p, stored in single precision (pair p at
/// weights[p]), and sums[i - begin] = (sum_p g_p, sum_p |g_p|^2) with g_p = w_p x_ij, a pair's push (the DFSPH
/// factor's sums), its first three entries the vector, in one pass over the pairs.
void pressureWeights(std::size_t begin, std::size_t end, const NeighbourList& list, const Row* x, const Real* gradient,
                     const Real* mass, PairWeight* weights, Row* sums);

/// For i in [begin, end): rate_i = sum_p w_p (u_i - u_j) . x_ij + u_i . S_i - c_i, a density rate Drho/Dt with
/// w_p = m_j g_p, S_i = sum_q wb_q x_ik the boundary's weights summed once a step and c_i = sum_q wb_q ub_k . x_ik the
/// bodies' velocities' share (boundarySum, bodyRate null: none).
void densityRate(std::size_t begin, std::size_t end, Pairs fluid, const Vec3* boundarySum, const Real* bodyRate,
                 const Row* x, const Row* u, Real* rate);

/// For i in [begin, end): dv_i = -dt (sum_p w_p (s_i + s_j) x_ij + s_i S_i), the velocity change of the pressures s
/// [BK17], S_i as for densityRate; also as rows where dvRows is not null (what densityRate reads).
void pressureChange(std::size_t begin, std::size_t end, Pairs fluid, const Vec3* boundarySum, const Row* x,
                    const Real* s, Real dt, Vec3* dv, Row* dvRows = nullptr);

}  // namespace ganache::sweeps
