// anchor_metrics: the shape and the compression of a particle set, measured the same way whichever program wrote it
// (a ganache particle cache, or a SPlisHSPlasH VTK particle file), for benchmarks/anchors.sh.
//
//   anchor_metrics --radius R --rho0 RHO --mass lattice|splishsplash [--floor Y] FILE
//
// Prints one JSON object: particle count, centroid, spread (RMS horizontal distance from the centroid's vertical),
// the 99th percentile and the largest height, and the compression max(0, rho / rho_0 - 1) (mean and largest) with
// rho = sum_j m_j W_ij over the fluid plus, with --floor, a plane at height Y sampled as ganache samples walls (Akinci
// boundary particles with flat-wall calibrated volumes). Each program's own particle mass is used (--mass): ganache
// gives each lattice particle the mass that makes the lattice rest density, SPlisHSPlasH gives m = 0.8 (2r)^3 rho_0.
// Where the largest compression is (a lone outlier or the bulk) is told by the most compressed particle's position,
// its nearest neighbour's distance in particle diameters, and the compression of the 99.9th percentile. Whether the
// fluid sits at its rest density at all is told by the bulk's median density error (rho / rho_0 - 1, signed, over the
// particles with at least the median neighbour count): SPlisHSPlasH's lattice mass starts a block 20 % light, and a
// solve that only pushes leaves it so until it is squeezed.

#include "core/kernels.h"
#include "core/neighbour_search.h"
#include "io/particle_cache.h"
#include "physics/boundary.h"

#include <fmt/format.h>

#include <algorithm>
#include <cstring>
#include <fstream>
#include <iostream>
#include <limits>
#include <string>
#include <vector>

using namespace ganache;

