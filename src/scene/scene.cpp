#include "scene/scene.h"

#include "geometry/shapes.h"
#include "io/checksum.h"
#include "physics/emitter.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <sstream>
#include <tuple>

namespace ganache {

namespace {

constexpr std::int64_t kSchemaVersion = 1;

std::string hashFile(const std::filesystem::path& file) {
    std::ifstream in(file, std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    return fmt::format("{:016x}", fnv1a64(bytes.data(), bytes.size()));
}

// Exactly one of the shape keys must be present.
std::string pickShape(Section& s, const std::vector<std::string>& shapes) {
    return s.exactlyOne(shapes, "shape", "e.g. `box: {min: [0, 0, 0], max: [1, 1, 1]}`");
}

void requireOrdered(Section& s, const Vec3& min, const Vec3& max, const std::string& what) {
    for (int a = 0; a < 3; ++a)
        if (!(min[a] < max[a]))
            s.fail("max", fmt::format("{}: max must exceed min on every axis (axis {}: min {}, max {})", what,
                                      "xyz"[a], formatNumber(min[a]), formatNumber(max[a])),
                   "swap the corners or give the box a non-zero size");
}

BoxShape readBox(Section s) {
    BoxShape b;
    b.min = s.vec3("min", std::nullopt, "m");
    b.max = s.vec3("max", std::nullopt, "m");
    requireOrdered(s, b.min, b.max, s.path());
    s.rejectUnused();
    return b;
}


// Turns an InputError "what\n  fix: how" into a SceneError at a key.
[[noreturn]] void failWith(Section& s, const std::string& key, const InputError& e) {
    const std::string text = e.what();
    const auto split = text.find("\n  fix: ");
    s.fail(key, text.substr(0, split), split == std::string::npos ? "check the file" : text.substr(split + 8));
}

// Repairs a mesh and records what it was like before; rejects meshes with nothing left to sample.
MeshShape finishMesh(Section& s, const std::string& key, MeshShape shape, TriangleMesh mesh) {
    shape.check = repairMesh(mesh);
    if (mesh.empty())
        s.fail(key, fmt::format("{}: every one of its {} triangles is degenerate (zero area)", shape.description,
                                shape.check.triangles),
               "repair or re-export the mesh");
    if (shape.inside == InsideMethod::LevelSet && !shape.check.closed())
        s.fail("inside", fmt::format("{}: `inside: level_set` needs a closed mesh, and this one has {} boundary and {} "
                                     "non-manifold edges",
                                     shape.description, shape.check.boundaryEdges, shape.check.nonManifoldEdges),
               "use `inside: winding_number` (or auto), or close the mesh");
    shape.mesh = std::make_shared<const TriangleMesh>(std::move(mesh));
    return shape;
}

// `mesh: {file, scale | rotate | translate | fit, inside}`.
MeshShape readMesh(Section m) {
    MeshShape shape;
    shape.file = m.file("file");
    shape.description = shape.file.filename().string();
    MeshPlacement& p = shape.placement;
    if (m.has("fit")) {
        for (const char* k : {"scale", "translate"})
            if (m.has(k))
                m.fail(k, fmt::format("{} has both `fit` and `{}`", m.path(), k),
                       "use `fit` to size and place the mesh, or scale/translate, not both");
        Section f = *m.child("fit");
        MeshPlacement::Fit fit;
        fit.size = f.positive("size", std::nullopt, "m (largest extent)");
        if (f.has("base") == f.has("centre"))
            f.fail("", fmt::format("{} needs exactly one of `centre` and `base`", f.path()),
                   "e.g. `fit: {size: 0.2, base: [0, 0, 0]}` to stand the mesh on the origin");
        fit.base = f.has("base");
        fit.point = f.vec3(fit.base ? "base" : "centre", std::nullopt, "m");
        f.rejectUnused();
        p.fit = fit;
    } else {
        p.scale = m.isList("scale") ? m.vec3("scale", p.scale, "")
                                    : Vec3::Constant(m.number("scale", 1, "", Bounds::positive()));
        if ((p.scale.array() == 0).any())
            m.fail("scale", m.path() + ".scale has a zero component", "give every axis a non-zero scale");
        p.translation = m.vec3("translate", p.translation, "m");
    }
    p.rotationDegrees = m.vec3("rotate", p.rotationDegrees, "degrees about x, then y, then z");
    const std::string inside = m.choice("inside", "auto", {"auto", "level_set", "winding_number"});
    shape.inside = inside == "level_set"  ? InsideMethod::LevelSet
                   : inside == "auto" ? InsideMethod::Auto
                                      : InsideMethod::WindingNumber;
    m.rejectUnused();
    TriangleMesh mesh;
    try {
        mesh = readMeshFile(shape.file);
    } catch (const InputError& e) {
        failWith(m, "file", e);
    }
    placeMesh(mesh, p);
    return finishMesh(m, "file", std::move(shape), std::move(mesh));
}

FluidSpec readFluid(Section s, std::size_t index, const std::vector<Material>& custom) {
    FluidSpec f;
    f.at = s.where();
    f.name = s.name("name", fmt::format("fluid{}", index));
    f.material = readMaterialChoice(s, custom);
    f.velocity = s.vec3("velocity", f.velocity, "m/s", limits::kSpeed);
    f.angularVelocity = s.vec3("angular_velocity", f.angularVelocity, "rad/s", limits::kAngularVelocity);
    f.jitter = s.number("jitter", f.jitter, "x lattice spacing", Bounds::closed(0, 0.25));
    f.temperature = s.number("temperature", f.temperature, "C (used with the heat effect)", Bounds{-273.15, 1e4});
    const std::string shape = pickShape(s, {"box", "sphere", "mesh"});
    if (shape == "box") {
        f.shape = readBox(*s.child("box"));
    } else if (shape == "mesh") {
        f.shape = readMesh(*s.child("mesh"));
    } else {
        Section sp = *s.child("sphere");
        SphereShape sh;
        sh.centre = sp.vec3("centre", std::nullopt, "m");
        sh.radius = sp.positive("radius", std::nullopt, "m");
        sp.rejectUnused();
        f.shape = sh;
    }
    s.rejectUnused();
    return f;
}

}  // namespace

namespace {

// A procedural solid as a mesh, its edges no longer than a particle radius.
MeshShape proceduralSolid(Section& s, const std::string& key, Real r) {
    Section p = *s.child(key);
    MeshShape shape;
    shape.description = key;
    TriangleMesh mesh;
    if (key == "sphere") {
        const Vec3 c = p.vec3("centre", std::nullopt, "m");
        mesh = sphereMesh(c, p.positive("radius", std::nullopt, "m"), r);
    } else if (key == "cylinder") {
        const Vec3 a = p.vec3("from", std::nullopt, "m"), b = p.vec3("to", std::nullopt, "m");
        if ((b - a).norm() <= 0) p.fail("to", p.path() + ": `from` and `to` are the same point", "give the axis a length");
        mesh = cylinderMesh(a, b, p.positive("radius", std::nullopt, "m"), r);
    } else if (key == "bars") {
        BarsGrid g;
        g.centre = p.vec3("centre", std::nullopt, "m");
        g.size = p.positive("size", std::nullopt, "m");
        g.count = p.integer("count", std::nullopt, 1, 1000);
        g.thickness = p.positive("thickness", std::nullopt, "m");
        mesh = barsMesh(g);
    } else {
        DoughHook h;
        h.top = p.vec3("top", std::nullopt, "m");
        h.shaftLength = p.number("shaft_length", std::nullopt, "m", Bounds::nonNegative());
        h.radius = p.positive("radius", std::nullopt, "m");
        h.helixHeight = p.positive("helix_height", std::nullopt, "m");
        h.turns = p.positive("turns", std::nullopt, "turns");
        h.rodRadius = p.positive("rod_radius", std::nullopt, "m");
        mesh = doughHookMesh(h, r);
    }
    p.rejectUnused();
    return finishMesh(p, "", std::move(shape), std::move(mesh));
}

BoundarySpec readBoundary(Section s, std::size_t index, Real particleRadius) {
    BoundarySpec b;
    b.at = s.where();
    b.name = s.name("name", fmt::format("boundary{}", index));
    const std::string shape = pickShape(s, {"box", "plane", "mesh", "sphere", "cylinder", "bars", "dough_hook"});
    if (shape == "box") {
        Section bs = *s.child("box");
        BoxBoundary box;
        box.min = bs.vec3("min", std::nullopt, "m");
        box.max = bs.vec3("max", std::nullopt, "m");
        requireOrdered(bs, box.min, box.max, bs.path());
        box.openTop = bs.boolean("open_top", box.openTop);
        bs.rejectUnused();
        b.shape = box;
    } else if (shape == "plane") {
        Section ps = *s.child("plane");
        PlaneBoundary plane;
        plane.point = ps.vec3("point", plane.point, "m");
        plane.normal = ps.direction("normal", plane.normal);
        ps.rejectUnused();
        b.shape = plane;
    } else if (shape == "mesh") {
        b.shape = readMesh(*s.child("mesh"));
    } else {
        b.shape = proceduralSolid(s, shape, particleRadius);
    }
    if (auto m = s.child("motion")) b.motion = readMotion(*m);
    s.rejectUnused();
    return b;
}

EmitterSpec readEmitter(Section s, std::size_t index, const Scene& scene, const std::vector<Material>& custom) {
    EmitterSpec e;
    e.at = s.where();
    e.name = s.name("name", fmt::format("emitter{}", index));
    e.material = readMaterialChoice(s, custom);
    if (pickShape(s, {"circle", "rectangle"}) == "circle") {
        Section c = *s.child("circle");
        e.nozzle = CircleNozzle{c.positive("radius", std::nullopt, "m")};
        c.rejectUnused();
    } else {
        Section rs = *s.child("rectangle");
        RectangleNozzle rect;
        rect.width = rs.positive("width", std::nullopt, "m");
        rect.height = rs.positive("height", std::nullopt, "m");
        rs.rejectUnused();
        e.nozzle = rect;
    }
    e.position = s.vec3("position", std::nullopt, "m");
    e.direction = s.direction("direction", e.direction);
    e.speed = s.number("speed", std::nullopt, "m/s", Bounds::positiveUpTo(limits::kSpeed));
    e.temperature = s.number("temperature", e.temperature, "C (used with the heat effect)", Bounds{-273.15, 1e4});
    std::tie(e.start, e.end) = readTimeWindow(s, scene.frames.timeOf(scene.frames.end));
    if (auto m = s.child("motion")) e.motion = readMotion(*m);
    s.rejectUnused();

    if (nozzleSites(e, scene.particleRadius).empty())
        s.fail(s.has("circle") ? "circle" : "rectangle",
               fmt::format("the nozzle of emitter '{}' is narrower than one particle (diameter {} m at {} quality)",
                           e.name, formatNumber(2 * scene.particleRadius), scene.quality.str()),
               "widen the nozzle (a circle needs radius >= r, a rectangle sides >= 2r) or use a finer --quality");
    // Where the nozzle is at its start, its end and each keyframe between.
    std::vector<Real> times{e.start, e.end};
    for (const auto& [t, offset] : e.motion.keyframes)
        if (t > e.start && t < e.end) times.push_back(t);
    std::sort(times.begin(), times.end());
    for (Real t : times) {
        const Vec3 p = e.motion.transform(e.position, t);
        if ((p.array() < scene.domainMin.array()).any() || (p.array() > scene.domainMax.array()).any())
            s.fail("position", fmt::format("emitter '{}' is outside the domain at t = {} s (at [{}, {}, {}])", e.name,
                                           formatNumber(t), formatNumber(p.x()), formatNumber(p.y()),
                                           formatNumber(p.z())),
                   "move the emitter (or its keyframes) inside domain.min/max, or enlarge the domain");
    }
    return e;
}

std::pair<Vec3, Vec3> boundsOf(const FluidShape& shape) {
    if (auto* b = std::get_if<BoxShape>(&shape)) return {b->min, b->max};
    if (auto* m = std::get_if<MeshShape>(&shape)) return m->mesh->bounds();
    const auto& s = std::get<SphereShape>(shape);
    return {s.centre.array() - s.radius, s.centre.array() + s.radius};
}

}  // namespace

Quality Quality::parse(const std::string& text) {
    if (text == "preview" || text == "final") return {text, 0};
    char* end = nullptr;
    const Real v = std::strtod(text.c_str(), &end);
    if (!text.empty() && end && *end == '\0' && std::isfinite(v) && v > 0) return {"number", v};
    throw InputError(fmt::format("--quality: expected preview, final or a positive number (got '{}')\n"
                                 "  fix: e.g. --quality preview, --quality final or --quality 1.5 "
                                 "(multiplies the particle radius)",
                                 text));
}

std::string Quality::str() const { return label == "number" ? formatNumber(scale) : label; }

const EffectSpec* Scene::findEffect(const std::string& effectName) const {
    for (const auto& e : effects)
        if (e.name == effectName) return &e;
    return nullptr;
}

SimulationSetup simulationSetup(const Scene& scene) {
    SimulationSetup s;
    s.particleRadius = scene.particleRadius;
    s.domainMin = scene.domainMin;
    s.domainMax = scene.domainMax;
    s.timeStep = scene.timeStep;
    s.pressure = scene.pressure;
    s.viscosityOrder = scene.viscosityOrder;
    for (const auto& f : scene.fluids) s.sources.push_back({f.material, f.temperature});
    for (const auto& e : scene.emitters) s.sources.push_back({e.material, e.temperature});
    for (const auto& b : scene.boundaries) s.bodies.push_back({b.name, b.motion});
    s.emitters = scene.emitters;
    s.effects = scene.effects;
    return s;
}

std::vector<Material> Scene::sourceMaterials() const {
    std::vector<Material> out;
    for (const auto& f : fluids) out.push_back(f.material);
    for (const auto& e : emitters) out.push_back(e.material);
    return out;
}

Real estimateFluidParticles(const Scene& scene, Real radius) {
    const Real cell = std::pow(2 * radius, 3);
    Real n = 0;
    for (const auto& f : scene.fluids) {
        if (auto* b = std::get_if<BoxShape>(&f.shape)) n += (b->max - b->min).prod() / cell;
        else if (auto* m = std::get_if<MeshShape>(&f.shape)) n += std::abs(m->check.volume) / cell;
        else n += 4.0 / 3.0 * M_PI * std::pow(std::get<SphereShape>(f.shape).radius, 3) / cell;
    }
    const Real lastFrame = scene.frames.timeOf(scene.frames.end);
    for (const auto& e : scene.emitters)
        n += emitterFlowRate(e, radius) * std::max<Real>(0, std::min(e.end, lastFrame) - e.start) / cell;
    return n;
}

const char* surfaceMethodName(SurfaceMethod method) {
    switch (method) {
    case SurfaceMethod::Spheres: return "spheres";
    case SurfaceMethod::SmoothSpheres: return "smooth_spheres";
    case SurfaceMethod::Anisotropic: return "anisotropic";
    }
    return "?";
}

namespace {

SurfaceSettings readSurface(Section s, const Scene& scene) {
    SurfaceSettings out;
    out.requested = true;
    out.at = s.where();
    const std::vector<SurfaceMethod> methods{SurfaceMethod::Anisotropic, SurfaceMethod::SmoothSpheres,
                                             SurfaceMethod::Spheres};
    std::vector<std::string> names;
    for (SurfaceMethod m : methods) names.push_back(surfaceMethodName(m));
    const std::string method = s.choice("method", names.front(), names);
    out.method = methods[std::size_t(std::find(names.begin(), names.end(), method) - names.begin())];
    out.voxelFraction = s.number("voxel_size", out.voxelFraction, "x particle radius", Bounds::closed(0.1, 2));
    out.smoothing = s.integer("smoothing", out.smoothing, 0, 50);
    out.mesh = s.boolean("mesh", out.mesh);
    out.meshPly = s.choice("mesh_format", "obj", {"obj", "ply"}) == "ply";
    out.adaptivity = s.number("adaptivity", out.adaptivity, "", Bounds::closed(0, 1));
    Section grids = s.section("grids");
    out.densityGrid = grids.boolean("density", false);
    out.temperatureGrid = grids.boolean("temperature", false);
    out.velocityGrid = grids.boolean("velocity", false);
    grids.rejectUnused();
    out.meshTemperature = s.boolean("mesh_temperature", false);
    s.rejectUnused();
    // Particles carry a temperature only when the heat effect runs.
    if ((out.temperatureGrid || out.meshTemperature) && !scene.findEffect("heat"))
        s.fail(out.temperatureGrid ? "grids" : "mesh_temperature",
               "temperatures are asked for, but the scene has no heat effect, so its particles carry none",
               "add `heat: {}` under effects, or drop the temperature request");
    return out;
}

CameraKey readCameraKey(Section& c, std::int64_t frame) {
    CameraKey k;
    k.frame = frame;
    k.position = c.vec3("position", std::nullopt, "m");
    k.target = c.vec3("target", std::nullopt, "m");
    k.fovDegrees = c.number("fov", k.fovDegrees, "degrees (vertical)", Bounds{1, 170, false, false});
    if ((k.target - k.position).norm() < 1e-9)
        c.fail("target", "the camera looks at its own position", "put the target away from the position");
    return k;
}

RenderSettings readRender(Section s, const Scene& scene) {
    RenderSettings out;
    out.requested = true;
    out.at = s.where();
    // OSMesa draws up to 16384 pixels a side; past 8192 a preview is a mistake, not a preview.
    out.width = s.integer("width", out.width, 16, 8192);
    out.height = s.integer("height", out.height, 16, 8192);
    if (s.isList("camera")) {
        for (Section key : s.list("camera")) {
            const std::int64_t frame = key.integer("frame", std::nullopt, scene.frames.start, scene.frames.end);
            if (!out.camera.empty() && frame <= out.camera.back().frame)
                key.fail("frame", "camera keys must come in increasing frame order", "sort the keys by frame");
            out.camera.push_back(readCameraKey(key, frame));
            key.rejectUnused();
        }
    } else if (auto camera = s.child("camera")) {
        out.camera.push_back(readCameraKey(*camera, scene.frames.start));
        camera->rejectUnused();
    }
    const std::string view = s.choice("view", "auto", {"auto", "mesh", "particles"});
    out.view = view == "mesh" ? RenderView::Mesh : view == "particles" ? RenderView::Particles : RenderView::Auto;
    if (out.view == RenderView::Mesh && !(scene.surface.requested && scene.surface.mesh))
        s.fail("view", "the mesh view needs surface meshes, and the scene asks for none",
               "add a `surface:` section (with `mesh: true`), or use `view: auto`");
    const std::vector<ColourBy> colourings{ColourBy::Velocity, ColourBy::Temperature, ColourBy::Viscosity};
    std::vector<std::string> names;
    for (ColourBy c : colourings) names.push_back(colourByName(c));
    const std::string colourBy = s.choice("colour_by", names.front(), names);
    out.colourBy = colourings[std::size_t(std::find(names.begin(), names.end(), colourBy) - names.begin())];
    if (out.colourBy == ColourBy::Viscosity && !scene.findEffect("viscosity"))
        s.fail("colour_by", "colouring by viscosity needs the viscosity effect: without it the fluid has none",
               "add `viscosity: {}` under effects, or colour by velocity");
    if (out.colourBy == ColourBy::Temperature && !scene.findEffect("heat"))
        s.fail("colour_by", "colouring by temperature needs the heat effect: without it particles carry none",
               "add `heat: {}` under effects, or colour by velocity");
    if (s.has("colour_min") || s.has("colour_max")) {
        const char* unit = out.colourBy == ColourBy::Velocity ? "m/s" : out.colourBy == ColourBy::Temperature ? "C" : "Pa s";
        const Real lo = s.number("colour_min", std::nullopt, unit), hi = s.number("colour_max", std::nullopt, unit);
        if (!(hi > lo))
            s.fail("colour_max", "the colour range's maximum must exceed its minimum", "raise colour_max above colour_min");
        out.colourRange = std::make_pair(lo, hi);
    }
    if (s.has("fluid_colour")) out.fluidColour = s.colour("fluid_colour", std::nullopt);
    out.ground = s.boolean("ground", out.ground);
    out.contactSheet = s.integer("contact_sheet", out.contactSheet, 0, 100);
    out.video = s.boolean("video", out.video);
    s.rejectUnused();
    return out;
}

}  // namespace

const char* colourByName(ColourBy c) {
    switch (c) {
    case ColourBy::Velocity: return "velocity";
    case ColourBy::Temperature: return "temperature";
    case ColourBy::Viscosity: return "viscosity";
    }
    return "?";
}

Scene loadScene(const std::filesystem::path& file, const Quality& quality) {
    Section root = openSceneFile(file);
    Scene scene;
    scene.file = file;
    scene.hash = hashFile(file);
    scene.quality = quality;

    if (!root.has("ganache"))
        root.failMissing("ganache", "the scene has no schema version",
                  fmt::format("add `ganache: {}` as the first line", kSchemaVersion));
    const std::int64_t version = root.integer("ganache", std::nullopt, 0, 1'000'000);
    if (version != kSchemaVersion)
        root.fail("ganache", fmt::format("schema version {} is not supported; this ganache reads version {}", version,
                                         kSchemaVersion),
                  fmt::format("write `ganache: {}` and check scenes/README.md for the keys of that version",
                              kSchemaVersion));

    const std::string stem = file.stem().string();
    const bool stemIsName = !stem.empty() && std::all_of(stem.begin(), stem.end(), [](unsigned char c) {
        return std::isalnum(c) || c == '_' || c == '-';
    });
    if (!stemIsName && !root.has("name"))
        root.failMissing("name", fmt::format("the scene has no `name` and its file name '{}' cannot serve as one "
                                             "(letters, digits, '_' and '-' only)", stem),
                         "add `name: my_scene` or rename the file");
    scene.name = root.name("name", stem);

    {
        Section fr = root.section("frames");
        scene.frames.fps = fr.number("fps", scene.frames.fps, "frames/s", Bounds::positiveUpTo(limits::kFps));
        scene.frames.start = fr.integer("start", scene.frames.start, 0, 9999);
        scene.frames.end = fr.integer("end", scene.frames.end, 0, 9999);
        if (scene.frames.end < scene.frames.start)
            fr.fail("end", fmt::format("frames.end ({}) comes before frames.start ({})", scene.frames.end,
                                        scene.frames.start),
                     "make end at least start");
        fr.rejectUnused();
    }

    Section particles = root.require("particles", "particles: {radius: 0.01}");
    scene.radiusAt = particles.where("radius");
    scene.finalRadius = particles.positive("radius", std::nullopt, "m");
    scene.previewScale = particles.number("preview_scale", scene.previewScale, "x radius", Bounds{1, 100});
    scene.maxParticles = particles.integer("max_count", scene.maxParticles, 1, 2'000'000'000);
    scene.exportPly = particles.choice("export", "none", {"none", "ply"}) == "ply";
    particles.rejectUnused();
    const Real radiusScale = quality.label == "preview" ? scene.previewScale
                             : quality.label == "final" ? 1
                                                        : quality.scale;
    scene.particleRadius = scene.finalRadius * radiusScale;

    Section domain = root.require("domain", "domain: {min: [-1, -1, -1], max: [1, 1, 1]}");
    scene.domainMin = domain.vec3("min", std::nullopt, "m", limits::kCoordinate);
    scene.domainMax = domain.vec3("max", std::nullopt, "m", limits::kCoordinate);
    requireOrdered(domain, scene.domainMin, scene.domainMax, "domain");
    domain.rejectUnused();
    // The domain must hold a kernel support (four radii) along every axis, or nothing in the scene can interact.
    const Real narrowest = (scene.domainMax - scene.domainMin).minCoeff();
    if (!(4 * scene.particleRadius <= narrowest))
        throw SceneError(scene.radiusAt,
                         fmt::format("particles.radius {} m gives a kernel support of {:.3g} m at {} quality, wider "
                                     "than the domain's narrowest side ({} m)",
                                     formatNumber(scene.finalRadius), 4 * scene.particleRadius, quality.str(),
                                     formatNumber(narrowest)),
                         fmt::format("give particles.radius well below {:.3g} m (a tenth of a fluid's size is already "
                                     "coarse)",
                                     narrowest / 4 / radiusScale));

    const std::vector<Material> custom = readMaterials(root.child("materials"));
    auto fluids = root.list("fluids");
    auto emitters = root.list("emitters");
    if (fluids.empty() && emitters.empty()) {
        const std::string what = "the scene has no fluid and no emitter";
        const std::string fix = "add `fluids:` with at least one entry, e.g. "
                                "`- {name: block, box: {min: [0, 0, 0], max: [0.1, 0.1, 0.1]}}`, or an `emitters:` list";
        if (root.has("fluids")) root.fail("fluids", what, fix);
        root.failMissing("fluids", what, fix);
    }
    for (std::size_t i = 0; i < fluids.size(); ++i) {
        scene.fluids.push_back(readFluid(fluids[i], i, custom));
        const auto [lo, hi] = boundsOf(scene.fluids.back().shape);
        if ((lo.array() < scene.domainMin.array()).any() || (hi.array() > scene.domainMax.array()).any())
            throw SceneError(scene.fluids.back().at,
                             fmt::format("fluid '{}' reaches outside the domain", scene.fluids.back().name),
                             "enlarge domain.min/max or move the fluid inside it");
    }
    auto boundaries = root.list("boundaries");
    for (std::size_t i = 0; i < boundaries.size(); ++i) scene.boundaries.push_back(readBoundary(boundaries[i], i, scene.particleRadius));
    for (std::size_t i = 0; i < emitters.size(); ++i)
        scene.emitters.push_back(readEmitter(emitters[i], i, scene, custom));

    {
        Section sim = root.section("simulation");
        Section ts = sim.section("time_step");
        TimeStepSettings& t = scene.timeStep;
        t.cfl = ts.number("cfl", t.cfl, "", Bounds{0, 1, true, false});
        t.dtMin = ts.positive("min", t.dtMin, "s");
        t.dtMax = ts.positive("max", t.dtMax, "s");
        if (t.dtMax < t.dtMin)
            ts.fail("max", fmt::format("simulation.time_step.max ({} s) is below min ({} s)", formatNumber(t.dtMax),
                                       formatNumber(t.dtMin)),
                    "make max at least min");
        t.fixedDt = ts.number("fixed", t.fixedDt, "s (0: adaptive CFL step)", Bounds::nonNegative());
        // A step so short that a frame takes millions of them would run for days: input, not a run-time surprise.
        const Real shortest = 1 / (scene.frames.fps * limits::kStepsPerFrame);
        for (const auto& [key, dt] : {std::pair<const char*, Real>{"min", t.dtMin}, {"fixed", t.fixedDt}})
            if (dt > 0 && dt < shortest)
                ts.fail(key, fmt::format("simulation.time_step.{} ({} s) would take up to {:.3g} steps a frame at {} "
                                         "frames/s",
                                         key, formatNumber(dt), 1 / (scene.frames.fps * dt),
                                         formatNumber(scene.frames.fps)),
                        fmt::format("give a step of at least {:.3g} s (a million steps a frame)", shortest));
        ts.rejectUnused();
        Section ps = sim.section("pressure");
        PressureSettings& p = scene.pressure;
        p.densityError = ps.number("density_error", 100 * p.densityError, "% of rest density",
                                   Bounds{0, 10, true, false}) / 100;
        p.divergenceError = ps.number("divergence_error", 100 * p.divergenceError, "% of rest density per step",
                                      Bounds{0, 10, true, false}) / 100;
        p.solver = ps.choice("solver", "mprgp", {"mprgp", "jacobi"}) == "jacobi" ? PressureSettings::Solver::Jacobi
                                                                               : PressureSettings::Solver::Mprgp;
        p.maxIterations = ps.integer("max_iterations", p.maxIterations, 1, 100000);
        p.minIterations = ps.integer("min_iterations", p.minIterations, 0, p.maxIterations);
        p.minDivergenceIterations =
            ps.integer("min_divergence_iterations", p.minDivergenceIterations, 0, p.maxIterations);
        p.impactIterations = ps.integer("impact_iterations", p.impactIterations, 0, p.maxIterations);
        p.rigidCorrection = ps.number("rigid_correction", p.rigidCorrection, "", Bounds::positiveUpTo(1));
        p.coarseFrom = ps.integer("coarse_from", p.coarseFrom, 0, std::numeric_limits<std::int32_t>::max());
        ps.rejectUnused();
        // A name, or (as before there were names) a number: 0 is the paper's order, n >= 1 n coupled passes.
        ViscosityOrder& order = scene.viscosityOrder;
        if (sim.isNumber("viscosity_coupling")) {
            const std::int64_t passes = sim.integer("viscosity_coupling", std::nullopt, 0, 10);
            order.kind = passes == 0 ? ViscosityOrder::Kind::Paper : ViscosityOrder::Kind::Coupled;
            order.passes = std::max<std::int64_t>(passes, 1);
        } else {
            order.kind = sim.choice("viscosity_coupling", "predicted", {"predicted", "paper"}) == "paper"
                             ? ViscosityOrder::Kind::Paper
                             : ViscosityOrder::Kind::Predicted;
        }
        scene.checkpointEvery = sim.integer("checkpoint_every", scene.checkpointEvery, 0, 9999);
        scene.checkpointsKept = sim.integer("checkpoints_kept", scene.checkpointsKept, 1, 100);
        sim.rejectUnused();
    }
    if (auto eff = root.child("effects")) scene.effects = readEffects(*eff);
    if (auto surface = root.child("surface")) scene.surface = readSurface(*surface, scene);
    if (auto render = root.child("render")) scene.render = readRender(*render, scene);
    root.rejectUnused();
    const SimulationSetup setup = simulationSetup(scene);
    for (const auto& e : scene.effects) e.params->check(setup, e.at);

    const Real estimate = estimateFluidParticles(scene, scene.particleRadius);
    if (estimate > Real(scene.maxParticles)) {
        // Scaled from a radius whose count is finite, so that an absurdly small radius still gets a usable fix.
        const Real base = std::isfinite(estimate) ? scene.particleRadius : 1e-3 * narrowest;
        const Real fits = base * std::cbrt(estimateFluidParticles(scene, base) / Real(scene.maxParticles));
        throw SceneError(scene.radiusAt,
                         fmt::format("a particle radius of {} m ({} quality) gives about {:.3g} fluid particles, "
                                     "above particles.max_count = {}",
                                     formatNumber(scene.particleRadius), quality.str(), estimate, scene.maxParticles),
                         fmt::format("use a radius of at least {:.3g} m at this quality (or a coarser --quality), or "
                                     "raise particles.max_count if the machine has the memory",
                                     fits));
    }
    scene.effective = root.effective();
    return scene;
}

std::string explainScene(const Scene& scene) {
    std::string header = fmt::format(
        "# effective scene '{}' from {} (hash {}), defaults filled in\n"
        "# quality {}: this run uses particle radius {} m (particles.radius {} m at final quality)\n",
        scene.name, scene.file.string(), scene.hash, scene.quality.str(), formatNumber(scene.particleRadius),
        formatNumber(scene.finalRadius));
    for (const auto& f : scene.fluids)
        header += fmt::format("# fluid '{}': material {} (density {} kg/m^3, mu {} Pa s; {})\n", f.name,
                              f.material.name, formatNumber(f.material.density), formatNumber(f.material.mu),
                              f.material.source);
    for (const auto& e : scene.emitters)
        header += fmt::format("# emitter '{}': material {}, {} particles per layer, {} m^3/s at this quality\n", e.name,
                              e.material.name, nozzleSites(e, scene.particleRadius).size(),
                              formatNumber(emitterFlowRate(e, scene.particleRadius)));
    return header + effectiveYaml(*scene.effective);
}

}  // namespace ganache
