#pragma once
// Section: strict, located reading of one map of a scene file (pbrt-style). Every read names its key, unit and
// fallback; the values read (defaults included) are recorded as the effective scene. The YAML parser stays inside
// section.cpp: whatever reads its own settings (an effect, a material) includes only this header.

#include "core/errors.h"
#include "core/types.h"

#include <filesystem>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace ganache {

/// The effective scene as read: every value with its default filled in, in reading order, with its unit.
struct EffectiveScene;

/// Allowed range of a number; open ends exclude the bound.
struct Bounds {
    Real lo = -std::numeric_limits<Real>::infinity();
    Real hi = std::numeric_limits<Real>::infinity();
    bool loOpen = false;
    bool hiOpen = false;
    static Bounds positive() { return {0, std::numeric_limits<Real>::infinity(), true, false}; }
    static Bounds nonNegative() { return {0, std::numeric_limits<Real>::infinity(), false, false}; }
    static Bounds closed(Real lo, Real hi) { return {lo, hi, false, false}; }
    static Bounds positiveUpTo(Real hi) { return {0, hi, true, false}; }  ///< (0, hi]
};

/// The largest magnitudes a scene may ask for. Beyond them the model means nothing and the quantities derived from
/// them (time steps, particle counts, positions) overflow or stall, so they are input errors at their key.
namespace limits {
constexpr Real kSpeed = 1e3;            ///< m/s: near the speed of sound in water, which incompressible SPH leaves out
constexpr Real kAcceleration = 1e4;     ///< m/s^2: about 1,000 g
constexpr Real kAngularVelocity = 1e4;  ///< rad/s: about 95,000 rpm
constexpr Real kCoordinate = 1e5;       ///< m: 100 km from the origin
constexpr Real kFps = 1e3;              ///< frames/s: a high-speed camera's
constexpr Real kViscosity = 1e10;       ///< Pa s: 50 times pitch's; anything stiffer is a solid (a boundary body)
constexpr Real kDensity = 1e5;          ///< kg/m^3: four times osmium's
constexpr Real kStepsPerFrame = 1e6;    ///< what a time step may be short enough to need
}  // namespace limits

/// One map of a scene file, with the file name and the keys read so far. Reads throw SceneError with
/// file:line:col, what is wrong and how to fix it. Call rejectUnused() after the last read. A copy has its own
/// record of the keys read.
class Section {
public:
    struct Impl;
    explicit Section(std::unique_ptr<Impl> impl);
    Section(const Section& other);
    Section& operator=(const Section& other);
    Section(Section&&) noexcept;
    Section& operator=(Section&&) noexcept;
    ~Section();

    const std::string& path() const;                     ///< e.g. "fluids[0].box"
    std::string keyPath(const std::string& key) const;   ///< e.g. "fluids[0].box.min"
    Location where() const;                              ///< the map itself
    Location where(const std::string& key) const;        ///< the key's value, or the map when absent
    bool has(const std::string& key) const;
    bool isList(const std::string& key) const;  ///< the key's value is a YAML sequence
    bool isNumber(const std::string& key) const;  ///< the key's value reads as a number

    Real number(const std::string& key, std::optional<Real> fallback, const std::string& unit, Bounds bounds = {});
    Real positive(const std::string& key, std::optional<Real> fallback, const std::string& unit) {
        return number(key, fallback, unit, Bounds::positive());
    }
    std::int64_t integer(const std::string& key, std::optional<std::int64_t> fallback, std::int64_t lo,
                         std::int64_t hi);
    /// A vector [x, y, z]; one longer than maxNorm is an error (see limits).
    Vec3 vec3(const std::string& key, std::optional<Vec3> fallback, const std::string& unit,
              Real maxNorm = std::numeric_limits<Real>::infinity());
    /// A direction: a non-zero [x, y, z], returned normalised (the value read is recorded as given).
    Vec3 direction(const std::string& key, std::optional<Vec3> fallback);
    bool boolean(const std::string& key, bool fallback);
    /// A name: letters, digits, '_' and '-'.
    std::string name(const std::string& key, std::optional<std::string> fallback);
    /// One of `choices`; anything else is an error with a "did you mean".
    std::string choice(const std::string& key, std::optional<std::string> fallback,
                       const std::vector<std::string>& choices);
    /// An sRGB colour [r, g, b], each component in [0, 1].
    Vec3 colour(const std::string& key, std::optional<Vec3> fallback);
    /// Which one of `keys` the map has; SceneError when it has none or several. `what` names the kind of thing the
    /// keys choose ("shape"), `example` shows one.
    std::string exactlyOne(const std::vector<std::string>& keys, const std::string& what, const std::string& example);
    /// A path, resolved relative to the scene file; it must exist. Recorded (and returned) as an absolute path.
    std::filesystem::path file(const std::string& key);

    /// A nested map, or nothing when the key is absent. A key with no value (`gravity:`) is an empty map.
    std::optional<Section> child(const std::string& key);
    /// A nested map; when the key is absent, an empty one whose reads all take their fallbacks.
    Section section(const std::string& key);
    /// A nested map that must be present.
    Section require(const std::string& key, const std::string& example);
    /// A list of maps (absent: empty).
    std::vector<Section> list(const std::string& key);
    /// The keys of this map in file order (for maps keyed by user names: materials, effects).
    std::vector<std::string> keys() const;
    /// Marks a key as handled by the caller (it may not be read through this section).
    void claim(const std::string& key);

    /// Throws at the first key nobody read (with a "did you mean" among the keys that were read) or at a
    /// key given twice.
    void rejectUnused() const;

    /// Throws a SceneError located at `key`'s value (or at the map when the key is absent).
    [[noreturn]] void fail(const std::string& key, const std::string& what, const std::string& fix) const;
    /// Reports a required key as absent, or, when the map holds a near-miss spelling of it, that misspelling
    /// as an unknown key with a "did you mean".
    [[noreturn]] void failMissing(const std::string& key, const std::string& what, const std::string& fix) const;
    /// Throws a SceneError located at the key itself (for keys that are names: unknown effects, materials).
    [[noreturn]] void failAtKey(const std::string& key, const std::string& what, const std::string& fix) const;

    /// Every value read so far from this file, defaults included.
    std::shared_ptr<const EffectiveScene> effective() const;

private:
    std::unique_ptr<Impl> m;
};

/// The closest of `candidates` to `word` by edit distance, or "" when none is close enough to suggest.
std::string closestMatch(const std::string& word, const std::vector<std::string>& candidates);
/// "a, b, c"
std::string joinNames(const std::vector<std::string>& names);
/// Shortest decimal text that reads back as the same double.
std::string formatNumber(Real v);

/// Parses a YAML file into a root Section; YAML syntax errors become SceneErrors with file:line:col.
Section openSceneFile(const std::filesystem::path& file);

/// The effective scene as YAML, each value with its unit as a comment.
std::string effectiveYaml(const EffectiveScene& scene);
/// The effective scene's values as JSON text (for report.json).
std::string effectiveJson(const EffectiveScene& scene);

}  // namespace ganache
