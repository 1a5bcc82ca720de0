#include "mechanics/elastic_energy.h"

#include <Eigen/LU>
#include <algorithm>
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

bool CorotationalElasticity::UpdatedAt(const MechanicalState& state, const RowMatX3d& x) const {
  return updated_state_ == &state && updated_version_ == state.topology_version() &&
         static_cast<int>(rotations_.size()) == state.num_tetrahedra() &&
         updated_positions_.rows() == x.rows() && updated_positions_ == x;
}

void CorotationalElasticity::Update(const MechanicalState& state, const RowMatX3d& x) {
  const int nt = state.num_tetrahedra();
  if (UpdatedAt(state, x)) return;
  updated_state_ = &state;
  updated_version_ = state.topology_version();
  updated_positions_ = x;
  if (static_cast<int>(rotations_.size()) != nt) {
    rotations_.resize(nt, Eigen::Matrix3d::Identity());
    quaternions_.resize(nt, Eigen::Quaterniond::Identity());
    rotated_gradients_.resize(nt);
  }
  const bool jacobian = options_.volume_term == VolumeTerm::kJacobian;
  if (jacobian) volume_gradients_.resize(nt);
  const bool polar = options_.rotation_method == RotationMethod::kPolar;
  const RowMatX4i& tets = state.tetrahedra();
  inverted_.clear();
  long long iterations = 0;
  double energy = 0.0;
  // Chunks of elements: deformation gradients first, then the rotations of the
  // whole chunk (PolarRotations interleaves elements), then rotated gradients.
  constexpr int kChunk = 64;
  Eigen::Matrix3d F[kChunk];
  for (int begin = 0; begin < nt; begin += kChunk) {
    const int count = std::min(kChunk, nt - begin);
    for (int k = 0; k < count; ++k) {
      const int t = begin + k;
      const Eigen::Matrix<double, 4, 3>& g = state.rest_data(t).shape_gradients;
      // F = sum_a x_a g_a^T.
      F[k].noalias() = x.row(tets(t, 0)).transpose() * g.row(0);
      for (int a = 1; a < 4; ++a) F[k].noalias() += x.row(tets(t, a)).transpose() * g.row(a);
      if (F[k].determinant() <= 0.0) inverted_.push_back(t);
    }
    if (polar) {
      iterations += PolarRotations(count, F, &quaternions_[begin], &rotations_[begin],
                                   options_.polar_max_iterations, options_.polar_tolerance);
    } else {
      for (int k = 0; k < count; ++k)
        iterations += ExtractRotation(F[k], options_.rotation_method, &rotations_[begin + k],
                                      options_.polar_max_iterations, options_.polar_tolerance);
    }
    for (int k = 0; k < count; ++k) {
      const int t = begin + k;
      const TetRestData& rest = state.rest_data(t);
      rotated_gradients_[t].noalias() = rest.shape_gradients * rotations_[t].transpose();
      if (jacobian)
        volume_gradients_[t].noalias() = rest.shape_gradients * Cofactor(F[k]).transpose();
      energy +=
          CorotationalEnergyOfF(rest, rotations_[t], F[k], options_.volume_term);  // for Value
    }
  }
  energy_ = energy;
  mean_iterations_ = nt > 0 ? static_cast<double>(iterations) / nt : 0.0;
}

double CorotationalElasticity::Value(const MechanicalState& state, const RowMatX3d& x) const {
  ARREG_ASSERT(static_cast<int>(rotations_.size()) == state.num_tetrahedra(),
               "Update() not called after a topology change");
  if (UpdatedAt(state, x)) return energy_;
  double e = 0.0;
  for (int t = 0; t < state.num_tetrahedra(); ++t)
    e += CorotationalEnergy(state.rest_data(t), rotations_[t], state.TetPositions(t, x),
                            options_.volume_term);
  return e;
}

void CorotationalElasticity::AddGradient(const MechanicalState& state, const RowMatX3d& x,
                                         RowMatX3d* gradient) const {
  ARREG_ASSERT(static_cast<int>(rotations_.size()) == state.num_tetrahedra(),
               "Update() not called after a topology change");
  const RowMatX4i& tets = state.tetrahedra();
  for (int t = 0; t < state.num_tetrahedra(); ++t) {
    Eigen::Matrix<double, 4, 3> g = Eigen::Matrix<double, 4, 3>::Zero();
    AddCorotationalGradient(state.rest_data(t), rotations_[t], state.TetPositions(t, x), &g,
                            options_.volume_term);
    for (int a = 0; a < 4; ++a) gradient->row(tets(t, a)) += g.row(a);
  }
}

void CorotationalElasticity::AddHessian(const MechanicalState& state, const RowMatX3d& x,
                                        double scale, SystemMatrix* hessian) const {
  ARREG_ASSERT(static_cast<int>(rotations_.size()) == state.num_tetrahedra(),
               "Update() not called after a topology change");
  // The blocks of WarpedStiffnessBlock written straight into their value
  // slots (the hot loop of the assembly: no 3x3 temporaries, each upper block
  // and its transpose from the same products).
  const RowMatX4i& tets = state.tetrahedra();
  double* values = hessian->values();
  const bool jacobian = options_.volume_term == VolumeTerm::kJacobian;
  for (int t = 0; t < state.num_tetrahedra(); ++t) {
    const TetRestData& rest = state.rest_data(t);
    const Eigen::Matrix<double, 4, 3>& g = rotated_gradients_[t];
    // The lambda block's gradients: R g_a (kLinear) or cof(F) g_a (kJacobian, Gauss-Newton).
    const Eigen::Matrix<double, 4, 3>& h = jacobian ? volume_gradients_[t] : g;
    const double vl = scale * rest.volume_mm3 * rest.lambda_kpa;
    const double vm = scale * rest.volume_mm3 * rest.mu_kpa;
    int stride[4];
    for (int a = 0; a < 4; ++a) stride[a] = hessian->column_stride(tets(t, a));
    for (int a = 0; a < 4; ++a) {
      const double ga[3] = {g(a, 0), g(a, 1), g(a, 2)};
      const double ha[3] = {h(a, 0), h(a, 1), h(a, 2)};
      for (int b = a; b < 4; ++b) {
        const double gb[3] = {g(b, 0), g(b, 1), g(b, 2)};
        const double hb[3] = {h(b, 0), h(b, 1), h(b, 2)};
        const double d = vm * (ga[0] * gb[0] + ga[1] * gb[1] + ga[2] * gb[2]);
        // block(r, c) = vl ha_r hb_c + vm gb_r ga_c + d delta_rc.
        double block[3][3];
        for (int r = 0; r < 3; ++r)
          for (int c = 0; c < 3; ++c) block[r][c] = vl * ha[r] * hb[c] + vm * gb[r] * ga[c];
        for (int r = 0; r < 3; ++r) block[r][r] += d;
        double* ab = values + hessian->BlockSlot(t, a, b);
        for (int c = 0; c < 3; ++c)
          for (int r = 0; r < 3; ++r) ab[c * stride[b] + r] += block[r][c];
        if (a != b) {
          double* ba = values + hessian->BlockSlot(t, b, a);
          for (int c = 0; c < 3; ++c)
            for (int r = 0; r < 3; ++r) ba[c * stride[a] + r] += block[c][r];
        }
      }
    }
  }
}

}  // namespace arreg::mechanics
