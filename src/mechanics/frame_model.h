// 6-DOF frame model: frames (frame nodes of a GeneralisedState) skin material
// samples by a linear blend of their rigid motions; each sample gets a
// deformation gradient and a total-Lagrangian Saint Venant-Kirchhoff energy
// weighted by its volume. Also the consistent body force (gravity) on the samples.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "mechanics/frame_shape_functions.h"
#include "mechanics/generalised_state.h"
#include "mechanics/tet_element.h"

namespace arreg::mechanics {

struct FrameModelOptions {
  // Project the Hessian to positive semi-definite: the geometric stiffness
  // uses the positive part of the second Piola-Kirchhoff stress S, and each
  // frame's rotational second-order block is clamped to its non-negative
  // eigenvalues. The material stiffness is always PSD. Default true (Newton
  // directions stay descent directions under compression); false gives the
  // exact Hessian.
  bool project_hessian = true;
};

// Frame i sits at rest at x_i0 with rest orientation R_i0; sample s at X_s.
// Skinned position p_s = sum_i w_i (x_i + R_i R_i0^T (X_s - x_i0)) and
// F_s = sum_i [x_i g_i^T + R_i C_i], g_i = grad w_i(X_s),
// C_i = R_i0^T ((X_s - x_i0) g_i^T + w_i I), so F_s = I at rest and F_s = Q
// under a rigid motion Q. E = sum_s V_s psi(F_s) with the Saint Venant-Kirchhoff
// psi = mu tr(E^2) + lambda/2 tr(E)^2, E = (F^T F - I) / 2.
//
// Zero-energy modes beyond the 6 rigid motions: with linearly complete weights
// (barycentric, trilinear, linear MLS) all frames turned by one rotation about
// their own positions leave every p_s unchanged (exactly, at any angle), and
// so do, to first order, rotations phi_i = alpha x_i0 (trilinear weights also
// phi_i = diag(a) x_i0). They move no material, so they change no result, but
// a static solve needs them pinned: clamping the frames of one face (2+ frames
// at distinct points) pins them for tetrahedral and MLS models; trilinear
// models keep phi_i = e_n x_i0 along the clamped face's normal n, which only a
// dynamic solve (rotational inertia) or an extra clamp pins. Shepard weights
// have only the 6 rigid modes.
class FrameModel : public GeneralisedEnergyTerm, public InertiaSource {
 public:
  // frame_nodes[i]: the state's frame node that stands for frame i of the
  // samples (its rest position and rotation are read from `state`). Throws
  // arreg::Error for a sample that names a frame outside frame_nodes, a node
  // that is not a frame node, a non-positive volume, or weights that are not a
  // partition of unity (|sum w - 1|, |sum grad w| > 1e-8).
  FrameModel(const GeneralisedState& state, std::vector<int> frame_nodes,
             const std::vector<FrameSample>& samples, const Material& material,
             const FrameModelOptions& options = {});

  std::string name() const override { return "frame_svk"; }
  void AppendStencils(std::vector<std::vector<int>>* stencils) const override;
  double Value(const GeneralisedState& state) const override;
  void AddGradient(const GeneralisedState& state, Eigen::VectorXd* gradient) const override;
  void AddHessian(const GeneralisedState& state, double scale, HessianSink* sink) const override;

  // Mass rho V_s of each sample goes to its frames in proportion to max(w_i, 0)
  // (renormalised; MLS weights may be slightly negative). Each share is a
  // point mass rigidly carried by the frame at the sample's rest offset l
  // (body axes) plus a cube of the sample's volume: I += m (|l|^2 I - l l^T)
  // + m V_s^(2/3) / 6 I. Total mass = rho sum V_s exactly.
  void AddNodeInertia(const GeneralisedState& state,
                      std::vector<NodeInertia>* inertia) const override;

  int num_samples() const { return static_cast<int>(sample_begin_.size()) - 1; }
  int num_frames() const { return static_cast<int>(frame_nodes_.size()); }
  const std::vector<int>& frame_nodes() const { return frame_nodes_; }
  double total_mass_kg() const;
  double sample_volume_mm3(int s) const { return volume_[s]; }
  const Eigen::Vector3d& sample_rest_position(int s) const { return rest_position_[s]; }

  // Current deformation gradient and skinned position of sample s.
  Eigen::Matrix3d DeformationGradient(const GeneralisedState& state, int s) const;
  Eigen::Vector3d SamplePosition(const GeneralisedState& state, int s) const;
  // Energy density psi(F) in kPa (= uJ/mm^3).
  double EnergyDensity(const Eigen::Matrix3d& f) const;

  // Frame-sample pairs of sample s: [sample_begin(s), sample_begin(s + 1)).
  int sample_begin(int s) const { return sample_begin_[s]; }
  int pair_node(int p) const { return pair_node_[p]; }
  double pair_weight(int p) const { return pair_weight_[p]; }
  // Rest offset of the sample in the frame's body axes: R_i0^T (X_s - x_i0).
  const Eigen::Vector3d& pair_offset(int p) const { return pair_offset_[p]; }
  const Material& material() const { return material_; }

 private:
  // Per-sample second Piola-Kirchhoff stress S and first P = F S (kPa).
  void Stress(const Eigen::Matrix3d& f, Eigen::Matrix3d* s, Eigen::Matrix3d* p) const;

  std::vector<int> frame_nodes_;
  Material material_;
  FrameModelOptions options_;
  double mu_ = 0, lambda_ = 0;  // kPa
  std::vector<Eigen::Vector3d> rest_position_;
  std::vector<double> volume_;
  std::vector<int> sample_begin_;  // #samples + 1
  std::vector<int> pair_node_;
  std::vector<double> pair_weight_;
  std::vector<Eigen::Vector3d> pair_gradient_, pair_offset_;
  std::vector<Eigen::Matrix3d> pair_c_;
};

// Gravity (a uniform acceleration) on the samples of a frame model, applied
// at the skinned sample positions: E = -sum_s rho V_s g . p_s. Unlike lumping
// the mass onto the frame positions it gives each frame the torque of its
// samples' weight. Hessian: only the rotational second-order blocks, clamped
// to PSD when the model projects its Hessian.
class FrameGravity : public GeneralisedEnergyTerm {
 public:
  // `model` must outlive this term. gravity in mm/s^2.
  FrameGravity(const FrameModel* model, const Eigen::Vector3d& gravity_mm_s2,
               bool project_hessian = true);
  std::string name() const override { return "frame_gravity"; }
  void AppendStencils(std::vector<std::vector<int>>* stencils) const override;
  double Value(const GeneralisedState& state) const override;
  void AddGradient(const GeneralisedState& state, Eigen::VectorXd* gradient) const override;
  void AddHessian(const GeneralisedState& state, double scale, HessianSink* sink) const override;

 private:
  const FrameModel* model_;
  Eigen::Vector3d gravity_;
  bool project_hessian_;
};

// Adds one frame node (identity rest rotation) per row of frame_positions;
// returns the node indices in row order.
std::vector<int> AddFrameNodes(const RowMatX3d& frame_positions, GeneralisedState* state);

}  // namespace arreg::mechanics
