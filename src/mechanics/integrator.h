// Time integration of a MechanicalState: implicit (backward) Euler with one
// Newton step per time step (thesis 3.3) or full Newton, and a static solver.
#pragma once

#include <Eigen/Core>
#include <memory>
#include <vector>

#include "mechanics/elastic_energy.h"
#include "mechanics/energy.h"
#include "mechanics/linear_solver.h"
#include "mechanics/mechanical_state.h"
#include "mechanics/system_matrix.h"

namespace arreg::mechanics {

enum class MassType { kLumped, kConsistent };
// Initial guess of an iterative linear solver for the first Newton increment
// y - x_n of a (sub)step.
enum class WarmStart {
  kVelocity,     // h v_n: the body keeps its velocity
  kExtrapolate,  // h (2 v_n - v_{n-1}): it keeps its acceleration (h v_n after
                 // a topology change, or when v_n is not the velocity that the
                 // last step wrote)
};

// Linear solver options of the implicit integrator: those of LinearSolverOptions
// except the iterative solvers' relative_tolerance, 1e-3. One Newton step per
// frame already differs from the exact implicit Euler step by its
// linearisation error (~1e-3 of the step on the benchmark meshes); the
// solver's error at 1e-3 is 10-100x smaller (docs/mechanics.md).
LinearSolverOptions DefaultStepSolverOptions();
enum class NewtonMode {
  kOneStep,     // one Newton iteration per (sub)step: the thesis' real-time choice
  kFullNewton,  // iterate until the increment is below newton_tolerance_mm
  // max_newton_iterations iterations per (sub)step (fewer once the increment is below
  // newton_tolerance_mm), and the step is complete after them: a fixed budget, as kOneStep is
  // one iteration, so the status stays kConverged (the registration's default, 2).
  kFixedIterations,
};

// Incremental potential solved at every (sub)step of length h, unknown y = x_{n+1}:
//   Phi(y) = 1/(2h^2) |y - x_n - h v_n|_M^2 + 1/(2h) (y - x_n)^T D (y - x_n) + E(y)
// with Rayleigh damping D = alpha M + beta K_el(x_n). grad Phi = 0 is backward
// Euler: M (v_{n+1} - v_n)/h = -grad E(x_{n+1}) - D v_{n+1}, x_{n+1} = x_n + h v_{n+1}.
// Newton: H dy = -grad Phi with H = M/h^2 + D/h + K(y) (K = Hessian of E).
// One step from y = x_n gives (M + h D + h^2 K) v_{n+1} = M v_n + h f(x_n), the
// thesis' eq. 3.69 with our sign convention (K positive semi-definite).
struct ImplicitEulerOptions {
  double dt_s = 1.0 / 30.0;  // time advanced by one Step() (a video frame) in s; default 1/30
  int substeps = 1;          // sub-steps per Step(), each of dt_s / substeps; default 1
  NewtonMode newton_mode = NewtonMode::kOneStep;  // default one Newton step (thesis)
  int max_newton_iterations = 20;                 // full Newton, or the fixed budget; default 20
  double newton_tolerance_mm = 1e-7;  // full Newton: stop when max |dy| (mm) is below; default 1e-7
  double rayleigh_mass_alpha = 0.0;   // alpha in 1/s; default 0
  double rayleigh_stiffness_beta = 0.0;  // beta in s; default 0
  MassType mass = MassType::kLumped;     // default lumped
  // Default CHOLMOD; relative_tolerance 1e-3 (DefaultStepSolverOptions).
  LinearSolverOptions linear_solver = DefaultStepSolverOptions();
  WarmStart warm_start = WarmStart::kExtrapolate;  // iterative solvers; default extrapolate
  // Backtracking (Armijo) line search on Phi along each Newton increment, with
  // the element rotations recomputed at every trial point. The warped stiffness
  // neglects dR/dx; where rotations change fast within a step (a cut's free
  // lips) the full increment can overshoot the minimum of Phi, and one step per
  // frame then settles into a period-2 oscillation (docs/mechanics.md, "Line
  // search"). A step that decreases Phi is taken whole, as without it.
  // Default true.
  bool line_search = true;
  // In the line search's merit, elements inverted at the increment's start keep their rotation
  // there (docs/mechanics.md, "Line search"); false recomputes theirs too. Default true.
  bool freeze_inverted_rotations = true;
  void Check() const;
};

enum class StepStatus {
  kConverged,          // one-step mode: the linear solve succeeded; full Newton: tolerance met
  kMaxIterations,      // Newton hit its iteration cap (the last iterate is kept)
  kLinearSolveFailed,  // the linear solver failed (indefinite / non-finite); state unchanged
};
const char* StepStatusName(StepStatus status);

struct StepSummary {
  StepStatus status = StepStatus::kConverged;
  int newton_iterations = 0;  // summed over sub-steps
  int linear_iterations = 0;  // CG iterations summed over solves
  int linear_solves = 0;
  int factorizations = 0;        // numeric Cholesky factorisations (cholmod, cholmod-pcg)
  int inverted_elements = 0;     // det F <= 0 at the last rotation update
  int line_search_cuts = 0;      // halvings of Newton increments by the line search
  double last_increment_mm = 0;  // max |dy| of the last Newton iteration
  double rotation_ms = 0;        // element rotations (polar decompositions)
  double assembly_ms = 0;        // gradients, Hessian into slots, Dirichlet rows
  double solve_ms = 0;           // linear solver (factorisation + solve, or CG)
  double total_ms = 0;
  bool pattern_rebuilt = false;  // topology changed since the last step
  std::string message;
};

// Adds a sub-step's counts and timings to the step's summary (StepSummary or
// GeneralisedSummary: the fields they share). The last sub-step's increment is
// kept; a failed status is kept with its message. Returns false when the step
// must stop (the linear solve failed).
template <typename Summary>
bool AccumulateSubStep(const Summary& sub, Summary* total) {
  total->newton_iterations += sub.newton_iterations;
  total->linear_iterations += sub.linear_iterations;
  total->linear_solves += sub.linear_solves;
  total->factorizations += sub.factorizations;
  total->line_search_cuts += sub.line_search_cuts;
  total->last_increment_mm = sub.last_increment_mm;
  total->assembly_ms += sub.assembly_ms;
  total->solve_ms += sub.solve_ms;
  total->pattern_rebuilt = total->pattern_rebuilt || sub.pattern_rebuilt;
  if (sub.status == StepStatus::kConverged) return true;
  total->status = sub.status;
  total->message = sub.message;
  return sub.status != StepStatus::kLinearSolveFailed;
}

// Caches the sparsity pattern and mass of a state; rebuilt on topology change.
class SystemCache {
 public:
  // Returns true when the pattern was (re)built.
  bool Refresh(const MechanicalState& state, MassType mass);
  SystemMatrix& hessian() { return hessian_; }
  // M x for positions-like (#V x 3) input.
  void MultiplyMass(const RowMatX3d& in, RowMatX3d* out) const;
  // Adds scale * M into the Hessian values.
  void AddMass(double scale, SystemMatrix* h) const;
  const std::vector<double>& mass_values() const { return mass_values_; }
  const Eigen::VectorXd& lumped_masses() const { return lumped_masses_; }
  MassType mass_type() const { return mass_type_; }

