// The preconditioned conjugate gradient loop shared by the CG solver and
// cholmod-pcg: they differ only in the product with A and the preconditioner.
#pragma once

#include <cmath>

#include <Eigen/Core>

#include "mechanics/linear_solver.h"

namespace arreg::mechanics {

// Work vectors kept by the solver between calls (no allocation per solve).
struct CgVectors {
  Eigen::VectorXd r, z, p, q;
};

// Solves A x = b from the current *x until |b - A x| <= relative_tolerance |b|
// or max_iterations. `multiply(v, &out)` sets out = A v; `precondition(r, &z)`
// sets z = M^-1 r and returns false when it failed (status kNumericalFailure
// with `precondition_failure` as message). Sets the iteration count, relative
// residual and status of *summary and returns the iterations. |b| = 0 gives x = 0.
template <class Multiply, class Precondition>
int PreconditionedConjugateGradient(const Multiply& multiply, const Precondition& precondition,
                                    const char* precondition_failure, const Eigen::VectorXd& b,
                                    double relative_tolerance, int max_iterations,
                                    Eigen::VectorXd* x, CgVectors* w,
                                    LinearSolverSummary* summary) {
  const double b_norm = b.norm();
  if (b_norm == 0.0) {
    x->setZero();
    return 0;
  }
  multiply(*x, &w->q);
  w->r.noalias() = b - w->q;
  const double threshold = relative_tolerance * b_norm;
  double r_norm = w->r.norm();
  int it = 0;
  if (r_norm > threshold) {
    if (!precondition(w->r, &w->z)) {
      summary->status = LinearSolverStatus::kNumericalFailure;
      summary->message = precondition_failure;
      return 0;
    }
    w->p = w->z;
    double rz = w->r.dot(w->z);
    while (it < max_iterations) {
      multiply(w->p, &w->q);
      const double curvature = w->p.dot(w->q);
      if (!(curvature > 0.0)) {
        summary->status = std::isfinite(curvature) ? LinearSolverStatus::kIndefinite
                                                   : LinearSolverStatus::kNumericalFailure;
        summary->message = "non-positive curvature p^T A p in CG";
        break;
      }
      const double alpha = rz / curvature;
      x->noalias() += alpha * w->p;
      w->r.noalias() -= alpha * w->q;
      r_norm = w->r.norm();
      ++it;
      if (r_norm <= threshold) break;
      if (!precondition(w->r, &w->z)) {
        summary->status = LinearSolverStatus::kNumericalFailure;
        summary->message = precondition_failure;
        break;
      }
      const double rz_new = w->r.dot(w->z);
      w->p = w->z + (rz_new / rz) * w->p;
      rz = rz_new;
    }
  }
  summary->iterations = it;
  summary->relative_residual = r_norm / b_norm;
  if (summary->status == LinearSolverStatus::kConverged && !(r_norm <= threshold))
    summary->status = std::isfinite(r_norm) ? LinearSolverStatus::kMaxIterations
                                            : LinearSolverStatus::kNumericalFailure;
  return it;
}

}  // namespace arreg::mechanics
