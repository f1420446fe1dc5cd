// The mesh of a level set's zero crossing: dual contouring with a vertex per surface piece of each voxel cell, then,
// within each 8^3 leaf, blocks of 2, 4 and 8 cells merged into one vertex where the surface through them is a single
// flat enough disk.
//
// A cell is the cube between eight voxel centres (corner n at offset (n & 1, n >> 1 & 1, n >> 2 & 1) from its first
// corner, whose voxel names it); "inside" is a value below zero. A cell's crossed edges are grouped into pieces as
// marching cubes joins them, with one rule for faces whose four edges are crossed, so that the pieces of cells
// that share a face meet consistently and the mesh is closed and manifold. Every crossed lattice edge gives a quad
// joining the vertices of the four cells around it (collapsed to a triangle, or dropped, where merged cells share
// a vertex); a cell's vertex is the mean of its piece's edge crossings.
//
// A block merges when (1) each of its eight children is empty or already one vertex; (2) the surface through it is
// a disk that the block's eight corners alone describe: their configuration has one piece and no face with four
// crossings, and the children's corners add no piece of their own (the sign at the middle of each block edge
// agrees with one of the edge's ends, at the middle of each face with one of that face's edge middles, at the
// centre with one of the face middles); (3) every normal of the children lies within acos(1 - adaptivity) of their
// mean (the spread of merged children counted); (4) every cell vertex of the block lies within 2 x adaptivity
// voxels of the tangent plane at the merged vertex: the children's mean moved onto the zero crossing along the
// gradient.

#include "surfacer/level_sets.h"

#include "core/parallel.h"

#include <Eigen/Core>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <memory>
#include <set>
#include <stdexcept>

namespace ganache::surfacing {

namespace {

using Vec3f = Eigen::Vector3f;
using IdTree = openvdb::Int32Tree;
using IdLeaf = IdTree::LeafNodeType;

constexpr int kLeaf = 8;
// A merged block's cell vertices lie within this many voxels per unit of adaptivity of its vertex's tangent plane:
// at 0.1, a fifth of a voxel. With the normals' cone alone, blocks of eight cells on a ball of 20 voxels' radius
// merged into triangles whose edges cut 1.8 voxels into it; with this bound the meshes of the quality tests hold
// as many triangles as OpenVDB's mesher gave at the same adaptivity, and lie closer to the level set.
constexpr double kDeviationPerAdaptivity = 2.0;

// Corner n of a cell: its offset along axis a.
constexpr int cornerOffset(int n, int a) { return n >> a & 1; }
constexpr int cornerAt(int x, int y, int z) { return x | y << 1 | z << 2; }

// Edge e = 4 a + u + 2 v runs along axis a, offset by u along axis (a + 1) % 3 and by v along (a + 2) % 3.
struct Edge {
    int axis;
    int from, to;  // corners
};

constexpr Edge edgeOf(int e) {
    const int a = e / 4, u = e & 1, v = e >> 1 & 1;
    int at[3] = {0, 0, 0};
    at[(a + 1) % 3] = u;
    at[(a + 2) % 3] = v;
    const int from = cornerAt(at[0], at[1], at[2]);
    return {a, from, from | 1 << a};
}

int edgeBetween(int p, int q) {
    const int a = p ^ q;  // a single bit: the axis
    const int axis = a == 1 ? 0 : a == 2 ? 1 : 2;
    const int base = p & q;
    return 4 * axis + cornerOffset(base, (axis + 1) % 3) + 2 * cornerOffset(base, (axis + 2) % 3);
}

// The pieces of a cell: the piece each crossed edge belongs to (-1 for an edge not crossed) and their number. On a
// face with four crossed edges the outside corners are joined across it (the inside ones cut off), unless the face's
// bit (2 axis + side) is set in `flips`; both cells that share a face make the same choice, so pieces meet
// consistently. `tunnels` has the bit of each such face whose two crossings belong to one piece.
struct Pieces {
    std::array<std::int8_t, 12> piece;
    int count = 0;
    int ambiguous = 0;  // faces with four crossed edges
    int tunnels = 0;

