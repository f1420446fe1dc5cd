// The OpenVDB files as Houdini (and Blender) read them: opened here with OpenVDB itself, as those programs do, to
// check the conventions they rely on. Houdini's VDB nodes take a float grid of class level set as an SDF and one of
// class fog volume as a density; `vel` of vector type contravariant-relative as velocity; point attributes P, v and
// id by those names; linear transforms in scene units (metres, y up: Houdini's own axes, so nothing is turned).

#include "io/particle_cache.h"
#include "surfacer/surfacer.h"

#include <gtest/gtest.h>
#include <openvdb/openvdb.h>
#include <openvdb/points/PointCount.h>
#include <openvdb/points/PointDataGrid.h>

#include <filesystem>

using namespace ganache;

namespace {

constexpr Real kR = 0.01;

ParticleSet ball() {
    ParticleSet p;
    std::uint64_t id = 0;
    for (int a = -6; a <= 6; ++a)
        for (int b = -6; b <= 6; ++b)
            for (int c = -6; c <= 6; ++c) {
                const Vec3 x = 2 * kR * Vec3(a, b, c);
                if (x.norm() < 0.1) p.add(x + Vec3(0, 0.2, 0), Vec3(1, 0, 0), 0.008, id++);
            }
    auto& t = p.addScalar("temperature", 0);
    for (Real& v : t) v = 40;
    return p;
}

openvdb::GridPtrVecPtr readAll(const std::filesystem::path& path) {
    openvdb::initialize();
    openvdb::io::File file(path.string());
    file.open();
    auto grids = file.getGrids();
    file.close();
    return grids;
}

openvdb::GridBase::Ptr named(const openvdb::GridPtrVec& grids, const std::string& name) {
    for (const auto& g : grids)
        if (g->getName() == name) return g;
    ADD_FAILURE() << "no grid '" << name << "'";
    return nullptr;
}

}  // namespace

TEST(VdbConventions, SurfaceGridsAreWhatHoudiniExpects) {
    SurfaceSettings s;
    s.requested = true;
    s.densityGrid = s.temperatureGrid = s.velocityGrid = true;
    const FrameSurface frame = surfaceParticles(ball(), kR, s);
    const auto path = std::filesystem::temp_directory_path() / "ganache_conventions.0007.vdb";
    frame.writeVdb(path, "conventions", 7);
    const auto grids = readAll(path);
    ASSERT_EQ(grids->size(), 4u);

    const auto surface = named(*grids, "surface");
    ASSERT_TRUE(surface);
    EXPECT_EQ(surface->getGridClass(), openvdb::GRID_LEVEL_SET) << "an SDF, not a fog volume";
    ASSERT_TRUE(surface->isType<openvdb::FloatGrid>());
    const auto& transform = surface->transform();
    EXPECT_TRUE(transform.isLinear());
    EXPECT_NEAR(transform.voxelSize()[0], 0.5 * kR, 1e-12) << "metres, voxel 0.5 r";
    EXPECT_EQ(transform.voxelSize()[0], transform.voxelSize()[2]) << "uniform voxels";
    // The level set is negative inside and its background is the narrow band's outer value (3 voxels).
    const auto sdf = openvdb::gridConstPtrCast<openvdb::FloatGrid>(surface);
    EXPECT_LT(sdf->tree().getValue(sdf->transform().worldToIndexCellCentered(openvdb::Vec3d(0, 0.2, 0))), 0);
    EXPECT_NEAR(sdf->background(), 3 * transform.voxelSize()[0], 1e-6);
    // y up, metres: the ball's top is at y = 0.3, not on z.
    const openvdb::CoordBBox box = sdf->evalActiveVoxelBoundingBox();
    const openvdb::Vec3d top = transform.indexToWorld(box.max());
    EXPECT_NEAR(top.y(), 0.3, 0.03);
    EXPECT_NEAR(top.z(), 0.1, 0.03);

    const auto density = named(*grids, "density");
    ASSERT_TRUE(density);
    EXPECT_EQ(density->getGridClass(), openvdb::GRID_FOG_VOLUME);
    EXPECT_TRUE(density->isType<openvdb::FloatGrid>());
    const auto vel = named(*grids, "vel");
    ASSERT_TRUE(vel);
    EXPECT_TRUE(vel->isType<openvdb::Vec3SGrid>());
    EXPECT_EQ(vel->getVectorType(), openvdb::VEC_CONTRAVARIANT_RELATIVE) << "Houdini's velocity fields";
    const auto temperature = named(*grids, "temperature");
    ASSERT_TRUE(temperature);
    EXPECT_TRUE(temperature->isType<openvdb::FloatGrid>());
    for (const auto& g : *grids) EXPECT_EQ(g->transform(), transform) << g->getName() << ": one transform for all";
}

TEST(VdbConventions, ParticleCachesAreWhatHoudiniExpects) {
    const ParticleSet fluid = ball();
    const auto path = std::filesystem::temp_directory_path() / "ganache_conventions_points.0007.vdb";
    writeParticleCache(path, fluid, {}, {"conventions", 7, 0.25, 24, kR});
    const auto grids = readAll(path);
    const auto points = openvdb::gridPtrCast<openvdb::points::PointDataGrid>(named(*grids, "points"));
    ASSERT_TRUE(points);
    const auto leaf = points->tree().cbeginLeaf();
    ASSERT_TRUE(leaf);
    const auto& descriptor = leaf->attributeSet().descriptor();
    auto typeOf = [&](const std::string& name) {
        const std::size_t at = descriptor.find(name);
        EXPECT_NE(at, openvdb::points::AttributeSet::INVALID_POS) << "no attribute " << name;
        return at == openvdb::points::AttributeSet::INVALID_POS ? std::string() : descriptor.type(at).first;
    };
    EXPECT_EQ(typeOf("P"), "vec3s");  // Houdini: P
    EXPECT_EQ(typeOf("v"), "vec3s");  // Houdini: v, velocity for motion blur
    EXPECT_EQ(typeOf("id"), "int64");
    EXPECT_EQ(typeOf("temperature"), "float");
    EXPECT_EQ(typeOf("mass"), "double");
    EXPECT_EQ(openvdb::points::pointCount(points->tree()), fluid.size());
    EXPECT_EQ(points->metaValue<double>("ganache_time"), 0.25);
    EXPECT_EQ(points->metaValue<std::int64_t>("ganache_frame"), 7);
}
