#include "io/particle_cache.h"

#include "core/errors.h"
#include "io/checksum.h"
#include "io/ply.h"
#include "io/vdb_file.h"

#include <fmt/format.h>

#include <openvdb/openvdb.h>
#include <openvdb/points/PointConversion.h>
#include <openvdb/points/PointDataGrid.h>
#include <openvdb/tools/PointIndexGrid.h>

#include <algorithm>
#include <numeric>

namespace ganache {

namespace {

namespace ovp = openvdb::points;

template <class T>
void addAttribute(ovp::PointDataGrid& grid, const openvdb::tools::PointIndexGrid& index, const std::string& name,
                  const std::vector<T>& values) {
    ovp::appendAttribute<T>(grid.tree(), name);
    ovp::PointAttributeVector<T> wrapper(values);
    ovp::populateAttribute<ovp::PointDataTree, openvdb::tools::PointIndexTree, ovp::PointAttributeVector<T>>(
        grid.tree(), index.tree(), name, wrapper);
}

// Builds a point grid from positions; returns it with the index grid that maps attributes into it.
std::pair<ovp::PointDataGrid::Ptr, openvdb::tools::PointIndexGrid::Ptr> makePointGrid(
    const std::vector<Vec3>& x, const openvdb::math::Transform::Ptr& transform, const std::string& name) {
    std::vector<openvdb::Vec3d> positions(x.size());
    for (std::size_t i = 0; i < x.size(); ++i) positions[i] = {x[i].x(), x[i].y(), x[i].z()};
    ovp::PointAttributeVector<openvdb::Vec3d> wrapper(positions);
    auto index = openvdb::tools::createPointIndexGrid<openvdb::tools::PointIndexGrid>(wrapper, *transform);
    auto grid = ovp::createPointDataGrid<ovp::NullCodec, ovp::PointDataGrid>(*index, wrapper, *transform);
    grid->setName(name);
    return {grid, index};
}

std::vector<openvdb::Vec3f> toFloat3(const std::vector<Vec3>& v) {
    std::vector<openvdb::Vec3f> out(v.size());
    for (std::size_t i = 0; i < v.size(); ++i) out[i] = openvdb::Vec3f(float(v[i].x()), float(v[i].y()), float(v[i].z()));
    return out;
}

// Calls f(worldPosition, leaf, index) for every point of the grid.
template <class F>
void forEachPoint(const ovp::PointDataGrid& grid, F&& f) {
    for (auto leaf = grid.tree().cbeginLeaf(); leaf; ++leaf) {
        ovp::AttributeHandle<openvdb::Vec3f> p(leaf->constAttributeArray("P"));
        for (auto idx = leaf->beginIndexOn(); idx; ++idx) {
            const openvdb::Vec3d w = grid.transform().indexToWorld(idx.getCoord().asVec3d() + p.get(*idx));
            f(Vec3(w.x(), w.y(), w.z()), *leaf, *idx);
        }
    }
}

template <class T>
T readValue(const ovp::PointDataTree::LeafNodeType& leaf, const std::string& name, openvdb::Index i) {
    return ovp::AttributeHandle<T>(leaf.constAttributeArray(name)).get(i);
}

}  // namespace

void writeParticlePly(const std::filesystem::path& path, const ParticleSet& fluid, const CacheInfo& info) {
    PlyFile ply(fmt::format("ganache {} frame {} (t = {:.4f} s): {} fluid particles of radius {} m\nunits: metres, "
                            "seconds, kilograms; y up",
                            info.scene, info.frame, info.time, fluid.size(), info.particleRadius));
    std::vector<std::string> properties = {"float x",  "float y",    "float z", "float vx",
                                           "float vy", "float vz", "float mass", "uint id"};
    std::vector<const std::vector<Real>*> scalars;
    std::vector<const std::vector<Vec3>*> vectors;
    for (const auto& [name, values] : fluid.scalars())
        if (fluid.isCached(name)) properties.push_back("float " + name), scalars.push_back(&values);
    for (const auto& [name, values] : fluid.vectors())
        if (fluid.isCached(name)) {
            for (const char* axis : {"_x", "_y", "_z"}) properties.push_back("float " + name + axis);
            vectors.push_back(&values);
        }
    ply.element("vertex", fluid.size(), properties);
    ply.reserve(fluid.size() * 4 * properties.size());
    // In id order, as the caches read back: a point keeps its place from frame to frame while none is added or lost.
    std::vector<std::size_t> order(fluid.size());
    std::iota(order.begin(), order.end(), std::size_t(0));
    std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return fluid.id()[a] < fluid.id()[b]; });
    for (const std::size_t i : order) {
        for (int k = 0; k < 3; ++k) ply.put(float(fluid.x()[i][k]));
        for (int k = 0; k < 3; ++k) ply.put(float(fluid.v()[i][k]));
        ply.put(float(fluid.mass()[i]));
        ply.put(std::uint32_t(fluid.id()[i]));  // ids stay far below 2^32: one per particle ever made
        for (const auto* values : scalars) ply.put(float((*values)[i]));
        for (const auto* values : vectors)
            for (int k = 0; k < 3; ++k) ply.put(float((*values)[i][k]));
    }
    ply.write(path);
}

