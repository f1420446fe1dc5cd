// Meshes become particles: volumes against analytic and mesh volumes, meshes with holes and flipped faces,
// placement, surfaces as boundaries, and a fluid that stays in its sampled box.

#include "geometry/shapes.h"
#include "physics/simulation.h"
#include "sampler/inside.h"
#include "sampler/sampler.h"

#include <gtest/gtest.h>

#include <fmt/format.h>

#include <filesystem>
#include <fstream>

using namespace ganache;
namespace fs = std::filesystem;

namespace {

const fs::path kSource = GANACHE_SOURCE_DIR;

fs::path tempDir() {
    const fs::path dir = fs::temp_directory_path() / "ganache_mesh_test";
    fs::create_directories(dir);
    return dir;
}

Scene sceneFrom(const std::string& name, const std::string& body, const std::string& quality = "final") {
    std::ofstream(tempDir() / (name + ".yaml")) << "ganache: 1\n" << body;
    return loadScene(tempDir() / (name + ".yaml"), Quality::parse(quality));
}

// Writes a mesh as Wavefront OBJ, so tests go through the same assimp loading as artists' files.
fs::path writeObj(const std::string& name, const TriangleMesh& m) {
    const fs::path file = tempDir() / (name + ".obj");
    std::ofstream out(file);
    for (const Vec3& v : m.vertices) out << fmt::format("v {:.17g} {:.17g} {:.17g}\n", v.x(), v.y(), v.z());
    for (const auto& t : m.triangles) out << fmt::format("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
    return file;
}

std::size_t fluidCount(const std::string& name, const std::string& meshKey, Real r) {
    const Scene s = sceneFrom(name, fmt::format(R"(particles: {{radius: {}}}
domain: {{min: [-1, -1, -1], max: [1, 1, 1]}}
fluids: [{{mesh: {}}}]
)",
                                                r, meshKey));
    return sampleScene(s).fluid.size();
}

}  // namespace

TEST(MeshSampler, SphereAndCubeVolumesWithinTwoPercent) {
    // R / r = 25 as for the analytic sphere: the lattice volume N (2r)^3 differs from the shape's volume by a
    // boundary layer of relative size about r / R, below 2 %. Both inside tests must give it.
    const Real r = 0.004, R = 0.1;
    const fs::path sphere = writeObj("sphere", sphereMesh(Vec3::Zero(), R, 0.002));
    const fs::path cube = writeObj("cube", boxMesh(Vec3(-0.1, -0.1, -0.1), Vec3(0.1, 0.1, 0.1)));
    const Real cell = std::pow(2 * r, 3);
    for (const char* method : {"level_set", "winding_number"}) {
        SCOPED_TRACE(method);
        const Real vs = Real(fluidCount("sphere", fmt::format("{{file: {}, inside: {}}}", sphere.string(), method), r)) * cell;
        EXPECT_NEAR(vs / (4.0 / 3.0 * M_PI * R * R * R), 1.0, 0.02);
        const Real vc = Real(fluidCount("cube", fmt::format("{{file: {}, inside: {}}}", cube.string(), method), r)) * cell;
        EXPECT_NEAR(vc / 0.008, 1.0, 0.02);
    }
}

TEST(MeshSampler, BunnyHoldsItsMeshVolume) {
    const fs::path bunny = kSource / "assets/cgal/bunny00.off";
    ASSERT_TRUE(fs::exists(bunny)) << "run scripts/assets.sh (scripts/setup.sh does) to fetch the bunny";
    const Scene s = sceneFrom("bunny", fmt::format(R"(particles: {{radius: 0.002}}
domain: {{min: [-1, -1, -1], max: [1, 1, 1]}}
fluids: [{{mesh: {{file: {}, fit: {{size: 0.2, centre: [0, 0, 0]}}}}}}]
)",
                                                   bunny.string()));
    const MeshShape& m = std::get<MeshShape>(s.fluids[0].shape);
    EXPECT_TRUE(m.check.closed());
    EXPECT_EQ(m.method(), InsideMethod::LevelSet);
    const Real sampled = Real(sampleScene(s).fluid.size()) * std::pow(0.004, 3);
    std::printf("bunny: mesh volume %.6g m^3, sampled %.6g m^3\n", m.check.volume, sampled);
    EXPECT_NEAR(sampled / m.check.volume, 1.0, 0.02);  // the same 1/(size/r) boundary layer as the sphere
}

