#include "core/neighbour_search.h"

#include "core/memory.h"
#include "core/parallel.h"

#include <tbb/enumerable_thread_specific.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>

#if defined(__AVX2__)
#include <immintrin.h>
#endif

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

// Whether points lie closer than sqrt(r2) to (px, py, pz): the same squared distance in both versions, so the same
// neighbours with and without AVX2.
#if defined(__AVX2__)
inline int closer4(__m256d px, __m256d py, __m256d pz, __m256d r2, __m256d x, __m256d y, __m256d z) {
    const __m256d ex = _mm256_sub_pd(px, x), ey = _mm256_sub_pd(py, y), ez = _mm256_sub_pd(pz, z);
    const __m256d d2 =
        _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(ex, ex), _mm256_mul_pd(ey, ey)), _mm256_mul_pd(ez, ez));
    return _mm256_movemask_pd(_mm256_cmp_pd(d2, r2, _CMP_LT_OQ));
}
#else
inline bool closer1(Real px, Real py, Real pz, Real r2, Real x, Real y, Real z) {
    const Real ex = px - x, ey = py - y, ez = pz - z;
    return ex * ex + ey * ey + ez * ez < r2;
}
#endif

#if defined(__AVX2__)
// The byte shuffle that packs the 32-bit lanes set in a 4-bit mask to the front.
struct PackTable {
    alignas(16) std::uint8_t bytes[16][16];
    PackTable() {
        for (int m = 0; m < 16; ++m) {
            int k = 0;
            for (int lane = 0; lane < 4; ++lane)
                if (m >> lane & 1)
                    for (int b = 0; b < 4; ++b) bytes[m][k++] = std::uint8_t(4 * lane + b);
            for (; k < 16; ++k) bytes[m][k] = 0x80;
        }
    }
};
const PackTable kPack;
#endif

// Appends to dst the indices idx[s] of the points s in [from, to) closer than sqrt(r2) to p, but for s == skip, and
// returns how many. dst needs room for to - from + 4: whole groups of four are stored.
std::size_t appendCloser(const Real* x, const Real* y, const Real* z, const std::uint32_t* idx, std::size_t from,
                         std::size_t to, const Vec3& p, Real r2, std::size_t skip, std::uint32_t* dst) {
    std::size_t found = 0;
#if defined(__AVX2__)
    const __m256d px = _mm256_set1_pd(p.x()), py = _mm256_set1_pd(p.y()), pz = _mm256_set1_pd(p.z());
    const __m256d r = _mm256_set1_pd(r2);
    const auto closer = [&](__m256d ex, __m256d ey, __m256d ez) { return closer4(px, py, pz, r, ex, ey, ez); };
    const auto append = [&](std::size_t s, int bits, __m128i ids) {
        if (skip - s < 4) bits &= ~(1 << (skip - s));
        const __m128i order = _mm_load_si128(reinterpret_cast<const __m128i*>(kPack.bytes[bits]));
        _mm_storeu_si128(reinterpret_cast<__m128i*>(dst + found), _mm_shuffle_epi8(ids, order));
        found += std::size_t(__builtin_popcount(unsigned(bits)));
    };
    std::size_t s = from;
    for (; s + 4 <= to; s += 4)
        append(s, closer(_mm256_loadu_pd(x + s), _mm256_loadu_pd(y + s), _mm256_loadu_pd(z + s)),
               _mm_loadu_si128(reinterpret_cast<const __m128i*>(idx + s)));
    if (s < to) {  // the last one to three points, loaded under a mask: the arrays end at `to` or soon after
        const __m256i lanes =
            _mm256_cmpgt_epi64(_mm256_set1_epi64x(std::int64_t(to - s)), _mm256_set_epi64x(3, 2, 1, 0));
        const int valid = (1 << (to - s)) - 1;
        append(s,
               closer(_mm256_maskload_pd(x + s, lanes), _mm256_maskload_pd(y + s, lanes),
                      _mm256_maskload_pd(z + s, lanes)) & valid,
               _mm_maskload_epi32(reinterpret_cast<const int*>(idx + s),
                                  _mm_cmpgt_epi32(_mm_set1_epi32(int(to - s)), _mm_set_epi32(3, 2, 1, 0))));
    }
#else
    for (std::size_t s = from; s != to; ++s) {
        dst[found] = idx[s];
        found += closer1(p.x(), p.y(), p.z(), r2, x[s], y[s], z[s]) && s != skip;
    }
#endif
    return found;
}

}  // namespace

