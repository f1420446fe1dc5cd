#include "scene/section.h"

#include <yaml-cpp/yaml.h>

#include <nlohmann/json.hpp>

#include <fmt/format.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

namespace ganache {

using Json = nlohmann::ordered_json;

struct EffectiveScene {
    std::string file;                       // the scene file as named by the user
    Json values = Json::object();           // in reading order
    std::map<std::string, std::string> units;  // JSON pointer -> unit, for the explain comments
};

struct Section::Impl {
    YAML::Node node;
    YAML::Mark mark;
    std::shared_ptr<EffectiveScene> out;
    std::string path;
    Json::json_pointer pointer;
    std::set<std::string> read;

    YAML::Node value(const std::string& key) {  // marks the key as read; undefined node when absent
        read.insert(key);
        return node[key];
    }
    void record(const std::string& key, Json v, const std::string& unit) {
        const auto p = pointer / key;
        out->values[p] = std::move(v);
        if (!unit.empty()) out->units[p.to_string()] = unit;
    }
};

namespace {

Section makeSection(YAML::Node node, std::shared_ptr<EffectiveScene> out, std::string dottedPath,
                    Json::json_pointer pointer, YAML::Mark mark) {
    auto impl = std::make_unique<Section::Impl>();
    if (!out->values.contains(pointer)) out->values[pointer] = Json::object();
    impl->node = std::move(node);
    impl->mark = mark;
    impl->out = std::move(out);
    impl->path = std::move(dottedPath);
    impl->pointer = std::move(pointer);
    return Section(std::move(impl));
}

Location locationOf(const std::string& file, const YAML::Mark& m) {
    if (m.line < 0) return {file, 0, 0};
    return {file, m.line + 1, m.column + 1};
}

std::string describe(const YAML::Node& n) {
    if (!n.IsDefined() || n.IsNull()) return "nothing";
    if (n.IsMap()) return "a map";
    if (n.IsSequence()) return "a list";
    return "'" + n.Scalar() + "'";
}

std::string unitSuffix(const std::string& unit) { return unit.empty() ? "" : " " + unit; }

std::size_t editDistance(const std::string& a, const std::string& b) {
    std::vector<std::size_t> row(b.size() + 1);
    for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
    for (std::size_t i = 1; i <= a.size(); ++i) {
        std::size_t diag = row[0];
        row[0] = i;
        for (std::size_t j = 1; j <= b.size(); ++j) {
            const std::size_t up = row[j];
            row[j] = std::min({row[j] + 1, row[j - 1] + 1, diag + (a[i - 1] == b[j - 1] ? 0 : 1)});
            diag = up;
        }
    }
    return row[b.size()];
}

std::string describeBounds(const Bounds& b, const std::string& unit) {
    const bool hasLo = std::isfinite(b.lo), hasHi = std::isfinite(b.hi);
    const std::string u = unitSuffix(unit);
    if (hasLo && hasHi && (b.loOpen || b.hiOpen))
        return fmt::format("{} {} and {} {}{}", b.loOpen ? ">" : ">=", formatNumber(b.lo), b.hiOpen ? "<" : "<=",
                           formatNumber(b.hi), u);
    if (hasLo && hasHi)
        return fmt::format("between {} and {}{}", formatNumber(b.lo), formatNumber(b.hi), u);
    if (hasLo) return fmt::format("{} {}{}", b.loOpen ? ">" : ">=", formatNumber(b.lo), u);
    return fmt::format("{} {}{}", b.hiOpen ? "<" : "<=", formatNumber(b.hi), u);
}

}  // namespace

std::string formatNumber(Real v) { return fmt::format("{}", v); }

std::string joinNames(const std::vector<std::string>& names) {
    std::string s;
    for (const auto& n : names) s += (s.empty() ? "" : ", ") + n;
    return s;
}

std::string closestMatch(const std::string& word, const std::vector<std::string>& candidates) {
    std::string best;
    std::size_t bestDistance = std::max<std::size_t>(2, word.size() / 3) + 1;
    for (const auto& c : candidates) {
        const std::size_t d = editDistance(word, c);
        if (d < bestDistance) bestDistance = d, best = c;
    }
    return best;
}

Section::Section(std::unique_ptr<Impl> impl) : m(std::move(impl)) {}
Section::Section(const Section& other) : m(std::make_unique<Impl>(*other.m)) {}
Section& Section::operator=(const Section& other) {
    m = std::make_unique<Impl>(*other.m);
    return *this;
}
Section::Section(Section&&) noexcept = default;
Section& Section::operator=(Section&&) noexcept = default;
Section::~Section() = default;

Location Section::where() const { return locationOf(m->out->file, m->mark); }

Location Section::where(const std::string& key) const {
    const YAML::Node n = m->node[key];
    if (n.IsDefined() && n.Mark().line >= 0) return locationOf(m->out->file, n.Mark());
    return where();
}

bool Section::has(const std::string& key) const { return m->node[key].IsDefined(); }

bool Section::isList(const std::string& key) const {
    const YAML::Node n = m->node[key];
    return n.IsDefined() && n.IsSequence();
}

const std::string& Section::path() const { return m->path; }

void Section::claim(const std::string& key) { m->read.insert(key); }

bool Section::isNumber(const std::string& key) const {
    const YAML::Node n = m->node[key];
    if (!n.IsDefined() || !n.IsScalar() || n.Scalar().empty()) return false;
    char* end = nullptr;
    std::strtod(n.Scalar().c_str(), &end);
    return end && *end == '\0';
}

std::string Section::keyPath(const std::string& key) const { return m->path.empty() ? key : m->path + "." + key; }

void Section::fail(const std::string& key, const std::string& what, const std::string& fix) const {
    throw SceneError(where(key), what, fix);
}

void Section::failAtKey(const std::string& key, const std::string& what, const std::string& fix) const {
    for (const auto& kv : m->node)
        if (kv.first.Scalar() == key) throw SceneError(locationOf(m->out->file, kv.first.Mark()), what, fix);
    fail(key, what, fix);
}

void Section::failMissing(const std::string& key, const std::string& what, const std::string& fix) const {
    for (const auto& kv : m->node) {
        const std::string other = kv.first.Scalar();
        if (!m->read.count(other) && other != key && closestMatch(other, {key}) == key)
            failAtKey(other, fmt::format("unknown key '{}' in {}", other, m->path.empty() ? "the scene" : m->path),
                      fmt::format("did you mean '{}'? ({})", key, what));
    }
    fail(key, what, fix);
}

namespace {

// A finite number, or a SceneError at the key.
Real parseNumber(const Section& section, const std::string& key, const YAML::Node& n, const std::string& unit) {
    if (!n.IsScalar())
        section.fail(key, fmt::format("{} must be a number{} (got {})", section.keyPath(key), unitSuffix(unit), describe(n)),
             fmt::format("write a single number, e.g. `{}: 1.0`", key));
    const std::string& s = n.Scalar();
    std::string lower = s;
    std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    const bool yamlSpecial = lower == ".nan" || lower == ".inf" || lower == "+.inf" || lower == "-.inf";
    char* end = nullptr;
    errno = 0;
    const Real v = std::strtod(s.c_str(), &end);
    if (yamlSpecial || (end && *end == '\0' && !s.empty() && !std::isfinite(v)) || errno == ERANGE)
        section.fail(key, fmt::format("{} must be a finite number{} (got '{}')", section.keyPath(key), unitSuffix(unit), s),
             "give an ordinary finite value; infinities and NaN are not accepted");
    if (s.empty() || !end || *end != '\0' || std::isspace(static_cast<unsigned char>(s[0])))
        section.fail(key, fmt::format("{} must be a number{} (got '{}')", section.keyPath(key), unitSuffix(unit), s),
             fmt::format("write a plain number such as 0.5 or 1.0e4, e.g. `{}: 1.0`", key));
    return v;
}

}  // namespace

Real Section::number(const std::string& key, std::optional<Real> fallback, const std::string& unit, Bounds b) {
    const YAML::Node n = m->value(key);
    Real v;
    if (!n.IsDefined()) {
        if (!fallback)
            failMissing(key, fmt::format("{} is missing: a number{} is required", keyPath(key), unitSuffix(unit)),
                 fmt::format("add `{}: <value>` to {}", key, m->path.empty() ? "the top level" : m->path));
        v = *fallback;
    } else {
        v = parseNumber(*this, key, n, unit);
        const bool tooLow = b.loOpen ? !(v > b.lo) : !(v >= b.lo);
        const bool tooHigh = b.hiOpen ? !(v < b.hi) : !(v <= b.hi);
        if (tooLow || tooHigh)
            fail(key, fmt::format("{} must be {} (got {})", keyPath(key), describeBounds(b, unit), n.Scalar()),
                 fmt::format("give a value {}", describeBounds(b, unit)));
    }
    m->record(key, v, unit);
    return v;
}

std::int64_t Section::integer(const std::string& key, std::optional<std::int64_t> fallback, std::int64_t lo,
                              std::int64_t hi) {
    const YAML::Node n = m->value(key);
    std::int64_t v;
    if (!n.IsDefined()) {
        if (!fallback)
            failMissing(key, fmt::format("{} is missing: a whole number is required", keyPath(key)),
                 fmt::format("add `{}: <whole number>`", key));
        v = *fallback;
    } else {
        if (!n.IsScalar()) fail(key, fmt::format("{} must be a whole number (got {})", keyPath(key), describe(n)),
                                fmt::format("e.g. `{}: {}`", key, lo));
        const std::string& s = n.Scalar();
        char* end = nullptr;
        errno = 0;
        const long long parsed = std::strtoll(s.c_str(), &end, 10);
        if (s.empty() || *end != '\0' || errno == ERANGE)
            fail(key, fmt::format("{} must be a whole number (got '{}')", keyPath(key), s),
                 fmt::format("write digits only, e.g. `{}: {}`", key, lo));
        v = parsed;
        if (v < lo || v > hi)
            fail(key, fmt::format("{} must be between {} and {} (got {})", keyPath(key), lo, hi, v),
                 fmt::format("give a whole number from {} to {}", lo, hi));
    }
    m->record(key, v, "");
    return v;
}

Vec3 Section::vec3(const std::string& key, std::optional<Vec3> fallback, const std::string& unit, Real maxNorm) {
    const YAML::Node n = m->value(key);
    Vec3 v;
    if (!n.IsDefined()) {
        if (!fallback)
            failMissing(key, fmt::format("{} is missing: a vector [x, y, z]{} is required", keyPath(key), unitSuffix(unit)),
                 fmt::format("add `{}: [x, y, z]`", key));
        v = *fallback;
    } else {
        if (!n.IsSequence() || n.size() != 3)
            fail(key, fmt::format("{} must be a list of 3 numbers{} (got {}{})", keyPath(key), unitSuffix(unit),
                                  describe(n), n.IsSequence() ? fmt::format(" of {} items", n.size()) : ""),
                 fmt::format("write `{}: [x, y, z]`, e.g. `{}: [0, 1, 0]`", key, key));
        for (int a = 0; a < 3; ++a) {
            const YAML::Node c = n[a];
            // Report the component's own position so that the column points at the bad number.
            if (!c.IsScalar())
                throw SceneError(locationOf(m->out->file, c.Mark()),
                                 fmt::format("{}[{}] must be a number (got {})", keyPath(key), a, describe(c)),
                                 fmt::format("write `{}: [x, y, z]` with plain numbers", key));
            try {
                v[a] = parseNumber(*this, key, c, unit);
            } catch (const SceneError& e) {
                throw SceneError(locationOf(m->out->file, c.Mark()),
                                 fmt::format("{}[{}] must be a finite number{} (got '{}')", keyPath(key), a,
                                             unitSuffix(unit), c.Scalar()),
                                 fmt::format("write `{}: [x, y, z]` with plain finite numbers", key));
            }
        }
        if (!(v.stableNorm() <= maxNorm))
            fail(key, fmt::format("{} has a magnitude of {:.3g}{}, above the {}{} a scene may use", keyPath(key),
                                  v.stableNorm(), unitSuffix(unit), formatNumber(maxNorm), unitSuffix(unit)),
                 fmt::format("give a vector no longer than {}{}", formatNumber(maxNorm), unitSuffix(unit)));
    }
    m->record(key, Json::array({v.x(), v.y(), v.z()}), unit);
    return v;
}

Vec3 Section::direction(const std::string& key, std::optional<Vec3> fallback) {
    const Vec3 v = vec3(key, fallback, "unit vector");
    if (v.norm() < 1e-12)
        fail(key, keyPath(key) + " must not be the zero vector",
             fmt::format("give a direction, e.g. `{}: [0, 1, 0]`", key));
    return v.normalized();
}

bool Section::boolean(const std::string& key, bool fallback) {
    const YAML::Node n = m->value(key);
    bool v = fallback;
    if (n.IsDefined()) {
        const std::string s = n.IsScalar() ? n.Scalar() : "";
        if (s == "true") v = true;
        else if (s == "false") v = false;
        else
            fail(key, fmt::format("{} must be true or false (got {})", keyPath(key), describe(n)),
                 fmt::format("write `{}: true` or `{}: false`", key, key));
    }
    m->record(key, v, "");
    return v;
}

std::string Section::name(const std::string& key, std::optional<std::string> fallback) {
    const YAML::Node n = m->value(key);
    std::string v;
    if (!n.IsDefined()) {
        if (!fallback) failMissing(key, fmt::format("{} is missing: a name is required", keyPath(key)),
                            fmt::format("add `{}: my_name`", key));
        v = *fallback;
    } else {
        v = n.IsScalar() ? n.Scalar() : "";
        const bool ok = !v.empty() && std::all_of(v.begin(), v.end(), [](unsigned char c) {
            return std::isalnum(c) || c == '_' || c == '-';
        });
        if (!ok)
            fail(key, fmt::format("{} must be a name of letters, digits, '_' or '-' (got {})", keyPath(key),
                                  describe(n)),
                 fmt::format("e.g. `{}: honey_block`", key));
    }
    m->record(key, v, "");
    return v;
}

std::string Section::choice(const std::string& key, std::optional<std::string> fallback,
                            const std::vector<std::string>& choices) {
    const YAML::Node n = m->value(key);
    std::string v;
    if (!n.IsDefined()) {
        if (!fallback) failMissing(key, fmt::format("{} is missing: one of {} is required", keyPath(key), joinNames(choices)),
                            fmt::format("add `{}: {}`", key, choices.front()));
        v = *fallback;
    } else {
        v = n.IsScalar() ? n.Scalar() : "";
        if (std::find(choices.begin(), choices.end(), v) == choices.end()) {
            const std::string guess = closestMatch(v, choices);
            fail(key, fmt::format("{}: unknown value {}", keyPath(key), describe(n)),
                 (guess.empty() ? "" : fmt::format("did you mean '{}'? ", guess)) +
                     fmt::format("accepted: {}", joinNames(choices)));
        }
    }
    m->record(key, v, "");
    return v;
}

Vec3 Section::colour(const std::string& key, std::optional<Vec3> fallback) {
    const Vec3 c = vec3(key, fallback, "sRGB");
    if (c.minCoeff() < 0 || c.maxCoeff() > 1)
        fail(key, "a colour's components lie in [0, 1] (sRGB)", fmt::format("write e.g. `{}: [0.32, 0.17, 0.09]`", key));
    return c;
}

std::string Section::exactlyOne(const std::vector<std::string>& keys, const std::string& what,
                                const std::string& example) {
    std::string found;
    for (const auto& k : keys)
        if (has(k)) {
            if (!found.empty())
                fail(k, fmt::format("{} has both '{}' and '{}'", path(), found, k), "give exactly one " + what);
            found = k;
        }
    if (found.empty())
        fail("", fmt::format("{} has no {}", path(), what), fmt::format("add one of: {}, {}", joinNames(keys), example));
    return found;
}

namespace {

/// Why `p` cannot be read as a file: empty when it is a regular file, else what it is instead.
std::string notARegularFile(const std::filesystem::path& p) {
    namespace fs = std::filesystem;
    std::error_code ec;
    const fs::file_status st = fs::status(p, ec);
    switch (st.type()) {
    case fs::file_type::regular: return {};
    case fs::file_type::not_found: return "does not exist";
    case fs::file_type::directory: return "is a folder, not a file";
    case fs::file_type::fifo: return "is a FIFO (named pipe), not a regular file";
    case fs::file_type::character: return "is a character device, not a regular file";
    case fs::file_type::block: return "is a block device, not a regular file";
    case fs::file_type::socket: return "is a socket, not a regular file";
    default: return ec ? fmt::format("cannot be examined ({})", ec.message()) : "is not a regular file";
    }
}

}  // namespace

std::filesystem::path Section::file(const std::string& key) {
    const YAML::Node n = m->value(key);
    if (!n.IsDefined() || !n.IsScalar() || n.Scalar().empty())
        fail(key, fmt::format("{} must be a file path (got {})", keyPath(key), describe(n)),
             fmt::format("write `{}: path/to/file`, relative to the scene file", key));
    std::filesystem::path p = n.Scalar();
    if (p.is_relative()) p = std::filesystem::path(m->out->file).parent_path() / p;
    const std::string problem = notARegularFile(p);
    if (problem == "does not exist")
        fail(key, fmt::format("{}: file '{}' does not exist (looked for {})", keyPath(key), n.Scalar(), p.string()),
             "check the spelling; relative paths start at the folder of the scene file");
    if (!problem.empty())
        fail(key, fmt::format("{}: '{}' ({}) {}", keyPath(key), n.Scalar(), p.string(), problem),
             "give the path of a regular file (a mesh file: .obj, .ply, .stl, ...)");
    // The effective scene names the file absolutely, so its printout loads from anywhere.
    p = std::filesystem::absolute(p).lexically_normal();
    m->record(key, p.string(), "");
    return p;
}

std::optional<Section> Section::child(const std::string& key) {
    const YAML::Node n = m->value(key);
    if (!n.IsDefined()) return std::nullopt;
    if (n.IsNull()) return makeSection(YAML::Node(YAML::NodeType::Map), m->out, keyPath(key), m->pointer / key, n.Mark());
    if (!n.IsMap())
        fail(key, fmt::format("{} must be a map of keys (got {})", keyPath(key), describe(n)),
             fmt::format("write `{}:` followed by indented `key: value` lines", key));
    return makeSection(n, m->out, keyPath(key), m->pointer / key, n.Mark());
}

Section Section::section(const std::string& key) {
    if (auto c = child(key)) return *c;
    return makeSection(YAML::Node(YAML::NodeType::Map), m->out, keyPath(key), m->pointer / key, m->mark);
}

Section Section::require(const std::string& key, const std::string& example) {
    if (!has(key)) failMissing(key, fmt::format("{} is missing", keyPath(key)), fmt::format("add `{}`", example));
    return *child(key);
}

std::vector<Section> Section::list(const std::string& key) {
    const YAML::Node n = m->value(key);
    std::vector<Section> out;
    if (!n.IsDefined()) return out;
    if (!n.IsSequence())
        fail(key, fmt::format("{} must be a list (got {})", keyPath(key), describe(n)),
             fmt::format("write each entry on its own line starting with '- ' under `{}:`", key));
    m->out->values[m->pointer / key] = Json::array();
    for (std::size_t i = 0; i < n.size(); ++i) {
        const YAML::Node item = n[i];
        const std::string itemPath = fmt::format("{}[{}]", keyPath(key), i);
        if (!item.IsMap())
            throw SceneError(locationOf(m->out->file, item.Mark()),
                             fmt::format("{} must be a map of keys (got {})", itemPath, describe(item)),
                             "write `- name: ...` followed by the entry's keys, indented");
        out.push_back(makeSection(item, m->out, itemPath, m->pointer / key / std::to_string(i), item.Mark()));
    }
    return out;
}

std::vector<std::string> Section::keys() const {
    std::vector<std::string> out;
    for (const auto& kv : m->node) out.push_back(kv.first.Scalar());
    return out;
}

void Section::rejectUnused() const {
    std::set<std::string> seen;
    const std::vector<std::string> known(m->read.begin(), m->read.end());
    for (const auto& kv : m->node) {
        const std::string key = kv.first.Scalar();
        const Location at = locationOf(m->out->file, kv.first.Mark());
        if (!seen.insert(key).second)
            throw SceneError(at, fmt::format("{} is given twice", keyPath(key)), "keep one of the two lines");
        if (!m->read.count(key)) {
            const std::string guess = closestMatch(key, known);
            throw SceneError(at, fmt::format("unknown key '{}' in {}", key, m->path.empty() ? "the scene" : m->path),
                             (guess.empty() ? "" : fmt::format("did you mean '{}'? ", guess)) +
                                 fmt::format("known keys here: {}", joinNames(known)));
        }
    }
}

Section openSceneFile(const std::filesystem::path& file) {
    auto out = std::make_shared<EffectiveScene>();
    out->file = file.string();
    const std::string problem = notARegularFile(file);
    if (problem == "does not exist")
        throw InputError(fmt::format("{}: scene file does not exist\n  fix: check the path; scenes/ holds examples",
                                     file.string()));
    if (!problem.empty())
        throw InputError(fmt::format("{}: {}\n  fix: give the path of a .yaml scene", file.string(), problem));
    std::ifstream in(file, std::ios::binary);
    if (!in) throw InputError(fmt::format("{}: cannot be read (permissions?)", file.string()));
    std::stringstream text;
    text << in.rdbuf();
    YAML::Node root;
    try {
        root = YAML::Load(text.str());
    } catch (const YAML::Exception& e) {
        throw SceneError(locationOf(out->file, e.mark), "YAML syntax error: " + e.msg,
                         "check indentation (spaces, not tabs), colons after keys and matching brackets");
    }
    if (!root.IsMap())
        throw SceneError({out->file, 1, 1}, "a scene must be a YAML map of keys (got " + describe(root) + ")",
                         "start the file with `ganache: 1`; see scenes/README.md");
    return makeSection(root, out, "", Json::json_pointer(""), YAML::Mark());
}

namespace {

std::string yamlScalar(const Json& v) {
    if (v.is_string()) {
        std::string s = "\"";
        for (char c : v.get<std::string>()) s += (c == '"' || c == '\\') ? std::string("\\") + c : std::string(1, c);
        return s + "\"";
    }
    if (v.is_number_float()) return formatNumber(v.get<Real>());
    if (v.is_array()) {
        std::string s = "[";
        for (std::size_t i = 0; i < v.size(); ++i) s += (i ? ", " : "") + yamlScalar(v[i]);
        return s + "]";
    }
    return v.dump();
}

bool isLeaf(const Json& v) {
    return !v.is_object() && !(v.is_array() && !v.empty() && v[0].is_object());
}

void emitYaml(const Json& v, const std::string& pointer, int indent, const EffectiveScene& s,
              std::string& out, bool firstInListItem = false) {
    const std::string pad(indent, ' ');
    bool first = true;
    for (const auto& [key, child] : v.items()) {
        const std::string p = pointer + "/" + key;
        const std::string lead = (firstInListItem && first) ? std::string(indent - 2, ' ') + "- " : pad;
        first = false;
        if (isLeaf(child)) {
            out += lead + key + ": " + (child.is_object() ? "{}" : yamlScalar(child));
            auto u = s.units.find(p);
            if (u != s.units.end()) out += "  # " + u->second;
            out += "\n";
        } else if (child.is_object()) {
            out += lead + key + ":" + (child.empty() ? " {}" : "") + "\n";
            emitYaml(child, p, indent + 2, s, out);
        } else {
            out += lead + key + ":\n";
            for (std::size_t i = 0; i < child.size(); ++i)
                emitYaml(child[i], p + "/" + std::to_string(i), indent + 4, s, out, true);
        }
    }
}

}  // namespace

std::shared_ptr<const EffectiveScene> Section::effective() const { return m->out; }

std::string effectiveJson(const EffectiveScene& scene) { return scene.values.dump(); }

std::string effectiveYaml(const EffectiveScene& scene) {
    std::string out;
    emitYaml(scene.values, "", 0, scene, out);
    return out;
}

}  // namespace ganache
