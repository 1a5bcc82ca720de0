// Shared fixtures of the mechanics tests: small box bodies and random
// perturbations with a fixed seed.
#pragma once

#include <random>

#include "core/mesh_generators.h"
#include "mechanics/mechanical_state.h"

namespace arreg::mechanics::testing {

inline TetMesh SmallBox(const Eigen::Vector3i& cells = {3, 2, 2},
                        const Eigen::Vector3d& size_mm = {30, 20, 20}) {
  return MakeBoxTetMesh(size_mm, cells, BoxTetSplit::kSix);
}

// Positions x + uniform noise in [-amplitude, amplitude] mm, deterministic.
inline RowMatX3d Perturbed(const RowMatX3d& x, double amplitude, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-amplitude, amplitude);
  RowMatX3d y = x;
  for (int i = 0; i < y.rows(); ++i)
    for (int c = 0; c < 3; ++c) y(i, c) += u(rng);
  return y;
}

}  // namespace arreg::mechanics::testing
