#pragma once
// Gravity: a uniform acceleration of every fluid particle, in the Forces stage.

#include "physics/effect.h"

namespace ganache {

struct GravityParams : EffectParams {
    Vec3 acceleration{0, -9.81, 0};  ///< [m/s^2]
};

std::shared_ptr<const EffectParams> readGravity(Section& s);
std::unique_ptr<Effect> makeGravity(const EffectParams& params, const SimulationSetup& setup, ParticleSet& particles);

}  // namespace ganache
