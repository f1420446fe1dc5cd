#include "physics/pressure/pressure_coarse.h"

#include "core/parallel.h"

#include <Eigen/OrderingMethods>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace ganache {

namespace {

// A cell's neighbours by offset (-1, 0 or 1 on each axis) as an index 0..26, 9 dx + 3 dy + dz + 13; 13 is the cell
// itself, 26 - k the opposite of k.
std::array<std::int32_t, 3> offsetBy(const std::array<std::int32_t, 3>& from, int slot) {
    return {from[0] + slot / 9 - 1, from[1] + slot / 3 % 3 - 1, from[2] + slot % 3 - 1};
}

}  // namespace

void PressureCoarseSpace::clear() {
    m_coords.clear();
    m_rows.clear();
    m_cellOf.clear();
}

void PressureCoarseSpace::build(const std::vector<Vec3>& x, const std::vector<Real>& mass,
                                const NeighbourList& fluid, const sweeps::PairWeights& weights,
                                const sweeps::Rows& xRows, const std::vector<Vec3>& gradientSum, Real cellSize,
                                Real support, std::size_t maxCells) {
    if (!(cellSize >= 2 * support)) throw std::logic_error("PressureCoarseSpace: cells narrower than two supports");
    const std::size_t n = x.size();
    clear();
    // Cells grow until there are at most maxCells: the simplicial factorisation's cost grows about as the square of
    // the cells in three dimensions.
    for (;;) {
        // A restored grid was built in a fixed order (see restore): from here on the order is the particles' choice.
        if (m_grid.cellSize() != cellSize || m_grid.slabPoints() != UniformGrid::kSlabPoints)
            m_grid = UniformGrid(cellSize);
        m_grid.build(x);
        if (m_grid.cellCount() <= maxCells) break;
        cellSize *= std::max(1.1, std::cbrt(Real(m_grid.cellCount()) / Real(maxCells)));
    }
    const std::size_t cells = m_grid.cellCount();
    if (cells < 2) return;  // one cell: the diagonal's own business
    m_cellOf.resize(n);
    const auto& sorted = m_grid.sortedIndices();
    for (std::size_t c = 0; c < cells; ++c) {
        m_coords.push_back(m_grid.cellCoords(c));
        for (std::size_t s = m_grid.cellBegin(c); s < m_grid.cellBegin(c + 1); ++s)
            m_cellOf[sorted[s]] = std::uint32_t(c);
    }

    // A_c[I, K] = sum_l (sum_{i in I} C_il) . (sum_{k in K} B_lk), with B_ll = C_ll = G_l, B_lj = a_lj and C_jl =
    // -a_jl = (m_l / m_j) a_lj: for each particle l, its pushes summed by the cell they come from, then their products.
    // Taken particle by particle in order, so the sums do not depend on the thread count.
    bool sameMass = true;
    for (std::size_t i = 1; i < n && sameMass; ++i) sameMass = mass[i] == mass[0];
    m_rows.assign(cells, {});
    const Real inverse = 1 / cellSize;
    std::array<Vec3, 27> b, c;
    b.fill(Vec3::Zero());
    c.fill(Vec3::Zero());
    std::array<std::uint32_t, 27> around{};  // the cells around the last home cell
    std::uint32_t lastHome = kNone;
    for (std::size_t l = 0; l < n; ++l) {
        const std::uint32_t homeCell = m_cellOf[l];
        const auto& home = m_coords[homeCell];
        if (homeCell != lastHome) {
            lastHome = homeCell;
            for (int k = 0; k < 27; ++k) {
                const auto to = offsetBy(home, k);
                const std::int64_t g = m_grid.findCell(to[0], to[1], to[2]);
                around[std::size_t(k)] = g < 0 ? kNone : std::uint32_t(g);
            }
        }
        // The neighbours come cell by cell of the fluid grid, so mostly in runs from one of these cells: the pushes
        // are summed over each run and added to its cell's slot where the run ends.
        std::uint32_t touched = 0;  // a bit per slot
        int current = 13;
        Vec3 runB = gradientSum[l], runC = gradientSum[l];
        auto flush = [&] {
            touched |= std::uint32_t(1) << current;
            b[std::size_t(current)] += runB;
            c[std::size_t(current)] += runC;
        };
        for (std::size_t p = fluid.first(l); p < fluid.last(l); ++p) {
            const std::uint32_t j = fluid.indices[p];
            const sweeps::Row& xj = xRows[j];  // a reference: a copy stalled on its store
            const sweeps::Row d = xRows[l] - xj;
            const Vec3 a = Real(weights[p]) * Vec3(d[0], d[1], d[2]);
            int t = 0;  // the slot of j's cell, by the grid's own floor(x / cellSize)
            for (int axis = 0; axis < 3; ++axis)
                t = 3 * t + int(std::floor(xj[axis] * inverse)) - home[std::size_t(axis)] + 1;
            if (t != current) {
                flush();
                current = t;
                runB = runC = Vec3::Zero();
            }
            runB += a;
            runC += sameMass ? a : Vec3((mass[l] / mass[j]) * a);
        }
        flush();
        for (std::uint32_t bits = touched; bits != 0; bits &= bits - 1) {
            const int u = __builtin_ctz(bits);
            auto& row = m_rows[around[std::size_t(u)]];
            for (std::uint32_t other = touched; other != 0; other &= other - 1) {
                const int v = __builtin_ctz(other);
                // v's cell seen from u's
                row[std::size_t(13 + 9 * (v / 9 - u / 9) + 3 * (v / 3 % 3 - u / 3 % 3) + (v % 3 - u % 3))] +=
                    c[std::size_t(u)].dot(b[std::size_t(v)]);
            }
        }
        for (std::uint32_t bits = touched; bits != 0; bits &= bits - 1) {
            const auto u = std::size_t(__builtin_ctz(bits));
            b[u] = c[u] = Vec3::Zero();
        }
    }
    factor();
}

