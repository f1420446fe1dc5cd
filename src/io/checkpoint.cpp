#include "io/checkpoint.h"

#include "core/byte_stream.h"
#include "io/atomic_file.h"
#include "io/checksum.h"

#include <fmt/format.h>

#include <cstring>
#include <fstream>
#include <iterator>
#include <stdexcept>
#include <type_traits>

namespace ganache {

namespace {

constexpr char kMagic[8] = {'G', 'N', 'C', 'H', 'C', 'K', 'P', 'T'};
// 2: effects save their own state; 3: the viscosity warm start's steps; 4: steps past the CFL limit; 5: which
// particles the viscosity moves as one body (attribute::kViscouslyRigid); 6: the latest constant-density solve's
// iterations (they set the next divergence-free solve's minimum); 7: the pressure solver's coarse space
constexpr std::uint32_t kVersion = 7;

// Writing and reading share one description of the state (fields() below): the same calls on a ByteWriter append
// each value, on a ByteReader take it back, so the two can never disagree on the order.
using Writer = ByteWriter;
using Reader = ByteReader;

// Particles: the core arrays, then each named attribute with whether particle caches carry it.
void fields(Writer& io, const ParticleSet& p) {
    io(std::uint64_t(p.size()));
    io(p.x());
    io(p.v());
    io(p.mass());
    io(p.id());
    io(std::uint64_t(p.scalars().size()));
    for (const auto& [name, values] : p.scalars()) io(name), io(std::uint8_t(p.isCached(name))), io(values);
    io(std::uint64_t(p.vectors().size()));
    for (const auto& [name, values] : p.vectors()) io(name), io(std::uint8_t(p.isCached(name))), io(values);
}

void fields(Reader& io, ParticleSet& p) {
    std::uint64_t n = 0;
    io(n);
    std::vector<Vec3> x, v;
    std::vector<Real> mass;
    std::vector<std::uint64_t> id;
    io(x), io(v), io(mass), io(id);
    if (x.size() != n || v.size() != n || mass.size() != n || id.size() != n)
        throw std::runtime_error("its particle arrays differ in length");
    p = ParticleSet();
    p.reserve(n);
    for (std::size_t i = 0; i < n; ++i) p.add(x[i], v[i], mass[i], id[i]);
    auto named = [&](auto add) {
        const std::size_t count = io.count(1);
        for (std::size_t a = 0; a < count; ++a) {
            std::string name;
            std::uint8_t cached = 0;
            io(name), io(cached);
            auto& values = add(name, cached != 0);
            io(values);
            if (values.size() != n) throw std::runtime_error("attribute '" + name + "' has the wrong length");
        }
    };
    named([&](const std::string& name, bool cached) -> std::vector<Real>& { return p.addScalar(name, 0, cached); });
    named([&](const std::string& name, bool cached) -> std::vector<Vec3>& {
        return p.addVector(name, Vec3::Zero(), cached);
    });
}

template <class IO, class Stats>
void statsFields(IO& io, Stats& s) {
    io(s.steps), io(s.pressureIterations), io(s.pressureCapHits), io(s.lastPressureIterations),
        io(s.divergenceIterations), io(s.divergenceCapHits), io(s.removedParticles), io(s.addedParticles),
        io(s.boundaryContacts), io(s.stepsPastCfl), io(s.cflExcess), io(s.dtMin), io(s.dtMax);
    auto& t = s.time;
    io(t.pressure), io(t.advect), io(t.neighbours), io(t.divergence);
    io(s.warnings), io(s.warningCount);
}

template <class IO, class Effect>
void effectFields(IO& io, Effect& e) {
    io(e.name), io(e.seconds), io(e.bytes);
}

template <class IO, class Info, class State>
void fields(IO& io, Info& info, State& s) {
    io(info.scene), io(info.sceneHash), io(info.particleRadius), io(info.frame);
    io(s.time), io(s.step);
    fields(io, s.fluid);
    if constexpr (std::is_const_v<State>) io(std::uint64_t(s.effects.size()));
    else s.effects.resize(io.count(1));
    for (auto& e : s.effects) effectFields(io, e);
    io(s.pressure);
    io(s.totalImpulse), io(s.totalAngular), io(s.peakForce);
    statsFields(io, s.stats);
}

}  // namespace

void writeCheckpoint(const std::filesystem::path& path, const CheckpointInfo& info, const SimulationState& state) {
    Writer out;
    out.raw(kMagic, sizeof kMagic);
    out(kVersion);
    fields(out, info, state);
    out.bytes += checksumFooter(out.bytes);
    writeBytesAtomically(path, out.bytes);
}

Checkpoint readCheckpoint(const std::filesystem::path& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw std::runtime_error("it cannot be opened");
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    std::string why;
    if (!checksumFooterMatches(bytes, why)) throw std::runtime_error("it " + why);
    Reader reader(std::string_view(bytes).substr(0, bytes.size() - kChecksumFooterSize));
    char magic[sizeof kMagic] = {};
    std::uint32_t version = 0;
    reader.raw(magic, sizeof magic);
    if (std::memcmp(magic, kMagic, sizeof kMagic) != 0) throw std::runtime_error("it is not a ganache checkpoint");
    reader(version);
    if (version != kVersion)
        throw std::runtime_error(fmt::format("it has format version {}; this build reads version {}", version,
                                             kVersion));
    Checkpoint c;
    fields(reader, c.info, c.state);
    if (!reader.atEnd()) throw std::runtime_error("it has bytes after its state");
    return c;
}

}  // namespace ganache
