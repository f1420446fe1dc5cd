#pragma once
// Scenes: YAML files (schema `ganache: 1`, documented in scenes/README.md) read into typed structs.
// Defaults live in the struct member initialisers below and nowhere else.

#include "core/errors.h"
#include "core/types.h"
#include "geometry/mesh.h"
#include "physics/setup.h"
#include "scene/section.h"

#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <variant>
#include <vector>

namespace ganache {

/// --quality: `preview` scales the particle radius by the scene's preview_scale, `final` uses the scene's
/// radius, and a number scales the radius by that number (2 = twice the radius, 1/8 of the particles).
struct Quality {
    std::string label = "preview";
    Real scale = 0;  ///< the number given, when label == "number"
    /// Parses preview | final | <positive number>; throws InputError otherwise.
    static Quality parse(const std::string& text);
    std::string str() const;
};

/// Output frames: frame `start` shows t = 0, frame f shows t = (f - start) / fps.
struct FrameRange {
    std::int64_t start = 1;
    std::int64_t end = 48;
    Real fps = 24;  ///< frames per second
    Real timeOf(std::int64_t frame) const { return Real(frame - start) / fps; }
    std::int64_t count() const { return end - start + 1; }
};

struct BoxShape {
    Vec3 min, max;  ///< corners [m]
};
struct SphereShape {
    Vec3 centre;
    Real radius = 0;  ///< [m]
};
/// How the sampler tells inside from outside for a mesh.
enum class InsideMethod {
    Auto,           ///< level set for closed meshes, winding numbers otherwise
    LevelSet,       ///< OpenVDB mesh-to-level-set (needs a closed mesh)
    WindingNumber,  ///< generalised winding numbers: holes, flipped and self-intersecting faces
};

/// A triangle mesh placed in the scene: read from a file or built by ganache (spheres, cylinders, bars, hooks),
/// loaded, placed and repaired (orientation) when the scene is loaded.
struct MeshShape {
    std::filesystem::path file;  ///< empty for procedural solids
    std::string description;     ///< the file, or the procedural shape's name
    MeshPlacement placement;
    InsideMethod inside = InsideMethod::Auto;
    std::shared_ptr<const TriangleMesh> mesh;
    MeshCheck check;             ///< facts of the mesh as read, before repair
    /// The method `inside` resolves to for this mesh.
    InsideMethod method() const {
        return inside != InsideMethod::Auto ? inside : check.closed() ? InsideMethod::LevelSet
                                                                      : InsideMethod::WindingNumber;
    }
};
using FluidShape = std::variant<BoxShape, SphereShape, MeshShape>;

/// A body of fluid present at t = 0.
struct FluidSpec {
    std::string name;
    Material material;
    Vec3 velocity = Vec3::Zero();  ///< initial velocity [m/s]
    Vec3 angularVelocity = Vec3::Zero();  ///< initial spin about the fluid's centre of mass [rad/s]
    FluidShape shape;
    Real jitter = 0;               ///< random offset of each lattice site, as a fraction of the spacing
    Real temperature = 20;         ///< initial temperature [C], used with the heat effect
    Location at;
};

/// The walls of a box (a tank when the fluid is inside, an obstacle when outside); open_top leaves out
/// the face at max y (y is up).
struct BoxBoundary {
    Vec3 min, max;
    bool openTop = false;
};
/// An infinite plane, sampled where it crosses the domain.
struct PlaneBoundary {
    Vec3 point = Vec3::Zero();
    Vec3 normal = Vec3::UnitY();  ///< unit length
};
/// A solid from a mesh file or a procedural shape: its surface is sampled, and fluid inside it is carved when
/// the mesh is closed.
using BoundaryShape = std::variant<BoxBoundary, PlaneBoundary, MeshShape>;

/// A solid the fluid cannot pass, made of boundary particles (Akinci et al. 2012); static unless it has a
/// motion.
struct BoundarySpec {
    std::string name;
    BoundaryShape shape;
    BodyMotion motion;
    Location at;
};

/// The `surface:` section: how particles become level sets and meshes (see surfacer/surfacer.h).
enum class SurfaceMethod { Spheres, SmoothSpheres, Anisotropic };

/// The scene's name of a method: "spheres", "smooth_spheres" or "anisotropic".
const char* surfaceMethodName(SurfaceMethod method);

struct SurfaceSettings {
    bool requested = false;  ///< the scene has a `surface:` section; without one the stage is not run
    SurfaceMethod method = SurfaceMethod::Anisotropic;
    Real voxelFraction = 0.5;        ///< voxel size / particle radius
    std::int64_t smoothing = 2;      ///< mean-curvature smoothing iterations of the level set
    bool mesh = true;                ///< write mesh/<scene>.####.obj (or .ply)
    bool meshPly = false;            ///< binary PLY meshes instead of OBJ text
    /// The mesher's adaptivity in [0, 1] (0: every polygon). At 0.1 the surfacer tests' ball and flat layer take 4.9x
    /// and 7.4x fewer triangles, within 0.75 voxel of the level set, with every quality test unchanged.
    Real adaptivity = 0.1;
    bool densityGrid = false;        ///< extra grid `density` (fog volume, 0 outside to 1 deep inside)
    bool temperatureGrid = false;    ///< extra grid `temperature` [C]
    bool velocityGrid = false;       ///< extra grid `vel` [m/s]
    bool meshTemperature = false;    ///< per-vertex temperature on the mesh
    Location at;
};

/// The `render:` section: preview images (see render/render.h).
enum class RenderView { Auto, Mesh, Particles };
enum class ColourBy { Velocity, Temperature, Viscosity };

/// Where the camera is on a frame; several keys are interpolated linearly between their frames.
struct CameraKey {
    std::int64_t frame = 0;
    Vec3 position = Vec3::Zero(), target = Vec3::Zero();  ///< [m]
    Real fovDegrees = 40;  ///< vertical field of view
};

struct RenderSettings {
    bool requested = false;   ///< the scene has a `render:` section; without one the stage is not run
    std::int64_t width = 1280, height = 720;  ///< pixels
    std::vector<CameraKey> camera;           ///< frames increasing; empty: framed on the first frame's bounds
    RenderView view = RenderView::Auto;      ///< auto: the surface mesh when the frame has one, else particles
    ColourBy colourBy = ColourBy::Velocity;  ///< particle colours
    std::optional<std::pair<Real, Real>> colourRange;  ///< colour_min, colour_max; none: each frame's own range
    std::optional<Vec3> fluidColour;         ///< sRGB; none: the first source's material colour
    bool ground = true;                      ///< a ground plane with the bodies' and fluid's shadows
    std::int64_t contactSheet = 12;          ///< frames on preview/<scene>.sheet.png; 0: no sheet
    bool video = true;                       ///< preview/<scene>.mp4 through ffmpeg, when it is installed
    Location at;
};

/// The scene's name of a particle colouring: "velocity", "temperature" or "viscosity".
const char* colourByName(ColourBy c);

struct Scene {
    std::filesystem::path file;
    std::string name;  ///< output file prefix
    std::string hash;  ///< FNV-1a 64 of the scene file's bytes, hex

