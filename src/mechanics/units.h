// Unit convention of the mechanics module: lengths in mm, mass in kg, time in s.
// Material parameters are given in SI (Pa, kg/m^3) and converted here once.
#pragma once

namespace arreg::mechanics {

// Internal units follow from (mm, kg, s):
//   force   kg mm / s^2   = mN
//   energy  kg mm^2 / s^2 = uJ (= mN mm)
//   stress  kg / (mm s^2) = kPa (= mN / mm^2)
//   spring stiffness kg / s^2 = N/m = mN/mm (the same number in both systems)
//   density kg / mm^3, acceleration mm / s^2.
inline constexpr double kPaToInternalStress = 1e-3;         // Pa -> kPa
inline constexpr double kKgPerM3ToInternalDensity = 1e-9;   // kg/m^3 -> kg/mm^3
inline constexpr double kStandardGravityMmPerS2 = 9806.65;  // g in mm/s^2

}  // namespace arreg::mechanics
