#pragma once
// Neighbourhood search on a uniform grid with cell-sorted particles (compact hashing after Ihmsen et al.
// 2011, "A parallel SPH implementation on multi-core CPUs"). TBB-parallel and deterministic: the lists do
// not depend on the thread count.

#include "core/types.h"

#include <algorithm>
#include <array>
#include <cstdint>
#include <utility>
#include <vector>

namespace ganache {

/// Neighbour lists in compressed rows: the neighbours of query particle i are
/// indices[offsets[i] .. offsets[i+1]), in a fixed order that does not depend on the thread count.
struct NeighbourList {
    struct Range {
        const std::uint32_t* first;
        const std::uint32_t* last;
        const std::uint32_t* begin() const { return first; }
        const std::uint32_t* end() const { return last; }
        std::size_t size() const { return std::size_t(last - first); }
    };

    std::vector<std::uint64_t> offsets{0};
    std::vector<std::uint32_t> indices;

    std::size_t particles() const { return offsets.size() - 1; }
    /// Pair p of particle i runs over offsets[i] .. offsets[i+1]; per-pair data is kept in that order.
    std::size_t first(std::size_t i) const { return std::size_t(offsets[i]); }
    std::size_t last(std::size_t i) const { return std::size_t(offsets[i + 1]); }
    std::size_t pairs() const { return indices.size(); }
    Range of(std::size_t i) const { return {indices.data() + offsets[i], indices.data() + offsets[i + 1]}; }

    /// findNeighbours' working memory, kept from one search to the next: memory freed and taken again every step
    /// went back to the system and was faulted in anew (1,400 page faults a step on a 50k block, 5-8 % of its time).
    struct Scratch {
        std::vector<std::vector<std::uint32_t>> chunks;
        std::vector<std::uint32_t> count, chunkOf, localStart;
    } scratch;
};

/// A uniform grid of cubic cells over one point set. Cells are addressed by absolute integer coordinates
/// floor(x / cellSize), so two grids with the same cell size line up (fluid and boundary grids). Points are
/// sorted cell by cell, which is also the locality order for reordering. The cells are in row order (the occupied
/// cells' longest side slowest) where a slab of cells three thick across the other two sides holds at most
/// kSlabPoints points, else in Z (Morton) order: a sweep over the points then finds the neighbours' values it read a
/// slab before still in the core's own cache, where Z order takes them from far back at each of its large steps.
class UniformGrid {
public:
    /// Cell coordinates must lie within +-kMaxCell on every axis (about +-10 km at a 1 cm cell).
    static constexpr std::int64_t kMaxCell = (std::int64_t(1) << 20) - 2;
    /// Row order up to this many points in three slabs of cells. A solver sweep reads two rows of 32 bytes at each
    /// neighbour; 32k points' are 2 MiB, two to four times a current core's level-2 cache, which the slab's pairs
    /// share. Measured on the block landing of the anchors (1 thread): 50k particles (8k in three slabs) 8-19 % less
    /// time a step in row order than in Z order, 195k (20k) 1-6 % less; a 1M blob (60k in three slabs, 2 threads)
    /// 2-4 % more (docs/benchmarks.md, "Cells in row order").
    static constexpr std::size_t kSlabPoints = 32768;

    /// slabPoints with which a grid keeps Z order for any point set.
    static constexpr std::size_t kAlwaysZOrder = 0;
    /// slabPoints with which a grid takes row order for any point set it can hold.
    static constexpr std::size_t kAlwaysRowOrder = std::size_t(1) << 40;

    /// slabPoints: kSlabPoints, kAlwaysZOrder (for consumers that walk space in blocks, as OpenVDB's trees do),
    /// kAlwaysRowOrder, or another bound for row order (at most 2^40).
    explicit UniformGrid(Real cellSize, std::size_t slabPoints = kSlabPoints);

    /// Sorts the points into cells. Throws std::runtime_error for a non-finite point or one outside the
    /// addressable range, naming its index.
    void build(const std::vector<Vec3>& x);

    /// Frees build()'s working memory, which it keeps for the next build (a grid rebuilt every step would otherwise
    /// allocate it anew each time, and fault it in again): for a grid built once, whose memory counts while it lives.
    void releaseWorkingMemory();

