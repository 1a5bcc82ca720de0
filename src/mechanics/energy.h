// The interface every mechanical force term implements: potential energy
// E(x), gradient dE/dx (the force is f = -dE/dx) and Hessian d2E/dx2.
#pragma once

#include <string>

#include "core/mesh.h"
#include "mechanics/mechanical_state.h"
#include "mechanics/system_matrix.h"

namespace arreg::mechanics {

// Sign convention, used throughout the module: x is the (#V x 3) matrix of
// current positions in mm, E(x) in uJ, gradient dE/dx in mN (force f = -dE/dx),
// Hessian K = d2E/dx2 in mN/mm (positive semi-definite for stable terms).
class EnergyTerm {
 public:
  virtual ~EnergyTerm() = default;
  virtual std::string name() const = 0;

  // Called once per new linearisation point before Value/Gradient/Hessian
  // (the elastic term recomputes its element rotations here). Terms whose
  // derivatives depend only on x need nothing.
  virtual void Update(const MechanicalState& state, const RowMatX3d& x) {}

  virtual double Value(const MechanicalState& state, const RowMatX3d& x) const = 0;
  // gradient: (#V x 3), accumulated into.
  virtual void AddGradient(const MechanicalState& state, const RowMatX3d& x,
                           RowMatX3d* gradient) const = 0;
  // Adds scale * Hessian into the matrix (whose pattern covers every pair of
  // vertices sharing a tetrahedron). Terms with zero Hessian do nothing.
  virtual void AddHessian(const MechanicalState& state, const RowMatX3d& x, double scale,
                          SystemMatrix* hessian) const = 0;
};

}  // namespace arreg::mechanics
