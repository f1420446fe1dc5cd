#pragma once
// Boundary bodies: how they move (a prescribed rotation and keyframed translation), their particles in one set
// (Akinci et al. 2012), and the fluid's push on them. The lever arm of a load is computed here and nowhere else.

#include "core/particles.h"
#include "core/types.h"

#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace ganache {

class Section;

/// Prescribed motion of a boundary body (also of emitters and heat sources): rotation about an axis through
/// `centre` (which moves with the translation) at a constant angular velocity, plus a translation interpolated
/// linearly between keyframes.
struct BodyMotion {
    Vec3 axis = Vec3::UnitY();         ///< unit length
    Vec3 centre = Vec3::Zero();        ///< [m], at t = 0
    Real angularVelocity = 0;          ///< [rad/s], right-handed about axis
    std::vector<std::pair<Real, Vec3>> keyframes;  ///< (time [s], offset [m]), times increasing; empty: none
    bool isStatic() const { return angularVelocity == 0 && keyframes.empty(); }
    /// Offset of the translation at time t (held constant before the first and after the last keyframe).
    Vec3 offset(Real t) const;
    /// Translation velocity at time t [m/s].
    Vec3 translationVelocity(Real t) const;
    /// The rotation the motion has applied by time t.
    Mat3 rotation(Real t) const;
    /// Where a point at x0 at t = 0 is at time t.
    Vec3 transform(const Vec3& x0, Real t) const { return centre + offset(t) + rotation(t) * (x0 - centre); }
    /// Velocity at time t of the moving point that is at x then [m/s].
    Vec3 velocity(const Vec3& x, Real t) const {
        return angularVelocity * axis.cross(x - centre - offset(t)) + translationVelocity(t);
    }
};

/// Reads a `motion:` map (`rotation: {axis, centre, angular_velocity}`, `keyframes: [{time, offset}, ...]`).
BodyMotion readMotion(Section m);
/// Reads `start` (default 0) and `end` [s] of something that acts for a while; end must come after start. With no
/// defaultEnd, an absent end never comes (infinity, not recorded in the effective scene).
std::pair<Real, Real> readTimeWindow(Section& s, std::optional<Real> defaultEnd);

/// A body as the simulation knows it: its name and motion (its particles come from the sample).
struct BodySetup {
    std::string name;
    BodyMotion motion;
};

/// Every boundary particle of the scene in one set (Akinci et al. 2012).
struct BoundaryParticles {
    std::vector<Vec3> x;
    std::vector<Vec3> v;           ///< velocities of the bodies' particles (zero for static bodies) [m/s]
    std::vector<Vec3> x0;          ///< positions at t = 0 [m]
    std::vector<Real> volume;      ///< V_k; pseudo-mass Psi_k = rho_0 V_k [m^3]
    std::vector<std::uint32_t> body;
    std::vector<std::string> names;
    std::vector<BodyMotion> motion;  ///< per body
    bool anyMoving = false;

    /// The sampled bodies, each with the motion of the body of the same name in `setups` (static when none).
    BoundaryParticles(const std::vector<BoundaryBody>& bodies, const std::vector<BodySetup>& setups);
    /// Places the moving bodies' particles where their motion has them at time t.
    void moveTo(Real t);
    /// The rotation centre of body `id` at time t [m].
    Vec3 centre(std::uint32_t id, Real t) const { return motion[id].centre + motion[id].offset(t); }
    /// From the rotation centre of particle k's body at time t to particle k [m].
    Vec3 leverArm(std::size_t k, Real t) const { return x[k] - centre(body[k], t); }
    /// The body of every boundary particle in [begin, end) (indices into this set), or kSeveralBodies.
    static constexpr std::uint32_t kSeveralBodies = ~std::uint32_t(0);
    std::uint32_t commonBody(const std::uint32_t* begin, const std::uint32_t* end) const {
        const std::uint32_t id = begin == end ? 0 : body[*begin];
        for (const std::uint32_t* k = begin; k != end; ++k)
            if (body[*k] != id) return kSeveralBodies;
        return id;
    }
    /// The particles of the moving bodies, body by body (particle caches carry them; static ones are in the sample),
    /// where they are now or, given a time, where their motion has them then.
    std::vector<BoundaryBody> movingBodies(std::optional<Real> t = {}) const;
};

/// The fluid's push on each body during one step, as impulses [N s] and angular impulses [N m s] about the body's
/// rotation centre at the step's end.
struct BodyLoads {
    std::vector<Vec3> impulse, angularImpulse;
    void clear(std::size_t bodies) {
        impulse.assign(bodies, Vec3::Zero());
        angularImpulse.assign(bodies, Vec3::Zero());
    }
    /// The impulse j [N s] the body of boundary particle k takes there, at time t.
    void add(const BoundaryParticles& b, std::size_t k, const Vec3& j, Real t) {
        const std::uint32_t id = b.body[k];
        impulse[id] += j;
        angularImpulse[id] += b.leverArm(k, t).cross(j);
    }
    /// The impulse j [N s] that body `id` takes from one fluid particle at x through its boundary neighbours, each
    /// push along the line from the neighbour to x: a push's moment does not change along its line, so their sum's
    /// is that of j at x, and the pairs need not be visited one by one.
    void addFrom(const BoundaryParticles& b, std::uint32_t id, const Vec3& x, const Vec3& j, Real t) {
        impulse[id] += j;
        angularImpulse[id] += (x - b.centre(id, t)).cross(j);
    }
    /// The pushes of one fluid particle at x on its boundary neighbours [first, last) (indices into b), each along
    /// the line from the neighbour to x: `total` is their sum, push(n) the n-th. Where the neighbours are all of one
    /// body, total is added at x (addFrom); otherwise each push where it acts.
    template <class Push>
    void addPushes(const BoundaryParticles& b, const std::uint32_t* first, const std::uint32_t* last, const Vec3& x,
                   const Vec3& total, Real t, Push push) {
        if (first == last) return;
        const std::uint32_t id = b.commonBody(first, last);
        if (id != BoundaryParticles::kSeveralBodies) {
            addFrom(b, id, x, total, t);
            return;
        }
        for (const std::uint32_t* k = first; k != last; ++k) add(b, *k, push(std::size_t(k - first)), t);
    }
    void add(const BodyLoads& other) {
        for (std::size_t id = 0; id < impulse.size(); ++id) {
            impulse[id] += other.impulse[id];
            angularImpulse[id] += other.angularImpulse[id];
        }
    }
    void subtract(const BodyLoads& other) {
        for (std::size_t id = 0; id < impulse.size(); ++id) {
            impulse[id] -= other.impulse[id];
            angularImpulse[id] -= other.angularImpulse[id];
        }
    }
};

/// Force and torque of the fluid on one body over a run.
struct BodyReport {
    Vec3 meanForce = Vec3::Zero();   ///< total impulse / time [N]
    Vec3 meanTorque = Vec3::Zero();  ///< [N m]
    Real peakForce = 0;              ///< largest |force| averaged over one step [N]
};

}  // namespace ganache