void PressureCoarseSpace::factor() {
    // The lower triangle of the symmetric part. A cell whose particles have no neighbours at all (a drop thrown off
    // alone: the bunny of Table 2 at 5 ms steps) has an empty row, a zero pivot. Its particles take no pressure, so
    // its right-hand side is always zero and any diagonal solves it: it gets the system's largest.
    const std::size_t cells = m_coords.size();
    Real largest = 0;
    for (const auto& row : m_rows) largest = std::max(largest, row[13]);
    std::vector<Eigen::Triplet<Real>> entries;
    for (std::size_t r = 0; r < cells; ++r)
        for (int k = 0; k < 27; ++k) {
            Real value = m_rows[r][std::size_t(k)];
            if (k == 13 && value == 0) value = largest > 0 ? largest : 1;
            if (value == 0) continue;
            const auto to = offsetBy(m_coords[r], k);
            const std::int64_t column = m_grid.findCell(to[0], to[1], to[2]);
            if (column < 0 || std::size_t(column) > r) continue;
            const Real mirror = m_rows[std::size_t(column)][std::size_t(26 - k)];
            entries.emplace_back(int(r), int(column), Real(0.5) * (value + mirror));
        }
    const auto size = static_cast<Eigen::Index>(cells);
    Eigen::SparseMatrix<Real> a(size, size);
    a.setFromTriplets(entries.begin(), entries.end());
    m_factor.compute(a);
    if (m_factor.info() != Eigen::Success) {
        clear();
        throw std::runtime_error("the pressure coarse space could not be factored; lower simulation.time_step.max, "
                                 "or set simulation.pressure.coarse_from above the particle count to do without it");
    }
}

void PressureCoarseSpace::assign(const std::vector<Vec3>& x) {
    m_cellOf.resize(x.size());
    if (!active()) return;
    const Real inverse = 1 / m_grid.cellSize();
    forEachParticle(x.size(), [&](std::size_t i) {
        const Vec3 c = (x[i] * inverse).array().floor();
        const std::int64_t g = m_grid.findCell(std::int64_t(c.x()), std::int64_t(c.y()), std::int64_t(c.z()));
        m_cellOf[i] = g < 0 ? kNone : std::uint32_t(g);
    });
}

void PressureCoarseSpace::save(ByteWriter& out) const {
    out(m_grid.cellSize());
    std::vector<std::int32_t> coords;
    std::vector<Real> rows;
    for (std::size_t c = 0; c < m_coords.size(); ++c) {
        coords.insert(coords.end(), m_coords[c].begin(), m_coords[c].end());
        rows.insert(rows.end(), m_rows[c].begin(), m_rows[c].end());
    }
    out(coords);
    out(rows);
}

void PressureCoarseSpace::restore(ByteReader& in) {
    Real cellSize = 0;
    std::vector<std::int32_t> coords;
    std::vector<Real> rows;
    in(cellSize), in(coords), in(rows);
    const std::size_t cells = coords.size() / 3;
    if (!(cellSize > 0) || !std::isfinite(cellSize) || coords.size() != 3 * cells || rows.size() != 27 * cells)
        throw std::runtime_error("its pressure coarse space is malformed");
    if (cells == 0) {
        clear();
        return;
    }
    // The grid from the cells' centres: the same cells. The build's grid took Z order or row order by how many
    // particles it held (UniformGrid::kSlabPoints), which the cells alone do not say, so the one of the two orders
    // that lists them as saved is it. Checked before anything is replaced.
    std::vector<Vec3> centres(cells);
    for (std::size_t c = 0; c < cells; ++c)
        for (int a = 0; a < 3; ++a) {
            if (std::abs(std::int64_t(coords[3 * c + std::size_t(a)])) > UniformGrid::kMaxCell)
                throw std::runtime_error("its pressure coarse space has a cell out of range");
            centres[c][a] = (Real(coords[3 * c + std::size_t(a)]) + Real(0.5)) * cellSize;
        }
    auto listsAsSaved = [&](const UniformGrid& grid) {
        if (grid.cellCount() != cells) throw std::runtime_error("its pressure coarse space repeats a cell");
        for (std::size_t c = 0; c < cells; ++c)
            if (!std::equal(grid.cellCoords(c).begin(), grid.cellCoords(c).end(),
                            coords.begin() + std::ptrdiff_t(3 * c)))
                return false;
        return true;
    };
    UniformGrid grid(cellSize, UniformGrid::kAlwaysRowOrder);
    grid.build(centres);
    if (!listsAsSaved(grid)) {
        grid = UniformGrid(cellSize, UniformGrid::kAlwaysZOrder);
        grid.build(centres);
        if (!listsAsSaved(grid)) throw std::runtime_error("its pressure coarse space's cells are out of order");
    }
    clear();
    m_grid = std::move(grid);
    m_rows.resize(cells);
    for (std::size_t c = 0; c < cells; ++c) {
        m_coords.push_back(m_grid.cellCoords(c));
        std::copy_n(rows.begin() + std::ptrdiff_t(27 * c), 27, m_rows[c].begin());
    }
    factor();
}

}  // namespace ganache