TEST(MeshSampler, HolesAndFlippedFacesSampleTheClosedInterior) {
    // A sphere with 5 % of its faces removed (holes) and, separately, every third face flipped: winding numbers
    // (and orientation repair) must give the interior of the closed sphere. Sites whose answer may change lie
    // near the holes; 1 % of the sites is a generous bound for 5 % missing surface spread over the sphere.
    const TriangleMesh closed = sphereMesh(Vec3::Zero(), 0.1, 0.01);
    TriangleMesh holes = closed, flipped = closed;
    holes.triangles.clear();
    for (std::size_t t = 0; t < closed.triangles.size(); ++t)
        if (t % 20 != 7) holes.triangles.push_back(closed.triangles[t]);
    for (std::size_t t = 0; t < flipped.triangles.size(); t += 3) std::swap(flipped.triangles[t][1], flipped.triangles[t][2]);

    const std::string base = R"(particles: {radius: 0.004}
domain: {min: [-1, -1, -1], max: [1, 1, 1]}
fluids: [{mesh: {file: FILE}}]
)";
    auto sample = [&](const std::string& name, const TriangleMesh& m) {
        std::string text = base;
        text.replace(text.find("FILE"), 4, writeObj(name, m).string());
        const Scene s = sceneFrom(name, text);
        return std::make_pair(std::get<MeshShape>(s.fluids[0].shape), sampleScene(s).fluid.x());
    };
    const auto [closedShape, reference] = sample("closed", closed);
    const auto [holeShape, withHoles] = sample("holes", holes);
    const auto [flippedShape, withFlips] = sample("flipped", flipped);
    EXPECT_EQ(closedShape.method(), InsideMethod::LevelSet);
    EXPECT_GT(holeShape.check.boundaryEdges, 0u);
    EXPECT_EQ(holeShape.method(), InsideMethod::WindingNumber);
    EXPECT_GT(flippedShape.check.flippedTriangles, 0u);
    EXPECT_TRUE(flippedShape.check.closed());

    const auto differ = [](const std::vector<Vec3>& a, const std::vector<Vec3>& b) {
        std::set<std::array<long, 3>> sa, sb;
        for (const Vec3& x : a) sa.insert({std::lround(x.x() * 1e5), std::lround(x.y() * 1e5), std::lround(x.z() * 1e5)});
        for (const Vec3& x : b) sb.insert({std::lround(x.x() * 1e5), std::lround(x.y() * 1e5), std::lround(x.z() * 1e5)});
        std::size_t n = 0;
        for (const auto& k : sa) n += !sb.count(k);
        for (const auto& k : sb) n += !sa.count(k);
        return n;
    };
    std::printf("sites: closed %zu, with holes %zu (%zu differ), flipped %zu (%zu differ)\n", reference.size(),
                withHoles.size(), differ(reference, withHoles), withFlips.size(), differ(reference, withFlips));
    EXPECT_LE(differ(reference, withHoles), reference.size() / 100);
    EXPECT_EQ(differ(reference, withFlips), 0u);
}

TEST(MeshSampler, WindingNumberIsOneInsideAndZeroOutside) {
    const TriangleMesh cube = boxMesh(Vec3::Zero(), Vec3::Ones());
    const WindingNumber w(cube);
    EXPECT_NEAR(w.at(Vec3(0.5, 0.5, 0.5)), 1.0, 1e-12);
    EXPECT_NEAR(w.at(Vec3(0.1, 0.9, 0.2)), 1.0, 1e-12);
    EXPECT_NEAR(w.at(Vec3(2, 0.5, 0.5)), 0.0, 1e-12);
    // Far from a fine sphere's triangles the tree answers with dipoles (first order): a few percent off 1 at the
    // centre and off 0 outside, far inside the margin of the 0.5 threshold that decides inside.
    const TriangleMesh sphere = sphereMesh(Vec3::Zero(), 1, 0.05);
    const WindingNumber ws(sphere);
    EXPECT_NEAR(ws.at(Vec3::Zero()), 1.0, 0.05);
    EXPECT_NEAR(ws.at(Vec3(0.5, 0.3, -0.2)), 1.0, 0.05);
    EXPECT_NEAR(ws.at(Vec3(3, 1, 2)), 0.0, 0.05);
    EXPECT_NEAR(ws.at(Vec3(1.1, 0, 0)), 0.0, 0.05);
}

