// Static and implicit-Euler solvers over generalised DOFs (point nodes and
// frame nodes with rotations), for shells, frame models, tets and their
// couplings in one system.
//
// Usage: build a GeneralisedState (AddPointNode / AddFrameNode, or
// AddTetVertexNodes for a tet body), make the terms (an element term
// implementing GeneralisedEnergyTerm, and InertiaSource where it carries mass;
// TetElasticityTerm, TetBodyTerm (a tet body's other EnergyTerms),
// ZeroLengthSpringTerm, GravityTerm from generalised_terms.h), set boundary conditions with
// SetFixedTranslation / SetFixedRotation (clamped = both, simply supported = translation only).
// Then either GeneralisedStaticSolver(options).Solve(&state, {&elastic, &springs, &gravity}) for
// the equilibrium (Newton with the terms' Hessians and an Armijo line search on the total energy),
// or, per time step, GeneralisedImplicitEuler(options).Step(&state, {&elastic}, {&springs,
// &gravity}, CollectNodeInertia(state, {&elastic})), where the first list is
// the elastic terms that Rayleigh's beta damps. Each Newton increment is
// (dx, dtheta) per node and the solvers apply it as x += dx, R <- Exp(dtheta) R
// (GeneralisedState::ApplyIncrement); terms are Update()d at every new point.
// The line search calls Update and Value at its trial points, and the next step
// (or Newton iteration) starts with Update at the point it accepted: a term that
// does its work in Update should return early when the configuration is the one
// of its last Update and compute its energy there (as CorotationalElasticity does),
// or one-step mode pays for that work twice per step.
// The sparse pattern is the union of the terms' stencils, rebuilt when nodes
// are added or the list of terms changes; call InvalidatePattern() after a
// term's stencils changed otherwise (elements replaced by a cut).
#pragma once

#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

#include "mechanics/generalised_state.h"
#include "mechanics/generalised_system.h"
#include "mechanics/integrator.h"
#include "mechanics/linear_solver.h"

namespace arreg::mechanics {

struct GeneralisedSummary {
  StepStatus status = StepStatus::kConverged;  // as StepSummary (integrator.h)
  int newton_iterations = 0;                   // summed over sub-steps
  int linear_iterations = 0;                   // CG iterations summed over solves
  int linear_solves = 0;
  int factorizations = 0;         // numeric Cholesky factorisations
  int line_search_cuts = 0;       // halvings of Newton increments
  double last_increment_mm = 0;   // max |dx| of the last Newton increment
  double last_increment_rad = 0;  // max |dtheta| component of the last Newton increment
  double energy = 0;              // static: total energy at the solution (uJ)
  double assembly_ms = 0;         // term updates, gradients, Hessian into slots, Dirichlet rows
  double solve_ms = 0;            // linear solver
  double total_ms = 0;
  bool pattern_rebuilt = false;
  std::string message;
};

struct GeneralisedStaticOptions {
  int max_iterations = 50;            // Newton iterations; default 50
  double tolerance_mm = 1e-9;         // converged when max |dx| (mm) is below ...; default 1e-9
  double tolerance_rad = 1e-9;        // ... and max |dtheta| (rad) is below; default 1e-9
  bool line_search = true;            // Armijo backtracking on the energy; default true
  LinearSolverOptions linear_solver;  // default CHOLMOD
  void Check() const;
};

// Minimises the sum of the terms' energies over the free DOFs (fixed ones keep
// their value); sets all velocities to zero. Status kMaxIterations when the
// tolerance was not met, kLinearSolveFailed (state at the last iterate) when
// the matrix was not positive definite (e.g. a rotation with no stiffness).
class GeneralisedStaticSolver {
 public:
  explicit GeneralisedStaticSolver(const GeneralisedStaticOptions& options);
  GeneralisedSummary Solve(GeneralisedState* state,
                           const std::vector<GeneralisedEnergyTerm*>& terms);
  void InvalidatePattern() { system_.Invalidate(); }
  const GeneralisedSystem& system() const { return system_; }

