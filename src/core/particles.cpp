#include "core/particles.h"

#include <algorithm>
#include <numeric>
#include <stdexcept>

namespace ganache {

void ParticleSet::add(const Vec3& x, const Vec3& v, Real mass, std::uint64_t id) {
    m_x.push_back(x);
    m_v.push_back(v);
    m_mass.push_back(mass);
    m_id.push_back(id);
    for (auto& [name, a] : m_scalars) a.push_back(0);
    for (auto& [name, a] : m_vectors) a.push_back(Vec3::Zero());
}

void ParticleSet::reserve(std::size_t n) {
    m_x.reserve(n);
    m_v.reserve(n);
    m_mass.reserve(n);
    m_id.reserve(n);
    for (auto& [name, a] : m_scalars) a.reserve(n);
    for (auto& [name, a] : m_vectors) a.reserve(n);
}

std::vector<Real>& ParticleSet::addScalar(const std::string& name, Real value, bool cached) {
    if (m_scalars.count(name) || m_vectors.count(name))
        throw std::logic_error("ParticleSet: attribute '" + name + "' exists already");
    if (!cached) m_uncached.insert(name);
    return m_scalars.emplace(name, std::vector<Real>(size(), value)).first->second;
}

std::vector<Vec3>& ParticleSet::addVector(const std::string& name, const Vec3& value, bool cached) {
    if (m_scalars.count(name) || m_vectors.count(name))
        throw std::logic_error("ParticleSet: attribute '" + name + "' exists already");
    if (!cached) m_uncached.insert(name);
    return m_vectors.emplace(name, std::vector<Vec3>(size(), value)).first->second;
}

std::vector<Real>* ParticleSet::findScalar(const std::string& name) {
    auto it = m_scalars.find(name);
    return it == m_scalars.end() ? nullptr : &it->second;
}
const std::vector<Real>* ParticleSet::findScalar(const std::string& name) const {
    auto it = m_scalars.find(name);
    return it == m_scalars.end() ? nullptr : &it->second;
}
std::vector<Vec3>* ParticleSet::findVector(const std::string& name) {
    auto it = m_vectors.find(name);
    return it == m_vectors.end() ? nullptr : &it->second;
}
const std::vector<Vec3>* ParticleSet::findVector(const std::string& name) const {
    auto it = m_vectors.find(name);
    return it == m_vectors.end() ? nullptr : &it->second;
}

namespace {

template <class Map>
std::string namesOf(const Map& attributes) {
    std::string out;
    for (const auto& entry : attributes) out += (out.empty() ? "" : ", ") + entry.first;
    return out.empty() ? "none" : out;
}

template <class Map>
bool sameNames(const Map& a, const Map& b) {
    return a.size() == b.size() && std::equal(a.begin(), a.end(), b.begin(),
                                              [](const auto& p, const auto& q) { return p.first == q.first; });
}

}  // namespace

void ParticleSet::assignValues(const ParticleSet& other) {
    if (!sameNames(m_scalars, other.m_scalars) || !sameNames(m_vectors, other.m_vectors) ||
        m_uncached != other.m_uncached)
        throw std::runtime_error("the saved particles carry the attributes " + namesOf(other.m_scalars) + " / " +
                                 namesOf(other.m_vectors) + ", this simulation's carry " + namesOf(m_scalars) + " / " +
                                 namesOf(m_vectors));
    m_x = other.m_x;
    m_v = other.m_v;
    m_mass = other.m_mass;
    m_id = other.m_id;
    for (auto& [name, values] : m_scalars) values = other.m_scalars.at(name);
    for (auto& [name, values] : m_vectors) values = other.m_vectors.at(name);
}

namespace {
template <class T>
void permute(std::vector<T>& a, const std::vector<std::uint32_t>& perm) {
    std::vector<T> out(a.size());
    for (std::size_t i = 0; i < perm.size(); ++i) out[i] = a[perm[i]];
    a.swap(out);
}

template <class T>
void eraseFlagged(std::vector<T>& a, const std::vector<std::uint8_t>& remove) {
    std::size_t k = 0;
    for (std::size_t i = 0; i < a.size(); ++i)
        if (!remove[i]) a[k++] = a[i];
    a.resize(k);
}
}  // namespace

void ParticleSet::reorder(const std::vector<std::uint32_t>& perm) {
    if (perm.size() != size()) throw std::logic_error("ParticleSet::reorder: permutation has the wrong size");
    permute(m_x, perm);
    permute(m_v, perm);
    permute(m_mass, perm);
    permute(m_id, perm);
    for (auto& [name, a] : m_scalars) permute(a, perm);
    for (auto& [name, a] : m_vectors) permute(a, perm);
}

std::size_t ParticleSet::removeIf(const std::vector<std::uint8_t>& remove) {
    if (remove.size() != size()) throw std::logic_error("ParticleSet::removeIf: flag array has the wrong size");
    const std::size_t before = size();
    eraseFlagged(m_x, remove);
    eraseFlagged(m_v, remove);
    eraseFlagged(m_mass, remove);
    eraseFlagged(m_id, remove);
    for (auto& [name, a] : m_scalars) eraseFlagged(a, remove);
    for (auto& [name, a] : m_vectors) eraseFlagged(a, remove);
    return before - size();
}

void ParticleSet::sortById() {
    std::vector<std::uint32_t> perm(size());
    std::iota(perm.begin(), perm.end(), 0u);
    std::sort(perm.begin(), perm.end(), [&](std::uint32_t a, std::uint32_t b) { return m_id[a] < m_id[b]; });
    reorder(perm);
}

}  // namespace ganache