TEST(MeshSampler, ReadsObjPlyStlOffAndGltf) {
    // The unit cube in each format an artist is likely to hand over; each must load as a closed mesh of volume 1.
    const TriangleMesh cube = boxMesh(Vec3::Zero(), Vec3::Ones());
    const fs::path dir = tempDir();
    writeObj("cube_obj", cube);
    {
        std::ofstream ply(dir / "cube_ply.ply");
        ply << "ply\nformat ascii 1.0\nelement vertex 8\nproperty float x\nproperty float y\nproperty float z\n"
               "element face 12\nproperty list uchar int vertex_indices\nend_header\n";
        for (const Vec3& v : cube.vertices) ply << v.x() << " " << v.y() << " " << v.z() << "\n";
        for (const auto& t : cube.triangles) ply << "3 " << t[0] << " " << t[1] << " " << t[2] << "\n";
        std::ofstream off(dir / "cube_off.off");
        off << "OFF\n8 12 0\n";
        for (const Vec3& v : cube.vertices) off << v.x() << " " << v.y() << " " << v.z() << "\n";
        for (const auto& t : cube.triangles) off << "3 " << t[0] << " " << t[1] << " " << t[2] << "\n";
        std::ofstream stl(dir / "cube_stl.stl");
        stl << "solid cube\n";
        for (const auto& t : cube.triangles) {
            stl << " facet normal 0 0 0\n  outer loop\n";
            for (std::uint32_t v : t)
                stl << "   vertex " << cube.vertices[v].x() << " " << cube.vertices[v].y() << " " << cube.vertices[v].z() << "\n";
            stl << "  endloop\n endfacet\n";
        }
        stl << "endsolid cube\n";
    }
    {
        // glTF 2.0 with its buffer embedded as base64: 8 float positions, then 36 unsigned-short indices.
        std::string bytes;
        for (const Vec3& v : cube.vertices)
            for (int a = 0; a < 3; ++a) {
                const float f = float(v[a]);
                bytes.append(reinterpret_cast<const char*>(&f), 4);
            }
        for (const auto& t : cube.triangles)
            for (std::uint32_t v : t) {
                const std::uint16_t i = std::uint16_t(v);
                bytes.append(reinterpret_cast<const char*>(&i), 2);
            }
        static const char* b64 = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
        std::string encoded;
        for (std::size_t i = 0; i < bytes.size(); i += 3) {
            std::uint32_t n = std::uint32_t(std::uint8_t(bytes[i])) << 16;
            if (i + 1 < bytes.size()) n |= std::uint32_t(std::uint8_t(bytes[i + 1])) << 8;
            if (i + 2 < bytes.size()) n |= std::uint8_t(bytes[i + 2]);
            encoded += b64[(n >> 18) & 63];
            encoded += b64[(n >> 12) & 63];
            encoded += i + 1 < bytes.size() ? b64[(n >> 6) & 63] : '=';
            encoded += i + 2 < bytes.size() ? b64[n & 63] : '=';
        }
        std::ofstream(dir / "cube_gltf.gltf") << fmt::format(
            R"({{"asset": {{"version": "2.0"}}, "scene": 0, "scenes": [{{"nodes": [0]}}], "nodes": [{{"mesh": 0}}],
"meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}, "indices": 1}}]}}],
"buffers": [{{"byteLength": {0}, "uri": "data:application/octet-stream;base64,{1}"}}],
"bufferViews": [{{"buffer": 0, "byteOffset": 0, "byteLength": 96}}, {{"buffer": 0, "byteOffset": 96, "byteLength": 72}}],
"accessors": [{{"bufferView": 0, "componentType": 5126, "count": 8, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 1]}},
              {{"bufferView": 1, "componentType": 5123, "count": 36, "type": "SCALAR"}}]}})",
            bytes.size(), encoded);
    }
    for (const char* name : {"cube_obj.obj", "cube_ply.ply", "cube_stl.stl", "cube_off.off", "cube_gltf.gltf"}) {
        SCOPED_TRACE(name);
        TriangleMesh m = readMeshFile(dir / name);
        const MeshCheck c = repairMesh(m);
        EXPECT_TRUE(c.closed()) << c.boundaryEdges << " boundary edges";
        EXPECT_NEAR(c.volume, 1.0, 1e-6);
        EXPECT_EQ(c.triangles, 12u);
    }
}

