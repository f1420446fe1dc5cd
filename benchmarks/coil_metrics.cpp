// coil_metrics: where a viscous rope lays itself down, frame by frame, for the rope-coiling scene
// (scenes/coiling.yaml; [WKBB18] Fig. 6, "a coil radius about constant").
//
//   coil_metrics [--axis X Z] [--slow SPEED] [--below HEIGHT] [--window N] [--falling SPEED] [--from T0] [--to T1]
//                CACHE...
//
// An emitter numbers its particles in the order it emits them, so along the rope the ids grow from the laid end to
// the nozzle. The rope has come to rest where its particles move slower than SPEED (default 0.1 m/s) below HEIGHT
// (default 0.06 m; a rope standing up to the nozzle is not laid); the N laid particles with the highest ids (default
// 64, a few layers of the stream) are the newest laid piece, and their centroid is where the rope touches down. The
// coil radius is that point's horizontal distance from the coil's centre, the centroid of all the laid rope (or a
// fixed vertical axis through X, Z, such as the nozzle's), its angle the direction about it. With --falling the
// touchdown is instead the centroid of the N lowest particles moving down faster than SPEED: the bottom of the
// falling stream, which the pile's own jostling (particles speeding up and slowing down in it) cannot move.
//
// Prints one JSON object: per frame the time, the laid particles, the touchdown height, radius and angle; over the
// frames with T0 <= t <= T1 (default: all) the mean radius and its coefficient of variation (standard deviation over
// mean), and the coiling frequency from the unwrapped angle when the frames are close enough to follow it (every
// turn between frames under a quarter of a revolution; otherwise null).

#include "io/particle_cache.h"
#include "tool_args.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

using namespace ganache;

namespace {

struct Touchdown {
    Real time = 0, height = 0, radius = 0, angle = 0;
    std::size_t laid = 0;
};

struct Options {
    bool axis = false;  // a fixed axis instead of the laid rope's centroid
    Real axisX = 0, axisZ = 0, slow = 0.1, below = 0.06;
    Real falling = 0;  // > 0: the touchdown is the bottom of the stream falling faster than this [m/s]
    std::size_t window = 64;
};

Touchdown touchdown(const CacheContents& cache, const Options& o) {
    const ParticleSet& p = cache.fluid;  // in id order
    Touchdown t;
    t.time = cache.info.time;
    Vec3 c = Vec3::Zero(), pile = Vec3::Zero();
    std::size_t n = 0;
    for (std::size_t i = p.size(); i-- > 0;)
        if (p.v()[i].norm() < o.slow && p.x()[i].y() < o.below) {
            if (n < o.window) c += p.x()[i], ++n;
            pile += p.x()[i];
            ++t.laid;
        }
    if (n == 0) return t;
    c /= Real(n);
    pile /= Real(t.laid);
    if (o.falling > 0) {
        // The bottom of the falling stream instead: the N lowest particles moving down faster than `falling`.
        std::vector<std::pair<Real, std::size_t>> stream;
        for (std::size_t i = 0; i < p.size(); ++i)
            if (p.v()[i].y() < -o.falling) stream.emplace_back(p.x()[i].y(), i);
        const std::size_t m = std::min(o.window, stream.size());
        if (m == 0) return Touchdown{t.time};  // nothing falling: no touchdown to measure
        std::partial_sort(stream.begin(), stream.begin() + std::ptrdiff_t(m), stream.end());
        c = Vec3::Zero();
        for (std::size_t k = 0; k < m; ++k) c += p.x()[stream[k].second];
        c /= Real(m);
    }
    const Real cx = o.axis ? o.axisX : pile.x(), cz = o.axis ? o.axisZ : pile.z();
    t.height = c.y();
    t.radius = std::hypot(c.x() - cx, c.z() - cz);
    t.angle = std::atan2(c.z() - cz, c.x() - cx);
    return t;
}

}  // namespace

int main(int argc, char** argv) {
    Options o;
    Real from = -std::numeric_limits<Real>::infinity(), to = std::numeric_limits<Real>::infinity();
    std::vector<std::string> files;
    try {
        for (int a = 1; a < argc; ++a) {
            const std::string arg = argv[a];
            auto value = [&] { return tools::nextNumber(argc, argv, a); };
            if (arg == "--axis") {
                o.axis = true;
                o.axisX = value();
                o.axisZ = value();
            } else if (arg == "--slow") {
                o.slow = value();
            } else if (arg == "--below") {
                o.below = value();
            } else if (arg == "--falling") {
                o.falling = value();
            } else if (arg == "--window") {
                o.window = std::size_t(std::max(1.0, value()));
            } else if (arg == "--from") {
                from = value();
            } else if (arg == "--to") {
                to = value();
            } else if (arg.rfind("--", 0) == 0) {
                throw std::runtime_error("unknown option " + arg);
            } else {
                files.push_back(arg);
            }
        }
        if (files.empty()) throw std::runtime_error("no particle cache given");
        std::vector<Touchdown> frames;
        for (const auto& f : files) frames.push_back(touchdown(readParticleCache(f), o));
        Real sum = 0, squares = 0, turned = 0, widest = 0, first = 0;
        std::size_t n = 0;
        const Touchdown* previous = nullptr;
        std::string rows;
        for (const Touchdown& t : frames) {
            rows += fmt::format("{}{{\"time\": {:.4f}, \"laid\": {}, \"height\": {:.5f}, \"radius\": {:.5f}, "
                                "\"angle\": {:.4f}}}",
                                rows.empty() ? "" : ",\n    ", t.time, t.laid, t.height, t.radius, t.angle);
            if (t.laid == 0 || t.time < from || t.time > to) continue;
            if (n == 0) first = t.time;
            sum += t.radius, squares += t.radius * t.radius, ++n;
            if (previous) {
                // The turn between two frames, taken the short way round.
                const Real d = std::remainder(t.angle - previous->angle, 2 * M_PI);
                turned += d;
                widest = std::max(widest, std::abs(d));
            }
            previous = &t;
        }
        if (n < 2) throw std::runtime_error("fewer than two frames with laid rope in the window");
        const Real mean = sum / Real(n);
        const Real cv = std::sqrt(std::max<Real>(squares / Real(n) - mean * mean, 0)) / mean;
        const Real span = previous->time - first;
        // Frames a quarter of a revolution or more apart may miss turns (aliasing): no frequency then.
        const std::string frequency =
            widest < 0.5 * M_PI && span > 0 ? fmt::format("{:.3f}", std::abs(turned) / (2 * M_PI) / span) : "null";
        std::cout << fmt::format("{{\"frames_in_window\": {}, \"mean_radius\": {:.5f}, \"radius_cv\": {:.4f}, "
                                 "\"frequency_hz\": {},\n  \"frames\": [\n    {}]}}\n",
                                 n, mean, cv, frequency, rows);
    } catch (const std::exception& e) {
        std::cerr << "coil_metrics: " << e.what() << "\n";
        return 1;
    }
}