 private:
  GeneralisedStaticOptions options_;
  std::unique_ptr<LinearSolver> solver_;
  GeneralisedSystem system_;
};

struct GeneralisedImplicitEulerOptions {
  double dt_s = 1.0 / 30.0;  // time advanced by one Step() in s; default 1/30
  int substeps = 1;          // sub-steps per Step(), each of dt_s / substeps; default 1
  NewtonMode newton_mode = NewtonMode::kOneStep;  // as ImplicitEulerOptions; default one step
  int max_newton_iterations = 20;                 // full Newton, or the fixed budget; default 20
  double newton_tolerance_mm = 1e-7;     // stop when max |dx| (mm) is below ...; default 1e-7
  double newton_tolerance_rad = 1e-9;    // ... and max |dtheta| (rad) is below; default 1e-9
  double rayleigh_mass_alpha = 0.0;      // alpha in 1/s (masses and rotational inertia); 0
  double rayleigh_stiffness_beta = 0.0;  // beta in s (over the elastic terms); default 0
  // Default CHOLMOD; relative_tolerance 1e-3 (DefaultStepSolverOptions, integrator.h).
  LinearSolverOptions linear_solver = DefaultStepSolverOptions();
  bool line_search = true;  // Armijo backtracking on Phi (below); default true
  void Check() const;
};

// Backward Euler on the incremental potential, per (sub)step of length h with
// the state (x_n, R_n, v_n, omega_n) at its start, unknowns x and R:
//   Phi = sum_n [ m/(2h^2) |x - x_n - h v_n|^2 + 1/(2h^2) phi^T I_n phi ]
//       + 1/(2h) q^T D q + E(x, R),
//   phi = Log(R R_n^T) - h omega_n,  q = (x - x_n, Log(R R_n^T)) per node,
//   I_n = R_n I_body R_n^T (spatial, frozen over the step), D = alpha M + beta K0,
// M the lumped masses and rotational inertias, K0 the elastic terms' Hessian at
// the step's start. With no rotation this is ImplicitEulerIntegrator's Phi (lumped
// mass), and the tet-only steps agree. grad Phi = 0 gives for the rotations
//   (L_{n+1} - L_n)/h = tau(R) - alpha L_{n+1} - beta (K0 q)_rot / h,
// with spatial angular momenta L_n = I_n omega_n and L_{n+1} = I_n Log(R R_n^T)/h:
// backward Euler on the angular momentum (no torque: L kept exactly). At the
// end v = (x - x_n)/h and omega = I_{n+1}^{-1} L_{n+1} with I_{n+1} = R I_body R^T,
// so that the next step starts from the momentum this one reached (omega =
// Log(R R_n^T)/h would drop the gyroscopic term omega x I omega); along body axes
// of zero inertia omega takes Log(R R_n^T)/h.
// Derivatives in phi at the current iterate R = Exp(theta) R_n: gradient rows
// J_l^-T(theta) (I_n phi/h^2 + ...); Hessian J_l^-T I_n J_l^-1/h^2 (the derivative
// of J_l^-1 is neglected, exact at theta = 0, i.e. in one-step mode); the damping
// Hessian is beta/h K0 with the same neglect. Fixed DOFs get zero increment and
// zero velocity.
class GeneralisedImplicitEuler {
 public:
  explicit GeneralisedImplicitEuler(const GeneralisedImplicitEulerOptions& options);

  // Advances the state by options.dt_s. `elastic`: the terms Rayleigh's beta damps;
  // `others`: the rest (springs, gravity, forces); `inertia`: num_nodes() entries
  // (CollectNodeInertia). On kLinearSolveFailed the state is left at the start of
  // the failing sub-step.
  GeneralisedSummary Step(GeneralisedState* state,
                          const std::vector<GeneralisedEnergyTerm*>& elastic,
                          const std::vector<GeneralisedEnergyTerm*>& others,
                          const std::vector<NodeInertia>& inertia);
  void InvalidatePattern() { system_.Invalidate(); }
  const GeneralisedImplicitEulerOptions& options() const { return options_; }
  const GeneralisedSystem& system() const { return system_; }

 private:
  GeneralisedSummary SubStep(GeneralisedState* state,
                             const std::vector<GeneralisedEnergyTerm*>& elastic,
                             const std::vector<GeneralisedEnergyTerm*>& others,
                             const std::vector<NodeInertia>& inertia, double h);

  GeneralisedImplicitEulerOptions options_;
  std::unique_ptr<LinearSolver> solver_;
  GeneralisedSystem system_;
  Eigen::VectorXd k0_values_;  // beta > 0: the elastic Hessian at the step's start (values)
  Eigen::VectorXd gradient_, rhs_, solution_;
};

// Kinetic energy sum_n m/2 |v|^2 + 1/2 omega^T R I_body R^T omega (uJ).
double GeneralisedKineticEnergy(const GeneralisedState& state,
                                const std::vector<NodeInertia>& inertia);
// Linear momentum sum_n m v (kg mm/s).
Eigen::Vector3d GeneralisedLinearMomentum(const GeneralisedState& state,
                                          const std::vector<NodeInertia>& inertia);
// Angular momentum about the origin sum_n m x x v + R I_body R^T omega (kg mm^2/s).
Eigen::Vector3d GeneralisedAngularMomentum(const GeneralisedState& state,
                                           const std::vector<NodeInertia>& inertia);

}  // namespace arreg::mechanics
