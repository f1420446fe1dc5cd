#pragma once
// ParticleSet: fluid particles stored as one array per attribute (structure of arrays).

#include "core/types.h"

#include <cstdint>
#include <map>
#include <set>
#include <string>
#include <vector>

namespace ganache {

/// A per-particle attribute by name and type (Real or Vec3), declared once as a constant: core/attributes.h for
/// those several parts share, an effect's own file for its private state. Cached attributes are written to particle
/// caches; uncached ones (solver warm starts) move with the particles but are never written.
template <class T>
struct Attribute {
    const char* name;
    bool cached = true;
};

/// Fluid particles, one array per attribute. Every attribute has size() entries. The core attributes
/// (position, velocity, mass, id) always exist; effects add their own named scalar or vector attributes
/// (temperature, per-particle viscosity, ...) only when a scene asks for them. reorder() is the one place
/// that permutes particles: it moves every attribute together, so no solver ever reorders its own arrays.
class ParticleSet {
public:
    std::size_t size() const { return m_x.size(); }
    bool empty() const { return m_x.empty(); }

    /// Appends one particle; named attributes get zero for it.
    void add(const Vec3& x, const Vec3& v, Real mass, std::uint64_t id);
    void reserve(std::size_t n);

    std::vector<Vec3>& x() { return m_x; }                      ///< positions [m]
    const std::vector<Vec3>& x() const { return m_x; }
    std::vector<Vec3>& v() { return m_v; }                      ///< velocities [m/s]
    const std::vector<Vec3>& v() const { return m_v; }
    std::vector<Real>& mass() { return m_mass; }                ///< masses [kg]
    const std::vector<Real>& mass() const { return m_mass; }
    const std::vector<std::uint64_t>& id() const { return m_id; }  ///< stable identities, unique in a run

    /// Adds an attribute (every particle gets `value`) and returns it; std::logic_error when it exists.
    std::vector<Real>& add(const Attribute<Real>& a, Real value = 0) { return addScalar(a.name, value, a.cached); }
    std::vector<Vec3>& add(const Attribute<Vec3>& a, const Vec3& value = Vec3::Zero()) {
        return addVector(a.name, value, a.cached);
    }
    /// The attribute, or null when the particles do not carry it.
    std::vector<Real>* find(const Attribute<Real>& a) { return findScalar(a.name); }
    const std::vector<Real>* find(const Attribute<Real>& a) const { return findScalar(a.name); }
    std::vector<Vec3>* find(const Attribute<Vec3>& a) { return findVector(a.name); }
    const std::vector<Vec3>* find(const Attribute<Vec3>& a) const { return findVector(a.name); }

    /// The same by name, for readers of files (caches, checkpoints) that meet attributes they do not know.
    std::vector<Real>& addScalar(const std::string& name, Real value = 0, bool cached = true);
    std::vector<Vec3>& addVector(const std::string& name, const Vec3& value = Vec3::Zero(), bool cached = true);
    bool isCached(const std::string& name) const { return !m_uncached.count(name); }
    std::vector<Real>* findScalar(const std::string& name);
    const std::vector<Real>* findScalar(const std::string& name) const;
    std::vector<Vec3>* findVector(const std::string& name);
    const std::vector<Vec3>* findVector(const std::string& name) const;
    const std::map<std::string, std::vector<Real>>& scalars() const { return m_scalars; }
    const std::map<std::string, std::vector<Vec3>>& vectors() const { return m_vectors; }

    /// Takes every value of `other`, which must carry the same attributes (names and cached or not), keeping this
    /// set's arrays where they are (effects hold them by address); std::runtime_error otherwise.
    void assignValues(const ParticleSet& other);

    /// Permutes every attribute: particle i afterwards is the particle perm[i] before.
    /// perm must be a permutation of 0..size()-1.
    void reorder(const std::vector<std::uint32_t>& perm);

    /// Removes the particles whose flag is non-zero, keeping the order of the rest; returns how many went.
    std::size_t removeIf(const std::vector<std::uint8_t>& remove);

    /// Sorts the particles by id (caches store particles in spatial order; ids restore a stable order).
    void sortById();

private:
    std::vector<Vec3> m_x, m_v;
    std::vector<Real> m_mass;
    std::vector<std::uint64_t> m_id;
    std::map<std::string, std::vector<Real>> m_scalars;
    std::map<std::string, std::vector<Vec3>> m_vectors;
    std::set<std::string> m_uncached;
};

/// Which source of fluid (index in SimulationSetup::sources) particle i came from, given the set's `fluid`
/// attribute (attribute::kFluid); a set without one has a single source, 0.
inline std::size_t sourceIndex(const std::vector<Real>* fluidAttribute, std::size_t i) {
    return fluidAttribute ? std::size_t((*fluidAttribute)[i]) : 0;
}

/// Boundary particles of one body (Akinci et al. 2012): positions and volumes. The pseudo-mass a fluid
/// particle sees is Psi_k = rho_0 V_k with its own rest density rho_0, so several fluids share one wall.
struct BoundaryBody {
    std::string name;
    std::vector<Vec3> x;
    std::vector<Real> volume;  ///< boundary volume V_k = 1 / sum_l W_kl [m^3]; Psi_k = rho_0 V_k
};

}  // namespace ganache
