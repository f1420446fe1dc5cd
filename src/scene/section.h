#pragma once
// Section: strict, located reading of one YAML map of a scene file (pbrt-style). Every read names its
// key, unit and fallback; the values read (defaults included) are recorded as the effective scene.

#include "core/errors.h"
#include "core/types.h"

#include <yaml-cpp/yaml.h>

#include <nlohmann/json.hpp>

#include <filesystem>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <vector>

namespace ganache {

/// The effective scene as read: values with defaults filled in, in reading order, and their units.
struct EffectiveScene {
    std::string file;                          ///< the scene file as named by the user
    nlohmann::ordered_json values = nlohmann::ordered_json::object();
    std::map<std::string, std::string> units;  ///< JSON pointer -> unit, for the explain comments
};

/// Allowed range of a number; open ends exclude the bound.
struct Bounds {
    Real lo = -std::numeric_limits<Real>::infinity();
    Real hi = std::numeric_limits<Real>::infinity();
    bool loOpen = false;
    bool hiOpen = false;
    static Bounds positive() { return {0, std::numeric_limits<Real>::infinity(), true, false}; }
    static Bounds nonNegative() { return {0, std::numeric_limits<Real>::infinity(), false, false}; }
    static Bounds closed(Real lo, Real hi) { return {lo, hi, false, false}; }
};

/// One YAML map of a scene, with the file name and the keys read so far. Reads throw SceneError with
/// file:line:col, what is wrong and how to fix it. Call rejectUnused() after the last read.
class Section {
public:
    Section(YAML::Node node, std::shared_ptr<EffectiveScene> out, std::string dottedPath,
            nlohmann::ordered_json::json_pointer pointer, YAML::Mark mark);

    const std::string& path() const { return m_path; }  ///< e.g. "fluids[0].box"
    Location where() const;                              ///< the map itself
    Location where(const std::string& key) const;        ///< the key's value, or the map when absent
    bool has(const std::string& key) const;
    bool isList(const std::string& key) const;  ///< the key's value is a YAML sequence

    Real number(const std::string& key, std::optional<Real> fallback, const std::string& unit, Bounds bounds = {});
    Real positive(const std::string& key, std::optional<Real> fallback, const std::string& unit) {
        return number(key, fallback, unit, Bounds::positive());
    }
    std::int64_t integer(const std::string& key, std::optional<std::int64_t> fallback, std::int64_t lo,
                         std::int64_t hi);
    Vec3 vec3(const std::string& key, std::optional<Vec3> fallback, const std::string& unit);
    /// A direction: a non-zero [x, y, z], returned normalised (the value read is recorded as given).
    Vec3 direction(const std::string& key, std::optional<Vec3> fallback);
    bool boolean(const std::string& key, bool fallback);
    /// A name: letters, digits, '_' and '-'.
    std::string name(const std::string& key, std::optional<std::string> fallback);
    /// One of `choices`; anything else is an error with a "did you mean".
    std::string choice(const std::string& key, std::optional<std::string> fallback,
                       const std::vector<std::string>& choices);
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
    void claim(const std::string& key) { m_read.insert(key); }

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

private:
    YAML::Node value(const std::string& key);  // marks the key as read; undefined node when absent
    void record(const std::string& key, nlohmann::ordered_json v, const std::string& unit);
    std::string keyPath(const std::string& key) const;
    Real parseNumber(const std::string& key, const YAML::Node& n, const std::string& unit) const;

    YAML::Node m_node;
    YAML::Mark m_mark;
    std::shared_ptr<EffectiveScene> m_out;
    std::string m_path;
    nlohmann::ordered_json::json_pointer m_pointer;
    std::set<std::string> m_read;
};

/// The closest of `candidates` to `word` by edit distance, or "" when none is close enough to suggest.
std::string closestMatch(const std::string& word, const std::vector<std::string>& candidates);
/// "a, b, c"
std::string joinNames(const std::vector<std::string>& names);
/// Shortest decimal text that reads back as the same double.
std::string formatNumber(Real v);

/// Parses a YAML file into a root Section; YAML syntax errors become SceneErrors with file:line:col.
Section openSceneFile(const std::filesystem::path& file, std::shared_ptr<EffectiveScene> out);

/// The effective scene as YAML, each value with its unit as a comment.
std::string effectiveYaml(const EffectiveScene& scene);

}  // namespace ganache