std::uint64_t closer64(const Real* x, const Real* y, const Real* z, int lanes, Real xi, Real yi, Real zi, Real r2) {
    std::uint64_t bits = 0;
#if defined(__AVX2__)
    const __m256d px = _mm256_set1_pd(xi), py = _mm256_set1_pd(yi), pz = _mm256_set1_pd(zi), r = _mm256_set1_pd(r2);
    for (int b = 0; b < lanes; b += 4)
        bits |= std::uint64_t(closer4(px, py, pz, r, _mm256_loadu_pd(x + b), _mm256_loadu_pd(y + b),
                                      _mm256_loadu_pd(z + b)))
                << b;
#else
    for (int b = 0; b < lanes; ++b) bits |= std::uint64_t(closer1(xi, yi, zi, r2, x[b], y[b], z[b])) << b;
#endif
    return bits;
}

void CellRuns::find(const UniformGrid& grid, const std::array<std::int32_t, 3>& cell) {
    count = 0;
    if (!grid.mayHoldAround(cell)) return;  // a fluid cell far from every wall: no lookups
    const int f = grid.fastAxis();
    const int outer = f == 2 ? 1 : 2, inner = f == 0 ? 1 : 0;  // of the other two axes, z before y before x
    // Appends cell `found` (-1: none) to the runs; `last` the cell found before it along the fast axis.
    const auto add = [&](std::int64_t found, std::int64_t& last) {
        if (found < 0) return;
        if (found == last + 1) {
            to[count - 1] = grid.cellBegin(std::size_t(found) + 1);
        } else {
            from[count] = grid.cellBegin(std::size_t(found));
            to[count] = grid.cellBegin(std::size_t(found) + 1);
            ++count;
        }
        last = found;
    };
    if (grid.dense()) {  // the table's margin holds every cell around this one: one load a cell, no tests
        const std::uint32_t* table = grid.denseCells();
        const std::size_t at = grid.denseSlot(cell[0], cell[1], cell[2]);
        std::ptrdiff_t step[3];
        for (int a = 0; a < 3; ++a) step[a] = std::ptrdiff_t(grid.denseStride(a));
        for (int d0 = -1; d0 <= 1; ++d0)
            for (int d1 = -1; d1 <= 1; ++d1) {
                const std::uint32_t* row = table + at + d0 * step[outer] + d1 * step[inner];
                std::int64_t last = -2;
                for (int d2 = -1; d2 <= 1; ++d2) add(std::int64_t(row[d2 * step[f]]) - 1, last);
            }
        return;
    }
    std::int64_t c[3];
    for (int d0 = -1; d0 <= 1; ++d0)
        for (int d1 = -1; d1 <= 1; ++d1) {
            std::int64_t last = -2;
            for (int d2 = -1; d2 <= 1; ++d2) {
                c[outer] = cell[std::size_t(outer)] + d0;
                c[inner] = cell[std::size_t(inner)] + d1;
                c[f] = cell[std::size_t(f)] + d2;
                add(grid.findCell(c[0], c[1], c[2]), last);
            }
        }
}

std::size_t CellRuns::points() const {
    std::size_t n = 0;
    for (int r = 0; r != count; ++r) n += to[r] - from[r];
    return n;
}

std::size_t CellRuns::positionOf(std::size_t s) const {
    std::size_t before = 0;
    for (int r = 0; r != count; before += to[r] - from[r], ++r)
        if (from[r] <= s && s < to[r]) return before + (s - from[r]);
    throw std::logic_error("CellRuns::positionOf: the point is in none of the runs");
}

