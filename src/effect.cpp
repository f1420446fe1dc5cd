#include "effect.h"

#include <fmt/format.h>

namespace ganache {

namespace {

std::shared_ptr<const EffectParams> readGravity(Section& s) {
    auto p = std::make_shared<GravityParams>();
    p->acceleration = s.vec3("acceleration", p->acceleration, "m/s^2");
    return p;
}

std::vector<std::string> effectNames() {
    std::vector<std::string> names;
    for (const auto& e : effectTable()) names.emplace_back(e.name);
    return names;
}

}  // namespace

const std::vector<EffectEntry>& effectTable() {
    static const std::vector<EffectEntry> table = {
        {"gravity", Stage::Forces, "uniform acceleration of every fluid particle", &readGravity},
    };
    return table;
}

std::vector<EffectSpec> readEffects(Section& effects) {
    std::vector<EffectSpec> specs;
    for (const std::string& key : effects.keys()) {
        const EffectEntry* entry = nullptr;
        for (const auto& e : effectTable())
            if (e.name == key) entry = &e;
        if (!entry) {
            const std::string guess = closestMatch(key, effectNames());
            effects.failAtKey(key, fmt::format("unknown effect '{}'", key),
                         (guess.empty() ? "" : fmt::format("did you mean '{}'? ", guess)) +
                             fmt::format("effects in this build: {}", joinNames(effectNames())));
        }
        const Location at = effects.where(key);
        // `gravity: {}` or a bare `gravity:` asks for the effect with all its defaults.
        Section s = *effects.child(key);
        specs.push_back({key, entry->stage, at, entry->read(s)});
        s.rejectUnused();
    }
    effects.rejectUnused();
    return specs;
}

}  // namespace ganache