    Pieces() = default;
    Pieces(int config, int flips) {
        auto inside = [&](int n) { return (config >> n & 1) != 0; };
        int parent[12];
        for (int e = 0; e < 12; ++e) parent[e] = e;
        auto root = [&](int e) {
            while (parent[e] != e) e = parent[e] = parent[parent[e]];
            return e;
        };
        auto join = [&](int a, int b) { parent[root(a)] = root(b); };
        bool crossed[12];
        for (int e = 0; e < 12; ++e) crossed[e] = inside(edgeOf(e).from) != inside(edgeOf(e).to);
        int faceEdge[6][4];
        for (int axis = 0; axis < 3; ++axis)
            for (int side = 0; side < 2; ++side) {
                // The face's corners in cyclic order, and the edge from each to the next.
                const int b = (axis + 1) % 3, c = (axis + 2) % 3, f = 2 * axis + side;
                int corner[4];
                const int uv[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
                for (int k = 0; k < 4; ++k) {
                    int at[3];
                    at[axis] = side, at[b] = uv[k][0], at[c] = uv[k][1];
                    corner[k] = cornerAt(at[0], at[1], at[2]);
                }
                int* edge = faceEdge[f];
                int n = 0, first = -1;
                for (int k = 0; k < 4; ++k) {
                    edge[k] = edgeBetween(corner[k], corner[(k + 1) % 4]);
                    if (crossed[edge[k]]) ++n, first = first < 0 ? edge[k] : first;
                }
                if (n == 2) {
                    for (int k = 0; k < 4; ++k)
                        if (crossed[edge[k]] && edge[k] != first) join(first, edge[k]);
                } else if (n == 4) {
                    ambiguous |= 1 << f;
                    const bool cutInside = !(flips >> f & 1);
                    for (int k = 0; k < 4; ++k)
                        if (inside(corner[k]) == cutInside) join(edge[(k + 3) % 4], edge[k]);
                }
            }
        std::int8_t label[12];
        for (int e = 0; e < 12; ++e) label[e] = -1;
        for (int e = 0; e < 12; ++e) {
            piece[std::size_t(e)] = -1;
            if (!crossed[e]) continue;
            const int r = root(e);
            if (label[r] < 0) label[r] = std::int8_t(count++);
            piece[std::size_t(e)] = label[r];
        }
        for (int f = 0; f < 6; ++f)
            if ((ambiguous >> f & 1) && piece[std::size_t(faceEdge[f][0])] == piece[std::size_t(faceEdge[f][2])])
                tunnels |= 1 << f;
    }
};

// Every configuration's pieces with no face flipped.
const std::array<Pieces, 256>& pieceTable() {
    static const std::array<Pieces, 256> table = [] {
        std::array<Pieces, 256> t;
        for (int config = 0; config < 256; ++config) t[std::size_t(config)] = Pieces(config, 0);
        return t;
    }();
    return table;
}

// Faces whose rule is flipped, each named by the cell below it along its axis and the axis. Where two cells that share
// a face both join its two crossings into one piece (a thread thinner than a voxel lying along the face, of air with
// the default rule), each cell's one vertex would join the other's twice and four quads would share an edge;
// flipping the face's rule cuts the thread there instead.
class FlippedFaces {
public:
    void add(const openvdb::Coord& below, int axis) { m_faces.insert(key(below, axis)); }
    bool empty() const { return m_faces.empty(); }
    // The flips of the faces of the cell at c (bit 2 axis + side).
    int around(const openvdb::Coord& c) const {
        int flips = 0;
        for (int a = 0; a < 3; ++a) {
            openvdb::Coord below = c;
            below[a] -= 1;
            flips |= int(m_faces.count(key(below, a))) << 2 * a | int(m_faces.count(key(c, a))) << (2 * a + 1);
        }
        return flips;
    }

private:
    static std::array<int, 4> key(const openvdb::Coord& c, int axis) { return {c.x(), c.y(), c.z(), axis}; }
    std::set<std::array<int, 4>> m_faces;
};

// A cell's pieces: the table's, or computed where a face of it is flipped.
struct CellPieces {
    const Pieces* pieces;
    Pieces own;

    CellPieces(int config, const FlippedFaces& flipped, const openvdb::Coord& cell) {
        pieces = &pieceTable()[std::size_t(config)];
        if (!pieces->ambiguous || flipped.empty()) return;
        const int flips = flipped.around(cell) & pieces->ambiguous;
        if (!flips) return;
        own = Pieces(config, flips);
        pieces = &own;
    }
    CellPieces(const CellPieces&) = delete;
};

// One vertex's share of a block: its position (leaf index space), unit normal, the largest angle between the
// normal and those of the cells merged into it, and how many cell vertices it stands for.
struct Patch {
    enum State : std::uint8_t { Empty, Single, Several } state;
    Vec3f x;
    Vec3f normal;
    float spread;
    int weight;
};

// The leaf's values at (i, j, k) in -1..8 through a LeafNeighbourhood, with trilinear sampling.
struct Values {
    const LeafNeighbourhood& at;