void CellCandidates::gather(const UniformGrid& grid, const std::array<std::int32_t, 3>& cell) {
    CellRuns runs;
    runs.find(grid, cell);
    gather(grid, runs);
}

void CellCandidates::gather(const UniformGrid& grid, const CellRuns& runs) {
    count = runs.points();
    const std::size_t room = 64 * words();
    if (index.size() < room) x.resize(room), y.resize(room), z.resize(room), index.resize(room);
    const std::size_t padded = (count + 3) / 4 * 4;
    const Real *gx = grid.sortedCoords(0).data(), *gy = grid.sortedCoords(1).data(), *gz = grid.sortedCoords(2).data();
    const std::uint32_t* sorted = grid.sortedIndices().data();
    // Cells hold a handful of points: plain loops beat memcpy calls here.
    std::size_t k = 0;
    for (int r = 0; r != runs.count; ++r)
        for (std::size_t s = runs.from[r]; s != runs.to[r]; ++s, ++k)
            x[k] = gx[s], y[k] = gy[s], z[k] = gz[s], index[k] = sorted[s];
    for (; k != padded; ++k) x[k] = y[k] = z[k] = std::numeric_limits<Real>::max();
}

void sortByKey(std::vector<std::pair<std::uint64_t, std::uint32_t>>& items,
               std::vector<std::pair<std::uint64_t, std::uint32_t>>& scratch) {
    // Least significant byte first, each pass stable, so that equal keys keep the order they came in; a byte in which
    // every key agrees is skipped (a fluid's cells share most of their keys' high bits). The histograms of all bytes
    // in one pass over the keys. Keys already in order (particles that stayed in their cells since the last sort)
    // are left as they are: the simulation's falling blocks would otherwise pay full passes every step.
    const std::size_t n = items.size();
    if (n < 2) return;
    std::uint64_t differ = 0;
    bool sorted = true;
    for (std::size_t i = 0; i < n; ++i) {
        differ |= items[i].first ^ items[0].first;
        sorted &= i == 0 || items[i - 1].first <= items[i].first;
    }
    if (sorted) return;
    int bytes[8], active = 0;
    for (int byte = 0; byte < 8; ++byte)
        if (differ >> (8 * byte) & 0xff) bytes[active++] = 8 * byte;
    std::array<std::array<std::uint32_t, 256>, 8> start{};
    for (const auto& item : items)
        for (int b = 0; b < active; ++b) ++start[std::size_t(b)][item.first >> bytes[b] & 0xff];
    scratch.resize(n);
    for (int b = 0; b < active; ++b) {
        std::uint32_t total = 0;
        for (auto& c : start[std::size_t(b)]) total += std::exchange(c, total);
        for (const auto& item : items) scratch[start[std::size_t(b)][item.first >> bytes[b] & 0xff]++] = item;
        items.swap(scratch);
    }
}

UniformGrid::UniformGrid(Real cellSize, std::size_t slabPoints) : m_cellSize(cellSize), m_slabPoints(slabPoints) {
    if (!(cellSize > 0) || !std::isfinite(cellSize))
        throw std::invalid_argument("UniformGrid: cell size must be positive and finite");
    if (slabPoints > kAlwaysRowOrder) throw std::invalid_argument("UniformGrid: slabPoints above 2^40");
}

