// The configuration in which a body's springs would hold it at rest, fitted
// from a dynamic state without changing it (the registration's output model).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <optional>
#include <vector>

#include "mechanics/elastic_energy.h"
#include "mechanics/energy.h"
#include "mechanics/integrator.h"
#include "mechanics/mechanical_state.h"
#include "mechanics/spring_energy.h"

namespace arreg::mechanics {

// Newton steps from the state's positions x towards the minimum over y of
//   Phi(y) = E_el(y) + s E_springs(y) + E_other(y) + 1/(2 h^2) |y - x|_M^2,
// the springs made s times stiffer. The last term only keeps the system definite
// (a piece held by no spring stays where it is); with h = 1 s it is ~1e-3 of the
// springs' stiffness on the scenes of docs/springs.md, so y is the quasi-static
// equilibrium: no inertia, no damping, and a spring lag that is s times smaller.
struct QuasiStaticFitOptions {
  double spring_factor = 6.0;          // s (> 0); default 6
  double regularisation_time_s = 1.0;  // h in s (> 0); default 1
  int newton_iterations = 1;           // Newton steps (>= 1); default 1
  // Default CHOLMOD-preconditioned CG, relative tolerance 1e-3 (DefaultStepSolverOptions).
  LinearSolverOptions linear_solver = DefaultStepSolverOptions();
  // Backtracking line search on Phi along each Newton increment
  // (ImplicitEulerOptions::line_search). The fit starts afresh from the dynamic state every
  // frame and carries nothing over, so an overshoot cannot build up into an oscillation as it
  // does in the dynamic model; with the search on, the fit's full step decreased Phi in every
  // frame of the six synthetic scenes where the dynamic step's search acted, and the search
  // costs a rotation pass per fit (0.3 ms on kidney-cut). Default false.
  bool line_search = false;
  // The material's element options (volume term, rotation); the dynamic model's, so that both
  // configurations minimise the same elastic energy.
  CorotationalOptions elastic;
  void Check() const;
};

class QuasiStaticFit {
 public:
  explicit QuasiStaticFit(const QuasiStaticFitOptions& options);

  // Fits a copy of `state` (which is not changed) with `springs` scaled by the
  // spring factor and `other_terms` (e.g. gravity) as they are. The fixed
  // vertices of `state` stay fixed. Vertices of a connected piece that no active
  // spring is anchored in keep their positions in `state`, and so do all
  // vertices when the linear solve fails (status kLinearSolveFailed).
  StepSummary Fit(const MechanicalState& state, const SpringEnergy& springs,
                  const std::vector<EnergyTerm*>& other_terms = {});

  // (#V x 3) fitted positions in mm, valid after Fit().
  const RowMatX3d& positions() const { return positions_; }
  const QuasiStaticFitOptions& options() const { return options_; }

 private:
  void KeepUnheldPieces(const MechanicalState& state, const SpringEnergy& springs);

  QuasiStaticFitOptions options_;
  std::optional<ImplicitEulerIntegrator> integrator_;  // rebuilt when the topology changes
  CorotationalElasticity elastic_;
  std::optional<MechanicalState> copy_;
  SpringEnergy springs_;
  std::uint64_t source_topology_version_ = 0;
  int source_tetrahedra_ = -1;
  Eigen::VectorXi piece_;  // (#T) connected piece of each tetrahedron (vertex adjacency)
  int num_pieces_ = 0;
  RowMatX3d positions_;
};

}  // namespace arreg::mechanics