    float operator()(int i, int j, int k) const { return at(i, j, k); }

    // Value and gradient of the trilinear interpolant at x (within the leaf's cells, 0..8 on each axis).
    float sample(const Vec3f& x, Vec3f& gradient) const {
        int c[3];
        float f[3];
        for (int a = 0; a < 3; ++a) {
            c[a] = std::clamp(int(std::floor(x[a])), 0, kLeaf - 1);
            f[a] = std::clamp(x[a] - float(c[a]), 0.f, 1.f);
        }
        float v[8];
        for (int n = 0; n < 8; ++n)
            v[n] = at(c[0] + cornerOffset(n, 0), c[1] + cornerOffset(n, 1), c[2] + cornerOffset(n, 2));
        return trilinear(v, Vec3f(f[0], f[1], f[2]), gradient);
    }

    static float trilinear(const float v[8], const Vec3f& f, Vec3f& gradient) {
        const float x = f[0], y = f[1], z = f[2];
        const float x00 = v[0] + x * (v[1] - v[0]), x10 = v[2] + x * (v[3] - v[2]);
        const float x01 = v[4] + x * (v[5] - v[4]), x11 = v[6] + x * (v[7] - v[6]);
        const float y0 = x00 + y * (x10 - x00), y1 = x01 + y * (x11 - x01);
        const float dx00 = v[1] - v[0], dx10 = v[3] - v[2], dx01 = v[5] - v[4], dx11 = v[7] - v[6];
        gradient[0] = (1 - z) * (dx00 + y * (dx10 - dx00)) + z * (dx01 + y * (dx11 - dx01));
        gradient[1] = (1 - z) * (x10 - x00) + z * (x11 - x01);
        gradient[2] = y1 - y0;
        return y0 + z * (y1 - y0);
    }
};

// A cell's corner values.
struct Cell {
    float v[8];

    Cell(const Values& values, int i, int j, int k) {
        for (int n = 0; n < 8; ++n)
            v[n] = values(i + cornerOffset(n, 0), j + cornerOffset(n, 1), k + cornerOffset(n, 2));
    }

    // The vertex of piece p (relative to the cell's first corner): the mean of its edges' crossings, and its normal.
    Vec3f vertex(const Pieces& pieces, int p, Vec3f& normal) const {
        Vec3f sum = Vec3f::Zero();
        int n = 0;
        for (int e = 0; e < 12; ++e) {
            if (pieces.piece[std::size_t(e)] != p) continue;
            const Edge edge = edgeOf(e);
            const float a = v[edge.from], b = v[edge.to];
            Vec3f x(float(cornerOffset(edge.from, 0)), float(cornerOffset(edge.from, 1)),
                    float(cornerOffset(edge.from, 2)));
            x[edge.axis] = std::clamp(a / (a - b), 0.f, 1.f);
            sum += x, ++n;
        }
        const Vec3f x = sum / float(n);
        Values::trilinear(v, x, normal);
        const float length = normal.norm();
        normal = length > 0 ? Vec3f(normal / length) : Vec3f::Zero();
        return x;
    }
};

// The inside configurations of the cells whose first corner lies in -1..7 around a leaf, from one pass over its
// neighbourhood's signs: each row's signs as bits, the four rows around a line of cells interleaved so that a cell's
// eight corners are eight bits in a row (corner n = x | y << 1 | z << 2 is bit 4 z + n of the cell's nibble pair).
struct Configs {
    std::uint8_t at[9][9][9];

    explicit Configs(const Values& values) {
        std::uint64_t spread[10][10];  // bit 4 k: row (i, j)'s point k inside
        for (int i = -1; i <= 8; ++i)
            for (int j = -1; j <= 8; ++j) {
                const float* row = values.at.row(i, j);
                std::uint64_t bits = 0;
                for (int k = 0; k < 10; ++k) bits |= std::uint64_t(row[k] < 0) << k;
                // Every bit to four times its place (a Morton code's spreading for four dimensions).
                bits = (bits ^ (bits << 24)) & 0x000000FF000000FFull;
                bits = (bits ^ (bits << 12)) & 0x000F000F000F000Full;
                bits = (bits ^ (bits << 6)) & 0x0303030303030303ull;
                bits = (bits ^ (bits << 3)) & 0x1111111111111111ull;
                spread[i + 1][j + 1] = bits;
            }
        for (int i = 0; i < 9; ++i)
            for (int j = 0; j < 9; ++j) {
                const std::uint64_t corners = spread[i][j] | spread[i + 1][j] << 1 | spread[i][j + 1] << 2 |
                                              spread[i + 1][j + 1] << 3;
                for (int k = 0; k < 9; ++k) at[i][j][k] = std::uint8_t(corners >> 4 * k);
            }
    }

