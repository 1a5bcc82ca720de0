#include "mechanics/elastic_energy.h"

#include <Eigen/LU>
#include <cmath>

#include "core/error.h"

namespace arreg::mechanics {

void CorotationalOptions::Check() const {
  ARREG_CHECK_INPUT(polar_max_iterations >= 1, "", "corotational.polar_max_iterations",
                    "must be >= 1, got ", polar_max_iterations);
  ARREG_CHECK_INPUT(std::isfinite(polar_tolerance) && polar_tolerance >= 0, "",
                    "corotational.polar_tolerance", "must be >= 0, got ", polar_tolerance);
}

CorotationalElasticity::CorotationalElasticity(const CorotationalOptions& options)
    : options_(options) {
  options_.Check();
}

void CorotationalElasticity::Update(const MechanicalState& state, const RowMatX3d& x) {
  const int nt = state.num_tetrahedra();
  if (static_cast<int>(rotations_.size()) != nt) {
    rotations_.resize(nt, Eigen::Matrix3d::Identity());
    rotated_gradients_.resize(nt);
  }
  int inverted = 0;
  long long iterations = 0;
  for (int t = 0; t < nt; ++t) {
    const TetRestData& rest = state.rest_data(t);
    const Eigen::Matrix3d F = DeformationGradient(rest, state.TetPositions(t, x));
    if (F.determinant() <= 0.0) ++inverted;
    iterations += ExtractRotation(F, options_.rotation_method, &rotations_[t],
                                  options_.polar_max_iterations, options_.polar_tolerance);
    rotated_gradients_[t].noalias() = rest.shape_gradients * rotations_[t].transpose();
  }
  num_inverted_ = inverted;
  mean_iterations_ = nt > 0 ? static_cast<double>(iterations) / nt : 0.0;
}

double CorotationalElasticity::Value(const MechanicalState& state, const RowMatX3d& x) const {
  ARREG_ASSERT(static_cast<int>(rotations_.size()) == state.num_tetrahedra(),
               "Update() not called after a topology change");
  double e = 0.0;
  for (int t = 0; t < state.num_tetrahedra(); ++t)
    e += CorotationalEnergy(state.rest_data(t), rotations_[t], state.TetPositions(t, x));
  return e;
}

void CorotationalElasticity::AddGradient(const MechanicalState& state, const RowMatX3d& x,
                                         RowMatX3d* gradient) const {
  ARREG_ASSERT(static_cast<int>(rotations_.size()) == state.num_tetrahedra(),
               "Update() not called after a topology change");
  const RowMatX4i& tets = state.tetrahedra();
  for (int t = 0; t < state.num_tetrahedra(); ++t) {
    Eigen::Matrix<double, 4, 3> g = Eigen::Matrix<double, 4, 3>::Zero();
    AddCorotationalGradient(state.rest_data(t), rotations_[t], state.TetPositions(t, x), &g);
    for (int a = 0; a < 4; ++a) gradient->row(tets(t, a)) += g.row(a);
  }
}

void CorotationalElasticity::AddHessian(const MechanicalState& state, const RowMatX3d& x,
                                        double scale, SystemMatrix* hessian) const {
  ARREG_ASSERT(static_cast<int>(rotations_.size()) == state.num_tetrahedra(),
               "Update() not called after a topology change");
  for (int t = 0; t < state.num_tetrahedra(); ++t) {
    const TetRestData& rest = state.rest_data(t);
    for (int a = 0; a < 4; ++a)
      for (int b = a; b < 4; ++b)
        hessian->AddSymmetricElementBlock(
            t, a, b, WarpedStiffnessBlock(rest, rotated_gradients_[t], a, b), scale);
  }
}

}  // namespace arreg::mechanics
