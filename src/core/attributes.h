#pragma once
// The per-particle attributes that several parts of ganache share, declared once. An attribute only one effect uses
// is declared in that effect's own file.

#include "core/particles.h"

namespace ganache::attribute {

/// Index of the particle's source of fluid (SimulationSetup::sources); present only when there are several.
inline constexpr Attribute<Real> kFluid{"fluid"};
/// Temperature [C]; present only with the heat effect.
inline constexpr Attribute<Real> kTemperature{"temperature"};
/// Dynamic viscosity [Pa s]; present only when the viscosity effect's value differs between particles.
inline constexpr Attribute<Real> kViscosity{"viscosity"};
/// Rest density rho_0 [kg/m^3], from the mass and the sampling lattice.
inline constexpr Attribute<Real> kRestDensity{"_rest_density", false};
/// 1 where the last implicit viscosity solve found the particle stiff enough to move with its neighbours as one
/// body, else 0; present only with the weiler2018 viscosity. The pressure warm start reads it (PressureDFSPH).
inline constexpr Attribute<Real> kViscouslyRigid{"_viscously_rigid", false};
/// The constant-density pressure kappa / rho of the last step: the next step's warm start (PressureDFSPH). Checkpoints
/// carry it; the stability tests set it to stage a pressure left on particles that have since come apart.
inline constexpr Attribute<Real> kPressureWarmStart{"_pressure", false};

}  // namespace ganache::attribute