    int operator()(int i, int j, int k) const { return at[i + 1][j + 1][k + 1]; }
};

int blockIndex(int level, int i, int j, int k) {
    const int n = kLeaf >> level;
    return (i * n + j) * n + k;
}

// Whether the signs of the block at `origin` of size 2h (in cells) allow merging it: one piece, told by its corners.
bool simpleDisk(const Values& values, const int origin[3], int h) {
    int sign[3][3][3];
    for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b)
            for (int c = 0; c < 3; ++c)
                sign[a][b][c] = values(origin[0] + a * h, origin[1] + b * h, origin[2] + c * h) < 0;
    int config = 0;
    for (int n = 0; n < 8; ++n)
        config |= sign[2 * cornerOffset(n, 0)][2 * cornerOffset(n, 1)][2 * cornerOffset(n, 2)] << n;
    const Pieces& corners = pieceTable()[std::size_t(config)];
    if (corners.count != 1 || corners.ambiguous) return false;
    // Each middle agrees with one of its neighbours of lower dimension: edge middles with their ends, face middles
    // with their edges' middles, the centre with the faces' middles.
    for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b)
            for (int c = 0; c < 3; ++c) {
                const int at[3] = {a, b, c};
                if (a != 1 && b != 1 && c != 1) continue;  // a corner
                bool agrees = false;
                for (int axis = 0; axis < 3 && !agrees; ++axis) {
                    if (at[axis] != 1) continue;
                    for (int side = 0; side <= 2; side += 2) {
                        int n[3] = {a, b, c};
                        n[axis] = side;
                        agrees |= sign[n[0]][n[1]][n[2]] == sign[a][b][c];
                    }
                }
                if (!agrees) return false;
            }
    return true;
}

// The vertices of one leaf's cells: merging, then each kept patch's position.
struct LeafVertices {
    std::vector<Vec3f> x;               // leaf index space
    std::vector<std::pair<std::uint16_t, std::int32_t>> first;  // cells with vertices: the cell, its first vertex
};

void leafVertices(const Values& values, const Configs& configs, const openvdb::Coord& origin,
                  const FlippedFaces& flipped, float maxAngle, float maxDeviation, bool adapt, LeafVertices& out) {
    const float cosMaxAngle = std::cos(maxAngle);
    // Level 0: the cells.
    std::array<Patch, 512> cells;
    for (int i = 0; i < kLeaf; ++i)
        for (int j = 0; j < kLeaf; ++j)
            for (int k = 0; k < kLeaf; ++k) {
                Patch& patch = cells[std::size_t(blockIndex(0, i, j, k))];
                const int config = configs(i, j, k);
                patch.state = Patch::Empty;
                if (config == 0 || config == 255) continue;
                const CellPieces pieces(config, flipped, origin.offsetBy(i, j, k));
                const int n = pieces.pieces->count;
                if (n > 1 || !adapt || pieces.pieces->ambiguous) {
                    patch.state = Patch::Several;
                    continue;
                }
                patch.state = Patch::Single;
                patch.x = Cell(values, i, j, k).vertex(*pieces.pieces, 0, patch.normal) +
                          Vec3f(float(i), float(j), float(k));
                patch.weight = 1;
                patch.spread = 0;
                if (patch.normal.isZero()) patch.state = Patch::Several;
            }
    // Levels 1-3: blocks of 2, 4 and 8 cells.
    std::array<Patch, 64> level1;
    std::array<Patch, 8> level2;
    std::array<Patch, 1> level3;
    Patch* levels[4] = {cells.data(), level1.data(), level2.data(), level3.data()};
    for (int level = 1; level <= 3; ++level) {
        const int n = kLeaf >> level, h = 1 << (level - 1);
        for (int bi = 0; bi < n; ++bi)
            for (int bj = 0; bj < n; ++bj)
                for (int bk = 0; bk < n; ++bk) {
                    Patch& block = levels[level][blockIndex(level, bi, bj, bk)];
                    Patch* children[8];
                    bool several = false, any = false;
                    for (int c = 0; c < 8; ++c) {
                        children[c] = &levels[level - 1][blockIndex(level - 1, 2 * bi + cornerOffset(c, 0),
                                                                    2 * bj + cornerOffset(c, 1),
                                                                    2 * bk + cornerOffset(c, 2))];
                        several |= children[c]->state == Patch::Several;
                        any |= children[c]->state == Patch::Single;
                    }
                    block.state = several ? Patch::Several : any ? Patch::Single : Patch::Empty;
                    if (block.state != Patch::Single) continue;
                    Vec3f normal = Vec3f::Zero(), x = Vec3f::Zero();
                    int weight = 0;
                    for (const Patch* child : children)
                        if (child->state == Patch::Single)
                            normal += float(child->weight) * child->normal, x += float(child->weight) * child->x,
                                weight += child->weight;
                    const float length = normal.norm();
                    bool flat = length > 0;
                    if (flat) normal /= length;
                    // A child's normals lie within its spread of its own: the cone test in cosines, a cosine per
                    // child that has merged already; the block's spread bounded by the widest child's.
                    float nearest = 1, widest = 0;
                    for (const Patch* child : children) {
                        if (!flat || child->state != Patch::Single) continue;
                        const float d = child->normal.dot(normal);
                        flat = d >= (child->spread > 0 ? std::cos(maxAngle - child->spread) : cosMaxAngle);
                        nearest = std::min(nearest, d), widest = std::max(widest, child->spread);
                    }
                    const int corner[3] = {2 * bi * h, 2 * bj * h, 2 * bk * h};
                    if (!flat || !simpleDisk(values, corner, h)) {
                        block.state = Patch::Several;
                        continue;
                    }
                    // The mean of the children, moved onto the crossing along the gradient and kept in the block.
                    x /= float(weight);
                    for (int step = 0; step < 2; ++step) {
                        Vec3f g;
                        const float value = values.sample(x, g);
                        const float g2 = g.squaredNorm();
                        if (g2 > 0) x -= value / g2 * g;
                        for (int a = 0; a < 3; ++a)
                            x[a] = std::clamp(x[a], float(corner[a]), float(corner[a] + 2 * h));
                    }
                    // Every cell's vertex close to the merged vertex's tangent plane.
                    const int size = 2 * h;
                    float deviation = 0;
                    for (int a = 0; a < size; ++a)
                        for (int b = 0; b < size; ++b)
                            for (int c = 0; c < size; ++c) {
                                const Patch& cell =
                                    cells[std::size_t(blockIndex(0, corner[0] + a, corner[1] + b, corner[2] + c))];
                                if (cell.state == Patch::Single)
                                    deviation = std::max(deviation, std::abs(normal.dot(cell.x - x)));
                            }
                    if (deviation > maxDeviation) {
                        block.state = Patch::Several;
                        continue;
                    }
                    block.x = x, block.normal = normal, block.weight = weight;
                    block.spread = std::acos(std::clamp(nearest, -1.f, 1.f)) + widest;
                }
    }
    // Numbering: the largest merged blocks first met in a depth-first walk, then the cells' own pieces.
    out.x.clear();
    out.first.clear();
    auto walk = [&](auto&& self, int level, int i, int j, int k) -> void {
        const Patch& patch = levels[level][blockIndex(level, i, j, k)];
        if (patch.state == Patch::Empty) return;
        const int size = 1 << level;
        if (level > 0 && patch.state == Patch::Single) {
            const std::int32_t id = std::int32_t(out.x.size());
            out.x.push_back(patch.x);
            for (int a = 0; a < size; ++a)
                for (int b = 0; b < size; ++b)
                    for (int c = 0; c < size; ++c) {
                        const int cell = blockIndex(0, i * size + a, j * size + b, k * size + c);
                        if (cells[cell].state != Patch::Empty) out.first.emplace_back(std::uint16_t(cell), id);
                    }
            return;
        }
        if (level == 0) {
            const int cell = blockIndex(0, i, j, k);
            out.first.emplace_back(std::uint16_t(cell), std::int32_t(out.x.size()));
            if (patch.state == Patch::Single) {
                out.x.push_back(patch.x);
                return;
            }
            const Cell corners(values, i, j, k);
            const CellPieces pieces(configs(i, j, k), flipped, origin.offsetBy(i, j, k));
            for (int p = 0; p < pieces.pieces->count; ++p) {
                Vec3f normal;
                out.x.push_back(corners.vertex(*pieces.pieces, p, normal) + Vec3f(float(i), float(j), float(k)));
            }
            return;
        }
        for (int c = 0; c < 8; ++c)
            self(self, level - 1, 2 * i + cornerOffset(c, 0), 2 * j + cornerOffset(c, 1), 2 * k + cornerOffset(c, 2));
    };
    walk(walk, 3, 0, 0, 0);
}

// The first-vertex numbers of the cells -1..7 around a leaf's (its own and those of the seven leaves before it).
struct IdNeighbourhood {
    openvdb::tree::ValueAccessor<const IdTree, false> tree;
    std::int32_t ids[9][9][9];

