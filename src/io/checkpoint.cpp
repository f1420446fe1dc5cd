#include "io/checkpoint.h"

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
constexpr std::uint32_t kVersion = 1;

// Writing and reading share one description of the state (fields() below): the same calls on a Writer append
// each value, on a Reader take it back, so the two can never disagree on the order.
class Writer {
public:
    template <class T>
    std::enable_if_t<std::is_arithmetic_v<T>> operator()(const T& value) {
        bytes.append(reinterpret_cast<const char*>(&value), sizeof value);
    }
    void operator()(const Vec3& v) { raw(v.data(), sizeof(Real) * 3); }
    void operator()(const std::string& s) {
        (*this)(std::uint64_t(s.size()));
        bytes += s;
    }
    template <class T>
    void operator()(const std::vector<T>& values) {
        (*this)(std::uint64_t(values.size()));
        if constexpr (std::is_arithmetic_v<T>) raw(values.data(), values.size() * sizeof(T));
        else
            for (const T& v : values) (*this)(v);
    }
    void raw(const void* data, std::size_t size) { bytes.append(static_cast<const char*>(data), size); }

    std::string bytes;
};

class Reader {
public:
    explicit Reader(std::string_view bytes) : m_in(bytes) {}

    template <class T>
    std::enable_if_t<std::is_arithmetic_v<T>> operator()(T& value) {
        raw(&value, sizeof value);
    }
    void operator()(Vec3& v) { raw(v.data(), sizeof(Real) * 3); }
    void operator()(std::string& s) {
        s.resize(count(1));
        raw(s.data(), s.size());
    }
    template <class T>
    void operator()(std::vector<T>& values) {
        values.resize(count(std::is_arithmetic_v<T> ? sizeof(T) : 1));
        if constexpr (std::is_arithmetic_v<T>) raw(values.data(), values.size() * sizeof(T));
        else
            for (T& v : values) (*this)(v);
    }
    void raw(void* data, std::size_t size) {
        if (size > m_in.size() - m_at) throw std::runtime_error("it ends early (truncated)");
        std::memcpy(data, m_in.data() + m_at, size);
        m_at += size;
    }
    // A length that the rest of the file can hold, at `least` bytes per element.
    std::size_t count(std::size_t least) {
        std::uint64_t n = 0;
        (*this)(n);
        if (n > (m_in.size() - m_at) / least) throw std::runtime_error("a length field is larger than the file");
        return std::size_t(n);
    }
    bool atEnd() const { return m_at == m_in.size(); }

private:
    std::string_view m_in;
    std::size_t m_at = 0;
};

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
    io(s.steps), io(s.pressureIterations), io(s.pressureCapHits), io(s.divergenceIterations),
        io(s.divergenceCapHits), io(s.viscositySolves), io(s.viscosityIterations), io(s.viscosityCapHits),
        io(s.viscosityWorstResidual), io(s.removedParticles), io(s.emittedParticles), io(s.boundaryContacts),
        io(s.heatSubsteps), io(s.heatSubstepsMax), io(s.dtMin), io(s.dtMax);
    auto& t = s.time;
    io(t.heat), io(t.forces), io(t.pressure), io(t.advect), io(t.emit), io(t.neighbours), io(t.divergence),
        io(t.viscosity), io(t.endOfStep);
    io(s.warnings), io(s.warningCount);
}

template <class IO, class Emitter>
void emitterFields(IO& io, Emitter& e) {
    io(e.travelled), io(e.report.name), io(e.report.emitted), io(e.report.blocked);
}

template <class IO, class Info, class State>
void fields(IO& io, Info& info, State& s) {
    io(info.scene), io(info.sceneHash), io(info.particleRadius), io(info.frame);
    io(s.time), io(s.step), io(s.nextId);
    fields(io, s.fluid);
    if constexpr (std::is_const_v<State>) io(std::uint64_t(s.emitters.size()));
    else s.emitters.resize(io.count(1));
    for (auto& e : s.emitters) emitterFields(io, e);
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