void writeParticleCache(const std::filesystem::path& path, const ParticleSet& fluid,
                        const std::vector<BoundaryBody>& boundaries, const CacheInfo& info) {
    openvdb::initialize();
    const Real voxel = info.particleRadius > 0 ? 4 * info.particleRadius : 1;
    auto transform = openvdb::math::Transform::createLinearTransform(voxel);

    auto [grid, index] = makePointGrid(fluid.x(), transform, "points");
    addAttribute(*grid, *index, "v", toFloat3(fluid.v()));
    addAttribute(*grid, *index, "mass", fluid.mass());
    std::vector<std::int64_t> ids(fluid.id().begin(), fluid.id().end());
    addAttribute(*grid, *index, "id", ids);
    for (const auto& [name, values] : fluid.scalars())
        if (fluid.isCached(name)) addAttribute(*grid, *index, name, std::vector<float>(values.begin(), values.end()));
    for (const auto& [name, values] : fluid.vectors())
        if (fluid.isCached(name)) addAttribute(*grid, *index, name, toFloat3(values));
    grid->insertMeta("ganache_scene", openvdb::StringMetadata(info.scene));
    grid->insertMeta("ganache_frame", openvdb::Int64Metadata(info.frame));
    grid->insertMeta("ganache_time", openvdb::DoubleMetadata(info.time));
    grid->insertMeta("ganache_fps", openvdb::DoubleMetadata(info.fps));
    grid->insertMeta("ganache_particle_radius", openvdb::DoubleMetadata(info.particleRadius));
    openvdb::GridPtrVec grids{grid};

    if (!boundaries.empty()) {
        std::vector<Vec3> bx;
        std::vector<Real> volume;
        std::vector<std::int32_t> body;
        std::string names;
        for (std::size_t b = 0; b < boundaries.size(); ++b) {
            bx.insert(bx.end(), boundaries[b].x.begin(), boundaries[b].x.end());
            volume.insert(volume.end(), boundaries[b].volume.begin(), boundaries[b].volume.end());
            body.insert(body.end(), boundaries[b].x.size(), std::int32_t(b));
            names += (b ? "," : "") + boundaries[b].name;
        }
        auto [bgrid, bindex] = makePointGrid(bx, transform, "boundary");
        addAttribute(*bgrid, *bindex, "volume", volume);
        addAttribute(*bgrid, *bindex, "body", body);
        bgrid->insertMeta("ganache_body_names", openvdb::StringMetadata(names));
        grids.push_back(bgrid);
    }

    writeVdbAtomically(path, openvdb::GridCPtrVec(grids.begin(), grids.end()));
}