    explicit IdNeighbourhood(const IdTree& t) : tree(t) {}

    void gather(const openvdb::Coord& origin) {
        for (int a = 0; a < 2; ++a)
            for (int b = 0; b < 2; ++b)
                for (int c = 0; c < 2; ++c) {
                    const IdLeaf* leaf = tree.probeConstLeaf(origin.offsetBy(-8 * (1 - a), -8 * (1 - b), -8 * (1 - c)));
                    const std::int32_t* values = leaf ? leaf->buffer().data() : nullptr;  // its check once, not per id
                    const int i0 = a ? 0 : -1, i1 = a ? 7 : -1, j0 = b ? 0 : -1, j1 = b ? 7 : -1, k0 = c ? 0 : -1,
                              k1 = c ? 7 : -1;
                    for (int i = i0; i <= i1; ++i)
                        for (int j = j0; j <= j1; ++j)
                            for (int k = k0; k <= k1; ++k)
                                ids[i + 1][j + 1][k + 1] = values ? values[(i & 7) * 64 + (j & 7) * 8 + (k & 7)] : -1;
                }
    }

    std::int32_t operator()(int i, int j, int k) const { return ids[i + 1][j + 1][k + 1]; }
};

}  // namespace

void contourLevelSet(const openvdb::FloatGrid& grid, Real adaptivity, std::vector<Vec3>& points,
                     std::vector<std::array<std::uint32_t, 3>>& triangles) {
    points.clear();
    triangles.clear();
    const openvdb::FloatTree& tree = grid.tree();
    std::vector<const FloatLeaf*> leaves;
    leaves.reserve(tree.leafCount());
    for (auto it = tree.cbeginLeaf(); it; ++it) leaves.push_back(&*it);
    // A cell is named by its first corner, which may lie in a tile below a leaf where the band is thinner than a
    // voxel (a trimmed band, a thread): the leaves below the tree's that it lacks are stood in for by leaves of their
    // tile's value, so that such cells get vertices too.
    std::vector<std::vector<openvdb::Coord>> missingBelow(leaves.size());
    forEachBlock(leaves.size(), [&](std::size_t begin, std::size_t end) {
        openvdb::tree::ValueAccessor<const openvdb::FloatTree, false> probe(tree);
        for (std::size_t l = begin; l != end; ++l)
            for (int n = 1; n < 8; ++n) {
                const openvdb::Coord o = leaves[l]->origin().offsetBy(
                    -kLeaf * cornerOffset(n, 0), -kLeaf * cornerOffset(n, 1), -kLeaf * cornerOffset(n, 2));
                if (!probe.probeConstLeaf(o)) missingBelow[l].push_back(o);
            }
    }, 64);
    std::vector<openvdb::Coord> missing;
    for (const auto& below : missingBelow) missing.insert(missing.end(), below.begin(), below.end());
    missingBelow = {};
    tbb::parallel_sort(missing.begin(), missing.end());
    missing.erase(std::unique(missing.begin(), missing.end()), missing.end());
    // Only where a voxel of the leaves above, next to this tile, lies on the other side of the surface.
    std::vector<std::uint8_t> crossed(missing.size(), 0);
    forEachBlock(missing.size(), [&](std::size_t begin, std::size_t end) {
        openvdb::tree::ValueAccessor<const openvdb::FloatTree, false> probe(tree);
        for (std::size_t m = begin; m != end; ++m) {
            const openvdb::Coord& o = missing[m];
            const bool inside = probe.getValue(o) < 0;
            for (int n = 1; n < 8 && !crossed[m]; ++n) {
                const FloatLeaf* above = probe.probeConstLeaf(
                    o.offsetBy(kLeaf * cornerOffset(n, 0), kLeaf * cornerOffset(n, 1), kLeaf * cornerOffset(n, 2)));
                if (!above) continue;
                // Its voxels at local coordinate 0 along the axes it is offset on.
                const int upTo[3] = {cornerOffset(n, 0) ? 1 : kLeaf, cornerOffset(n, 1) ? 1 : kLeaf,
                                     cornerOffset(n, 2) ? 1 : kLeaf};
                for (int i = 0; i < upTo[0] && !crossed[m]; ++i)
                    for (int j = 0; j < upTo[1] && !crossed[m]; ++j)
                        for (int k = 0; k < upTo[2] && !crossed[m]; ++k)
                            crossed[m] = (above->getValue(openvdb::Index(i * 64 + j * 8 + k)) < 0) != inside;
            }
        }
    }, 64);
    std::vector<std::unique_ptr<FloatLeaf>> standIns;
    for (std::size_t m = 0; m < missing.size(); ++m) {
        if (!crossed[m]) continue;
        standIns.push_back(std::make_unique<FloatLeaf>(missing[m], tree.getValue(missing[m])));
        leaves.push_back(standIns.back().get());
    }
    const bool adapt = adaptivity > 0;
    const float maxAngle = float(std::acos(std::clamp(1 - adaptivity, Real(-1), Real(1))));
    const float maxDeviation = float(kDeviationPerAdaptivity * adaptivity);

    // Vertices, leaf by leaf, with every face's rule as the table has it; each leaf notes the faces whose two cells
    // would both join its two crossings (found by the cell above), and the few leaves next to such a face are done
    // again once those faces are flipped.
    const auto& table = pieceTable();
    std::vector<LeafVertices> vertices(leaves.size());
    // The configurations of the leaves with vertices, for the faces below (signs do not change on a flip).
    std::vector<std::unique_ptr<const Configs>> configsOf(leaves.size());
    std::vector<std::vector<std::pair<openvdb::Coord, int>>> tunnels(leaves.size());
    const FlippedFaces none;
    forEachBlock(leaves.size(), [&](std::size_t begin, std::size_t end) {
        LeafNeighbourhood at(tree);
        for (std::size_t l = begin; l != end; ++l) {
            at.gather(*leaves[l]);
            const Values values{at};
            const Configs configs(values);
            const openvdb::Coord o = leaves[l]->origin();
            leafVertices(values, configs, o, none, maxAngle, maxDeviation, adapt, vertices[l]);
            for (int i = 0; i < kLeaf; ++i)
                for (int j = 0; j < kLeaf; ++j)
                    for (int k = 0; k < kLeaf; ++k) {
                        const int own = table[std::size_t(configs(i, j, k))].tunnels;
                        for (int a = 0; own && a < 3; ++a) {
                            int q[3] = {i, j, k};
                            --q[a];
                            if ((own >> 2 * a & 1) &&
                                (table[std::size_t(configs(q[0], q[1], q[2]))].tunnels >> (2 * a + 1) & 1))
                                tunnels[l].emplace_back(o.offsetBy(q[0], q[1], q[2]), a);
                        }
                    }
            if (!vertices[l].x.empty()) configsOf[l] = std::make_unique<const Configs>(configs);
        }
    }, 16);
    FlippedFaces flipped;
    std::set<openvdb::Coord> again;  // origins of the leaves next to a flipped face
    for (const auto& found : tunnels)
        for (const auto& [below, axis] : found) {
            flipped.add(below, axis);
            openvdb::Coord above = below;
            above[axis] += 1;
            again.insert(below & ~(kLeaf - 1)), again.insert(above & ~(kLeaf - 1));
        }
    tunnels = {};
    if (!flipped.empty()) {
        LeafNeighbourhood at(tree);
        for (std::size_t l = 0; l < leaves.size(); ++l) {
            if (!again.count(leaves[l]->origin())) continue;
            at.gather(*leaves[l]);
            const Values values{at};
            leafVertices(values, Configs(values), leaves[l]->origin(), flipped, maxAngle, maxDeviation, adapt,
                         vertices[l]);
        }
    }
    std::vector<std::size_t> offset(leaves.size() + 1, 0);
    for (std::size_t l = 0; l < leaves.size(); ++l) offset[l + 1] = offset[l] + vertices[l].x.size();
    // The id leaves are made and filled in parallel, then added to their tree on one thread.
    std::vector<std::unique_ptr<IdLeaf>> idLeaves(leaves.size());
    points.resize(offset.back());
    const openvdb::math::Transform& transform = grid.transform();
    forEachBlock(leaves.size(), [&](std::size_t begin, std::size_t end) {
        for (std::size_t l = begin; l != end; ++l) {
            const LeafVertices& v = vertices[l];
            if (v.x.empty()) continue;
            const openvdb::Coord o = leaves[l]->origin();
            IdLeaf* leaf = (idLeaves[l] = std::make_unique<IdLeaf>(o, -1)).get();
            for (const auto& [cell, first] : v.first) leaf->setValueOn(cell, std::int32_t(offset[l]) + first);
            for (std::size_t k = 0; k < v.x.size(); ++k) {
                const openvdb::Vec3d w = transform.indexToWorld(
                    openvdb::Vec3d(o.x() + v.x[k].x(), o.y() + v.x[k].y(), o.z() + v.x[k].z()));
                points[offset[l] + k] = Vec3(w.x(), w.y(), w.z());
            }
        }
    }, 16);
    vertices = {};
    IdTree ids(-1);
    for (auto& leaf : idLeaves)
        if (leaf) ids.addLeaf(leaf.release());

    // Faces: each crossed edge starting at a leaf's voxel joins the four cells around it. Per axis a of the edge,
    // the four cells' offsets from the edge's first voxel, counter-clockwise seen from +a, and where the edge lies in
    // each (as constants: offsets written into an array per edge stalled the loads that read it back).
    struct AroundEdge {
        int offset[4][3];
        int edge[4];
    };
    static constexpr auto kAround = [] {
        std::array<AroundEdge, 3> out{};
        const int uv[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
        for (int a = 0; a < 3; ++a)
            for (int n = 0; n < 4; ++n) {
                out[a].offset[n][(a + 1) % 3] = -uv[n][0];
                out[a].offset[n][(a + 2) % 3] = -uv[n][1];
                out[a].edge[n] = 4 * a + uv[n][0] + 2 * uv[n][1];
            }
        return out;
    }();
    const bool anyFlipped = !flipped.empty();
    std::vector<std::vector<std::array<std::uint32_t, 3>>> faces(leaves.size());
    forEachBlock(leaves.size(), [&](std::size_t begin, std::size_t end) {
        IdNeighbourhood id(ids);
        for (std::size_t l = begin; l != end; ++l) {
            if (offset[l + 1] == offset[l]) continue;
            id.gather(leaves[l]->origin());
            const Configs& configs = *configsOf[l];
            auto& out = faces[l];
            for (int i = 0; i < kLeaf; ++i)
                for (int j = 0; j < kLeaf; ++j)
                    for (int k = 0; k < kLeaf; ++k) {
                        const int own = configs(i, j, k);
                        if (own == 0 || own == 255) continue;
                        const bool inside = own & 1;
                        for (int a = 0; a < 3; ++a) {
                            if (bool(own >> (1 << a) & 1) == inside) continue;
                            std::uint32_t vertex[4];
                            for (int n = 0; n < 4; ++n) {
                                const int* d = kAround[std::size_t(a)].offset[n];
                                const int qi = i + d[0], qj = j + d[1], qk = k + d[2];
                                const int config = configs(qi, qj, qk);
                                const int edge = kAround[std::size_t(a)].edge[n];
                                int piece = table[std::size_t(config)].piece[std::size_t(edge)];
                                if (anyFlipped && table[std::size_t(config)].ambiguous)
                                    piece = CellPieces(config, flipped, leaves[l]->origin().offsetBy(qi, qj, qk))
                                                .pieces->piece[std::size_t(edge)];
                                const std::int32_t first = id(qi, qj, qk);
                                if (first < 0)  // every crossed cell was given vertices above
                                    throw std::logic_error("mesher: a crossed voxel cell has no vertex");
                                vertex[n] = std::uint32_t(first + piece);
                            }
                            // Outward is +a where the edge starts inside.
                            if (!inside) std::swap(vertex[1], vertex[3]);
                            std::uint32_t kept[4];
                            int m = 0;
                            for (int n = 0; n < 4; ++n)
                                if (vertex[n] != vertex[(n + 3) % 4]) kept[m++] = vertex[n];
                            if (m == 4) {
                                out.push_back({kept[0], kept[1], kept[2]});
                                out.push_back({kept[0], kept[2], kept[3]});
                            } else if (m == 3) {
                                out.push_back({kept[0], kept[1], kept[2]});
                            }
                        }
                    }
        }
    }, 16);
    std::size_t count = 0;
    for (const auto& f : faces) count += f.size();
    triangles.reserve(count);
    for (const auto& f : faces) triangles.insert(triangles.end(), f.begin(), f.end());
}

}  // namespace ganache::surfacing
