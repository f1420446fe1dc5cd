#include "physics/materials.h"

#include "scene/section.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace ganache {

Real ViscosityLaw::at(Real temperature) const {
    if (kind == Kind::Reynolds) return std::clamp(mu0 * std::exp(-alpha * (temperature - t0)), muMin, muMax);
    if (temperature <= ramp.front().first) return ramp.front().second;
    for (std::size_t k = 1; k < ramp.size(); ++k)
        if (temperature < ramp[k].first) {
            const auto& [ta, ma] = ramp[k - 1];
            const auto& [tb, mb] = ramp[k];
            const Real s = (temperature - ta) / (tb - ta);
            return std::exp((1 - s) * std::log(ma) + s * std::log(mb));
        }
    return ramp.back().second;
}

namespace {

// Chocolate melting as in Weiler et al. 2018, Sec. 7: 5e6 Pa s cold (20 C) down to 100 Pa s at 50 C, with
// Reynolds' law through both points: alpha = ln(5e6 / 100) / 30 K.
ViscosityLaw chocolateLaw() {
    ViscosityLaw law;
    law.mu0 = 5.0e6;
    law.t0 = 20;
    law.alpha = std::log(5.0e6 / 100) / 30;
    law.muMin = 100;
    law.muMax = 5.0e6;
    return law;
}

Material make(std::string name, Vec3 colour, Real density, Real mu, Real k, Real c, std::string source,
              std::optional<ViscosityLaw> law = std::nullopt) {
    Material m;
    m.colour = colour;
    m.name = std::move(name);
    m.density = density;
    m.mu = mu;
    m.conductivity = k;
    m.heatCapacity = c;
    m.source = std::move(source);
    m.law = std::move(law);
    return m;
}

}  // namespace

const std::vector<Material>& materialPresets() {
    // Preview colours (sRGB): water pale blue, honey amber, chocolate dark brown.
    const Vec3 kWater(0.55, 0.72, 0.92), kHoney(0.86, 0.55, 0.12), kChocolate(0.32, 0.17, 0.09);
    static const std::vector<Material> presets = {
        make("water", kWater, 998.2, 1.002e-3, 0.598, 4182,
             "liquid water at 20 C, standard property tables (e.g. CRC Handbook of Chemistry and Physics)"),
        make("honey", kHoney, 1420, 10, 0.5, 2400,
             "a typical honey near 20 C; honeys range from about 2 to 20 Pa s with their water content "
             "(Yanniotis, Skaltsi, Karaburnioti 2006, J. Food Engineering 72(4)); conductivity and heat capacity "
             "typical of honeys with 17-20 % water"),
        make("molten_chocolate", kChocolate, 1250, 100, 0.17, 1600,
             "viscosity of chocolate at 50 C as used by Weiler et al. 2018, Sec. 7 (melting bunny); density a "
             "typical value for dark chocolate (about 1.2-1.3 g/cm^3); conductivity and heat capacity typical "
             "of chocolate (about 0.17 W/(m K), 1.6 kJ/(kg K))"),
        make("solid_chocolate", kChocolate, 1250, 5.0e6, 0.17, 1600,
             "the cold, almost rigid chocolate of Weiler et al. 2018, Sec. 7 (melting bunny); other values as "
             "molten_chocolate"),
        make("chocolate", kChocolate, 1250, 5.0e6, 0.17, 1600,
             "chocolate that melts: Reynolds' law from 5e6 Pa s at 20 C to 100 Pa s at 50 C (Weiler et al. 2018, "
             "Sec. 7), clamped to that range; other values as molten_chocolate",
             chocolateLaw()),
    };
    return presets;
}



const Material* findPreset(const std::string& name) {
    for (const auto& m : materialPresets())
        if (m.name == name) return &m;
    return nullptr;
}

namespace {

std::vector<std::string> presetNames() {
    std::vector<std::string> names;
    for (const auto& m : materialPresets()) names.push_back(m.name);
    return names;
}

// `viscosity_law: {reynolds: {...}}` or `{ramp: [{temperature, mu}, ...]}`.
ViscosityLaw readViscosityLaw(Section s) {
    ViscosityLaw law;
    if (s.exactlyOne({"reynolds", "ramp"}, "viscosity law", "e.g. `reynolds: {mu0: 5.0e6, alpha: 0.35}`") == "reynolds") {
        Section r = *s.child("reynolds");
        law.mu0 = r.number("mu0", std::nullopt, "Pa s", Bounds::positiveUpTo(limits::kViscosity));
        law.t0 = r.number("t0", law.t0, "C");
        law.alpha = r.number("alpha", std::nullopt, "1/K");
        law.muMin = r.number("min", law.mu0 * 1e-6, "Pa s", Bounds::positiveUpTo(limits::kViscosity));
        law.muMax = r.number("max", std::min(law.mu0 * 1e6, limits::kViscosity), "Pa s",
                               Bounds::positiveUpTo(limits::kViscosity));
        if (law.muMax < law.muMin)
            r.fail("max", fmt::format("{}.max ({} Pa s) is below min ({} Pa s)", r.path(), formatNumber(law.muMax),
                                      formatNumber(law.muMin)),
                   "make max at least min");
        r.rejectUnused();
    } else {
        law.kind = ViscosityLaw::Kind::Ramp;
        for (Section& p : s.list("ramp")) {
            const Real t = p.number("temperature", std::nullopt, "C");
            if (!law.ramp.empty() && !(t > law.ramp.back().first))
                p.fail("temperature", fmt::format("{}.temperature ({} C) must be above the previous point's ({} C)",
                                                  p.path(), formatNumber(t), formatNumber(law.ramp.back().first)),
                       "list the ramp in increasing temperature");
            law.ramp.emplace_back(t, p.number("mu", std::nullopt, "Pa s", Bounds::positiveUpTo(limits::kViscosity)));
            p.rejectUnused();
        }
        if (law.ramp.empty())
            s.fail("ramp", s.path() + ".ramp has no points", "give at least one `{temperature: C, mu: Pa s}`");
    }
    s.rejectUnused();
    return law;
}

}  // namespace

std::vector<Material> readMaterials(std::optional<Section> section) {
    std::vector<Material> out;
    if (!section) return out;
    for (const std::string& key : section->keys()) {
        if (findPreset(key))
            section->failAtKey(key, fmt::format("material '{}' has the name of a built-in preset", key),
                          "pick another name; presets cannot be redefined");
        Section m = *section->child(key);
        const std::string base = m.choice("base", "water", presetNames());
        Material mat = *findPreset(base);
        mat.name = key;
        mat.density = m.number("density", mat.density, "kg/m^3", Bounds::closed(1, limits::kDensity));
        mat.mu = m.number("mu", mat.mu, "Pa s", Bounds::closed(0, limits::kViscosity));
        mat.conductivity = m.number("conductivity", mat.conductivity, "W/(m K)", Bounds::nonNegative());
        mat.heatCapacity = m.positive("heat_capacity", mat.heatCapacity, "J/(kg K)");
        if (auto law = m.child("viscosity_law")) mat.law = readViscosityLaw(*law);
        mat.colour = m.colour("colour", mat.colour);
        mat.source = "user material based on " + base;
        m.rejectUnused();
        out.push_back(mat);
    }
    section->rejectUnused();
    return out;
}

Material readMaterialChoice(Section& fluid, const std::vector<Material>& custom) {
    std::vector<std::string> names = presetNames();
    for (const auto& m : custom) names.push_back(m.name);
    const std::string name = fluid.choice("material", "water", names);
    for (const auto& m : custom)
        if (m.name == name) return m;
    return *findPreset(name);
}

}  // namespace ganache
