#include "physics/emitter.h"

#include "core/attributes.h"
#include "core/byte_stream.h"
#include "core/kernels.h"
#include "physics/setup.h"
#include "physics/simulation.h"

#include <fmt/format.h>

#include <cmath>

namespace ganache {

namespace {

// A site closer than this (in lattice spacings) to fluid already at the nozzle is skipped: a particle placed
// there would start compressed and push the stream apart.
constexpr Real kBlockedFraction = 0.75;

// Width axis of a nozzle: x, or z when the emitter points (nearly) along x, projected into its plane.
std::pair<Vec3, Vec3> nozzleAxes(const Vec3& direction) {
    const Vec3 ref = std::abs(direction.x()) > 0.9 ? Vec3::UnitZ() : Vec3::UnitX();
    const Vec3 u = (ref - ref.dot(direction) * direction).normalized();
    return {u, direction.cross(u)};
}

}  // namespace

std::vector<Vec3> nozzleSites(const EmitterSpec& e, Real r) {
    const Real d = 2 * r;
    const auto [u, w] = nozzleAxes(e.direction);
    const Real slack = 1e-9 * d;
    std::vector<Vec3> sites;
    if (auto* c = std::get_if<CircleNozzle>(&e.nozzle)) {
        const int n = int(std::floor(c->radius / d));
        for (int j = -n; j <= n; ++j)
            for (int i = -n; i <= n; ++i)
                if (d * std::hypot(Real(i), Real(j)) + r <= c->radius + slack) sites.push_back(d * (i * u + j * w));
    } else {
        const auto& rect = std::get<RectangleNozzle>(e.nozzle);
        const int nu = int(std::floor(rect.width / d + 1e-9));
        const int nw = int(std::floor(rect.height / d + 1e-9));
        for (int j = 0; j < nw; ++j)
            for (int i = 0; i < nu; ++i)
                sites.push_back(d * ((i - 0.5 * (nu - 1)) * u + (j - 0.5 * (nw - 1)) * w));
    }
    return sites;
}

Real emitterFlowRate(const EmitterSpec& e, Real r) {
    return Real(nozzleSites(e, r).size()) * 4 * r * r * e.speed;
}

Emitters::Emitters(const SimulationSetup& setup, const ParticleSet& particles) : m_spacing(2 * setup.particleRadius) {
    const CubicSpline kernel(supportRadiusFor(setup.particleRadius));
    const std::size_t firstSource = setup.sources.size() - setup.emitters.size();
    for (std::size_t e = 0; e < setup.emitters.size(); ++e) {
        Nozzle n;
        n.spec = setup.emitters[e];
        n.sites = nozzleSites(n.spec, setup.particleRadius);
        for (const Vec3& s : n.sites) n.reach = std::max(n.reach, s.norm());
        n.mass = latticeMass(m_spacing, n.spec.material.density, kernel);
        n.travelled = m_spacing;  // the first layer leaves as emission starts
        n.sourceIndex = std::uint32_t(firstSource + e);
        m_nozzles.push_back(std::move(n));
        m_reports.push_back({setup.emitters[e].name, 0, 0});
    }
    for (std::uint64_t id : particles.id()) m_nextId = std::max(m_nextId, id + 1);
}

void Emitters::apply(StepContext& ctx, ParticleSet& particles) {
    const Real t0 = ctx.time, t1 = ctx.time + ctx.dt;
    for (std::size_t e = 0; e < m_nozzles.size(); ++e) {
        Nozzle& n = m_nozzles[e];
        const Real active = std::min(t1, n.spec.end) - std::max(t0, n.spec.start);
        if (active <= 0) continue;
        n.travelled += n.spec.speed * active;
        const Real last = std::min(t1, n.spec.end);
        // Round-off in the sum of travelled distances must not drop a layer that leaves exactly at `end`.
        while (n.travelled >= m_spacing * (1 - 1e-9)) {
            // This layer left the nozzle when the fluid had travelled one spacing, `travelled - spacing` ago.
            const Real left = std::max(n.spec.start, last - std::max<Real>(0, n.travelled - m_spacing) / n.spec.speed);
            emitLayer(n, e, left, last - left, particles, ctx);
            n.travelled -= m_spacing;
        }
    }
}

std::vector<Counter> Emitters::counters(std::size_t) const {
    std::size_t emitted = 0, blocked = 0;
    for (const auto& r : m_reports) emitted += r.emitted, blocked += r.blocked;
    return {{"particles_emitted", double(emitted)}, {"sites_blocked", double(blocked)}};
}

void Emitters::save(ByteWriter& out) const {
    out(m_nextId);
    out(std::uint64_t(m_nozzles.size()));
    for (std::size_t e = 0; e < m_nozzles.size(); ++e)
        out(m_reports[e].name), out(m_nozzles[e].travelled), out(m_reports[e].emitted), out(m_reports[e].blocked);
}

void Emitters::restore(ByteReader& in) {
    in(m_nextId);
    const std::size_t count = in.count(1);
    if (count != m_nozzles.size())
        throw std::runtime_error(fmt::format("the saved state has {} emitter(s), the scene {}", count, m_nozzles.size()));
    for (std::size_t e = 0; e < count; ++e) {
        std::string name;
        in(name);
        if (name != m_reports[e].name)
            throw std::runtime_error(fmt::format("the saved state's emitter {} is '{}', the scene's '{}'", e, name,
                                                 m_reports[e].name));
        in(m_nozzles[e].travelled), in(m_reports[e].emitted), in(m_reports[e].blocked);
    }
}

void Emitters::emitLayer(Nozzle& n, std::size_t index, Real t, Real age, ParticleSet& particles,
                         StepContext& ctx) {
    const BodyMotion& motion = n.spec.motion;
    const Mat3 rotation = motion.rotation(t);
    const Vec3 centre = motion.transform(n.spec.position, t);
    const Vec3 direction = rotation * n.spec.direction;

    // Fluid still near the opening (a stream that backs up) blocks the sites it covers.
    const Real blockDistance = kBlockedFraction * m_spacing;
    const Vec3 layerCentre = centre + age * (n.spec.speed * direction + motion.velocity(centre, t));
    std::vector<Vec3> nearby;
    for (const Vec3& x : particles.x())
        if ((x - layerCentre).norm() <= n.reach + 2 * blockDistance) nearby.push_back(x);

    std::vector<Real>* source = particles.find(attribute::kFluid);
    std::vector<Real>* temperature = particles.find(attribute::kTemperature);
    std::size_t blocked = 0;
    for (const Vec3& site : n.sites) {
        // Each particle leaves at the nozzle's speed plus the velocity of its point of the (moving) nozzle, and
        // has flown `age` seconds since.
        const Vec3 start = centre + rotation * site;
        const Vec3 velocity = n.spec.speed * direction + motion.velocity(start, t);
        const Vec3 x = start + age * velocity;
        bool free = true;
        for (const Vec3& y : nearby) free = free && (x - y).squaredNorm() >= blockDistance * blockDistance;
        if (!free) {
            ++blocked;
            continue;
        }
        particles.add(x, velocity, n.mass, m_nextId++);
        if (source) source->back() = Real(n.sourceIndex);
        if (temperature) temperature->back() = n.spec.temperature;
    }
    EmitterReport& report = m_reports[index];
    report.emitted += n.sites.size() - blocked;
    if (blocked > 0 && report.blocked == 0)
        ctx.stats.warn(fmt::format("t = {:.4f} s: emitter '{}' found fluid still at its nozzle and skipped {} of {} "
                               "sites; the stream is backing up (later skips are counted in the report)",
                               t, n.spec.name, blocked, n.sites.size()));
    report.blocked += blocked;
}

}  // namespace ganache