TEST(MeshSampler, JitterMovesParticlesRepeatablyWithinItsBound) {
    auto sample = [](const std::string& jitter) {
        return sampleScene(sceneFrom(jitter == "0" ? "jitter_off" : "jitter_on", R"(particles: {radius: 0.01}
domain: {min: [-1, -1, -1], max: [1, 1, 1]}
fluids: [{jitter: )" + jitter + R"(, box: {min: [0, 0, 0], max: [0.2, 0.2, 0.2]}}]
)"));
    };
    const Sample plain = sample("0"), a = sample("0.2"), b = sample("0.2");
    ASSERT_EQ(plain.fluid.size(), a.fluid.size());
    EXPECT_EQ(a.fluid.x(), b.fluid.x()) << "the same scene samples the same particles";
    Real largest = 0;
    for (std::size_t i = 0; i < a.fluid.size(); ++i)
        largest = std::max(largest, (a.fluid.x()[i] - plain.fluid.x()[i]).cwiseAbs().maxCoeff());
    EXPECT_LE(largest, 0.2 * 0.02 + 1e-12);
    EXPECT_GT(largest, 0.1 * 0.02);
    // A jittered start is compressed somewhere, and the sample says by how much.
    EXPECT_GT(a.density.maxCompression, plain.density.maxCompression);
}

TEST(MeshSampler, PlacementIsAppliedAsDocumented) {
    TriangleMesh m = boxMesh(Vec3::Zero(), Vec3(1, 2, 3));
    MeshPlacement p;
    p.scale = Vec3(2, 1, 1);
    p.rotationDegrees = Vec3(0, 90, 0);  // about y: x -> -z, z -> x
    p.translation = Vec3(10, 0, 0);
    TriangleMesh a = m;
    placeMesh(a, p);
    auto [lo, hi] = a.bounds();
    EXPECT_TRUE(lo.isApprox(Vec3(10, 0, -2), 1e-12)) << lo.transpose();
    EXPECT_TRUE(hi.isApprox(Vec3(13, 2, 0), 1e-12)) << hi.transpose();
    EXPECT_NEAR(a.signedVolume(), 12.0, 1e-9);

    // A mirror keeps the faces outward.
    TriangleMesh mirrored = m;
    MeshPlacement mirror;
    mirror.scale = Vec3(-1, 1, 1);
    placeMesh(mirrored, mirror);
    EXPECT_NEAR(mirrored.signedVolume(), 6.0, 1e-9);

    // fit: the largest extent becomes `size`; base puts the bottom centre on the point.
    TriangleMesh fitted = m;
    MeshPlacement fit;
    fit.fit = MeshPlacement::Fit{0.3, Vec3(1, 0, 1), true};
    placeMesh(fitted, fit);
    std::tie(lo, hi) = fitted.bounds();
    EXPECT_NEAR((hi - lo).maxCoeff(), 0.3, 1e-12);
    EXPECT_NEAR(lo.y(), 0.0, 1e-12);
    EXPECT_TRUE((0.5 * (lo + hi)).cwiseProduct(Vec3(1, 0, 1)).isApprox(Vec3(1, 0, 1), 1e-12));
}

TEST(MeshSampler, ProceduralSolidsAreClosedAndSampledDensely) {
    const Scene s = sceneFrom("solids", R"(particles: {radius: 0.005}
domain: {min: [-1, -1, -1], max: [1, 1, 1]}
fluids: [{box: {min: [-0.3, 0.3, -0.3], max: [0.3, 0.4, 0.3]}}]
boundaries:
  - {name: ball, sphere: {centre: [0, 0, 0], radius: 0.1}}
  - {name: post, cylinder: {from: [0.3, -0.2, 0], to: [0.3, 0.2, 0], radius: 0.03}}
  - {name: grid, bars: {centre: [0, -0.3, 0], size: 0.4, count: 5, thickness: 0.02}}
  - {name: hook, dough_hook: {top: [-0.3, 0.25, 0], shaft_length: 0.1, radius: 0.05, helix_height: 0.15, turns: 1.5, rod_radius: 0.01}}
)");
    const Sample out = sampleScene(s);
    ASSERT_EQ(out.boundaries.size(), 4u);
    for (const BoundarySpec& b : s.boundaries) {
        SCOPED_TRACE(b.name);
        const MeshShape& m = std::get<MeshShape>(b.shape);
        EXPECT_EQ(m.check.boundaryEdges, 0u);
        EXPECT_GT(m.check.volume, 0.0);
    }
    // The sphere's surface: every boundary particle on it, and no point of it farther than r from one.
    const auto& ball = out.boundaries[0].x;
    for (const Vec3& x : ball) EXPECT_NEAR(x.norm(), 0.1, 0.001);
    for (int k = 0; k < 200; ++k) {
        const Vec3 dir = Vec3(std::sin(k * 1.3) * std::cos(k * 0.7), std::cos(k * 1.3), std::sin(k * 1.3) * std::sin(k * 0.7)).normalized();
        Real nearest = 1;
        for (const Vec3& x : ball) nearest = std::min(nearest, (x - 0.1 * dir).norm());
        EXPECT_LE(nearest, 0.005) << dir.transpose();
    }
    // The bars are ten overlapping boxes of 0.4 x 0.02 x 0.02; a mesh's signed volume adds its pieces, so the
    // crossings count twice.
    EXPECT_NEAR(std::get<MeshShape>(s.boundaries[2].shape).check.volume, 10 * 0.4 * 0.02 * 0.02, 1e-9);
    EXPECT_EQ(std::get<MeshShape>(s.boundaries[2].shape).check.components, 10u);
}

TEST(MeshSampler, FluidInsideAClosedSolidIsCarved) {
    const fs::path cube = writeObj("solid_cube", boxMesh(Vec3(-0.1, -0.1, -0.1), Vec3(0.1, 0.1, 0.1)));
    const Scene s = sceneFrom("carved", fmt::format(R"(particles: {{radius: 0.01}}
domain: {{min: [-1, -1, -1], max: [1, 1, 1]}}
fluids: [{{box: {{min: [-0.2, -0.2, -0.2], max: [0.2, 0.2, 0.2]}}}}]
boundaries: [{{name: block, mesh: {{file: {}}}}}]
)",
                                                     cube.string()));
    const Sample out = sampleScene(s);
    for (const Vec3& x : out.fluid.x())
        EXPECT_FALSE((x.array().abs() < 0.1 + 0.02 - 1e-9).all()) << "fluid inside or within 2r of the solid at " << x.transpose();
    EXPECT_GT(out.fluid.size(), 0u);
}