namespace {

// Positions of a legacy binary VTK file as SPlisHSPlasH writes it: "POINTS n float", big-endian.
std::vector<Vec3> readVtkPoints(const std::string& file) {
    std::ifstream in(file, std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const std::size_t at = bytes.find("POINTS ");
    if (at == std::string::npos) throw std::runtime_error(file + ": no POINTS section");
    const std::size_t eol = bytes.find('\n', at);
    std::size_t n = 0;
    char type[16] = {};
    if (std::sscanf(bytes.c_str() + at, "POINTS %zu %15s", &n, type) != 2 || std::string(type) != "float")
        throw std::runtime_error(file + ": expected `POINTS n float`");
    if (eol + 1 + 12 * n > bytes.size()) throw std::runtime_error(file + ": truncated");
    std::vector<Vec3> x(n);
    for (std::size_t i = 0; i < n; ++i)
        for (int c = 0; c < 3; ++c) {
            unsigned char b[4];
            std::memcpy(b, bytes.data() + eol + 1 + 12 * i + 4 * c, 4);
            std::swap(b[0], b[3]);
            std::swap(b[1], b[2]);
            float f;
            std::memcpy(&f, b, 4);
            x[i][c] = f;
        }
    return x;
}

}  // namespace

int main(int argc, char** argv) {
    Real radius = 0, rho0 = 1000, floorY = 0;
    bool floor = false, splishsplash = false;
    std::string file;
    for (int a = 1; a < argc; ++a) {
        const std::string arg = argv[a];
        if (arg == "--radius" && a + 1 < argc) radius = std::stod(argv[++a]);
        else if (arg == "--rho0" && a + 1 < argc) rho0 = std::stod(argv[++a]);
        else if (arg == "--floor" && a + 1 < argc) floor = true, floorY = std::stod(argv[++a]);
        else if (arg == "--mass" && a + 1 < argc) splishsplash = std::string(argv[++a]) == "splishsplash";
        else file = arg;
    }
    if (file.empty() || radius <= 0) {
        std::cerr << "usage: anchor_metrics --radius R --rho0 RHO --mass lattice|splishsplash [--floor Y] FILE\n";
        return 2;
    }
    try {
        const bool vtk = file.size() > 4 && file.compare(file.size() - 4, 4, ".vtk") == 0;
        const std::vector<Vec3> x = vtk ? readVtkPoints(file) : readParticleCache(file).fluid.x();
        const std::size_t n = x.size();
        const CubicSpline w(supportRadiusFor(radius));
        const Real h = w.supportRadius(), d = 2 * radius;
        const Real mass = splishsplash ? Real(0.8) * d * d * d * rho0 : latticeMass(d, rho0, w);

        Vec3 lo = Vec3::Constant(1e30), hi = -lo, centre = Vec3::Zero();
        for (const Vec3& p : x) lo = lo.cwiseMin(p), hi = hi.cwiseMax(p), centre += p / Real(n);
        std::vector<Real> heights;
        Real spread = 0;
        for (const Vec3& p : x) {
            spread += ((p.x() - centre.x()) * (p.x() - centre.x()) + (p.z() - centre.z()) * (p.z() - centre.z())) / Real(n);
            heights.push_back(p.y());
        }
        std::sort(heights.begin(), heights.end());

        UniformGrid grid(h);
        NeighbourList fluid;
        findFluidNeighbours(grid, x, h, fluid);
        std::vector<Vec3> wall;
        std::vector<Real> volume;
        NeighbourList near;
        UniformGrid wallGrid(h);
        if (floor) {
            // Sampled 2h past the fluid on every side, so that every wall particle within reach of the fluid has its
            // whole neighbourhood for its volume (at the sheet's edge, short of it, the wall weighed more).
            wall = planePoints(Vec3(0, floorY, 0), Vec3::UnitY(), lo.array() - 2 * h, hi.array() + 2 * h, radius, h);
            volume = boundaryVolumes(wall, w);
            wallGrid.build(wall);
            findNeighbours(grid, x, wallGrid, wall, h, false, near);
        }
        Real meanCompression = 0, maxCompression = 0;
        std::size_t worst = 0;
        std::vector<std::pair<std::size_t, Real>> error(n);  // (neighbour count, rho / rho_0 - 1)
        for (std::size_t i = 0; i < n; ++i) {
            Real rho = mass * w.W0();
            for (std::uint32_t j : fluid.of(i)) rho += mass * w.W(x[i] - x[j]);
            if (floor)
                for (std::uint32_t k : near.of(i)) rho += rho0 * volume[k] * w.W(x[i] - wall[k]);
            const Real c = std::max<Real>(0, rho / rho0 - 1);
            meanCompression += c / Real(n);
            if (c > maxCompression) maxCompression = c, worst = i;
            error[i] = {fluid.of(i).size(), rho / rho0 - 1};
        }
        // The 99.9th percentile of compression (of the error: compression is its positive part), then the median error
        // of the upper half by neighbour count.
        std::vector<Real> sorted(n);
        for (std::size_t i = 0; i < n; ++i) sorted[i] = error[i].second;
        std::sort(sorted.begin(), sorted.end());
        const Real p999 = n ? std::max<Real>(0, sorted[std::size_t(0.999 * Real(n - 1))]) : 0;
        std::sort(error.begin(), error.end());
        std::vector<Real> inner;
        for (std::size_t i = n / 2; i < n; ++i) inner.push_back(error[i].second);
        std::sort(inner.begin(), inner.end());
        Real nearest = std::numeric_limits<Real>::infinity();
        for (std::uint32_t j : fluid.of(worst)) nearest = std::min(nearest, (x[worst] - x[j]).norm() / d);
        if (!std::isfinite(nearest)) nearest = 0;  // no neighbour, and JSON has no infinity
        // The most compressed particle's place, or null where none is compressed.
        const std::string at = maxCompression > 0 ? fmt::format("[{:.6f}, {:.6f}, {:.6f}]", x[worst].x(), x[worst].y(),
                                                                 x[worst].z())
                                                  : "null";
        fmt::print("{{\"file\": \"{}\", \"n\": {}, \"centroid\": [{:.6f}, {:.6f}, {:.6f}], \"spread_m\": {:.6f}, "
                   "\"height_p99_m\": {:.6f}, \"height_max_m\": {:.6f}, \"compression_mean\": {:.6g}, "
                   "\"compression_max\": {:.6g}, \"compression_p999\": {:.6g}, \"most_compressed_at\": {}, "
                   "\"most_compressed_nearest_d\": {:.4f}, \"bulk_density_error_median\": {:.6g}}}\n",
                   file, n, centre.x(), centre.y(), centre.z(), std::sqrt(spread),
                   heights.empty() ? 0.0 : heights[std::size_t(0.99 * Real(heights.size() - 1))],
                   heights.empty() ? 0.0 : heights.back(), meanCompression, maxCompression,
                   p999, at, maxCompression > 0 ? nearest : 0.0,
                   inner.empty() ? 0.0 : inner[inner.size() / 2]);
    } catch (const std::exception& e) {
        std::cerr << "anchor_metrics: " << e.what() << "\n";
        return 1;
    }
    return 0;
}