    Real cellSize() const { return m_cellSize; }
    std::size_t slabPoints() const { return m_slabPoints; }
    std::size_t pointCount() const { return m_sorted.size(); }
    std::size_t cellCount() const { return m_cellKeys.size(); }

    /// Point indices, cell by cell, cells in the grid's order: a locality-preserving permutation of the points.
    const std::vector<std::uint32_t>& sortedIndices() const { return m_sorted; }

    /// Coordinate `axis` of the points in sorted order, as they were when the grid was built.
    const std::vector<Real>& sortedCoords(int axis) const { return m_sortedCoords[std::size_t(axis)]; }

    /// The sorted points of cell c are sortedIndices()[cellBegin(c) .. cellBegin(c + 1)).
    std::size_t cellBegin(std::size_t c) const { return m_cellBegin[c]; }
    /// Integer coordinates of cell c.
    const std::array<std::int32_t, 3>& cellCoords(std::size_t c) const { return m_cellCoords[c]; }
    /// Whether any of the 27 cells around this one can hold a point (it lies within one cell of the occupied cells'
    /// bounding box).
    bool mayHoldAround(const std::array<std::int32_t, 3>& cell) const;
    /// Index of the occupied cell with these coordinates, or -1 when it holds no point.
    std::int64_t findCell(std::int64_t cx, std::int64_t cy, std::int64_t cz) const;
    /// Whether cells are found through a dense table over the occupied cells' bounding box (compact point sets)
    /// rather than through the hash (sparse ones).
    bool dense() const { return !m_denseCells.empty(); }
    /// The dense table: cell index + 1 (0: empty) at denseSlot(); valid where dense().
    const std::uint32_t* denseCells() const { return m_denseCells.data(); }
    /// Where a cell lies in the dense table: any cell within kDenseMargin of the occupied cells' bounding box.
    std::size_t denseSlot(std::int64_t cx, std::int64_t cy, std::int64_t cz) const {
        return std::size_t(((cz - m_denseMin[2]) * m_denseSize[1] + (cy - m_denseMin[1])) * m_denseSize[0] +
                           (cx - m_denseMin[0]));
    }
    /// How far apart in the dense table two cells one apart along `axis` lie.
    std::size_t denseStride(int axis) const {
        return std::size_t(axis == 0 ? 1 : axis == 1 ? m_denseSize[0] : m_denseSize[0] * m_denseSize[1]);
    }
    /// Whether the cells are in row order rather than Z order.
    bool rowOrder() const { return m_rowOrder; }
    /// The axis along which neighbouring cells follow each other in the sorted order where both hold points: in row
    /// order the fastest, in Z order x (the lowest bit of a Morton key is x's, so half of such cells do).
    int fastAxis() const { return m_fastAxis; }

private:
    /// Chooses the cells' order for a build of n points whose cells span [lo, hi].
    void chooseOrder(std::size_t n, const std::array<std::int64_t, 3>& lo, const std::array<std::int64_t, 3>& hi);
    /// The sort key of a cell; in row order only for cells within the box the order was chosen for.
    std::uint64_t key(std::int64_t cx, std::int64_t cy, std::int64_t cz) const;