void UniformGrid::build(const std::vector<Vec3>& x) {
    const std::size_t n = x.size();
    if (n >= std::size_t(UINT32_MAX)) throw std::runtime_error("neighbour search: more than 4 billion points");
    const Real inv = 1 / m_cellSize;
    // The box of the points' cells, for the order; a point the grid cannot address stops the build, named.
    using Box = std::pair<Vec3, Vec3>;
    const Real big = std::numeric_limits<Real>::max();
    const Box box = deterministicBlockReduce<Box>(
        n,
        [&](std::size_t begin, std::size_t end) {
            Box b(Vec3::Constant(big), Vec3::Constant(-big));
            for (std::size_t i = begin; i != end; ++i) {
                const Vec3 c = (x[i] * inv).array().floor();
                if (!c.allFinite() || c.cwiseAbs().maxCoeff() > Real(kMaxCell))
                    throw std::runtime_error("neighbour search: point " + std::to_string(i) +
                                             (x[i].allFinite() ? " lies too far from the origin for the grid"
                                                               : " has a non-finite position"));
                b.first = b.first.cwiseMin(c), b.second = b.second.cwiseMax(c);
            }
            return b;
        },
        Box(Vec3::Constant(big), Vec3::Constant(-big)),
        [](const Box& a, const Box& b) { return Box(a.first.cwiseMin(b.first), a.second.cwiseMax(b.second)); });
    m_rowOrder = false;
    m_fastAxis = 0;
    if (box.first.x() <= box.second.x())
        chooseOrder(n, {std::int64_t(box.first.x()), std::int64_t(box.first.y()), std::int64_t(box.first.z())},
                    {std::int64_t(box.second.x()), std::int64_t(box.second.y()), std::int64_t(box.second.z())});

    auto& keyed = m_keyed;
    keyed.resize(n);
    forEachBlock(n, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i != end; ++i) {
            const Vec3 c = (x[i] * inv).array().floor();
            keyed[i] = {key(std::int64_t(c.x()), std::int64_t(c.y()), std::int64_t(c.z())), std::uint32_t(i)};
        }
    }, 1024);
    // Indices ascend in keyed, so a stable sort by key gives the (key, index) order, the same for any thread count.
    sortByKey(keyed, m_keyedScratch);

    m_sorted.resize(n);
    for (auto& c : m_sortedCoords) c.resize(n);
    forEachBlock(n, [&](std::size_t begin, std::size_t end) {
        for (std::size_t s = begin; s != end; ++s) {
            m_sorted[s] = keyed[s].second;
            for (int a = 0; a < 3; ++a) m_sortedCoords[std::size_t(a)][s] = x[keyed[s].second][a];
        }
    }, 1024);
    m_cellKeys.clear();
    m_cellBegin.clear();
    m_cellCoords.clear();
    for (std::size_t s = 0; s < n; ++s) {
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

    // Where the occupied cells fill a good part of their bounding box (a body of fluid, a tank's walls), a dense
    // table finds a cell with one load instead of a hashed probe; its size is capped at a few words per cell. It
    // reaches kDenseMargin cells past the box, so that the cells around any cell that mayHoldAround() lie in it and
    // CellRuns::find reads them without a test of bounds.
    m_denseCells.clear();
    if (m_cellCoords.empty()) return;
    auto& lo = m_cellMin;
    auto& hi = m_cellMax;
    lo = {m_cellCoords[0][0], m_cellCoords[0][1], m_cellCoords[0][2]};
    hi = lo;
    for (const auto& c : m_cellCoords)
        for (int a = 0; a < 3; ++a) {
            lo[a] = std::min<std::int64_t>(lo[a], c[a]);
            hi[a] = std::max<std::int64_t>(hi[a], c[a]);
        }
    std::uint64_t volume = 1;
    for (int a = 0; a < 3; ++a) volume *= std::uint64_t(hi[a] - lo[a] + 1);
    if (volume > 16 * m_cellCoords.size() + 4096) return;
    for (int a = 0; a < 3; ++a) {
        m_denseMin[a] = lo[a] - kDenseMargin;
        m_denseSize[a] = hi[a] - lo[a] + 1 + 2 * kDenseMargin;
    }
    m_denseCells.assign(std::size_t(m_denseSize[0] * m_denseSize[1] * m_denseSize[2]), 0);
    for (std::size_t c = 0; c < m_cellCoords.size(); ++c) {
        const auto& cc = m_cellCoords[c];
        m_denseCells[denseSlot(cc[0], cc[1], cc[2])] = std::uint32_t(c + 1);
    }
}

