#include "core/neighbour_search.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <cmath>
#include <stdexcept>
#include <string>

namespace ganache {

namespace {

constexpr std::uint64_t kEmpty = ~std::uint64_t(0);
constexpr std::int64_t kBias = std::int64_t(1) << 20;  // shifts cell coordinates into 21 unsigned bits

// Spreads the low 21 bits of v so that they occupy every third bit.
std::uint64_t spreadBits(std::uint64_t v) {
    v &= 0x1fffff;
    v = (v | v << 32) & 0x1f00000000ffffULL;
    v = (v | v << 16) & 0x1f0000ff0000ffULL;
    v = (v | v << 8) & 0x100f00f00f00f00fULL;
    v = (v | v << 4) & 0x10c30c30c30c30c3ULL;
    v = (v | v << 2) & 0x1249249249249249ULL;
    return v;
}

std::uint64_t mortonKey(std::int64_t cx, std::int64_t cy, std::int64_t cz) {
    return spreadBits(std::uint64_t(cx + kBias)) | spreadBits(std::uint64_t(cy + kBias)) << 1 |
           spreadBits(std::uint64_t(cz + kBias)) << 2;
}

std::uint64_t hashSlot(std::uint64_t key, int bits) { return (key * 0x9E3779B97F4A7C15ULL) >> (64 - bits); }

}  // namespace

UniformGrid::UniformGrid(Real cellSize) : m_cellSize(cellSize) {
    if (!(cellSize > 0) || !std::isfinite(cellSize))
        throw std::invalid_argument("UniformGrid: cell size must be positive and finite");
}

void UniformGrid::build(const std::vector<Vec3>& x) {
    const std::size_t n = x.size();
    if (n >= std::size_t(UINT32_MAX)) throw std::runtime_error("neighbour search: more than 4 billion points");
    const Real inv = 1 / m_cellSize;

    std::vector<std::pair<std::uint64_t, std::uint32_t>> keyed(n);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 4096), [&](const auto& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            const Vec3 c = (x[i] * inv).array().floor();
            if (!c.allFinite() || c.cwiseAbs().maxCoeff() > Real(kMaxCell))
                throw std::runtime_error("neighbour search: point " + std::to_string(i) +
                                         (x[i].allFinite() ? " lies too far from the origin for the grid"
                                                           : " has a non-finite position"));
            keyed[i] = {mortonKey(std::int64_t(c.x()), std::int64_t(c.y()), std::int64_t(c.z())),
                        std::uint32_t(i)};
        }
    });
    // (key, index) pairs are unique, so the sorted order is the same for any thread count.
    tbb::parallel_sort(keyed.begin(), keyed.end());

    m_sorted.resize(n);
    m_cellKeys.clear();
    m_cellBegin.clear();
    m_cellCoords.clear();
    for (std::size_t s = 0; s < n; ++s) {
        m_sorted[s] = keyed[s].second;
        if (s == 0 || keyed[s].first != keyed[s - 1].first) {
            m_cellKeys.push_back(keyed[s].first);
            m_cellBegin.push_back(std::uint32_t(s));
            const Vec3 c = (x[keyed[s].second] * inv).array().floor();
            m_cellCoords.push_back({std::int32_t(c.x()), std::int32_t(c.y()), std::int32_t(c.z())});
        }
    }
    m_cellBegin.push_back(std::uint32_t(n));

    m_tableBits = 4;
    while ((std::size_t(1) << m_tableBits) < 2 * m_cellKeys.size()) ++m_tableBits;
    m_tableKeys.assign(std::size_t(1) << m_tableBits, kEmpty);
    m_tableCells.assign(std::size_t(1) << m_tableBits, 0);
    const std::uint64_t mask = (std::uint64_t(1) << m_tableBits) - 1;
    for (std::size_t c = 0; c < m_cellKeys.size(); ++c) {
        std::uint64_t slot = hashSlot(m_cellKeys[c], m_tableBits);
        while (m_tableKeys[slot] != kEmpty) slot = (slot + 1) & mask;
        m_tableKeys[slot] = m_cellKeys[c];
        m_tableCells[slot] = std::uint32_t(c);
    }
}