    Real m_cellSize;
    std::size_t m_slabPoints;
    bool m_rowOrder = false;
    int m_fastAxis = 0;
    std::array<std::int64_t, 3> m_rowMin{}, m_rowSize{};  // row order: the box the keys cover
    std::array<int, 3> m_rowShift{};                      // row order: where each axis's offset in the box goes
    std::vector<std::uint32_t> m_sorted;
    std::vector<std::pair<std::uint64_t, std::uint32_t>> m_keyed;  // build()'s (cell key, point), kept between builds
    std::vector<std::pair<std::uint64_t, std::uint32_t>> m_keyedScratch;  // sortByKey's other buffer
    std::array<std::vector<Real>, 3> m_sortedCoords;  // the points' coordinates in sorted order
    std::vector<std::uint64_t> m_cellKeys;   // sort keys of the occupied cells, ascending
    std::vector<std::uint32_t> m_cellBegin;  // cellCount() + 1 offsets into m_sorted
    std::vector<std::array<std::int32_t, 3>> m_cellCoords;
    std::array<std::int64_t, 3> m_cellMin{}, m_cellMax{};  // the occupied cells' bounding box
    std::vector<std::uint64_t> m_tableKeys;  // open-addressing hash: sort key -> cell index
    std::vector<std::uint32_t> m_tableCells;
    int m_tableBits = 0;
    // How many cells the dense table reaches past the occupied cells' bounding box: the cells around a cell within one
    // of the box (mayHoldAround) lie within two.
    static constexpr std::int64_t kDenseMargin = 2;
    // Dense lookup: cell index + 1 (0: empty) for every cell of the box [m_denseMin, m_denseMin + m_denseSize).
    std::vector<std::uint32_t> m_denseCells;
    std::array<std::int64_t, 3> m_denseMin{};
    std::array<std::int64_t, 3> m_denseSize{};
};

/// Sorts (key, index) pairs by key, pairs of equal keys in the order they came in (a stable radix sort; `scratch` is
/// its other buffer, kept by the caller between sorts): with indices ascending in `items`, the order of std::sort.
void sortByKey(std::vector<std::pair<std::uint64_t, std::uint32_t>>& items,
               std::vector<std::pair<std::uint64_t, std::uint32_t>>& scratch);

/// Bit b of the result: whether candidate b < lanes (at most 64) from x, y, z lies closer than sqrt(r2) to (xi, yi,
/// zi). The arrays hold lanes values rounded up to a multiple of 4 (past the last candidate, values too far for any
/// test); only those are read: a cell's last word of candidates is mostly empty.
std::uint64_t closer64(const Real* x, const Real* y, const Real* z, int lanes, Real xi, Real yi, Real zi, Real r2);

/// The points of the 27 cells of a grid around one cell (given by its coordinates, so it may be a cell of another
/// grid with the same cell size) as runs of the grid's sorted points: cells z slowest, then y, x fastest (the grid's
/// fast axis fastest where it is not x), and cells that follow each other in the sorted order joined into one run.
struct CellRuns {
    std::size_t from[27], to[27];
    int count = 0;

    void find(const UniformGrid& grid, const std::array<std::int32_t, 3>& cell);
    /// How many points the runs hold.
    std::size_t points() const;
    /// Where sorted point s, which one of the runs holds, comes among the runs' points.
    std::size_t positionOf(std::size_t s) const;
};

/// The points of the 27 cells of a grid around one cell, coordinates apart so that closer64 tests them 64 at a time;
/// past `count`, up to a multiple of 4, values too far for any test. Kept between gathers: it only grows.
struct CellCandidates {
    std::vector<Real> x, y, z;
    std::vector<std::uint32_t> index;  // each point's index in the set the grid was built from
    std::size_t count = 0;

    void gather(const UniformGrid& grid, const std::array<std::int32_t, 3>& cell);
    /// The points of these runs of the grid's, in their order.
    void gather(const UniformGrid& grid, const CellRuns& runs);
    /// Words of 64 candidates to test.
    std::size_t words() const { return (count + 63) / 64; }
    /// The candidates in word w, closer64's lanes.
    int lanes(std::size_t w) const { return int(std::min<std::size_t>(64, count - 64 * w)); }
};

/// Finds, for every query point i, the target points j with |x_i - x_j| < radius. With sameSet the query
/// and target are one set (and one grid) and i is not its own neighbour. Both grids must have cell size >= radius and
/// be built from queryX and targetX respectively. Each list is in CellRuns' order of the target's points.
void findNeighbours(const UniformGrid& queryGrid, const std::vector<Vec3>& queryX, const UniformGrid& targetGrid,
                    const std::vector<Vec3>& targetX, Real radius, bool sameSet, NeighbourList& out);

/// Fluid-fluid lists: builds `grid` from x and finds the neighbours of each point among the others.
void findFluidNeighbours(UniformGrid& grid, const std::vector<Vec3>& x, Real radius, NeighbourList& out);

}  // namespace ganache
