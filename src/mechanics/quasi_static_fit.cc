#include "mechanics/quasi_static_fit.h"

#include <cmath>

#include "core/error.h"
#include "core/mesh_ops.h"

namespace arreg::mechanics {

void QuasiStaticFitOptions::Check() const {
  ARREG_CHECK_INPUT(std::isfinite(spring_factor) && spring_factor > 0, "", "fit.spring_factor",
                    "must be > 0, got ", spring_factor);
  ARREG_CHECK_INPUT(std::isfinite(regularisation_time_s) && regularisation_time_s > 0, "",
                    "fit.regularisation_time_s", "must be > 0, got ", regularisation_time_s);
  ARREG_CHECK_INPUT(newton_iterations >= 1, "", "fit.newton_iterations", "must be >= 1, got ",
                    newton_iterations);
  linear_solver.Check();
  elastic.Check();
}

QuasiStaticFit::QuasiStaticFit(const QuasiStaticFitOptions& options) : options_(options) {
  options_.Check();
}

StepSummary QuasiStaticFit::Fit(const MechanicalState& state, const SpringEnergy& springs,
                                const std::vector<EnergyTerm*>& other_terms) {
  if (!integrator_ || state.topology_version() != source_topology_version_ ||
      state.num_tetrahedra() != source_tetrahedra_) {
    // A fresh integrator (its pattern cache is keyed by the copy's version,
    // which a new copy may repeat) and fresh element rotations.
    ImplicitEulerOptions io;
    io.dt_s = options_.regularisation_time_s;
    io.newton_mode =
        options_.newton_iterations > 1 ? NewtonMode::kFullNewton : NewtonMode::kOneStep;
    io.max_newton_iterations = options_.newton_iterations;
    io.linear_solver = options_.linear_solver;
    io.warm_start = WarmStart::kVelocity;
    io.line_search = options_.line_search;
    integrator_.emplace(io);
    elastic_ = CorotationalElasticity(options_.elastic);
    source_topology_version_ = state.topology_version();
    source_tetrahedra_ = state.num_tetrahedra();
    piece_ = ConnectedComponents(state.CurrentMesh(), Adjacency::kVertex, &num_pieces_);
  }
  copy_ = state;
  copy_->mutable_velocities().setZero();
  springs_ = springs;
  for (int id = 0; id < springs_.size(); ++id)
    if (springs_.spring(id).active)
      springs_.SetStiffness(id, options_.spring_factor * springs_.spring(id).stiffness_n_per_m);
  std::vector<EnergyTerm*> terms = {&springs_};
  terms.insert(terms.end(), other_terms.begin(), other_terms.end());
  const StepSummary summary = integrator_->Step(&*copy_, &elastic_, terms);
  if (summary.status == StepStatus::kLinearSolveFailed) {
    positions_ = state.positions();
  } else {
    positions_ = copy_->positions();
    KeepUnheldPieces(state, springs);
  }
  return summary;
}

void QuasiStaticFit::KeepUnheldPieces(const MechanicalState& state, const SpringEnergy& springs) {
  if (num_pieces_ <= 1 && springs.num_active() > 0) return;
  std::vector<char> held(num_pieces_, 0);
  for (int id = 0; id < springs.size(); ++id)
    if (springs.spring(id).active) held[piece_[springs.spring(id).anchor.tet]] = 1;
  for (int t = 0; t < state.num_tetrahedra(); ++t) {
    if (held[piece_[t]]) continue;
    for (int a = 0; a < 4; ++a) {
      const int v = state.tetrahedra()(t, a);
      positions_.row(v) = state.positions().row(v);
    }
  }
}

}  // namespace arreg::mechanics
