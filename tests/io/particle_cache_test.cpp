#include "io/particle_cache.h"

#include "core/errors.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

using namespace ganache;
namespace fs = std::filesystem;

namespace {

fs::path tempDir() {
    const fs::path d = fs::temp_directory_path() / "ganache_cache_test";
    fs::create_directories(d);
    return d;
}

ParticleSet someParticles() {
    ParticleSet p;
    p.addScalar("temperature");
    for (int i = 0; i < 500; ++i) {
        const Real t = Real(i);
        p.add(Vec3(0.01 * std::sin(t), -0.3 + 0.001 * t, 0.02 * std::cos(0.7 * t)), Vec3(t, -t, 0.5), 1e-3 + 1e-7 * t,
              std::uint64_t(1000 - i));
        p.findScalar("temperature")->back() = 20 + 0.1 * t;
    }
    return p;
}

}  // namespace

TEST(ParticleCache, SaveReloadCompare) {
    const ParticleSet p = someParticles();
    std::vector<BoundaryBody> bodies{{"floor", {Vec3(0, -1, 0), Vec3(0.1, -1, 0)}, {1e-6, 2e-6}},
                                     {"wall", {Vec3(1, 0, 0)}, {3e-6}}};
    const fs::path file = tempDir() / "roundtrip.0001.vdb";
    writeParticleCache(file, p, bodies, {"roundtrip", 7, 0.25, 24, 0.005});

    const CacheContents c = readParticleCache(file);
    EXPECT_EQ(c.info.scene, "roundtrip");
    EXPECT_EQ(c.info.frame, 7);
    EXPECT_DOUBLE_EQ(c.info.time, 0.25);
    EXPECT_DOUBLE_EQ(c.info.particleRadius, 0.005);
    ASSERT_EQ(c.fluid.size(), p.size());
    ParticleSet expected = p;
    expected.sortById();
    const Real voxel = 4 * 0.005;
    for (std::size_t i = 0; i < p.size(); ++i) {
        EXPECT_EQ(c.fluid.id()[i], expected.id()[i]);
        // 32-bit offsets within a voxel: error below 1e-6 of a voxel.
        EXPECT_LT((c.fluid.x()[i] - expected.x()[i]).norm(), 1e-6 * voxel);
        // 32-bit floats: 1e-6 relative.
        EXPECT_LT((c.fluid.v()[i] - expected.v()[i]).norm(), 1e-6 * (1 + expected.v()[i].norm()));
        EXPECT_DOUBLE_EQ(c.fluid.mass()[i], expected.mass()[i]);  // stored in double
        EXPECT_NEAR((*c.fluid.findScalar("temperature"))[i], (*expected.findScalar("temperature"))[i], 1e-4);
    }
    ASSERT_EQ(c.boundaries.size(), 2u);
    EXPECT_EQ(c.boundaries[0].name, "floor");
    EXPECT_EQ(c.boundaries[1].name, "wall");
    EXPECT_EQ(c.boundaries[0].x.size(), 2u);
    ASSERT_EQ(c.boundaries[1].volume.size(), 1u);
    EXPECT_DOUBLE_EQ(c.boundaries[1].volume[0], 3e-6);
    // Only the attributes the particles have: no effect attribute appears uninvited.
    EXPECT_EQ(c.fluid.findScalar("viscosity"), nullptr);
}

TEST(ParticleCache, EmptySetWritesAValidFile) {
    const fs::path file = tempDir() / "empty.vdb";
    writeParticleCache(file, ParticleSet(), {}, {"empty", 1, 0, 24, 0.01});
    const CacheContents c = readParticleCache(file);
    EXPECT_EQ(c.fluid.size(), 0u);
    EXPECT_TRUE(c.boundaries.empty());
}

TEST(ParticleCache, WritesLeaveNoTemporaryFiles) {
    const fs::path dir = tempDir() / "atomic";
    fs::remove_all(dir);
    writeParticleCache(dir / "a.vdb", someParticles(), {}, {"a", 1, 0, 24, 0.01});
    std::size_t files = 0;
    for (const auto& e : fs::directory_iterator(dir)) {
        EXPECT_EQ(e.path().filename(), "a.vdb");
        ++files;
    }
    EXPECT_EQ(files, 1u);
}

TEST(ParticleCache, MissingOrCorruptFilesAreInputErrors) {
    EXPECT_THROW(readParticleCache(tempDir() / "does_not_exist.vdb"), InputError);
    const fs::path junk = tempDir() / "junk.vdb";
    std::ofstream(junk) << "not a vdb file";
    try {
        readParticleCache(junk);
        FAIL() << "junk accepted";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("junk.vdb"), std::string::npos);
    }
    // A truncated real cache.
    const fs::path good = tempDir() / "truncated.vdb";
    writeParticleCache(good, someParticles(), {}, {"t", 1, 0, 24, 0.01});
    fs::resize_file(good, fs::file_size(good) / 2);
    EXPECT_THROW(readParticleCache(good), InputError);
    // One flipped byte in the middle of a complete cache.
    const fs::path flipped = tempDir() / "flipped.vdb";
    writeParticleCache(flipped, someParticles(), {}, {"f", 1, 0, 24, 0.01});
    {
        std::fstream f(flipped, std::ios::in | std::ios::out | std::ios::binary);
        f.seekg(std::streamoff(fs::file_size(flipped) / 2));
        char c = 0;
        f.get(c);
        f.seekp(std::streamoff(fs::file_size(flipped) / 2));
        f.put(char(c ^ 0x5a));
    }
    try {
        readParticleCache(flipped);
        FAIL() << "flipped byte accepted";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("checksum"), std::string::npos) << e.what();
    }
}
