// coil_metrics: where a viscous rope lays itself down, frame by frame, for the rope-coiling scene
// (scenes/coiling.yaml; [WKBB18] Fig. 6, "a coil radius about constant").
//
//   coil_metrics [--axis X Z] [--slow SPEED] [--below HEIGHT] [--window N] [--falling SPEED] [--turn N [--circle E]]
//                [--from T0] [--to T1] CACHE...
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
//
// --turn N measures each frame's newest laid loop instead, whatever the coil as a whole has drifted: the laid
// particles in id order, N at a time, trace the laid rope's centre line; walked back from its newest point until the
// line has turned one revolution, it gives the newest turn, and a circle fitted to that turn (least squares on
// x^2 + z^2 + D x + E z + F = 0) its radius and centre. The turn is a circle when the points' RMS distance from that
// circle is at most E times its radius (default 0.1); a rope that lays meanders or figures of eight turns a
// revolution only over several loops, and the circle fitted to them says how wide the pile is, not how wide a coil.
// Over the window the summary then gives the turns' mean radius and its coefficient of variation, the same for the
// turns that are circles, and the coiling frequency: the emitter's rate (ids a second, from the frames) over the ids a
// circular turn took.

#include "io/particle_cache.h"
#include "tool_args.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
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
    std::uint64_t newestId = 0;  // the highest id of the frame
    // --turn: the circle's RMS misfit over its radius, the ids the turn took (0: no turn)
    Real misfit = 0;
    std::uint64_t turnIds = 0;
};

struct Options {
    bool axis = false;  // a fixed axis instead of the laid rope's centroid
    std::size_t turn = 0;  // > 0: fit a circle to the newest laid turn, its centre line in points of this many ids
    Real circle = 0.1;     // the largest RMS misfit over the radius of a turn that counts as a circle
    Real axisX = 0, axisZ = 0, slow = 0.1, below = 0.06;
    Real falling = 0;  // > 0: the touchdown is the bottom of the stream falling faster than this [m/s]
    std::size_t window = 64;
};

// Whether particle i has come to rest on the pile: slower than SPEED below HEIGHT.
bool laid(const ParticleSet& p, std::size_t i, const Options& o) {
    return p.v()[i].norm() < o.slow && p.x()[i].y() < o.below;
}

// The newest laid turn (see --turn above): its radius and angle about the fitted centre, misfit and ids in t.
void fitNewestTurn(const ParticleSet& p, const Options& o, Touchdown& t) {
    std::vector<Vec3> line;  // newest first
    std::vector<std::uint64_t> oldest;  // the oldest id of each point
    Vec3 sum = Vec3::Zero();
    std::size_t k = 0;
    for (std::size_t i = p.size(); i-- > 0;)
        if (laid(p, i, o)) {
            sum += p.x()[i];
            if (++k == o.turn) line.push_back(sum / Real(k)), oldest.push_back(p.id()[i]), sum.setZero(), k = 0;
        }
    Real turned = 0, heading = 0;
    std::size_t used = 0;
    for (std::size_t q = 1; q < line.size() && std::abs(turned) < 2 * M_PI; ++q) {
        const Vec3 d = line[q - 1] - line[q];
        const Real h = std::atan2(d.z(), d.x());
        if (q > 1) turned += std::remainder(h - heading, 2 * M_PI);
        heading = h;
        used = q + 1;
    }
    if (std::abs(turned) < 2 * M_PI) return;
    using Matrix = Eigen::Matrix<Real, Eigen::Dynamic, 3>;
    using Vector = Eigen::Matrix<Real, Eigen::Dynamic, 1>;
    Matrix a = Matrix::Zero(Eigen::Index(used), 3);
    Vector b = Vector::Zero(Eigen::Index(used));
    for (std::size_t q = 0; q < used; ++q) {
        const Real x = line[q].x(), z = line[q].z();
        a.row(Eigen::Index(q)) << x, z, 1;
        b[Eigen::Index(q)] = -(x * x + z * z);
    }
    const Eigen::Matrix<Real, 3, 1> f = a.colPivHouseholderQr().solve(b);
    const Real cx = -f[0] / 2, cz = -f[1] / 2;
    t.radius = std::sqrt(std::max<Real>(cx * cx + cz * cz - f[2], 0));
    Real squares = 0;
    for (std::size_t q = 0; q < used; ++q)
        squares += std::pow(std::hypot(line[q].x() - cx, line[q].z() - cz) - t.radius, 2);
    t.misfit = std::sqrt(squares / Real(used)) / t.radius;
    t.angle = std::atan2(line[0].z() - cz, line[0].x() - cx);
    t.turnIds = t.newestId - oldest[used - 1] + 1;
}