void UniformGrid::chooseOrder(std::size_t n, const std::array<std::int64_t, 3>& lo,
                              const std::array<std::int64_t, 3>& hi) {
    std::array<int, 3> axes{0, 1, 2};  // fastest to slowest: the longest side slowest, so that slabs are small
    for (int a = 0; a < 3; ++a) m_rowSize[std::size_t(a)] = hi[std::size_t(a)] - lo[std::size_t(a)] + 1;
    std::stable_sort(axes.begin(), axes.end(),
                     [&](int a, int b) { return m_rowSize[std::size_t(a)] < m_rowSize[std::size_t(b)]; });
    m_rowOrder = 3 * n <= m_slabPoints * std::size_t(m_rowSize[std::size_t(axes[2])]);
    if (!m_rowOrder) return;
    m_fastAxis = axes[0];
    m_rowMin = lo;
    int shift = 0;
    for (int a : axes) {
        m_rowShift[std::size_t(a)] = shift;
        while (std::int64_t(1) << (shift - m_rowShift[std::size_t(a)]) < m_rowSize[std::size_t(a)]) ++shift;
    }
}

std::uint64_t UniformGrid::key(std::int64_t cx, std::int64_t cy, std::int64_t cz) const {
    if (!m_rowOrder) return mortonKey(cx, cy, cz);
    return std::uint64_t(cx - m_rowMin[0]) << m_rowShift[0] | std::uint64_t(cy - m_rowMin[1]) << m_rowShift[1] |
           std::uint64_t(cz - m_rowMin[2]) << m_rowShift[2];
}

void UniformGrid::releaseWorkingMemory() {
    std::vector<std::pair<std::uint64_t, std::uint32_t>>().swap(m_keyed);
    std::vector<std::pair<std::uint64_t, std::uint32_t>>().swap(m_keyedScratch);
}

bool UniformGrid::mayHoldAround(const std::array<std::int32_t, 3>& cell) const {
    if (m_cellKeys.empty()) return false;
    for (int a = 0; a < 3; ++a)
        if (cell[a] < m_cellMin[a] - 1 || cell[a] > m_cellMax[a] + 1) return false;
    return true;
}

