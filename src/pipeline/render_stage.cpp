// The render stage: preview/<scene>.NNNN.png per frame (the surface mesh, or the particles), a contact sheet and,
// when ffmpeg is installed, an MP4.

#include "pipeline/frame_stage.h"
#include "pipeline/stages.h"

#include "core/attributes.h"
#include "physics/viscosity/viscosity.h"

#include "app/process.h"
#include "app/progress.h"
#include "core/errors.h"
#include "io/atomic_file.h"
#include "io/particle_cache.h"
#include "render/render.h"
#include "surfacer/surfacer.h"

#include <fmt/format.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <cstdlib>
#include <mutex>
#include <sys/wait.h>

namespace ganache {

namespace {

const Vec3 kBodyColour(0.62, 0.62, 0.6);  // boundary bodies: a neutral light grey

// The camera on frame f: the scene's keys interpolated linearly (held before the first and after the last).
Camera cameraAt(const std::vector<CameraKey>& keys, std::int64_t f) {
    auto fromKey = [](const CameraKey& k) { return Camera{k.position, k.target, k.fovDegrees}; };
    if (f <= keys.front().frame) return fromKey(keys.front());
    for (std::size_t k = 1; k < keys.size(); ++k)
        if (f < keys[k].frame) {
            const CameraKey &a = keys[k - 1], &b = keys[k];
            const Real s = Real(f - a.frame) / Real(b.frame - a.frame);
            return Camera{a.position + s * (b.position - a.position), a.target + s * (b.target - a.target),
                          a.fovDegrees + s * (b.fovDegrees - a.fovDegrees)};
        }
    return fromKey(keys.back());
}

// The scene's solid bodies at time t as flat-shaded meshes (planes are the ground, not drawn as bodies). Box
// walls are drawn from inside only (the walls facing the camera are culled away), so a tank shows its content.
std::vector<DrawMesh> bodiesAt(const Scene& scene, Real t) {
    std::vector<DrawMesh> out;
    for (const BoundarySpec& b : scene.boundaries) {
        std::vector<Vec3> vertices;
        std::vector<std::array<std::uint32_t, 3>> triangles;
        bool cutaway = false;
        if (const auto* box = std::get_if<BoxBoundary>(&b.shape)) {
            for (int k = 0; k < 8; ++k)
                vertices.emplace_back(k & 1 ? box->max.x() : box->min.x(), k & 2 ? box->max.y() : box->min.y(),
                                      k & 4 ? box->max.z() : box->min.z());
            // Outward faces (-x, +x, -y, +y, -z, +z), two triangles each.
            const std::uint32_t faces[6][4] = {{0, 4, 6, 2}, {1, 3, 7, 5}, {0, 1, 5, 4},
                                               {2, 6, 7, 3}, {0, 2, 3, 1}, {4, 5, 7, 6}};
            for (int f = 0; f < 6; ++f) {
                if (f == 3 && box->openTop) continue;
                triangles.push_back({faces[f][0], faces[f][1], faces[f][2]});
                triangles.push_back({faces[f][0], faces[f][2], faces[f][3]});
            }
            cutaway = true;
        } else if (const auto* mesh = std::get_if<MeshShape>(&b.shape)) {
            vertices = mesh->mesh->vertices;
            triangles = mesh->mesh->triangles;
        } else {
            continue;
        }
        for (Vec3& v : vertices) v = b.motion.transform(v, t);
        DrawMesh m = flatMesh(vertices, triangles, kBodyColour);
        m.cutaway = cutaway;
        out.push_back(std::move(m));
    }
    return out;
}

// Where the ground goes: the highest plane body facing up, else under the lowest point of what is drawn.
std::optional<Real> groundHeight(const Scene& scene, const Vec3& lo) {
    std::optional<Real> plane;
    for (const BoundarySpec& b : scene.boundaries)
        if (const auto* p = std::get_if<PlaneBoundary>(&b.shape); p && p->normal.y() > 0.99 && b.motion.isStatic())
            plane = std::max(plane.value_or(-std::numeric_limits<Real>::infinity()), p->point.y());
    if (plane) return plane;
    return std::isfinite(lo.y()) ? std::optional<Real>(lo.y()) : std::nullopt;
}

void grow(Vec3& lo, Vec3& hi, const std::vector<Vec3>& points) {
    for (const Vec3& p : points) lo = lo.cwiseMin(p), hi = hi.cwiseMax(p);
}

// The value particles are coloured by, and the legend's title.
std::pair<std::vector<Real>, std::string> colourValues(const Scene& scene, const ParticleSet& fluid) {
    std::vector<Real> values(fluid.size());
    switch (scene.render.colourBy) {
    case ColourBy::Velocity:
        for (std::size_t i = 0; i < fluid.size(); ++i) values[i] = fluid.v()[i].norm();
        return {values, "speed [m/s]"};
    case ColourBy::Temperature:
        if (const auto* t = fluid.find(attribute::kTemperature)) values = *t;
        return {values, "temperature [c]"};
    case ColourBy::Viscosity: {
        // Each particle's own when viscosity varies; otherwise the effect's, or its source material's.
        const auto* own = fluid.find(attribute::kViscosity);
        const auto* source = fluid.find(attribute::kFluid);
        const auto* params = static_cast<const ViscosityParams*>(scene.findEffect("viscosity")->params.get());
        const std::vector<Material> materials = scene.sourceMaterials();
        for (std::size_t i = 0; i < fluid.size(); ++i) {
            const Real mu = own ? (*own)[i]
                                : params->mu ? *params->mu
                                             : materials[source ? std::size_t((*source)[i]) : 0].mu;
            values[i] = std::log10(std::max<Real>(mu, 1e-12));
        }
        return {values, "log10 viscosity [pa s]"};
    }
    }
    return {values, ""};
}

}  // namespace

void runRender(const Scene& scene, const OutputLayout& layout, std::pair<std::int64_t, std::int64_t> frames,
               bool force, bool framesOnly, RunReport& report) {
    StageRecord& stage = report.addStage("render");
    const RenderSettings& settings = scene.render;
    if (!settings.requested) {
        stage.status = "skipped";
        stage.note = "the scene asks for no previews (no `render:` section)";
        return;
    }
    Stopwatch clock;
    requireParticleCaches("render", scene, layout, frames);
    const bool meshesExist = scene.surface.requested && scene.surface.mesh;
    auto usesMesh = [&](std::int64_t f) {
        return settings.view == RenderView::Mesh ||
               (settings.view == RenderView::Auto && meshesExist && std::filesystem::exists(layout.mesh(f)));
    };
    FrameJobs jobs("render", "rendered", frames, force, [&](std::int64_t f) {
        return upToDate(layout.preview(f), layout.particles(f)) && upToDate(layout.preview(f), scene.file) &&
               (!usesMesh(f) || upToDate(layout.preview(f), layout.mesh(f)));
    });
    const auto& todo = jobs.todo();

    // The camera: the scene's, or framed once on the scene's first frame (the same for every frame).
    std::vector<CameraKey> keys = settings.camera;
    std::optional<Real> ground;
    if (!todo.empty()) {
        const std::int64_t first = std::filesystem::exists(layout.particles(scene.frames.start)) ? scene.frames.start
                                                                                                  : frames.first;
        const CacheContents cache = readParticleCache(layout.particles(first));
        Vec3 lo = Vec3::Constant(std::numeric_limits<Real>::infinity()), hi = -lo;
        grow(lo, hi, cache.fluid.x());
        for (const DrawMesh& m : bodiesAt(scene, cache.info.time)) grow(lo, hi, m.points);
        if (settings.ground) ground = groundHeight(scene, lo);
        if (keys.empty()) {
            if (!(lo.array() <= hi.array()).all()) lo = scene.domainMin, hi = scene.domainMax;
            const Camera c = frameBounds(lo, hi, Real(settings.width) / Real(settings.height));
            keys.push_back(CameraKey{first, c.position, c.target, c.fovDegrees});
        }
    }
    const Vec3 fluidColour = settings.fluidColour.value_or(scene.sourceMaterials().front().colour);

    std::mutex lock;
    std::vector<std::string> warnings;
    std::size_t meshFrames = 0;
    // One offscreen context per worker thread; llvmpipe itself spreads each frame over the cores too.
    tbb::enumerable_thread_specific<std::unique_ptr<Renderer>> renderers;
    std::filesystem::create_directories(layout.preview(frames.first).parent_path());
    jobs.run(0, todo.size(), [&](std::int64_t f) {
        const CacheContents cache = [&] {
            try {
                return readParticleCache(layout.particles(f));
            } catch (const std::exception& e) {
                throw InputError(e.what());
            }
        }();
        FrameView view;
        view.camera = cameraAt(keys, f);
        view.groundHeight = ground;
        view.meshes = bodiesAt(scene, cache.info.time);
        Vec3 lo = Vec3::Constant(std::numeric_limits<Real>::infinity()), hi = -lo;
        std::vector<std::string> notes;
        const bool mesh = usesMesh(f);
        if (mesh) {
            if (!std::filesystem::exists(layout.mesh(f)))
                throw InputError(fmt::format("{}: no surface mesh for this frame\n  fix: run `ganache surface {} "
                                             "--frames {}`, or render with `view: auto`",
                                             layout.mesh(f).string(), scene.file.string(), f));
            SurfaceMesh surface = readSurfaceMesh(layout.mesh(f));
            if (surface.triangles.empty() && !cache.fluid.empty())
                notes.push_back(fmt::format("frame {}: the preview shows no fluid: the surface mesh of its {} fluid "
                                            "particle(s) is empty (see the surface stage's warning); render with "
                                            "`view: particles` to see them",
                                            f, cache.fluid.size()));
            DrawMesh m;
            m.points = std::move(surface.points);
            m.normals = std::move(surface.normals);
            m.triangles = std::move(surface.triangles);
            m.colour = fluidColour;
            m.gloss = 0.6;
            grow(lo, hi, m.points);
            view.meshes.insert(view.meshes.begin(), std::move(m));
        } else if (!cache.fluid.empty()) {
            auto [values, title] = colourValues(scene, cache.fluid);
            const auto [minIt, maxIt] = std::minmax_element(values.begin(), values.end());
            Real a = *minIt, b = *maxIt;
            if (settings.colourRange) std::tie(a, b) = *settings.colourRange;
            if (!(b > a)) b = a + 1;
            DrawPoints points;
            points.radius = cache.info.particleRadius;
            points.x = cache.fluid.x();
            for (Real v : values) points.colour.push_back(colourRamp((v - a) / (b - a)));
            view.points = std::move(points);
            view.legend = Legend{title, a, b};
            grow(lo, hi, cache.fluid.x());
        }
        if ((lo.array() <= hi.array()).all()) {
            const Vec3 d = view.camera.target - view.camera.position;
            if ((view.camera.position.array() > lo.array()).all() && (view.camera.position.array() < hi.array()).all())
                notes.push_back(fmt::format("frame {}: the camera is inside the fluid's bounds", f));
            else if (d.normalized().dot((0.5 * (lo + hi) - view.camera.position).normalized()) <
                     std::cos(std::min<Real>(M_PI / 2, view.camera.fovDegrees * M_PI / 180)))
                notes.push_back(fmt::format("frame {}: the camera looks away from the fluid", f));
        }
        auto& renderer = renderers.local();
        if (!renderer) renderer = std::make_unique<Renderer>(int(settings.width), int(settings.height));
        writePng(layout.preview(f), renderer->render(view));
        const std::lock_guard<std::mutex> guard(lock);
        meshFrames += mesh;
        warnings.insert(warnings.end(), notes.begin(), notes.end());
    });
    const std::size_t done = jobs.done();
    std::sort(warnings.begin(), warnings.end());
    for (const std::string& w : warnings) report.addWarning("render: " + w);
    for (std::int64_t f : todo) {
        if (std::filesystem::exists(layout.preview(f))) stage.outputs.push_back(layout.preview(f).string());
    }

    // The contact sheet and the video, made again only when one of the range's previews is newer (or they are
    // missing); not at all for a part of a range (a farm's render task: its assemble job makes them).
    std::string sheetNote, videoNote;
    const std::int64_t count = frames.second - frames.first + 1;
    auto stale = [&](const std::filesystem::path& whole) {
        if (framesOnly) return false;
        if (done > 0) return true;
        for (std::int64_t f = frames.first; f <= frames.second; ++f)
            if (!upToDate(whole, layout.preview(f))) return true;
        return false;
    };
    if (settings.contactSheet > 0 && stale(layout.sheet())) {
        // Up to contact_sheet frames spread evenly over the range.
        std::vector<Image> images;
        std::vector<std::string> captions;
        const std::int64_t n = std::min<std::int64_t>(settings.contactSheet, count);
        for (std::int64_t k = 0; k < n; ++k) {
            const std::int64_t f = frames.first + (n == 1 ? 0 : k * (count - 1) / (n - 1));
            if (!std::filesystem::exists(layout.preview(f))) continue;
            images.push_back(readPng(layout.preview(f)));
            captions.push_back(fmt::format("frame {}", f));
        }
        if (!images.empty()) {
            writePng(layout.sheet(), contactSheet(images, captions, 4, 1600));
            stage.outputs.push_back(layout.sheet().string());
            sheetNote = fmt::format("; contact sheet of {} frames", images.size());
        }
    }
    // The video, from every frame of the range, when ffmpeg is there.
    if (settings.video && !jobs.failed() && !jobs.stopped() && stale(layout.video())) {
        if (!onPath("ffmpeg")) {
            videoNote = "; no MP4: ffmpeg is not installed (`apt-get install ffmpeg`)";
        } else {
            // ffmpeg writes into the atomic writer's file (it names the muxer: the file has no .mp4 name yet).
            try {
                writeAtomically(layout.video(), [&](const std::filesystem::path& target) {
                    const std::string command = fmt::format(
                        "ffmpeg -y -loglevel error -framerate {} -start_number {} -i '{}' -frames:v {} -c:v libx264 "
                        "-pix_fmt yuv420p -vf 'pad=ceil(iw/2)*2:ceil(ih/2)*2' -f mp4 '{}'",
                        formatNumber(scene.frames.fps), frames.first,
                        (layout.preview(frames.first).parent_path() / (scene.name + ".%04d.png")).string(), count,
                        target.string());
                    const int status = std::system(command.c_str());
                    if (status != 0) throw std::runtime_error(fmt::format("ffmpeg failed (exit {})", WEXITSTATUS(status)));
                });
                stage.outputs.push_back(layout.video().string());
                videoNote = "; MP4 written";
            } catch (const std::runtime_error& e) {
                report.addWarning(fmt::format("render: no MP4: {}", e.what()));
            }
        }
    }
    stage.seconds = clock.seconds();
    stage.frames = std::int64_t(done);
    stage.status = todo.empty() ? "skipped" : "done";
    stage.note = fmt::format("{} frames rendered at {}x{} ({} of them from surface meshes){}{}{}", done,
                             settings.width, settings.height, meshFrames,
                             jobs.skipped() ? fmt::format("; {} up to date, skipped (--force redoes them)", jobs.skipped())
                                            : "",
                             sheetNote, videoNote);
    jobs.finish();
}

}  // namespace ganache
