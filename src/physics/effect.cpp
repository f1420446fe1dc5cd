#include "physics/effect.h"

#include "physics/gravity.h"
#include "physics/heat/heat.h"
#include "physics/viscosity/viscosity.h"
#include "scene/section.h"

#include <fmt/format.h>

#include <stdexcept>

namespace ganache {

namespace {

std::vector<EffectEntry>& registry() {
    // One row per effect: its scene key, its stage, what it does, its reader and its factory.
    static std::vector<EffectEntry> table = {
        {"gravity", Stage::Forces, "uniform acceleration of every fluid particle", &readGravity, &makeGravity},
        {"viscosity", Stage::Viscosity,
         "viscosity: the implicit solver of Weiler et al. 2018, or (for comparison) explicit or takahashi2015",
         &readViscosity, &makeViscosity},
        {"heat", Stage::Start, "temperature: conduction, radiation, heat sources; melting through viscosity laws",
         &readHeat, &makeHeat},
    };
    return table;
}

std::vector<std::string> effectNames() {
    std::vector<std::string> names;
    for (const auto& e : effectTable()) names.emplace_back(e.name);
    return names;
}

}  // namespace

const std::vector<EffectEntry>& effectTable() { return registry(); }

void registerEffect(const EffectEntry& entry) {
    if (findEffectEntry(entry.name))
        throw std::logic_error(fmt::format("an effect named '{}' is registered already", entry.name));
    registry().push_back(entry);
}

const EffectEntry* findEffectEntry(std::string_view name) {
    for (const auto& e : effectTable())
        if (e.name == name) return &e;
    return nullptr;
}

std::vector<EffectSpec> readEffects(Section& effects) {
    std::vector<EffectSpec> specs;
    for (const std::string& key : effects.keys()) {
        const EffectEntry* entry = findEffectEntry(key);
        if (!entry) {
            const std::string guess = closestMatch(key, effectNames());
            effects.failAtKey(key, fmt::format("unknown effect '{}'", key),
                              (guess.empty() ? "" : fmt::format("did you mean '{}'? ", guess)) +
                                  fmt::format("effects in this build: {}", joinNames(effectNames())));
        }
        const Location at = effects.where(key);
        // `gravity: {}` or a bare `gravity:` asks for the effect with all its defaults.
        Section s = *effects.child(key);
        specs.push_back({key, at, entry->read(s)});
        s.rejectUnused();
    }
    effects.rejectUnused();
    return specs;
}

}  // namespace ganache