std::int64_t UniformGrid::findCell(std::int64_t cx, std::int64_t cy, std::int64_t cz) const {
    if (m_cellKeys.empty()) return -1;
    if (dense()) {
        const std::int64_t ix = cx - m_denseMin[0], iy = cy - m_denseMin[1], iz = cz - m_denseMin[2];
        if (ix < 0 || iy < 0 || iz < 0 || ix >= m_denseSize[0] || iy >= m_denseSize[1] || iz >= m_denseSize[2])
            return -1;
        return std::int64_t(m_denseCells[denseSlot(cx, cy, cz)]) - 1;
    }
    if (m_rowOrder) {
        const std::int64_t c[3] = {cx, cy, cz};
        for (std::size_t a = 0; a < 3; ++a)
            if (c[a] < m_rowMin[a] || c[a] >= m_rowMin[a] + m_rowSize[a]) return -1;
    } else if (std::abs(cx) > kMaxCell + 1 || std::abs(cy) > kMaxCell + 1 || std::abs(cz) > kMaxCell + 1) {
        return -1;
    }
    const std::uint64_t key = this->key(cx, cy, cz);
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

    if (sameSet && &queryGrid != &targetGrid)
        throw std::logic_error("findNeighbours: one set searched against itself needs one grid");
    const Real *tx = targetGrid.sortedCoords(0).data(), *ty = targetGrid.sortedCoords(1).data();
    const Real* tz = targetGrid.sortedCoords(2).data();
    const std::uint32_t* tSorted = targetGrid.sortedIndices().data();

    // One pass: chunks of query cells write their particles' lists into their own buffers (fixed chunk
    // boundaries, so the result is the same for any thread count); a second, cheap pass copies each list
    // to its place in particle order.
    constexpr std::size_t kCellsPerChunk = 64;
    const std::size_t cells = queryGrid.cellCount();
    const std::size_t chunks = (cells + kCellsPerChunk - 1) / kCellsPerChunk;
    auto& buffers = out.scratch.chunks;
    if (buffers.size() < chunks) buffers.resize(chunks);
    auto& count = out.scratch.count;
    auto& chunkOf = out.scratch.chunkOf;
    auto& localStart = out.scratch.localStart;
    count.resize(n), chunkOf.resize(n), localStart.resize(n);
    // In row order the runs along the fast axis are long and are tested where they lie; in Z order cells along x
    // mostly lie apart, and short runs cost more in their ends than a copy into one run (CellCandidates).
    const bool copy = !targetGrid.rowOrder();
    tbb::enumerable_thread_specific<CellCandidates> scratch;
    parallelRange(chunks, 1, n, [&](const auto& range) {
        CellRuns runs;
        CellCandidates& cand = scratch.local();
        for (std::size_t chunk = range.begin(); chunk != range.end(); ++chunk) {
            auto& buffer = buffers[chunk];  // never shrunk: its size is room, the lists fill it from the start
            std::size_t used = 0;
            const std::size_t lastCell = std::min(cells, (chunk + 1) * kCellsPerChunk);
            for (std::size_t c = chunk * kCellsPerChunk; c < lastCell; ++c) {
                runs.find(targetGrid, queryGrid.cellCoords(c));
                const std::size_t first = queryGrid.cellBegin(c), room = runs.points() + 4;
                // Where the query's own point s lies among the candidates: in a set's own grid, s itself.
                std::size_t self = sameSet ? first : SIZE_MAX;
                const Real *cx = tx, *cy = ty, *cz = tz;
                const std::uint32_t* ci = tSorted;
                if (copy) {
                    cand.gather(targetGrid, runs);
                    cx = cand.x.data(), cy = cand.y.data(), cz = cand.z.data(), ci = cand.index.data();
                    if (sameSet) self = runs.positionOf(first);
                }
                for (std::size_t s = first; s < queryGrid.cellBegin(c + 1); ++s, self += sameSet) {
                    const std::uint32_t i = qSorted[s];
                    if (buffer.size() < used + room) buffer.resize(std::max(2 * buffer.size(), used + room));
                    std::uint32_t* dst = buffer.data() + used;
                    std::size_t found = 0;
                    if (copy)
                        found = appendCloser(cx, cy, cz, ci, 0, cand.count, queryX[i], r2, self, dst);
                    else
                        for (int k = 0; k < runs.count; ++k)
                            found += appendCloser(cx, cy, cz, ci, runs.from[k], runs.to[k], queryX[i], r2, self,
                                                  dst + found);
                    chunkOf[i] = std::uint32_t(chunk);
                    localStart[i] = std::uint32_t(used);
                    count[i] = std::uint32_t(found);
                    used += found;
                }
            }
        }
    });

    out.offsets.resize(n + 1);
    out.offsets[0] = 0;
    for (std::size_t i = 0; i < n; ++i) out.offsets[i + 1] = out.offsets[i] + count[i];
    resizeForRefill(out.indices, out.offsets[n]);
    forEachBlock(n, [&](std::size_t begin, std::size_t end) {
        // Particles whose lists follow each other in one buffer (all of a chunk's, where the particles are in the
        // grid's order) are copied in one go.
        for (std::size_t i = begin, j; i != end; i = j) {
            for (j = i + 1; j != end && chunkOf[j] == chunkOf[i] && localStart[j] == localStart[j - 1] + count[j - 1];)
                ++j;
            std::memcpy(out.indices.data() + out.offsets[i], buffers[chunkOf[i]].data() + localStart[i],
                        (out.offsets[j] - out.offsets[i]) * sizeof(std::uint32_t));
        }
    });
}

void findFluidNeighbours(UniformGrid& grid, const std::vector<Vec3>& x, Real radius, NeighbourList& out) {
    grid.build(x);
    findNeighbours(grid, x, grid, x, radius, true, out);
}

}  // namespace ganache