std::int64_t UniformGrid::findCell(std::int64_t cx, std::int64_t cy, std::int64_t cz) const {
    if (m_cellKeys.empty()) return -1;
    if (std::abs(cx) > kMaxCell + 1 || std::abs(cy) > kMaxCell + 1 || std::abs(cz) > kMaxCell + 1) return -1;
    const std::uint64_t key = mortonKey(cx, cy, cz);
    const std::uint64_t mask = (std::uint64_t(1) << m_tableBits) - 1;
    for (std::uint64_t slot = hashSlot(key, m_tableBits);; slot = (slot + 1) & mask) {
        if (m_tableKeys[slot] == key) return m_tableCells[slot];
        if (m_tableKeys[slot] == kEmpty) return -1;
    }
}

void findNeighbours(const UniformGrid& queryGrid, const std::vector<Vec3>& queryX, const UniformGrid& targetGrid,
                    const std::vector<Vec3>& targetX, Real radius, bool sameSet, NeighbourList& out) {
    if (queryGrid.cellSize() < radius || targetGrid.cellSize() != queryGrid.cellSize())
        throw std::logic_error("findNeighbours: grids need one cell size, at least the search radius");
    if (queryGrid.pointCount() != queryX.size() || targetGrid.pointCount() != targetX.size())
        throw std::logic_error("findNeighbours: a grid was built from another point set");

    const std::size_t n = queryX.size();
    const Real r2 = radius * radius;
    const auto& qSorted = queryGrid.sortedIndices();
    const auto& tSorted = targetGrid.sortedIndices();

    struct Candidate {
        Vec3 x;
        std::uint32_t j;
    };
    tbb::enumerable_thread_specific<std::vector<Candidate>> scratch;

    // One pass: chunks of query cells write their particles' lists into their own buffers (fixed chunk
    // boundaries, so the result is the same for any thread count); a second, cheap pass copies each list
    // to its place in particle order.
    constexpr std::size_t kCellsPerChunk = 64;
    const std::size_t cells = queryGrid.cellCount();
    const std::size_t chunks = (cells + kCellsPerChunk - 1) / kCellsPerChunk;
    std::vector<std::vector<std::uint32_t>> buffers(chunks);
    std::vector<std::uint32_t> count(n), chunkOf(n), localStart(n);

    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, chunks, 1), [&](const auto& range) {
        auto& candidates = scratch.local();
        for (std::size_t chunk = range.begin(); chunk != range.end(); ++chunk) {
            auto& buffer = buffers[chunk];
            const std::size_t lastCell = std::min(cells, (chunk + 1) * kCellsPerChunk);
            for (std::size_t c = chunk * kCellsPerChunk; c < lastCell; ++c) {
                const auto& cc = queryGrid.cellCoords(c);
                candidates.clear();
                for (int dz = -1; dz <= 1; ++dz)
                    for (int dy = -1; dy <= 1; ++dy)
                        for (int dx = -1; dx <= 1; ++dx) {
                            const std::int64_t t = targetGrid.findCell(cc[0] + dx, cc[1] + dy, cc[2] + dz);
                            if (t < 0) continue;
                            for (std::size_t s = targetGrid.cellBegin(t); s < targetGrid.cellBegin(t + 1); ++s)
                                candidates.push_back({targetX[tSorted[s]], tSorted[s]});
                        }
                for (std::size_t s = queryGrid.cellBegin(c); s < queryGrid.cellBegin(c + 1); ++s) {
                    const std::uint32_t i = qSorted[s];
                    const Vec3 xi = queryX[i];
                    chunkOf[i] = std::uint32_t(chunk);
                    localStart[i] = std::uint32_t(buffer.size());
                    for (const Candidate& cand : candidates)
                        if ((xi - cand.x).squaredNorm() < r2 && !(sameSet && cand.j == i)) buffer.push_back(cand.j);
                    count[i] = std::uint32_t(buffer.size() - localStart[i]);
                }
            }
        }
    });

    out.offsets.resize(n + 1);
    out.offsets[0] = 0;
    for (std::size_t i = 0; i < n; ++i) out.offsets[i + 1] = out.offsets[i] + count[i];
    out.indices.resize(out.offsets[n]);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 4096), [&](const auto& range) {
        for (std::size_t i = range.begin(); i != range.end(); ++i)
            std::copy_n(buffers[chunkOf[i]].data() + localStart[i], count[i], out.indices.data() + out.offsets[i]);
    });
}

void findFluidNeighbours(UniformGrid& grid, const std::vector<Vec3>& x, Real radius, NeighbourList& out) {
    grid.build(x);
    findNeighbours(grid, x, grid, x, radius, true, out);
}

}  // namespace ganache
