#include "mechanics/integrator.h"

#include <chrono>
#include <cmath>

#include "core/error.h"

namespace arreg::mechanics {

namespace {

using Clock = std::chrono::steady_clock;
double MsSince(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

Eigen::Map<Eigen::VectorXd> Flat(RowMatX3d* m) { return {m->data(), m->size()}; }
Eigen::Map<const Eigen::VectorXd> Flat(const RowMatX3d& m) { return {m.data(), m.size()}; }

void ZeroFixedRows(const std::vector<char>& fixed, RowMatX3d* m) {
  for (int v = 0; v < static_cast<int>(fixed.size()); ++v)
    if (fixed[v]) m->row(v).setZero();
}

void UpdateTerms(const MechanicalState& state, const RowMatX3d& x, CorotationalElasticity* elastic,
                 const std::vector<EnergyTerm*>& terms) {
  elastic->Update(state, x);
  for (EnergyTerm* t : terms) t->Update(state, x);
}

double TotalEnergy(const MechanicalState& state, const RowMatX3d& x,
                   const CorotationalElasticity& elastic, const std::vector<EnergyTerm*>& terms) {
  double e = elastic.Value(state, x);
  for (const EnergyTerm* t : terms) e += t->Value(state, x);
  return e;
}

void TotalGradient(const MechanicalState& state, const RowMatX3d& x,
                   const CorotationalElasticity& elastic, const std::vector<EnergyTerm*>& terms,
                   RowMatX3d* g) {
  g->setZero(state.num_vertices(), 3);
  elastic.AddGradient(state, x, g);
  for (const EnergyTerm* t : terms) t->AddGradient(state, x, g);
}

// Halvings of a Newton increment by the integrator's line search at most (the
// shortest step is 1/64 of it).
constexpr int kMaxLineSearchCuts = 6;
// [mm] Newton increments below this are taken whole: near rest, Phi and its slope
// along such an increment are at the round-off of the summed energies (1e-25 uJ
// against slopes of 1e-25 on a 60 mm box at rest).
constexpr double kLineSearchMinIncrementMm = 1e-6;

StepStatus FromLinear(const LinearSolverSummary& s) {
  return s.status == LinearSolverStatus::kConverged ||
                 s.status == LinearSolverStatus::kMaxIterations
             ? StepStatus::kConverged
             : StepStatus::kLinearSolveFailed;
}

}  // namespace

LinearSolverOptions DefaultStepSolverOptions() {
  LinearSolverOptions options;
  options.relative_tolerance = 1e-3;
  return options;
}

const char* StepStatusName(StepStatus status) {
  switch (status) {
    case StepStatus::kConverged:
      return "converged";
    case StepStatus::kMaxIterations:
      return "max-iterations";
    case StepStatus::kLinearSolveFailed:
      return "linear-solve-failed";
  }
  return "?";
}

void ImplicitEulerOptions::Check() const {
  ARREG_CHECK_INPUT(std::isfinite(dt_s) && dt_s > 0, "", "integrator.dt_s", "must be > 0, got ",
                    dt_s);
  ARREG_CHECK_INPUT(substeps >= 1, "", "integrator.substeps", "must be >= 1, got ", substeps);
  ARREG_CHECK_INPUT(max_newton_iterations >= 1, "", "integrator.max_newton_iterations",
                    "must be >= 1, got ", max_newton_iterations);
  ARREG_CHECK_INPUT(std::isfinite(newton_tolerance_mm) && newton_tolerance_mm > 0, "",
                    "integrator.newton_tolerance_mm", "must be > 0, got ", newton_tolerance_mm);
  ARREG_CHECK_INPUT(std::isfinite(rayleigh_mass_alpha) && rayleigh_mass_alpha >= 0, "",
                    "integrator.rayleigh_mass_alpha", "must be >= 0, got ", rayleigh_mass_alpha);
  ARREG_CHECK_INPUT(std::isfinite(rayleigh_stiffness_beta) && rayleigh_stiffness_beta >= 0, "",
                    "integrator.rayleigh_stiffness_beta", "must be >= 0, got ",
                    rayleigh_stiffness_beta);
  linear_solver.Check();
}

void StaticSolverOptions::Check() const {
  ARREG_CHECK_INPUT(max_iterations >= 1, "", "static_solver.max_iterations", "must be >= 1, got ",
                    max_iterations);
  ARREG_CHECK_INPUT(std::isfinite(tolerance_mm) && tolerance_mm > 0, "",
                    "static_solver.tolerance_mm", "must be > 0, got ", tolerance_mm);
  linear_solver.Check();
}

bool SystemCache::Refresh(const MechanicalState& state, MassType mass) {
  if (version_ == state.topology_version() && mass == mass_type_ &&
      hessian_.num_vertices() == state.num_vertices())
    return false;
  version_ = state.topology_version();
  mass_type_ = mass;
  hessian_ = SystemMatrix(state.num_vertices(), state.tetrahedra());
  lumped_masses_ = state.LumpedVertexMasses();
  if (mass == MassType::kConsistent) {
    // Consistent mass of a linear tetrahedron: m/20 (1 + delta_ab) I per block.
    hessian_.SetZero();
    for (int t = 0; t < state.num_tetrahedra(); ++t) {
      const double m = state.rest_data(t).mass_kg;
      for (int a = 0; a < 4; ++a)
        for (int b = 0; b < 4; ++b)
          hessian_.AddElementBlock(t, a, b,
                                   Eigen::Matrix3d::Identity() * (m / 20.0 * (a == b ? 2.0 : 1.0)));
    }
    mass_values_.assign(hessian_.values(), hessian_.values() + hessian_.nonzeros());
    mass_matrix_ = hessian_.matrix();
    hessian_.SetZero();
  } else {
    mass_values_.clear();
    mass_matrix_.resize(0, 0);
  }
  return true;
}

void SystemCache::MultiplyMass(const RowMatX3d& in, RowMatX3d* out) const {
  if (mass_type_ == MassType::kConsistent) {
    out->resize(in.rows(), 3);
    Flat(out) = mass_matrix_ * Flat(in);
  } else {
    *out = in.array().colwise() * lumped_masses_.array();
  }
}

void SystemCache::AddMass(double scale, SystemMatrix* h) const {
  if (mass_type_ == MassType::kConsistent) {
    double* v = h->values();
    for (size_t k = 0; k < mass_values_.size(); ++k) v[k] += scale * mass_values_[k];
  } else {
    for (int i = 0; i < lumped_masses_.size(); ++i)
      h->AddToVertexDiagonal(i, scale * lumped_masses_[i]);
  }
}

ImplicitEulerIntegrator::ImplicitEulerIntegrator(const ImplicitEulerOptions& options)
    : options_(options) {
  options_.Check();
  solver_ = LinearSolver::Create(options_.linear_solver);
}

double ImplicitEulerIntegrator::KineticEnergy(const MechanicalState& state) {
  if (cache_.Refresh(state, options_.mass)) solver_->PatternChanged();
  cache_.MultiplyMass(state.velocities(), &tmp_);
  return 0.5 * Flat(state.velocities()).dot(Flat(tmp_));
}

StepSummary ImplicitEulerIntegrator::Step(MechanicalState* state, CorotationalElasticity* elastic,
                                          const std::vector<EnergyTerm*>& terms) {
  StepSummary total;
  const auto t0 = Clock::now();
  const double h = options_.dt_s / options_.substeps;
  for (int s = 0; s < options_.substeps; ++s) {
    const StepSummary sub = SubStep(state, elastic, terms, h);
    total.inverted_elements = sub.inverted_elements;
    total.rotation_ms += sub.rotation_ms;
    if (!AccumulateSubStep(sub, &total)) break;
  }
  total.total_ms = MsSince(t0);
  return total;
}

StepSummary ImplicitEulerIntegrator::SubStep(MechanicalState* state,
                                             CorotationalElasticity* elastic,
                                             const std::vector<EnergyTerm*>& terms, double h) {
  StepSummary summary;
  auto t = Clock::now();
  summary.pattern_rebuilt = cache_.Refresh(*state, options_.mass);
  if (summary.pattern_rebuilt) {
    solver_->PatternChanged();
    previous_velocity_.resize(0, 3);
    written_velocity_.resize(0, 3);
  }
  SystemMatrix& H = cache_.hessian();
  const std::vector<char>& fixed = state->fixed_mask();
  const RowMatX3d x0 = state->positions();
  const RowMatX3d& v0 = state->velocities();
  RowMatX3d y = x0;
  const double alpha = options_.rayleigh_mass_alpha, beta = options_.rayleigh_stiffness_beta;
  const double mass_scale = 1.0 / (h * h) + alpha / h;
  const bool one_step = options_.newton_mode == NewtonMode::kOneStep;
  const int max_it = one_step ? 1 : options_.max_newton_iterations;
  summary.assembly_ms += MsSince(t);

  // Phi(z): the inertia and damping terms about x_n (K0, the elastic stiffness at x_n, in
  // k0_matrix_) plus the energies, whose terms must have been updated at z. The damping terms
  // vanish at z = x_n.
  const auto potential = [&](const RowMatX3d& z, bool at_start) {
    tmp_ = z - x0;
    trial_ = tmp_ - h * v0;
    cache_.MultiplyMass(trial_, &inertia_);
    double phi = 0.5 / (h * h) * Flat(trial_).dot(Flat(inertia_));
    if (!at_start && alpha > 0) {
      cache_.MultiplyMass(tmp_, &inertia_);
      phi += 0.5 * alpha / h * Flat(tmp_).dot(Flat(inertia_));
    }
    if (!at_start && beta > 0) phi += 0.5 * beta / h * Flat(tmp_).dot(k0_matrix_ * Flat(tmp_));
    return phi + TotalEnergy(*state, z, *elastic, terms);
  };
  const bool keep_k0 = beta > 0 && (max_it > 1 || options_.line_search);

  for (int it = 0; it < max_it; ++it) {
    t = Clock::now();
    UpdateTerms(*state, y, elastic, terms);
    summary.inverted_elements = elastic->num_inverted();
    summary.rotation_ms += MsSince(t);

    t = Clock::now();
    // grad Phi = M (y - x_n - h v_n)/h^2 + D (y - x_n)/h + grad E(y).
    TotalGradient(*state, y, *elastic, terms, &gradient_);
    tmp_ = y - x0;
    if (it > 0) {
      cache_.MultiplyMass((tmp_ - h * v0) / (h * h) + (alpha / h) * tmp_, &inertia_);
      if (beta > 0) Flat(&inertia_) += (beta / h) * (k0_matrix_ * Flat(tmp_));
    } else {
      cache_.MultiplyMass(-v0 / h, &inertia_);
    }
    gradient_ += inertia_;
    ZeroFixedRows(fixed, &gradient_);
    rhs_ = -Flat(gradient_);

    H.SetZero();
    elastic->AddHessian(*state, y, 1.0, &H);
    if (beta > 0) {
      double* v = H.values();
      if (it == 0) {
        // K0 is H itself here; only later Newton iterations and the line search need a copy
        // of it (the one-step mode without line search saves a matrix copy per step).
        if (keep_k0) k0_matrix_ = H.matrix();
        for (int k = 0; k < H.nonzeros(); ++k) v[k] *= 1.0 + beta / h;
      } else {
        const double* k0 = k0_matrix_.valuePtr();
        for (int k = 0; k < H.nonzeros(); ++k) v[k] += (beta / h) * k0[k];
      }
    }
    cache_.AddMass(mass_scale, &H);
    for (const EnergyTerm* term : terms) term->AddHessian(*state, y, 1.0, &H);
    H.ApplyDirichlet(fixed);
    solver_->ValuesChanged();
    // Warm start of the first increment y - x_n: h v_n, or h (2 v_n - v_{n-1})
    // (on the benchmark's travelling wave the initial residual drops 10x).
    if (it == 0) {
      if (options_.warm_start == WarmStart::kExtrapolate &&
          previous_velocity_.rows() == v0.rows() && written_velocity_ == v0)
        tmp_ = h * (2.0 * v0 - previous_velocity_);
      else
        tmp_ = h * v0;
      ZeroFixedRows(fixed, &tmp_);
      solution_ = Flat(tmp_);
    } else {
      solution_.setZero(rhs_.size());
    }
    summary.assembly_ms += MsSince(t);

    t = Clock::now();
    const LinearSolverSummary ls = solver_->Solve(H.matrix(), rhs_, &solution_);
    summary.solve_ms += MsSince(t);
    summary.linear_iterations += ls.iterations;
    ++summary.linear_solves;
    summary.factorizations += ls.numeric_factorization ? 1 : 0;
    ++summary.newton_iterations;
    summary.status = FromLinear(ls);
    if (summary.status != StepStatus::kConverged) {
      summary.message = std::string("linear solver: ") + LinearSolverStatusName(ls.status) +
                        (ls.message.empty() ? "" : " (" + ls.message + ")");
      return summary;  // state unchanged
    }
    summary.last_increment_mm = solution_.cwiseAbs().maxCoeff();
    // Armijo backtracking on Phi; skipped when the increment is no descent direction (an
    // inexact iterative solve), where the full increment is all there is, and when it moves
    // no vertex by kLineSearchMinIncrementMm, where round-off decides the test.
    const double slope = -rhs_.dot(solution_);  // grad Phi . dy
    if (options_.line_search && slope < 0.0 &&
        summary.last_increment_mm > kLineSearchMinIncrementMm) {
      t = Clock::now();
      line_start_ = y;
      const double phi0 = potential(y, it == 0);  // the terms are updated at y (above)
      // Elements inverted at the start enter the merit with their rotation there (the step's
      // own quadratic model): along an increment that un-inverts one its rotation flips, and
      // Phi with rotations recomputed rises before it falls.
      frozen_.clear();
      if (options_.freeze_inverted_rotations)
        for (const int e : elastic->inverted()) frozen_.emplace_back(e, elastic->rotations()[e]);
      double step = 1.0;
      for (int cut = 0;; ++cut) {
        y = line_start_;
        Flat(&y) += step * solution_;
        UpdateTerms(*state, y, elastic, terms);
        double phi = potential(y, false);
        for (const auto& [e, R0] : frozen_) {
          const Eigen::Matrix<double, 4, 3> ye = state->TetPositions(e, y);
          phi += CorotationalEnergy(state->rest_data(e), R0, ye, elastic->options().volume_term) -
                 CorotationalEnergy(state->rest_data(e), elastic->rotations()[e], ye,
                                    elastic->options().volume_term);
        }
        // With an allowance for round-off in the summed potential, so that a step near the
        // minimum is not rejected for noise; the smallest step is taken rather than none.
        if (phi <= phi0 + 1e-4 * step * slope + 1e-10 * std::abs(phi0) || cut == kMaxLineSearchCuts)
          break;
        step *= 0.5;
        ++summary.line_search_cuts;
      }
      summary.inverted_elements = elastic->num_inverted();
      summary.rotation_ms += MsSince(t);
    } else {
      Flat(&y) += solution_;
    }
    if (!one_step && summary.last_increment_mm < options_.newton_tolerance_mm) break;
    if (options_.newton_mode == NewtonMode::kFullNewton && it + 1 == max_it)
      summary.status = StepStatus::kMaxIterations;
  }
  previous_velocity_ = v0;
  RowMatX3d& v = state->mutable_velocities();
  v = (y - x0) / h;
  ZeroFixedRows(fixed, &v);
  written_velocity_ = v;
  state->mutable_positions() = y;
  return summary;
}

StaticSolver::StaticSolver(const StaticSolverOptions& options) : options_(options) {
  options_.Check();
  solver_ = LinearSolver::Create(options_.linear_solver);
}

StepSummary StaticSolver::Solve(MechanicalState* state, CorotationalElasticity* elastic,
                                const std::vector<EnergyTerm*>& terms) {
  StepSummary summary;
  const auto t_start = Clock::now();
  if (cache_.Refresh(*state, MassType::kLumped)) solver_->PatternChanged();
  SystemMatrix& H = cache_.hessian();
  const std::vector<char>& fixed = state->fixed_mask();
  RowMatX3d x = state->positions(), g, trial;
  Eigen::VectorXd rhs, dx;
  summary.status = StepStatus::kMaxIterations;
  UpdateTerms(*state, x, elastic, terms);
  double energy = TotalEnergy(*state, x, *elastic, terms);
  for (int it = 0; it < options_.max_iterations; ++it) {
    auto t = Clock::now();
    TotalGradient(*state, x, *elastic, terms, &g);
    ZeroFixedRows(fixed, &g);
    rhs = -Flat(g);
    H.SetZero();
    elastic->AddHessian(*state, x, 1.0, &H);
    for (const EnergyTerm* term : terms) term->AddHessian(*state, x, 1.0, &H);
    H.ApplyDirichlet(fixed);
    solver_->ValuesChanged();
    summary.assembly_ms += MsSince(t);
    t = Clock::now();
    dx.setZero(rhs.size());
    const LinearSolverSummary ls = solver_->Solve(H.matrix(), rhs, &dx);
    summary.solve_ms += MsSince(t);
    summary.linear_iterations += ls.iterations;
    ++summary.linear_solves;
    summary.factorizations += ls.numeric_factorization ? 1 : 0;
    ++summary.newton_iterations;
    if (FromLinear(ls) != StepStatus::kConverged) {
      summary.status = StepStatus::kLinearSolveFailed;
      summary.message = std::string("linear solver: ") + LinearSolverStatusName(ls.status);
      break;
    }
    // Armijo backtracking on the energy (true rotations at the trial point).
    double step = 1.0;
    const double slope = -rhs.dot(dx);  // grad E . dx (< 0 for a descent direction)
    t = Clock::now();
    for (int ls_it = 0; ls_it < (options_.line_search ? 12 : 1); ++ls_it) {
      trial = x;
      Flat(&trial) += step * dx;
      UpdateTerms(*state, trial, elastic, terms);
      const double e = TotalEnergy(*state, trial, *elastic, terms);
      // Armijo condition, with an allowance for round-off in the summed energy
      // so that steps near the solution are not rejected for noise.
      if (!options_.line_search || e <= energy + 1e-4 * step * slope + 1e-12 * std::abs(energy)) {
        energy = e;
        break;
      }
      step *= 0.5;
      if (ls_it == 11) energy = e;  // accept the smallest step rather than stall
    }
    x = trial;
    summary.rotation_ms += MsSince(t);
    // Converged when the full Newton increment is small (a short line-search
    // step alone says nothing about the distance to the solution).
    summary.last_increment_mm = dx.cwiseAbs().maxCoeff();
    if (summary.last_increment_mm < options_.tolerance_mm) {
      summary.status = StepStatus::kConverged;
      break;
    }
  }
  summary.inverted_elements = elastic->num_inverted();
  state->mutable_positions() = x;
  state->mutable_velocities().setZero();
  summary.total_ms = MsSince(t_start);
  return summary;
}

}  // namespace arreg::mechanics