 private:
  std::uint64_t version_ = 0;
  MassType mass_type_ = MassType::kLumped;
  SystemMatrix hessian_;
  SparseMatrixd mass_matrix_;  // consistent mass (same pattern as hessian_)
  std::vector<double> mass_values_;
  Eigen::VectorXd lumped_masses_;  // (#V) kg
};

class ImplicitEulerIntegrator {
 public:
  explicit ImplicitEulerIntegrator(const ImplicitEulerOptions& options);

  // Advances the state by options.dt_s. `elastic` is the body's elasticity
  // (Rayleigh damping uses its stiffness), `terms` the other energies
  // (springs, gravity, point forces). Fixed vertices keep their position
  // and get zero velocity. On kLinearSolveFailed the state is left unchanged.
  StepSummary Step(MechanicalState* state, CorotationalElasticity* elastic,
                   const std::vector<EnergyTerm*>& terms);

  // Kinetic energy 1/2 v^T M v in uJ, with the integrator's mass type.
  double KineticEnergy(const MechanicalState& state);
  const ImplicitEulerOptions& options() const { return options_; }
  LinearSolver& linear_solver() { return *solver_; }

 private:
  StepSummary SubStep(MechanicalState* state, CorotationalElasticity* elastic,
                      const std::vector<EnergyTerm*>& terms, double h);

  ImplicitEulerOptions options_;
  std::unique_ptr<LinearSolver> solver_;
  SystemCache cache_;
  SparseMatrixd k0_matrix_;  // elastic stiffness at x_n (damping), H's pattern
  Eigen::VectorXd rhs_, solution_;
  RowMatX3d gradient_, inertia_, tmp_, trial_, line_start_;
  std::vector<std::pair<int, Eigen::Matrix3d>> frozen_;
  // WarmStart::kExtrapolate: v_{n-1}, and the v_n this integrator wrote (the
  // extrapolation is skipped when the caller changed the velocities since).
  RowMatX3d previous_velocity_, written_velocity_;
};

struct StaticSolverOptions {
  int max_iterations = 50;            // Newton iterations; default 50
  double tolerance_mm = 1e-9;         // stop when max |dx| (mm) is below; default 1e-9
  bool line_search = true;            // backtrack on the energy; default true
  LinearSolverOptions linear_solver;  // default CHOLMOD
  void Check() const;
};

// Minimises E(x) over the free vertices (fixed ones stay where they are):
// Newton with the stiffness-warping Hessian and an Armijo backtracking line
// search on the energy (rotations recomputed at every trial point).
class StaticSolver {
 public:
  explicit StaticSolver(const StaticSolverOptions& options);
  StepSummary Solve(MechanicalState* state, CorotationalElasticity* elastic,
                    const std::vector<EnergyTerm*>& terms);

 private:
  StaticSolverOptions options_;
  std::unique_ptr<LinearSolver> solver_;
  SystemCache cache_;
};

}  // namespace arreg::mechanics
