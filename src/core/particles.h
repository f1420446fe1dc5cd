#pragma once
// ParticleSet: fluid particles stored as one array per attribute (structure of arrays).

#include "core/types.h"

#include <cstdint>
#include <map>
#include <set>
#include <string>
#include <vector>

namespace ganache {

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

    /// Adds a named per-particle scalar (initialised to `value`) and returns it; throws if it exists.
    /// Cached attributes are written to particle caches; uncached ones (solver warm starts) are state that
    /// moves with the particles but is never written.
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

/// Which source of fluid (index in Scene::sourceMaterials()) particle i came from, given the set's `fluid`
/// attribute; a set without one has a single source, 0.
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
