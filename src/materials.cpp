#include "materials.h"

namespace ganache {

const std::vector<Material>& materialPresets() {
    static const std::vector<Material> presets = {
        {"water", 998.2, 1.002e-3,
         "liquid water at 20 C, standard property tables (e.g. CRC Handbook of Chemistry and Physics)"},
        {"honey", 1420, 10,
         "a typical honey near 20 C; honeys range from about 2 to 20 Pa s with their water content "
         "(Yanniotis, Skaltsi, Karaburnioti 2006, J. Food Engineering 72(4))"},
        {"molten_chocolate", 1250, 100,
         "viscosity of chocolate at 50 C as used by Weiler et al. 2018, Sec. 7 (melting bunny); density a "
         "typical value for dark chocolate (about 1.2-1.3 g/cm^3)"},
        {"solid_chocolate", 1250, 5.0e6,
         "the cold, almost rigid chocolate of Weiler et al. 2018, Sec. 7 (melting bunny); density as "
         "molten_chocolate"},
    };
    return presets;
}

const Material* findPreset(const std::string& name) {
    for (const auto& m : materialPresets())
        if (m.name == name) return &m;
    return nullptr;
}

}  // namespace ganache
