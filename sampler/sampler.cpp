#include "sampler/sampler.h"

#include "physics/boundary.h"

#include "app/progress.h"
#include "core/attributes.h"
#include "core/kernels.h"
#include "core/neighbour_search.h"
#include "core/parallel.h"

#include "sampler/inside.h"

#include <cmath>
#include <unordered_map>
#include <variant>

namespace ganache {

namespace {

// For every point, 1 when the fluid shape holds it.
std::vector<std::uint8_t> insideShape(const FluidShape& shape, const std::vector<Vec3>& x, Real r) {
    if (auto* m = std::get_if<MeshShape>(&shape)) return insideMesh(*m, x, r);
    std::vector<std::uint8_t> in(x.size());
    for (std::size_t i = 0; i < x.size(); ++i) {
        if (auto* b = std::get_if<BoxShape>(&shape))
            in[i] = (x[i].array() >= b->min.array()).all() && (x[i].array() <= b->max.array()).all();
        else {
            const auto& sp = std::get<SphereShape>(shape);
            in[i] = (x[i] - sp.centre).squaredNorm() <= sp.radius * sp.radius;
        }
    }
    return in;
}

// Lattice sites of spacing d inside the shape. A box holds round(extent / d) sites per axis, centred in it,
// so that the sampled volume n d^3 matches the box; a sphere's lattice is centred on its centre, a mesh's on
// its bounding box.
std::vector<Vec3> latticeSites(const FluidShape& shape, Real d, const SampleCache* cache, Sample& out) {
    std::vector<Vec3> sites;
    if (auto* b = std::get_if<BoxShape>(&shape)) {
        Eigen::Vector3i n;
        for (int a = 0; a < 3; ++a) n[a] = std::max(1, int(std::lround((b->max[a] - b->min[a]) / d)));
        const Vec3 first = Real(0.5) * (b->min + b->max) - Real(0.5) * d * (n.cast<Real>() - Vec3::Ones());
        sites.reserve(std::size_t(n.prod()));
        for (int k = 0; k < n.z(); ++k)
            for (int j = 0; j < n.y(); ++j)
                for (int i = 0; i < n.x(); ++i) sites.push_back(first + d * Vec3(i, j, k));
        return sites;
    }
    const auto* mesh = std::get_if<MeshShape>(&shape);
    const std::uint64_t key = mesh ? sampleKey(*mesh->mesh, "fluid sites", d, int(mesh->method())) : 0;
    if (mesh && cache)
        if (auto hit = cache->load(key)) {
            ++out.cacheHits;
            return *hit;
        }
    Vec3 centre, halfExtent;
    if (auto* m = mesh) {
        const auto [lo, hi] = m->mesh->bounds();
        centre = 0.5 * (lo + hi);
        halfExtent = 0.5 * (hi - lo);
    } else {
        const auto& sp = std::get<SphereShape>(shape);
        centre = sp.centre;
        halfExtent = Vec3::Constant(sp.radius);
    }
    const Eigen::Vector3i m = (halfExtent / d).array().ceil().cast<int>();
    for (int k = -m.z(); k <= m.z(); ++k)
        for (int j = -m.y(); j <= m.y(); ++j)
            for (int i = -m.x(); i <= m.x(); ++i) sites.push_back(centre + d * Vec3(i, j, k));
    const std::vector<std::uint8_t> in = insideShape(shape, sites, d / 2);
    std::vector<Vec3> kept;
    for (std::size_t i = 0; i < sites.size(); ++i)
        if (in[i]) kept.push_back(sites[i]);
    if (mesh && cache) {
        cache->store(key, kept);
        ++out.cacheMisses;
    }
    return kept;
}

// A deterministic offset in [-1, 1]^3 for site i of fluid f (splitmix64 of the pair).
Vec3 jitterOffset(std::size_t f, std::size_t i) {
    std::uint64_t z = (std::uint64_t(f) << 40) ^ std::uint64_t(i);
    Vec3 out;
    for (int a = 0; a < 3; ++a) {
        z += 0x9e3779b97f4a7c15ull;
        std::uint64_t x = z;
        x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
        x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
        x ^= x >> 31;
        out[a] = 2 * (Real(x >> 11) / Real(1ull << 53)) - 1;
    }
    return out;
}

// A mesh's surface with spacing <= r: each triangle carries a triangular grid fine enough for its longest edge;
// points closer than r/2 to one already taken (shared edges and corners) are dropped.
std::vector<Vec3> sampleSurface(const TriangleMesh& mesh, Real r) {
    const Real merge = 0.5 * r;
    std::unordered_map<std::uint64_t, std::vector<std::uint32_t>> cells;
    auto key = [&](const Eigen::Vector3i& c) {
        return (std::uint64_t(std::uint32_t(c.x()) & 0x1fffff) << 42) | (std::uint64_t(std::uint32_t(c.y()) & 0x1fffff) << 21) |
               std::uint64_t(std::uint32_t(c.z()) & 0x1fffff);
    };
    std::vector<Vec3> out;
    auto add = [&](const Vec3& p) {
        const Eigen::Vector3i c = (p / merge).array().floor().cast<int>();
        for (int dz = -1; dz <= 1; ++dz)
            for (int dy = -1; dy <= 1; ++dy)
                for (int dx = -1; dx <= 1; ++dx) {
                    auto it = cells.find(key(c + Eigen::Vector3i(dx, dy, dz)));
                    if (it == cells.end()) continue;
                    for (std::uint32_t k : it->second)
                        if ((out[k] - p).squaredNorm() < merge * merge) return;
                }
        cells[key(c)].push_back(std::uint32_t(out.size()));
        out.push_back(p);
    };
    for (const auto& t : mesh.triangles) {
        const Vec3 &a = mesh.vertices[t[0]], &b = mesh.vertices[t[1]], &c = mesh.vertices[t[2]];
        const Real longest = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
        const int n = std::max(1, int(std::ceil(longest / r)));
        for (int i = 0; i <= n; ++i)
            for (int j = 0; i + j <= n; ++j) add(a + (b - a) * (Real(i) / n) + (c - a) * (Real(j) / n));
    }
    return out;
}

}  // namespace

DensityCheck checkDensity(const ParticleSet& fluid, const std::vector<Real>& restDensity,
                          const std::vector<BoundaryBody>& boundaries, const CubicSpline& w) {
    DensityCheck out;
    const std::size_t n = fluid.size();
    if (n == 0) return out;
    const Real h = w.supportRadius();
    UniformGrid fluidGrid(h);
    NeighbourList ff;
    findFluidNeighbours(fluidGrid, fluid.x(), h, ff);

    std::vector<Vec3> bx;
    std::vector<Real> bv;
    for (const auto& b : boundaries) {
        bx.insert(bx.end(), b.x.begin(), b.x.end());
        bv.insert(bv.end(), b.volume.begin(), b.volume.end());
    }
    UniformGrid boundaryGrid(h);
    boundaryGrid.build(bx);
    NeighbourList fb;
    findNeighbours(fluidGrid, fluid.x(), boundaryGrid, bx, h, false, fb);

    // A particle with as many fluid neighbours as the fullest one has no free surface within reach.
    std::size_t fullest = 0;
    for (std::size_t i = 0; i < n; ++i) fullest = std::max(fullest, ff.of(i).size());

    const auto& x = fluid.x();
    const auto& m = fluid.mass();
    Real sumInterior = 0;
    for (std::size_t i = 0; i < n; ++i) {
        Real rho = m[i] * w.W0();
        for (std::uint32_t j : ff.of(i)) rho += m[j] * w.W(x[i] - x[j]);
        for (std::uint32_t k : fb.of(i)) rho += restDensity[i] * bv[k] * w.W(x[i] - bx[k]);
        const Real error = rho / restDensity[i] - 1;
        out.maxCompression = std::max(out.maxCompression, error);
        if (ff.of(i).size() == fullest && fb.of(i).size() == 0) {
            sumInterior += error;
            ++out.interiorCount;
        }
    }
    out.meanInterior = out.interiorCount ? sumInterior / Real(out.interiorCount) : 0;
    return out;
}

Sample sampleScene(const Scene& scene, const SampleCache* cache) {
    Sample out;
    const Real r = scene.particleRadius;
    const Real d = 2 * r;
    const CubicSpline w(supportRadiusFor(r));
    std::vector<Real> restDensity;

    Progress progress("sample", scene.fluids.size() + scene.boundaries.size());
    std::size_t done = 0;
    const Real h = w.supportRadius();
    std::vector<Vec3> allBoundary;
    for (const BoundarySpec& spec : scene.boundaries) {
        BoundaryBody body;
        body.name = spec.name;
        if (auto* box = std::get_if<BoxBoundary>(&spec.shape)) body.x = boxWallPoints(box->min, box->max, box->openTop, r);
        else if (auto* mesh = std::get_if<MeshShape>(&spec.shape)) {
            const std::uint64_t key = sampleKey(*mesh->mesh, "surface", r, 0);
            auto hit = cache ? cache->load(key) : std::nullopt;
            if (hit) ++out.cacheHits;
            body.x = hit ? std::move(*hit) : sampleSurface(*mesh->mesh, r);
            if (cache && !hit) cache->store(key, body.x), ++out.cacheMisses;
        }
        else {
            const auto& plane = std::get<PlaneBoundary>(spec.shape);
            body.x = planePoints(plane.point, plane.normal, scene.domainMin, scene.domainMax, r, h);
        }
        body.volume = boundaryVolumes(body.x, w);
        allBoundary.insert(allBoundary.end(), body.x.begin(), body.x.end());
        out.boundaries.push_back(std::move(body));
        progress.update(++done);
    }
    // Fluid closer to a wall than the lattice spacing would start compressed: a wall stands in for one layer
    // of fluid at that distance (see flatWallCalibration).
    UniformGrid boundaryGrid(d);
    boundaryGrid.build(allBoundary);
    const Real keepDistance2 = (d * (1 - 1e-6)) * (d * (1 - 1e-6));
    auto tooCloseToWall = [&](const Vec3& x) {
        const Vec3 c = (x / d).array().floor();
        for (int dz = -1; dz <= 1; ++dz)
            for (int dy = -1; dy <= 1; ++dy)
                for (int dx = -1; dx <= 1; ++dx) {
                    const std::int64_t cell = boundaryGrid.findCell(std::int64_t(c.x()) + dx, std::int64_t(c.y()) + dy,
                                                                    std::int64_t(c.z()) + dz);
                    if (cell < 0) continue;
                    for (std::size_t s = boundaryGrid.cellBegin(cell); s < boundaryGrid.cellBegin(cell + 1); ++s)
                        if ((allBoundary[boundaryGrid.sortedIndices()[s]] - x).squaredNorm() < keepDistance2) return true;
                }
        return false;
    };

    // Which fluid (or emitter) a particle came from matters only when there are several (per-fluid viscosity,
    // colours); emitters give their particles the indices after the fluids'.
    std::vector<Real>* fluidIndex = scene.sourceMaterials().size() > 1 ? &out.fluid.add(attribute::kFluid) : nullptr;
    for (std::size_t f = 0; f < scene.fluids.size(); ++f) {
        const FluidSpec& spec = scene.fluids[f];
        const Real mass = latticeMass(d, spec.material.density, w);
        const std::vector<Vec3> sites = latticeSites(spec.shape, d, cache, out);
        // Sites an earlier fluid holds, or that lie inside a closed solid, are carved.
        std::vector<std::uint8_t> taken(sites.size(), 0), solid(sites.size(), 0);
        for (std::size_t e = 0; e < f; ++e) {
            const auto in = insideShape(scene.fluids[e].shape, sites, r);
            for (std::size_t i = 0; i < sites.size(); ++i) taken[i] |= in[i];
        }
        for (const BoundarySpec& b : scene.boundaries)
            if (auto* mesh = std::get_if<MeshShape>(&b.shape); mesh && mesh->check.closed()) {
                const auto in = insideMesh(*mesh, sites, r);
                for (std::size_t i = 0; i < sites.size(); ++i) solid[i] |= in[i];
            }
        std::size_t count = 0, byBoundaries = 0;
        for (std::size_t i = 0; i < sites.size(); ++i) {
            const Vec3 x = sites[i] + (spec.jitter > 0 ? Vec3(spec.jitter * d * jitterOffset(f, i)) : Vec3::Zero());
            if (taken[i]) {
                ++out.carved;
                continue;
            }
            if (solid[i] || tooCloseToWall(x)) {
                ++byBoundaries;
                continue;
            }
            out.fluid.add(x, spec.velocity, mass, out.fluid.size());
            if (fluidIndex) fluidIndex->back() = Real(f);
            restDensity.push_back(spec.material.density);
            ++count;
        }
        if (spec.angularVelocity.squaredNorm() > 0 && count > 0) {  // spin about this fluid's centre of mass
            const std::size_t first = out.fluid.size() - count;
            Vec3 centre = Vec3::Zero();
            for (std::size_t i = first; i < out.fluid.size(); ++i) centre += out.fluid.x()[i];
            centre /= Real(count);
            for (std::size_t i = first; i < out.fluid.size(); ++i)
                out.fluid.v()[i] += spec.angularVelocity.cross(out.fluid.x()[i] - centre);
        }
        out.carvedByBoundaries += byBoundaries;
        out.fluidCounts.push_back(count);
        out.fluidSites.push_back(sites.size());
        out.fluidCarvedByBoundaries.push_back(byBoundaries);
        progress.update(++done);
    }
    progress.finish();
    out.density = checkDensity(out.fluid, restDensity, out.boundaries, w);
    return out;
}

}  // namespace ganache