    FrameRange frames;

    Real finalRadius = 0;            ///< particles.radius [m], the radius at final quality
    Real previewScale = 2;           ///< particles.preview_scale
    std::int64_t maxParticles = 20'000'000;  ///< particles.max_count: refuse scenes estimated above it
    bool exportPly = false;          ///< particles.export: ply: points/<scene>.NNNN.ply besides each cache
    Location radiusAt;
    Quality quality;
    Real particleRadius = 0;         ///< the radius this run uses [m], after --quality

    Vec3 domainMin, domainMax;       ///< particles leaving this box are removed [m]

    std::vector<FluidSpec> fluids;
    std::vector<BoundarySpec> boundaries;
    std::vector<EmitterSpec> emitters;
    std::vector<EffectSpec> effects;

    TimeStepSettings timeStep;
    PressureSettings pressure;
    /// simulation.viscosity_coupling: where the viscosity solve sits in a step (predicted, paper, or n coupled passes).
    ViscosityOrder viscosityOrder;
    /// simulation.checkpoint_every: a checkpoint after every this many frames (and after the last); 0: none.
    std::int64_t checkpointEvery = 10;
    /// simulation.checkpoints_kept: the newest this many are kept, so a damaged one has one to fall back on.
    std::int64_t checkpointsKept = 2;

    SurfaceSettings surface;
    RenderSettings render;

    std::shared_ptr<const EffectiveScene> effective;  ///< every value read, defaults included

    const EffectSpec* findEffect(const std::string& name) const;
    /// The material of every source of fluid: the fluids, then the emitters. A particle's attribute::kFluid
    /// (present when there are several sources) indexes this list.
    std::vector<Material> sourceMaterials() const;
};

/// What the simulation needs of the scene.
SimulationSetup simulationSetup(const Scene& scene);

/// Loads and validates a scene; throws SceneError (file:line:col, what, fix) or InputError.
Scene loadScene(const std::filesystem::path& file, const Quality& quality);

/// Fluid particles the scene's shapes hold at `radius` on a lattice of spacing 2 radius, plus what its emitters
/// add by the last frame (an estimate).
Real estimateFluidParticles(const Scene& scene, Real radius);

/// `ganache scene --explain`: the effective scene as YAML with units and a header naming the quality.
std::string explainScene(const Scene& scene);

}  // namespace ganache