CacheContents readParticleCache(const std::filesystem::path& path) {
    openvdb::initialize();
    std::error_code ec;
    if (!std::filesystem::is_regular_file(path, ec))
        throw InputError(fmt::format("{}: particle cache not found\n  fix: run the stage that writes it first "
                                     "(`ganache sample SCENE` for the initial state)",
                                     path.string()));
    // OpenVDB trusts the sizes it reads: a truncated file can make it allocate gigabytes. The footer is
    // checked first, so OpenVDB only ever sees complete files.
    std::string why;
    if (!verifyChecksumFooter(path, why))
        throw InputError(fmt::format("{}: particle cache {}\n  fix: delete it and run the stage that writes it "
                                     "again",
                                     path.string(), why));
    openvdb::GridPtrVecPtr grids;
    try {
        openvdb::io::File file(path.string());
        file.open(false);
        grids = file.getGrids();
        file.close();
    } catch (const std::exception& e) {
        throw InputError(fmt::format("{}: not a readable OpenVDB particle cache ({})\n  fix: the file is corrupt or "
                                     "truncated; delete it and run the stage that writes it again",
                                     path.string(), e.what()));
    }
    ovp::PointDataGrid::Ptr points, boundary;
    for (const auto& g : *grids) {
        if (g->getName() == "points") points = openvdb::gridPtrCast<ovp::PointDataGrid>(g);
        if (g->getName() == "boundary") boundary = openvdb::gridPtrCast<ovp::PointDataGrid>(g);
    }
    if (!points)
        throw InputError(fmt::format("{}: has no OpenVDB points grid named 'points'\n  fix: this is not a ganache "
                                     "particle cache; run the stage that writes it again",
                                     path.string()));

    CacheContents out;
    auto meta = [&](const char* key, auto fallback) {
        using M = openvdb::TypedMetadata<decltype(fallback)>;
        auto m = points->getMetadata<M>(key);
        return m ? m->value() : fallback;
    };
    out.info.scene = meta("ganache_scene", std::string());
    out.info.frame = meta("ganache_frame", std::int64_t(0));
    out.info.time = meta("ganache_time", 0.0);
    out.info.fps = meta("ganache_fps", 24.0);
    out.info.particleRadius = meta("ganache_particle_radius", 0.0);

    // Effect attributes: every attribute beyond the core ones, by type.
    std::vector<std::string> scalarNames, vectorNames;
    if (auto leaf = points->tree().cbeginLeaf()) {
        for (const auto& [name, pos] : leaf->attributeSet().descriptor().map()) {
            if (name == "P" || name == "v" || name == "id" || name == "mass") continue;
            const auto& array = leaf->constAttributeArray(pos);
            if (array.hasValueType<float>()) scalarNames.push_back(name);
            else if (array.hasValueType<openvdb::Vec3f>()) vectorNames.push_back(name);
        }
    }
    for (const auto& n : scalarNames) out.fluid.addScalar(n);
    for (const auto& n : vectorNames) out.fluid.addVector(n);
    forEachPoint(*points, [&](const Vec3& x, const auto& leaf, openvdb::Index i) {
        const openvdb::Vec3f v = readValue<openvdb::Vec3f>(leaf, "v", i);
        out.fluid.add(x, Vec3(v.x(), v.y(), v.z()), readValue<double>(leaf, "mass", i),
                      std::uint64_t(readValue<std::int64_t>(leaf, "id", i)));
        const std::size_t k = out.fluid.size() - 1;
        for (const auto& n : scalarNames) (*out.fluid.findScalar(n))[k] = readValue<float>(leaf, n, i);
        for (const auto& n : vectorNames) {
            const openvdb::Vec3f a = readValue<openvdb::Vec3f>(leaf, n, i);
            (*out.fluid.findVector(n))[k] = Vec3(a.x(), a.y(), a.z());
        }
    });
    out.fluid.sortById();

    if (boundary) {
        std::string names;
        if (auto m = boundary->getMetadata<openvdb::StringMetadata>("ganache_body_names")) names = m->value();
        std::size_t start = 0;
        while (true) {
            const std::size_t comma = names.find(',', start);
            out.boundaries.push_back({names.substr(start, comma - start), {}, {}});
            if (comma == std::string::npos) break;
            start = comma + 1;
        }
        forEachPoint(*boundary, [&](const Vec3& x, const auto& leaf, openvdb::Index i) {
            const auto b = std::size_t(readValue<std::int32_t>(leaf, "body", i));
            if (b >= out.boundaries.size())
                throw InputError(fmt::format("{}: boundary particle names body {} of {}; the cache is corrupt",
                                             path.string(), b, out.boundaries.size()));
            out.boundaries[b].x.push_back(x);
            out.boundaries[b].volume.push_back(readValue<double>(leaf, "volume", i));
        });
    }
    return out;
}

}  // namespace ganache
