// A HessianSink that assembles a term's blocks into one dense matrix (tests of
// generalised energy terms: finite differences, symmetry, spectra).
#pragma once

#include <Eigen/Core>

#include "mechanics/generalised_state.h"

namespace arreg::mechanics::testing {

// Adds block (a, b) and, for a != b, its transpose at (b, a), as the
// HessianSink contract says.
class DenseHessianSink : public HessianSink {
 public:
  explicit DenseHessianSink(const GeneralisedState& state)
      : state_(state), matrix_(Eigen::MatrixXd::Zero(state.num_dofs(), state.num_dofs())) {}
  void AddBlock(int a, int b, const Eigen::Ref<const Eigen::MatrixXd>& block,
                double scale) override {
    const int oa = state_.dof_offset(a), ob = state_.dof_offset(b);
    matrix_.block(oa, ob, block.rows(), block.cols()) += scale * block;
    if (a != b) matrix_.block(ob, oa, block.cols(), block.rows()) += scale * block.transpose();
  }
  const Eigen::MatrixXd& matrix() const { return matrix_; }

 private:
  const GeneralisedState& state_;
  Eigen::MatrixXd matrix_;
};

}  // namespace arreg::mechanics::testing
