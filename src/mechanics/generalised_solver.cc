#include "mechanics/generalised_solver.h"

#include <Eigen/Eigenvalues>
#include <chrono>
#include <cmath>

#include "core/error.h"
#include "mechanics/so3.h"

namespace arreg::mechanics {

namespace {

using Clock = std::chrono::steady_clock;
double Ms(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

// The terms of a solve as one list (elastic first).
std::vector<GeneralisedEnergyTerm*> Concat(const std::vector<GeneralisedEnergyTerm*>& a,
                                           const std::vector<GeneralisedEnergyTerm*>& b) {
  std::vector<GeneralisedEnergyTerm*> all = a;
  all.insert(all.end(), b.begin(), b.end());
  return all;
}

void UpdateAll(const GeneralisedState& state, const std::vector<GeneralisedEnergyTerm*>& terms) {
  for (GeneralisedEnergyTerm* t : terms) t->Update(state);
}

double EnergyOf(const GeneralisedState& state, const std::vector<GeneralisedEnergyTerm*>& terms) {
  double e = 0;
  for (const GeneralisedEnergyTerm* t : terms) e += t->Value(state);
  return e;
}

void GradientOf(const GeneralisedState& state, const std::vector<GeneralisedEnergyTerm*>& terms,
                Eigen::VectorXd* g) {
  g->setZero(state.num_dofs());
  for (const GeneralisedEnergyTerm* t : terms) t->AddGradient(state, g);
}

void ZeroFixed(const std::vector<char>& fixed, Eigen::VectorXd* v) {
  for (int i = 0; i < v->size(); ++i)
    if (fixed[i]) (*v)[i] = 0.0;
}

// Max |dx| and max |dtheta| component of an increment.
void IncrementSizes(const GeneralisedState& state, const Eigen::VectorXd& d, double* mm,
                    double* rad) {
  *mm = 0;
  *rad = 0;
  for (int n = 0; n < state.num_nodes(); ++n) {
    const int o = state.dof_offset(n);
    *mm = std::max(*mm, d.segment<3>(o).cwiseAbs().maxCoeff());
    if (state.is_frame(n)) *rad = std::max(*rad, d.segment<3>(o + 3).cwiseAbs().maxCoeff());
  }
}

// Positions and rotations of a state, to return to the start of a line search.
struct Configuration {
  RowMatX3d positions;
  std::vector<Eigen::Matrix3d> rotations;
  void Save(const GeneralisedState& s) {
    positions = s.positions();
    rotations.resize(s.num_nodes());
    for (int n = 0; n < s.num_nodes(); ++n) rotations[n] = s.rotation(n);
  }
  void Restore(GeneralisedState* s) const {
    s->mutable_positions() = positions;
    for (int n = 0; n < s->num_nodes(); ++n)
      if (s->is_frame(n)) s->mutable_rotation(n) = rotations[n];
  }
};

StepStatus FromLinearSolve(const LinearSolverSummary& s) {
  return s.status == LinearSolverStatus::kConverged ||
                 s.status == LinearSolverStatus::kMaxIterations
             ? StepStatus::kConverged
             : StepStatus::kLinearSolveFailed;
}

void CountSolve(const LinearSolverSummary& ls, GeneralisedSummary* s) {
  s->linear_iterations += ls.iterations;
  ++s->linear_solves;
  s->factorizations += ls.numeric_factorization ? 1 : 0;
  ++s->newton_iterations;
}

std::string SolveFailure(const LinearSolverSummary& ls) {
  return std::string("linear solver: ") + LinearSolverStatusName(ls.status) +
         (ls.message.empty() ? "" : " (" + ls.message + ")");
}

// Halvings of an implicit step's Newton increment at most (1/64 of it), and the
// increment below which it is taken whole (Phi's round-off decides the test
// there): the values of ImplicitEulerIntegrator, so that tet-only steps agree.
constexpr int kStepLineSearchCuts = 6;
constexpr double kStepLineSearchMinMm = 1e-6;
// [rad] The same for rotation increments: 1e-6 mm at 100 mm from the node.
constexpr double kStepLineSearchMinRad = 1e-8;
// The static solver's halvings (1/4096 of the increment at most).
constexpr int kStaticLineSearchCuts = 12;

}  // namespace

void GeneralisedStaticOptions::Check() const {
  ARREG_CHECK_INPUT(max_iterations >= 1, "", "generalised_static.max_iterations",
                    "must be >= 1, got ", max_iterations);
  ARREG_CHECK_INPUT(std::isfinite(tolerance_mm) && tolerance_mm > 0, "",
                    "generalised_static.tolerance_mm", "must be > 0, got ", tolerance_mm);
  ARREG_CHECK_INPUT(std::isfinite(tolerance_rad) && tolerance_rad > 0, "",
                    "generalised_static.tolerance_rad", "must be > 0, got ", tolerance_rad);
  linear_solver.Check();
}

void GeneralisedImplicitEulerOptions::Check() const {
  ARREG_CHECK_INPUT(std::isfinite(dt_s) && dt_s > 0, "", "generalised_euler.dt_s",
                    "must be > 0, got ", dt_s);
  ARREG_CHECK_INPUT(substeps >= 1, "", "generalised_euler.substeps", "must be >= 1, got ",
                    substeps);
  ARREG_CHECK_INPUT(max_newton_iterations >= 1, "", "generalised_euler.max_newton_iterations",
                    "must be >= 1, got ", max_newton_iterations);
  ARREG_CHECK_INPUT(std::isfinite(newton_tolerance_mm) && newton_tolerance_mm > 0, "",
                    "generalised_euler.newton_tolerance_mm", "must be > 0, got ",
                    newton_tolerance_mm);
  ARREG_CHECK_INPUT(std::isfinite(newton_tolerance_rad) && newton_tolerance_rad > 0, "",
                    "generalised_euler.newton_tolerance_rad", "must be > 0, got ",
                    newton_tolerance_rad);
  ARREG_CHECK_INPUT(std::isfinite(rayleigh_mass_alpha) && rayleigh_mass_alpha >= 0, "",
                    "generalised_euler.rayleigh_mass_alpha", "must be >= 0, got ",
                    rayleigh_mass_alpha);
  ARREG_CHECK_INPUT(std::isfinite(rayleigh_stiffness_beta) && rayleigh_stiffness_beta >= 0, "",
                    "generalised_euler.rayleigh_stiffness_beta", "must be >= 0, got ",
                    rayleigh_stiffness_beta);
  linear_solver.Check();
}

// ---------------------------------------------------------------------------

GeneralisedStaticSolver::GeneralisedStaticSolver(const GeneralisedStaticOptions& options)
    : options_(options) {
  options_.Check();
  solver_ = LinearSolver::Create(options_.linear_solver);
}

GeneralisedSummary GeneralisedStaticSolver::Solve(
    GeneralisedState* state, const std::vector<GeneralisedEnergyTerm*>& terms) {
  GeneralisedSummary summary;
  if (state->num_dofs() == 0) return summary;  // nothing to solve (converged)
  const auto t_start = Clock::now();
  summary.pattern_rebuilt = system_.Refresh(*state, terms);
  if (summary.pattern_rebuilt) solver_->PatternChanged();
  const std::vector<char> fixed = state->FixedDofMask();
  Eigen::VectorXd g, rhs, dq;
  Configuration start;
  summary.status = StepStatus::kMaxIterations;
  UpdateAll(*state, terms);
  double energy = EnergyOf(*state, terms);
  for (int it = 0; it < options_.max_iterations; ++it) {
    auto t = Clock::now();
    GradientOf(*state, terms, &g);
    ZeroFixed(fixed, &g);
    rhs = -g;
    system_.SetZero();
    for (const GeneralisedEnergyTerm* term : terms) term->AddHessian(*state, 1.0, &system_);
    system_.ApplyDirichlet(fixed);
    solver_->ValuesChanged();
    summary.assembly_ms += Ms(t);
    t = Clock::now();
    dq.setZero(rhs.size());
    const LinearSolverSummary ls = solver_->Solve(system_.matrix(), rhs, &dq);
    summary.solve_ms += Ms(t);
    CountSolve(ls, &summary);
    if (FromLinearSolve(ls) != StepStatus::kConverged) {
      summary.status = StepStatus::kLinearSolveFailed;
      summary.message = SolveFailure(ls);
      break;
    }
    // Armijo backtracking on the energy, terms updated at every trial point.
    t = Clock::now();
    start.Save(*state);
    const double slope = -rhs.dot(dq);  // grad E . dq (< 0 for a descent direction)
    double step = 1.0;
    const int cuts = options_.line_search ? kStaticLineSearchCuts : 0;
    for (int cut = 0;; ++cut) {
      start.Restore(state);
      state->ApplyIncrement(step * dq);
      UpdateAll(*state, terms);
      const double e = EnergyOf(*state, terms);
      // With an allowance for round-off in the summed energy near the solution;
      // the smallest step is taken rather than none.
      if (e <= energy + 1e-4 * step * slope + 1e-12 * std::abs(energy) || cut >= cuts) {
        energy = e;
        break;
      }
      step *= 0.5;
      ++summary.line_search_cuts;
    }
    summary.assembly_ms += Ms(t);
    // Converged when the full Newton increment is small (a short line-search
    // step alone says nothing about the distance to the solution).
    IncrementSizes(*state, dq, &summary.last_increment_mm, &summary.last_increment_rad);
    if (summary.last_increment_mm < options_.tolerance_mm &&
        summary.last_increment_rad < options_.tolerance_rad) {
      summary.status = StepStatus::kConverged;
      break;
    }
  }
  summary.energy = energy;
  state->mutable_velocities().setZero();
  state->mutable_angular_velocities().setZero();
  summary.total_ms = Ms(t_start);
  return summary;
}

// ---------------------------------------------------------------------------

GeneralisedImplicitEuler::GeneralisedImplicitEuler(const GeneralisedImplicitEulerOptions& options)
    : options_(options) {
  options_.Check();
  solver_ = LinearSolver::Create(options_.linear_solver);
}

GeneralisedSummary GeneralisedImplicitEuler::Step(
    GeneralisedState* state, const std::vector<GeneralisedEnergyTerm*>& elastic,
    const std::vector<GeneralisedEnergyTerm*>& others, const std::vector<NodeInertia>& inertia) {
  ARREG_CHECK_INPUT(static_cast<int>(inertia.size()) == state->num_nodes(), "",
                    "generalised step inertia", inertia.size(), " entries for ", state->num_nodes(),
                    " nodes");
  GeneralisedSummary total;
  if (state->num_dofs() == 0) return total;  // nothing moves
  const auto t0 = Clock::now();
  const double h = options_.dt_s / options_.substeps;
  for (int s = 0; s < options_.substeps; ++s) {
    const GeneralisedSummary sub = SubStep(state, elastic, others, inertia, h);
    total.last_increment_rad = sub.last_increment_rad;
    if (!AccumulateSubStep(sub, &total)) break;
  }
  total.total_ms = Ms(t0);
  return total;
}

GeneralisedSummary GeneralisedImplicitEuler::SubStep(
    GeneralisedState* state, const std::vector<GeneralisedEnergyTerm*>& elastic,
    const std::vector<GeneralisedEnergyTerm*>& others, const std::vector<NodeInertia>& inertia,
    double h) {
  GeneralisedSummary summary;
  auto t = Clock::now();
  const std::vector<GeneralisedEnergyTerm*> terms = Concat(elastic, others);
  summary.pattern_rebuilt = system_.Refresh(*state, terms);
  if (summary.pattern_rebuilt) solver_->PatternChanged();
  const int nn = state->num_nodes();
  const std::vector<char> fixed = state->FixedDofMask();
  Configuration start;
  start.Save(*state);
  const RowMatX3d v0 = state->velocities();
  const RowMatX3d w0 = state->angular_velocities();
  // Spatial rotational inertia at the step's start, and the angular momenta L_n.
  std::vector<Eigen::Matrix3d> inertia_n(nn, Eigen::Matrix3d::Zero());
  for (int n = 0; n < nn; ++n)
    if (state->is_frame(n))
      inertia_n[n] = start.rotations[n] * inertia[n].body_inertia * start.rotations[n].transpose();
  const double alpha = options_.rayleigh_mass_alpha, beta = options_.rayleigh_stiffness_beta;
  const double mass_scale = 1.0 / (h * h) + alpha / h;
  const bool one_step = options_.newton_mode == NewtonMode::kOneStep;
  const int max_it = one_step ? 1 : options_.max_newton_iterations;
  const bool keep_k0 = beta > 0 && (max_it > 1 || options_.line_search);
  Eigen::VectorXd q(state->num_dofs());  // (x - x_n, Log(R R_n^T)) per node
  std::vector<Eigen::Matrix3d> jinv(nn, Eigen::Matrix3d::Identity());  // J_l^-1(theta)
  // Log(R R_n^T) per frame node, composed from the increments applied in this step rather
  // than taken from the matrices: the first increment d gives theta = d exactly, where the
  // log of a rotation of angle t loses the digits below 1e-16 / t (the angular momentum of a
  // free body would drift by 1e-13 per step).
  std::vector<Eigen::Vector3d> theta(nn, Eigen::Vector3d::Zero()), theta_line(nn);
  const auto advance = [&](double step, const Eigen::VectorXd& increment) {
    state->ApplyIncrement(step * increment);
    for (int n = 0; n < nn; ++n) {
      if (!state->is_frame(n)) continue;
      const Eigen::Vector3d d = step * increment.segment<3>(state->dof_offset(n) + 3);
      theta[n] = theta_line[n].squaredNorm() == 0 ? d : LogSO3(ExpSO3(d) * ExpSO3(theta_line[n]));
    }
  };
  // q, and J_l^-1 where the gradient and Hessian need it (Phi alone does not), at the
  // current configuration.
  const auto step_coordinates = [&](bool jacobians) {
    for (int n = 0; n < nn; ++n) {
      const int o = state->dof_offset(n);
      q.segment<3>(o) = (state->position(n) - start.positions.row(n).transpose());
      if (!state->is_frame(n)) continue;
      q.segment<3>(o + 3) = theta[n];
      if (jacobians) jinv[n] = LeftJacobianInverseSO3(theta[n]);
    }
  };
  // Phi at the current configuration (terms updated there); the damping terms vanish at
  // the step's start.
  const auto potential = [&](bool at_start) {
    step_coordinates(false);
    double phi = 0;
    for (int n = 0; n < nn; ++n) {
      const int o = state->dof_offset(n);
      const Eigen::Vector3d dx = q.segment<3>(o);
      phi += 0.5 * inertia[n].mass_kg / (h * h) * (dx - h * v0.row(n).transpose()).squaredNorm();
      if (!at_start && alpha > 0) phi += 0.5 * alpha / h * inertia[n].mass_kg * dx.squaredNorm();
      if (!state->is_frame(n)) continue;
      const Eigen::Vector3d rot = q.segment<3>(o + 3);
      const Eigen::Vector3d p = rot - h * w0.row(n).transpose();
      phi += 0.5 / (h * h) * p.dot(inertia_n[n] * p);
      if (!at_start && alpha > 0) phi += 0.5 * alpha / h * rot.dot(inertia_n[n] * rot);
    }
    if (!at_start && beta > 0) {
      const Eigen::Map<const SparseMatrixd> k0(system_.num_dofs(), system_.num_dofs(),
                                               system_.nonzeros(), system_.matrix().outerIndexPtr(),
                                               system_.matrix().innerIndexPtr(), k0_values_.data());
      phi += 0.5 * beta / h * q.dot(k0 * q);
    }
    return phi + EnergyOf(*state, terms);
  };

  summary.assembly_ms += Ms(t);
  // After a line search the terms are updated at the point it accepted, and Phi there is
  // known: the next Newton iteration starts from both.
  bool terms_current = false;
  double phi_current = 0;
  for (int it = 0; it < max_it; ++it) {
    t = Clock::now();
    if (!terms_current) UpdateAll(*state, terms);
    // grad Phi: grad E + inertia + damping (rotation rows through J_l^-T).
    GradientOf(*state, terms, &gradient_);
    if (it > 0) {
      step_coordinates(true);
    } else {
      q.setZero();
      std::fill(jinv.begin(), jinv.end(), Eigen::Matrix3d::Identity());
    }
    Eigen::VectorXd damping;
    if (beta > 0 && it > 0) {
      const Eigen::Map<const SparseMatrixd> k0(system_.num_dofs(), system_.num_dofs(),
                                               system_.nonzeros(), system_.matrix().outerIndexPtr(),
                                               system_.matrix().innerIndexPtr(), k0_values_.data());
      damping = (beta / h) * (k0 * q);
    }
    for (int n = 0; n < nn; ++n) {
      const int o = state->dof_offset(n);
      const Eigen::Vector3d dx = q.segment<3>(o);
      gradient_.segment<3>(o) +=
          inertia[n].mass_kg * ((dx - h * v0.row(n).transpose()) / (h * h) + (alpha / h) * dx);
      if (damping.size()) gradient_.segment<3>(o) += damping.segment<3>(o);
      if (!state->is_frame(n)) continue;
      const Eigen::Vector3d rot = q.segment<3>(o + 3);
      Eigen::Vector3d r =
          inertia_n[n] * ((rot - h * w0.row(n).transpose()) / (h * h) + (alpha / h) * rot);
      if (damping.size()) r += damping.segment<3>(o + 3);
      gradient_.segment<3>(o + 3) += jinv[n].transpose() * r;
    }
    ZeroFixed(fixed, &gradient_);
    rhs_ = -gradient_;

    system_.SetZero();
    for (const GeneralisedEnergyTerm* term : elastic) term->AddHessian(*state, 1.0, &system_);
    if (beta > 0) {
      double* v = system_.values();
      const int nz = system_.nonzeros();
      if (it == 0) {
        if (keep_k0) k0_values_ = Eigen::Map<const Eigen::VectorXd>(v, nz);
        for (int k = 0; k < nz; ++k) v[k] *= 1.0 + beta / h;
      } else {
        for (int k = 0; k < nz; ++k) v[k] += (beta / h) * k0_values_[k];
      }
    }
    for (int n = 0; n < nn; ++n) {
      const int d = state->node_dofs(n);
      Eigen::Matrix<double, 6, 6> block = Eigen::Matrix<double, 6, 6>::Zero();
      block.topLeftCorner<3, 3>().diagonal().setConstant(inertia[n].mass_kg);
      if (d == 6) block.bottomRightCorner<3, 3>() = jinv[n].transpose() * inertia_n[n] * jinv[n];
      system_.AddBlock(n, n, block.topLeftCorner(d, d), mass_scale);
    }
    for (const GeneralisedEnergyTerm* term : others) term->AddHessian(*state, 1.0, &system_);
    system_.ApplyDirichlet(fixed);
    solver_->ValuesChanged();
    // Initial guess of an iterative solver: the first increment h (v_n, omega_n).
    solution_.setZero(rhs_.size());
    if (it == 0) {
      for (int n = 0; n < nn; ++n) {
        const int o = state->dof_offset(n);
        solution_.segment<3>(o) = h * v0.row(n).transpose();
        if (state->is_frame(n)) solution_.segment<3>(o + 3) = h * w0.row(n).transpose();
      }
      ZeroFixed(fixed, &solution_);
    }
    summary.assembly_ms += Ms(t);

    t = Clock::now();
    const LinearSolverSummary ls = solver_->Solve(system_.matrix(), rhs_, &solution_);
    summary.solve_ms += Ms(t);
    CountSolve(ls, &summary);
    summary.status = FromLinearSolve(ls);
    if (summary.status != StepStatus::kConverged) {
      summary.message = SolveFailure(ls);
      start.Restore(state);
      return summary;
    }
    IncrementSizes(*state, solution_, &summary.last_increment_mm, &summary.last_increment_rad);
    // Armijo backtracking on Phi; skipped when the increment is no descent direction (an
    // inexact iterative solve) and when it is at round-off size.
    const double slope = -rhs_.dot(solution_);
    t = Clock::now();
    if (options_.line_search && slope < 0.0 &&
        (summary.last_increment_mm > kStepLineSearchMinMm ||
         summary.last_increment_rad > kStepLineSearchMinRad)) {
      Configuration line_start;
      line_start.Save(*state);
      theta_line = theta;
      // The terms are updated at the line start (above, or by the last line search).
      const double phi0 = terms_current ? phi_current : potential(it == 0);
      double step = 1.0;
      for (int cut = 0;; ++cut) {
        line_start.Restore(state);
        advance(step, solution_);
        UpdateAll(*state, terms);
        phi_current = potential(false);
        if (phi_current <= phi0 + 1e-4 * step * slope + 1e-10 * std::abs(phi0) ||
            cut == kStepLineSearchCuts)
          break;
        step *= 0.5;
        ++summary.line_search_cuts;
      }
      terms_current = true;
    } else {
      theta_line = theta;
      advance(1.0, solution_);
      terms_current = false;
    }
    summary.assembly_ms += Ms(t);
    if (!one_step && summary.last_increment_mm < options_.newton_tolerance_mm &&
        summary.last_increment_rad < options_.newton_tolerance_rad)
      break;
    if (options_.newton_mode == NewtonMode::kFullNewton && it + 1 == max_it)
      summary.status = StepStatus::kMaxIterations;
  }

  // Velocities: v = (x - x_n)/h; omega from the angular momentum L_{n+1} = I_n theta / h.
  step_coordinates(false);
  RowMatX3d& v = state->mutable_velocities();
  RowMatX3d& w = state->mutable_angular_velocities();
  for (int n = 0; n < nn; ++n) {
    const int o = state->dof_offset(n);
    v.row(n) = q.segment<3>(o).transpose() / h;
    if (state->fixed_translation(n)) v.row(n).setZero();
    if (!state->is_frame(n)) continue;
    if (state->fixed_rotation(n)) {
      w.row(n).setZero();
      continue;
    }
    const Eigen::Matrix3d& R = state->rotation(n);
    const Eigen::Vector3d momentum_body = R.transpose() * (inertia_n[n] * theta[n] / h);
    const Eigen::Vector3d step_body = R.transpose() * theta[n] / h;
    const Eigen::Matrix3d& body = inertia[n].body_inertia;
    Eigen::Vector3d omega_body = Eigen::Vector3d::Zero();
    const double trace = body.trace();
    if (trace > 0 && body.determinant() > 1e-9 * trace * trace * trace) {
      omega_body = body.inverse() * momentum_body;  // the common case: closed-form 3x3 inverse
    } else {
      const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(body);
      const double largest = eig.eigenvalues().cwiseAbs().maxCoeff();
      for (int k = 0; k < 3; ++k) {
        const Eigen::Vector3d u = eig.eigenvectors().col(k);
        const double lambda = eig.eigenvalues()[k];
        // Body axes whose inertia is zero to rounding carry no momentum.
        if (lambda > 1e-12 * largest && largest > 0)
          omega_body += (u.dot(momentum_body) / lambda) * u;
        else
          omega_body += u.dot(step_body) * u;
      }
    }
    w.row(n) = (R * omega_body).transpose();
  }
  return summary;
}

// ---------------------------------------------------------------------------

double GeneralisedKineticEnergy(const GeneralisedState& state,
                                const std::vector<NodeInertia>& inertia) {
  double e = 0;
  for (int n = 0; n < state.num_nodes(); ++n) {
    e += 0.5 * inertia[n].mass_kg * state.velocities().row(n).squaredNorm();
    if (!state.is_frame(n)) continue;
    const Eigen::Vector3d w = state.angular_velocities().row(n).transpose();
    const Eigen::Matrix3d& R = state.rotation(n);
    e += 0.5 * w.dot(R * inertia[n].body_inertia * R.transpose() * w);
  }
  return e;
}

Eigen::Vector3d GeneralisedLinearMomentum(const GeneralisedState& state,
                                          const std::vector<NodeInertia>& inertia) {
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  for (int n = 0; n < state.num_nodes(); ++n)
    p += inertia[n].mass_kg * state.velocities().row(n).transpose();
  return p;
}

Eigen::Vector3d GeneralisedAngularMomentum(const GeneralisedState& state,
                                           const std::vector<NodeInertia>& inertia) {
  Eigen::Vector3d l = Eigen::Vector3d::Zero();
  for (int n = 0; n < state.num_nodes(); ++n) {
    l += inertia[n].mass_kg *
         state.position(n).cross(Eigen::Vector3d(state.velocities().row(n).transpose()));
    if (!state.is_frame(n)) continue;
    const Eigen::Matrix3d& R = state.rotation(n);
    l +=
        R * inertia[n].body_inertia * R.transpose() * state.angular_velocities().row(n).transpose();
  }
  return l;
}

}  // namespace arreg::mechanics