TEST(MeshSampler, AnOpenContainerMeshHoldsItsFluid) {
    // A box mesh without its top: five thin walls, not closed, so nothing is carved as "inside" and the fluid
    // dropped into it (falling 2 cm with a sideways push) stays between its walls for half a second. At this
    // coarse resolution (144 particles) single particles splash high: with 5 cm and twice the push one cleared
    // a 0.3 m wall, so the walls are tall and the drop gentle; what is tested is that none passes a wall.
    TriangleMesh cup = boxMesh(Vec3(-0.1, 0, -0.1), Vec3(0.1, 0.3, 0.1));
    std::vector<std::array<std::uint32_t, 3>> walls;
    for (const auto& t : cup.triangles) {
        bool top = true;
        for (std::uint32_t v : t) top = top && cup.vertices[v].y() > 0.15;
        if (!top) walls.push_back(t);
    }
    cup.triangles = walls;
    const fs::path file = writeObj("cup", cup);
    const Scene s = sceneFrom("cup", fmt::format(R"(particles: {{radius: 0.01}}
domain: {{min: [-0.5, -0.5, -0.5], max: [0.5, 0.5, 0.5]}}
fluids: [{{velocity: [0.5, 0, 0.25], box: {{min: [-0.06, 0.04, -0.06], max: [0.06, 0.12, 0.06]}}}}]
boundaries: [{{name: cup, mesh: {{file: {}}}}}]
effects: {{gravity: {{}}}}
)",
                                                 file.string()));
    const MeshShape& m = std::get<MeshShape>(s.boundaries[0].shape);
    EXPECT_FALSE(m.check.closed());
    EXPECT_EQ(m.check.boundaryEdges, 4u);
    Sample out = sampleScene(s);
    const std::size_t n = out.fluid.size();
    EXPECT_EQ(n, 6u * 4u * 6u) << "no site carved as inside the open cup";
    Simulation sim(simulationSetup(s), std::move(out.fluid), out.boundaries);
    sim.advanceTo(0.5);
    ASSERT_EQ(sim.particles().size(), n);
    for (const Vec3& x : sim.particles().x())
        EXPECT_TRUE(std::abs(x.x()) < 0.1 && std::abs(x.z()) < 0.1 && x.y() > 0) << x.transpose();
}

