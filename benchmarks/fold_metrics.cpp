// fold_metrics: the folds a viscous sheet lays down under a moving nozzle, for the buckling scene
// (scenes/buckling.yaml; [WKBB18] Fig. 7, "a uniform buckling").
//
//   fold_metrics [--below HEIGHT] [--slow SPEED] [--chunk N] [--reverse DISTANCE] [--skip K] CACHE
//
// An emitter numbers its particles in the order it emits them, so the laid stream (below HEIGHT, default 0.12 m, and
// slower than SPEED, default 0.2 m/s: not the falling sheet, which lands at over 1 m/s) read in id order runs along
// the stream from where it first landed to where it lands now. Its centroid over every N ids (default 250, about one row of the scene's nozzle at
// --quality final) traces the sheet's centre line. The nozzle moves along +x: where the line turns back along x the
// sheet folds over itself, and where it swings back across z it meanders. A turn counts when the line has come back
// by at least DISTANCE (default 1 cm) from its furthest point since the last turn (hysteresis against the jitter of
// a centroid). The fold wavelength is the distance along x from one forward turn to the next; its coefficient of
// variation (standard deviation over mean) says how regular the folds are. The first K forward turns (default 1:
// the landing of the stream's head) are left out. Defaults suit scenes/buckling.yaml; scale them with a scene.
//
// Prints one JSON object: the laid particles, the folds (forward turns along x) with their x positions,
// the wavelength and its coefficient of variation, the same for the swings across z, and the centre line.

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

struct Options {
    Real slow = 0.2, below = 0.12, reverse = 0.01;
    std::size_t chunk = 250, skip = 1;
};

std::string list(const std::vector<Real>& values) {
    std::string out;
    for (Real v : values) out += (out.empty() ? "" : ", ") + fmt::format("{:.4f}", v);
    return "[" + out + "]";
}

// The turns of a path coordinate: where it reverses by at least `reverse` from its furthest point since the last
// turn, as indices into `s`. The start is not a turn.
struct Turns {
    std::vector<std::size_t> maxima, minima;
};

Turns turnsOf(const std::vector<Real>& s, Real reverse) {
    Turns t;
    int direction = 0;         // +1 rising, -1 falling, 0 not yet known
    std::size_t hi = 0, lo = 0;  // the furthest points since the last turn
    for (std::size_t k = 1; k < s.size(); ++k) {
        if (s[k] > s[hi]) hi = k;
        if (s[k] < s[lo]) lo = k;
        if (direction >= 0 && s[hi] - s[k] >= reverse) {
            if (hi > 0) t.maxima.push_back(hi);
            direction = -1;
            lo = k;
        } else if (direction <= 0 && s[k] - s[lo] >= reverse) {
            if (lo > 0) t.minima.push_back(lo);
            direction = 1;
            hi = k;
        }
    }
    return t;
}

// Mean and coefficient of variation of the gaps between consecutive values, as JSON numbers (null when too few).
std::pair<std::string, std::string> spacing(const std::vector<Real>& at) {
    std::vector<Real> gaps;
    for (std::size_t k = 1; k < at.size(); ++k) gaps.push_back(std::abs(at[k] - at[k - 1]));
    if (gaps.empty()) return {"null", "null"};
    Real mean = 0, squares = 0;
    for (Real g : gaps) mean += g, squares += g * g;
    mean /= Real(gaps.size());
    const Real sd = std::sqrt(std::max<Real>(squares / Real(gaps.size()) - mean * mean, 0));
    return {fmt::format("{:.5f}", mean), gaps.size() > 1 ? fmt::format("{:.4f}", sd / mean) : "null"};
}

}  // namespace

int main(int argc, char** argv) {
    Options o;
    std::string file;
    try {
        for (int a = 1; a < argc; ++a) {
            const std::string arg = argv[a];
            auto value = [&] { return tools::nextNumber(argc, argv, a); };
            if (arg == "--slow") o.slow = value();
            else if (arg == "--below") o.below = value();
            else if (arg == "--reverse") o.reverse = value();
            else if (arg == "--chunk") o.chunk = std::size_t(std::max<Real>(1, value()));
            else if (arg == "--skip") o.skip = std::size_t(std::max<Real>(0, value()));
            else if (arg.rfind("--", 0) == 0) throw std::runtime_error("unknown option " + arg);
            else if (file.empty()) file = arg;
            else throw std::runtime_error("one cache only (the frame whose folds are measured)");
        }
        if (file.empty()) throw std::runtime_error("no particle cache given");
        const CacheContents cache = readParticleCache(file);
        const ParticleSet& p = cache.fluid;  // in id order

        // The centre line: centroids of consecutive runs of `chunk` laid particles.
        std::vector<Real> px, pz;
        Vec3 sum = Vec3::Zero();
        std::size_t inChunk = 0, laid = 0;
        for (std::size_t i = 0; i < p.size(); ++i) {
            if (!(p.v()[i].norm() < o.slow && p.x()[i].y() < o.below)) continue;
            sum += p.x()[i];
            ++laid;
            if (++inChunk == o.chunk) {
                px.push_back(sum.x() / Real(o.chunk));
                pz.push_back(sum.z() / Real(o.chunk));
                sum.setZero();
                inChunk = 0;
            }
        }
        if (px.size() < 3) throw std::runtime_error(fmt::format("only {} particles laid in this frame", laid));

        const Turns x = turnsOf(px, o.reverse), z = turnsOf(pz, o.reverse);
        std::vector<Real> folds;  // x of the forward turns (where the stream folds back), after the first `skip`
        for (std::size_t k = o.skip; k < x.maxima.size(); ++k) folds.push_back(px[x.maxima[k]]);
        std::vector<Real> swings;  // x of every swing across z, left and right
        std::vector<std::size_t> zt = z.maxima;
        zt.insert(zt.end(), z.minima.begin(), z.minima.end());
        std::sort(zt.begin(), zt.end());
        for (std::size_t k : zt) swings.push_back(px[k]);
        std::vector<Real> swingSides;  // one side's swings: a full wavelength apart
        for (std::size_t k : z.maxima) swingSides.push_back(px[k]);
        const auto [foldMean, foldCv] = spacing(folds);
        const auto [swingMean, swingCv] = spacing(swingSides);
        std::cout << fmt::format(
            "{{\"time\": {:.4f}, \"laid\": {}, \"chunk\": {}, \"reverse\": {:.4f},\n"
            "  \"folds\": {}, \"fold_x\": {}, \"fold_wavelength\": {}, \"fold_wavelength_cv\": {},\n"
            "  \"swings\": {}, \"swing_x\": {}, \"swing_wavelength\": {}, \"swing_wavelength_cv\": {},\n"
            "  \"path_x\": {},\n  \"path_z\": {}}}\n",
            cache.info.time, laid, o.chunk, o.reverse, folds.size(), list(folds), foldMean, foldCv, swings.size(),
            list(swings), swingMean, swingCv, list(px), list(pz));
    } catch (const std::exception& e) {
        std::cerr << "fold_metrics: " << e.what() << "\n";
        return 1;
    }
}
