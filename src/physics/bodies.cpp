#include "physics/bodies.h"

#include "scene/section.h"

#include <fmt/format.h>

#include <limits>

namespace ganache {

Vec3 BodyMotion::offset(Real t) const {
    if (keyframes.empty()) return Vec3::Zero();
    if (t <= keyframes.front().first) return keyframes.front().second;
    for (std::size_t k = 1; k < keyframes.size(); ++k)
        if (t < keyframes[k].first) {
            const auto& [t0, a] = keyframes[k - 1];
            const auto& [t1, b] = keyframes[k];
            return a + (t - t0) / (t1 - t0) * (b - a);
        }
    return keyframes.back().second;
}

Mat3 BodyMotion::rotation(Real t) const {
    if (angularVelocity == 0) return Mat3::Identity();
    return Eigen::AngleAxis<Real>(angularVelocity * t, axis).toRotationMatrix();
}

Vec3 BodyMotion::translationVelocity(Real t) const {
    for (std::size_t k = 1; k < keyframes.size(); ++k)
        if (t >= keyframes[k - 1].first && t < keyframes[k].first)
            return (keyframes[k].second - keyframes[k - 1].second) / (keyframes[k].first - keyframes[k - 1].first);
    return Vec3::Zero();
}

std::pair<Real, Real> readTimeWindow(Section& s, std::optional<Real> defaultEnd) {
    const Real start = s.number("start", 0, "s", Bounds::nonNegative());
    if (!defaultEnd && !s.has("end")) return {start, std::numeric_limits<Real>::infinity()};
    const Real end = s.number("end", defaultEnd, defaultEnd ? "s (default: the last frame)" : "s", Bounds::nonNegative());
    if (!(end > start))
        s.fail("end", fmt::format("{}.end ({} s) must come after start ({} s)", s.path(), formatNumber(end),
                                  formatNumber(start)),
               defaultEnd ? "make end later than start" : "make end later than start, or leave it out to never end");
    return {start, end};
}

BodyMotion readMotion(Section m) {
    BodyMotion mo;
    if (auto rot = m.child("rotation")) {
        mo.axis = rot->direction("axis", mo.axis);
        mo.centre = rot->vec3("centre", mo.centre, "m");
        mo.angularVelocity = rot->number("angular_velocity", std::nullopt, "rad/s",
                                         Bounds::closed(-limits::kAngularVelocity, limits::kAngularVelocity));
        rot->rejectUnused();
    }
    for (Section& k : m.list("keyframes")) {
        const Real t = k.number("time", std::nullopt, "s", Bounds::nonNegative());
        if (!mo.keyframes.empty() && !(t > mo.keyframes.back().first))
            k.fail("time", fmt::format("{}.time ({} s) must come after the previous keyframe ({} s)", k.path(),
                                       formatNumber(t), formatNumber(mo.keyframes.back().first)),
                   "list keyframes in increasing time");
        const Vec3 offset = k.vec3("offset", std::nullopt, "m", limits::kCoordinate);
        if (!mo.keyframes.empty()) {
            const Real speed = (offset - mo.keyframes.back().second).norm() / (t - mo.keyframes.back().first);
            if (!(speed <= limits::kSpeed))
                k.fail("offset", fmt::format("{}.offset moves the body at {:.3g} m/s since the previous keyframe, above "
                                             "the {} m/s a scene may use", k.path(), speed, formatNumber(limits::kSpeed)),
                       "space the keyframes further apart in time, or shorten the move");
        }
        mo.keyframes.emplace_back(t, offset);
        k.rejectUnused();
    }
    m.rejectUnused();
    return mo;
}

BoundaryParticles::BoundaryParticles(const std::vector<BoundaryBody>& bodies, const std::vector<BodySetup>& setups) {
    for (std::size_t b = 0; b < bodies.size(); ++b) {
        names.push_back(bodies[b].name);
        x.insert(x.end(), bodies[b].x.begin(), bodies[b].x.end());
        volume.insert(volume.end(), bodies[b].volume.begin(), bodies[b].volume.end());
        body.insert(body.end(), bodies[b].x.size(), std::uint32_t(b));
        // Caches name their bodies; the scene's motion goes with the body of the same name.
        BodyMotion m;
        for (const auto& setup : setups)
            if (setup.name == bodies[b].name) m = setup.motion;
        anyMoving |= !m.isStatic();
        motion.push_back(m);
    }
    x0 = x;
    v.assign(x.size(), Vec3::Zero());
}

void BoundaryParticles::moveTo(Real t) {
    if (!anyMoving) return;
    for (std::size_t k = 0; k < x.size(); ++k) {
        const BodyMotion& m = motion[body[k]];
        if (m.isStatic()) continue;
        x[k] = m.transform(x0[k], t);
        v[k] = m.velocity(x[k], t);
    }
}

std::vector<BoundaryBody> BoundaryParticles::movingBodies(std::optional<Real> t) const {
    std::vector<BoundaryBody> out;
    if (!anyMoving) return out;
    for (std::size_t b = 0; b < names.size(); ++b) out.push_back({names[b], {}, {}});
    for (std::size_t k = 0; k < x.size(); ++k) {
        const BodyMotion& m = motion[body[k]];
        out[body[k]].x.push_back(t && !m.isStatic() ? m.transform(x0[k], *t) : x[k]);
        out[body[k]].volume.push_back(volume[k]);
    }
    return out;
}

}  // namespace ganache
