// Corotational linear elasticity of all tetrahedra of a MechanicalState as
// one energy term: per-element rotations, energy, forces and warped stiffness.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <vector>

#include "mechanics/energy.h"

namespace arreg::mechanics {

struct CorotationalOptions {
  RotationMethod rotation_method = RotationMethod::kPolar;  // default polar (Newton iteration)
  int polar_max_iterations = 20;   // cap of the polar iteration per element; default 20
  double polar_tolerance = 1e-12;  // stop when the rotation update angle (rad) is below; 1e-12
  // Volumetric part of the energy (tet_element.h): kLinear lambda/2 tr(eps)^2 or kJacobian
  // lambda/2 (det F - 1)^2. Default kJacobian: tr(eps) measures the volume change only to
  // first order, so under the registration's large stretch the linear term loses volume the
  // material does not (a nu = 0.45 bar pulled to 184 %: volume ratio 0.71 against 1.04) and
  // the model's free faces sink by millimetres (docs/mechanics.md, "Volume term").
  VolumeTerm volume_term = VolumeTerm::kJacobian;
  void Check() const;
};

// Energy E(x) = sum_e V_e (mu eps_e:eps_e + lambda/2 tr(eps_e)^2) with
// eps_e = sym(R_e^T F_e(x) - I) and the rotations R_e frozen at the last
// Update(). Gradient and Hessian are exact derivatives of this frozen-rotation
// energy; the Hessian R K_e R^T is the stiffness-warping approximation of the
// true Hessian (it neglects dR/dx). For the polar rotation the gradient also
// equals the exact gradient of the energy with R_e = R_e(x) (R^T F is then
// symmetric and commutes with the stress), which the tests check.
// With VolumeTerm::kJacobian the volumetric part is V_e lambda/2 (det F_e - 1)^2 (no
// rotation in it): exact gradient V lambda (J - 1) cof(F) g_a; Hessian its Gauss-Newton part
// V lambda (cof(F) g_a)(cof(F) g_b)^T, positive semi-definite (the dropped
// V lambda (J - 1) d2J/dx2 is indefinite and vanishes with J - 1), equal to the warped
// lambda block at F = R.
class CorotationalElasticity : public EnergyTerm {
 public:
  explicit CorotationalElasticity(const CorotationalOptions& options = {});
  std::string name() const override { return "corotational-elasticity"; }

  // Recomputes R_e for every element from x (warm-started from the last ones); nothing when
  // the last Update was at the same positions (bit for bit) of the same state and topology,
  // as when an integrator's line search ends at the positions the next step starts from.
  void Update(const MechanicalState& state, const RowMatX3d& x) override;
  // At the positions of the last Update, the energy that Update summed (no second pass).
  double Value(const MechanicalState& state, const RowMatX3d& x) const override;
  void AddGradient(const MechanicalState& state, const RowMatX3d& x,
                   RowMatX3d* gradient) const override;
  void AddHessian(const MechanicalState& state, const RowMatX3d& x, double scale,
                  SystemMatrix* hessian) const override;

  const std::vector<Eigen::Matrix3d>& rotations() const { return rotations_; }
  // Elements with det F <= 0 at the last Update().
  int num_inverted() const { return static_cast<int>(inverted_.size()); }
  const std::vector<int>& inverted() const { return inverted_; }  // their indices, ascending
  // Mean polar iterations per element at the last Update().
  double mean_rotation_iterations() const { return mean_iterations_; }
  const CorotationalOptions& options() const { return options_; }

 private:
  CorotationalOptions options_;
  std::vector<Eigen::Matrix3d> rotations_;
  std::vector<Eigen::Quaterniond> quaternions_;  // kPolar: the same rotations (warm starts)
  std::vector<Eigen::Matrix<double, 4, 3>> rotated_gradients_;  // rows R g_a
  std::vector<Eigen::Matrix<double, 4, 3>> volume_gradients_;   // kJacobian: rows cof(F) g_a
  std::vector<int> inverted_;  // elements with det F <= 0 at the last Update()
  double mean_iterations_ = 0.0;
  // The last Update was at x of this state (and its topology).
  bool UpdatedAt(const MechanicalState& state, const RowMatX3d& x) const;
  double energy_ = 0.0;  // the energy at the last Update's positions
  // Where the rotations were last computed: the state, its topology version and x.
  const MechanicalState* updated_state_ = nullptr;
  std::uint64_t updated_version_ = 0;
  RowMatX3d updated_positions_;
};

}  // namespace arreg::mechanics