Touchdown touchdown(const CacheContents& cache, const Options& o) {
    const ParticleSet& p = cache.fluid;  // in id order
    Touchdown t;
    t.time = cache.info.time;
    for (std::uint64_t id : p.id()) t.newestId = std::max(t.newestId, id);
    Vec3 c = Vec3::Zero(), pile = Vec3::Zero();
    std::size_t n = 0;
    for (std::size_t i = p.size(); i-- > 0;)
        if (laid(p, i, o)) {
            if (n < o.window) c += p.x()[i], ++n;
            pile += p.x()[i];
            ++t.laid;
        }
    if (n == 0) return t;
    if (o.turn > 0) {
        fitNewestTurn(p, o, t);
        return t;
    }
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

// Mean and coefficient of variation (standard deviation over mean) of n values from their sum and sum of squares.
std::pair<Real, Real> meanAndVariation(Real sum, Real squares, std::size_t n) {
    const Real mean = sum / Real(n);
    return {mean, std::sqrt(std::max<Real>(squares / Real(n) - mean * mean, 0)) / mean};
}

// The summary of the touchdowns about the coil's centre (without --turn).
std::string touchdowns(const std::vector<Touchdown>& frames, Real from, Real to) {
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
    const auto [mean, cv] = meanAndVariation(sum, squares, n);
    const Real span = previous->time - first;
    // Frames a quarter of a revolution or more apart may miss turns (aliasing): no frequency then.
    const std::string frequency =
        widest < 0.5 * M_PI && span > 0 ? fmt::format("{:.3f}", std::abs(turned) / (2 * M_PI) / span) : "null";
    return fmt::format("{{\"frames_in_window\": {}, \"mean_radius\": {:.5f}, \"radius_cv\": {:.4f}, "
                       "\"frequency_hz\": {},\n  \"frames\": [\n    {}]}}\n",
                       n, mean, cv, frequency, rows);
}

// The summary of the newest turns (--turn): their radius and its variation, and the same for the turns that are
// circles, with the coiling frequency.
std::string newestTurns(const std::vector<Touchdown>& frames, const Options& o, Real from, Real to) {
    // The emitter's rate from the frames in which ids grew: after the emitter stops they no longer do.
    Real emitted = 0, emitting = 0;
    for (std::size_t k = 1; k < frames.size(); ++k)
        if (frames[k].newestId > frames[k - 1].newestId && frames[k].time >= from && frames[k - 1].time <= to) {
            emitted += Real(frames[k].newestId - frames[k - 1].newestId);
            emitting += frames[k].time - frames[k - 1].time;
        }
    Real sum = 0, squares = 0, circleSum = 0, circleSquares = 0, ids = 0;
    std::size_t inWindow = 0, turns = 0, circles = 0;
    std::string rows;
    for (const Touchdown& t : frames) {
        rows += fmt::format("{}{{\"time\": {:.4f}, \"laid\": {}, \"radius\": {:.5f}, \"misfit\": {:.4f}, "
                            "\"turn_ids\": {}}}",
                            rows.empty() ? "" : ",\n    ", t.time, t.laid, t.radius, t.misfit, t.turnIds);
        if (t.laid == 0 || t.time < from || t.time > to) continue;
        ++inWindow;
        if (t.turnIds == 0) continue;
        ++turns;
        sum += t.radius, squares += t.radius * t.radius;
        if (t.misfit > o.circle) continue;
        ++circles;
        circleSum += t.radius, circleSquares += t.radius * t.radius, ids += Real(t.turnIds);
    }
    const Real rate = emitting > 0 ? emitted / emitting : 0;
    // "null" where there is nothing to measure
    const auto summary = [](Real s, Real q, std::size_t n) {
        if (n == 0) return std::string("null, null");
        const auto [mean, cv] = meanAndVariation(s, q, n);
        return fmt::format("{:.5f}, {:.4f}", mean, cv);
    };
    const std::string frequency =
        circles > 0 && rate > 0 ? fmt::format("{:.3f}", rate / (ids / Real(circles))) : "null";
    return fmt::format("{{\"frames_in_window\": {}, \"turns\": {}, \"turn_radius_and_cv\": [{}], \"circles\": {}, "
                       "\"circle_radius_and_cv\": [{}], \"emitted_per_s\": {:.0f}, \"frequency_hz\": {},\n"
                       "  \"frames\": [\n    {}]}}\n",
                       inWindow, turns, summary(sum, squares, turns), circles,
                       summary(circleSum, circleSquares, circles), rate, frequency, rows);
}

}  // namespace

int main(int argc, char** argv) {
    Options o;
    Real from = -std::numeric_limits<Real>::infinity(), to = std::numeric_limits<Real>::infinity();
    std::vector<std::string> files;
    bool circleGiven = false;
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
            } else if (arg == "--turn") {
                o.turn = std::size_t(std::max(1.0, value()));
            } else if (arg == "--circle") {
                o.circle = value();
                circleGiven = true;
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
        if (circleGiven && o.turn == 0) throw std::runtime_error("--circle applies to --turn N; give --turn as well");
        std::vector<Touchdown> frames;
        for (const auto& f : files) frames.push_back(touchdown(readParticleCache(f), o));
        std::cout << (o.turn > 0 ? newestTurns(frames, o, from, to) : touchdowns(frames, from, to));
    } catch (const std::exception& e) {
        std::cerr << "coil_metrics: " << e.what() << "\n";
        return 1;
    }
}
