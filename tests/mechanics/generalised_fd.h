// Finite-difference helpers for tests of generalised energy terms (frame
// models, vessels): gradient and dense Hessian of a term, a state perturbed
// along one DOF, and the rotation-corrected gradient whose central difference
// is the symmetric Hessian.
#pragma once

#include <Eigen/Core>

#include "dense_hessian_sink.h"
#include "mechanics/generalised_state.h"
#include "mechanics/so3.h"

namespace arreg::mechanics::testing {

inline Eigen::VectorXd Gradient(const GeneralisedEnergyTerm& term, const GeneralisedState& state) {
  Eigen::VectorXd g = Eigen::VectorXd::Zero(state.num_dofs());
  term.AddGradient(state, &g);
  return g;
}

inline Eigen::MatrixXd Hessian(const GeneralisedEnergyTerm& term, const GeneralisedState& state) {
  DenseHessianSink sink(state);
  term.AddHessian(state, 1.0, &sink);
  return sink.matrix();
}

// The state after a perturbation h along DOF k: x += h or R <- Exp(h e) R.
inline GeneralisedState Perturbed(const GeneralisedState& state, int k, double h) {
  GeneralisedState out = state;
  Eigen::VectorXd increment = Eigen::VectorXd::Zero(state.num_dofs());
  increment[k] = h;
  out.ApplyIncrement(increment);
  return out;
}

// Gradient of f(phi) = E(Exp(phi) R) at phi = h e_k (k a DOF): the term's
// gradient about the perturbed state, with the perturbed node's rotation rows
// mapped by J_l(h e)^T (so3.h), so that its difference quotient is the
// symmetric Hessian of f at 0.
inline Eigen::VectorXd GradientAlong(const GeneralisedEnergyTerm& term,
                                     const GeneralisedState& state, int k, double h) {
  Eigen::VectorXd g = Gradient(term, Perturbed(state, k, h));
  for (int n = 0; n < state.num_nodes(); ++n) {
    const int rotation = state.dof_offset(n) + 3;
    if (state.is_frame(n) && k >= rotation && k < rotation + 3)
      g.segment<3>(rotation) =
          LeftJacobianSO3(h * Eigen::Vector3d::Unit(k - rotation)).transpose() *
          g.segment<3>(rotation);
  }
  return g;
}

}  // namespace arreg::mechanics::testing