TEST(MeshSampler, CachedInputsGiveTheSameSampleAndCorruptOnesAreRedone) {
    const fs::path sphere = writeObj("cached_sphere", sphereMesh(Vec3::Zero(), 0.1, 0.01));
    const fs::path folder = tempDir() / "cache";
    fs::remove_all(folder);
    auto scene = [&](const std::string& radius) {
        return sceneFrom("cached", fmt::format(R"(particles: {{radius: {}}}
domain: {{min: [-1, -1, -1], max: [1, 1, 1]}}
fluids: [{{mesh: {{file: {}}}}}]
boundaries: [{{name: post, cylinder: {{from: [0.3, 0, 0], to: [0.3, 0.2, 0], radius: 0.05}}}}]
)",
                                               radius, sphere.string()));
    };
    const SampleCache cache(folder);
    const Sample first = sampleScene(scene("0.01"), &cache);
    EXPECT_EQ(first.cacheHits, 0u);
    EXPECT_EQ(first.cacheMisses, 2u);  // the fluid's sites and the post's surface
    const Sample again = sampleScene(scene("0.01"), &cache);
    EXPECT_EQ(again.cacheHits, 2u);
    EXPECT_EQ(again.fluid.x(), first.fluid.x());
    EXPECT_EQ(again.boundaries[0].x, first.boundaries[0].x);
    // Another radius is another key.
    EXPECT_EQ(sampleScene(scene("0.012"), &cache).cacheHits, 0u);
    // A damaged file is a miss, sampled again and rewritten.
    for (const auto& e : fs::directory_iterator(folder)) {
        std::fstream f(e.path(), std::ios::in | std::ios::out | std::ios::binary);
        f.seekp(30);
        f.put('\x5a');
    }
    const Sample repaired = sampleScene(scene("0.01"), &cache);
    EXPECT_EQ(repaired.cacheHits, 0u);
    EXPECT_EQ(repaired.fluid.x(), first.fluid.x());
    EXPECT_EQ(sampleScene(scene("0.01"), &cache).cacheHits, 2u);
}

TEST(MeshSampler, FluidInAClosedBoxNeverLeavesItOverASecond) {
    // Water thrown against the walls of a closed box for a simulated second: every particle stays inside.
    const Scene s = sceneFrom("sloshing", R"(particles: {radius: 0.01}
domain: {min: [-0.5, -0.5, -0.5], max: [0.5, 0.5, 0.5]}
fluids: [{velocity: [2, 1, 0], box: {min: [-0.15, -0.15, -0.15], max: [0.05, 0.05, 0.05]}}]
boundaries: [{name: tank, box: {min: [-0.2, -0.2, -0.2], max: [0.2, 0.2, 0.2]}}]
effects: {gravity: {}}
)");
    Sample out = sampleScene(s);
    const std::size_t n = out.fluid.size();
    Simulation sim(simulationSetup(s), std::move(out.fluid), out.boundaries);
    for (Real t = 0.1; t <= 1.0 + 1e-9; t += 0.1) {
        sim.advanceTo(t);
        for (const Vec3& x : sim.particles().x())
            ASSERT_TRUE((x.array().abs() < 0.2).all()) << "t = " << t << ": particle at " << x.transpose() << ", "
                                                         << sim.stats().steps << " steps";
    }
    EXPECT_EQ(sim.particles().size(), n);
}
