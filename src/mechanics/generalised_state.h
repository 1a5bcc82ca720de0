// Generalised degrees of freedom: point nodes (3 translational DOFs: tet
// vertices, fine-surface points) and frame nodes (3 translational + 3
// rotational DOFs: Bezier shell corner nodes, 6-DOF frames) in one system.
//
// A frame node stores its orientation R (a rotation matrix). Increments are
// spatial (left): R <- Exp(phi) R (mechanics/so3.h). Every energy term gives
// its gradient and Hessian with respect to (x, phi) at phi = 0 around the
// stored configuration, so a solver linearises at the current rotations and
// updates them after each Newton iteration (R_ref <- Exp(dtheta) R_ref).
//
// DOF layout: nodes in index order; a point node owns 3 DOFs (x, y, z), a frame
// node 6 (x, y, z, phi_x, phi_y, phi_z). dof_offset(n) is the first of node n.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "core/mesh.h"

namespace arreg::mechanics {

class GeneralisedState {
 public:
  GeneralisedState() = default;

  // Appends a point node (rest = current position, zero velocity); returns its index.
  int AddPointNode(const Eigen::Vector3d& rest_position);
  // Appends a frame node with rest orientation `rest_rotation` (current = rest);
  // returns its index. Throws arreg::Error if the matrix is not a rotation (1e-9).
  int AddFrameNode(const Eigen::Vector3d& rest_position, const Eigen::Matrix3d& rest_rotation);
  // Appends a copy of `node` (rest and current position and rotation,
  // velocities, fixed flags; a cut duplicating a node); returns its index.
  int DuplicateNode(int node);

  int num_nodes() const { return static_cast<int>(is_frame_.size()); }
  int num_frames() const { return num_frames_; }
  int num_dofs() const { return num_dofs_; }
  bool is_frame(int node) const { return is_frame_[node] != 0; }
  int node_dofs(int node) const { return is_frame(node) ? 6 : 3; }
  int dof_offset(int node) const { return dof_offset_[node]; }

  // Positions and linear velocities of all nodes (#N x 3), mm and mm/s.
  const RowMatX3d& rest_positions() const { return rest_positions_; }
  const RowMatX3d& positions() const { return positions_; }
  const RowMatX3d& velocities() const { return velocities_; }
  RowMatX3d& mutable_positions() { return positions_; }
  RowMatX3d& mutable_velocities() { return velocities_; }
  Eigen::Vector3d position(int node) const { return positions_.row(node).transpose(); }

  // Orientation of a frame node (identity for point nodes), rest and current,
  // and its spatial angular velocity in rad/s (zero for point nodes).
  const Eigen::Matrix3d& rest_rotation(int node) const { return rest_rotations_[node]; }
  const Eigen::Matrix3d& rotation(int node) const { return rotations_[node]; }
  Eigen::Matrix3d& mutable_rotation(int node) { return rotations_[node]; }
  const RowMatX3d& angular_velocities() const { return angular_velocities_; }
  RowMatX3d& mutable_angular_velocities() { return angular_velocities_; }

  // Applies a DOF increment (num_dofs()): x += dx, R <- Exp(dphi) R.
  void ApplyIncrement(const Eigen::VectorXd& increment);

  // Boundary conditions per node: a clamped frame node keeps translation and
  // rotation, a simply supported one only its translation (rotation free).
  void SetFixedTranslation(int node, bool fixed);
  void SetFixedRotation(int node, bool fixed);
  bool fixed_translation(int node) const { return fixed_translation_[node] != 0; }
  bool fixed_rotation(int node) const { return fixed_rotation_[node] != 0; }
  // One entry per DOF: 1 where the DOF is fixed (Dirichlet, zero increment).
  std::vector<char> FixedDofMask() const;

  // Incremented when nodes are added (patterns rebuilt) and when a fixed flag changes.
  std::uint64_t topology_version() const { return topology_version_; }
  std::uint64_t constraint_version() const { return constraint_version_; }

 private:
  RowMatX3d rest_positions_, positions_, velocities_, angular_velocities_;
  std::vector<Eigen::Matrix3d> rest_rotations_, rotations_;
  std::vector<char> is_frame_, fixed_translation_, fixed_rotation_;
  std::vector<int> dof_offset_;
  int num_frames_ = 0;
  int num_dofs_ = 0;
  std::uint64_t topology_version_ = 1;
  std::uint64_t constraint_version_ = 1;
};

// Receives Hessian blocks: the (dofs(a) x dofs(b)) block between nodes a and b
// of one stencil. A term adds block (a, b) only; the sink adds its transpose
// at (b, a) for a != b. Pairs outside every stencil of the term are an error.
class HessianSink {
 public:
  virtual ~HessianSink() = default;
  virtual void AddBlock(int node_a, int node_b, const Eigen::Ref<const Eigen::MatrixXd>& block,
                        double scale) = 0;
};

// An energy over generalised DOFs (shell elements, frame samples, tets seen as
// point nodes, coupling springs). Units as EnergyTerm: mm, uJ, mN (moments in
// mN mm), stiffness in mN/mm, mN, mN mm per rad^2.
class GeneralisedEnergyTerm {
 public:
  virtual ~GeneralisedEnergyTerm() = default;
  virtual std::string name() const = 0;
  // Appends the node sets whose DOFs the term couples (a shell triangle: its 3
  // nodes; a frame sample: its frames); the system pattern is their union.
  virtual void AppendStencils(std::vector<std::vector<int>>* stencils) const = 0;
  // Called at each new linearisation point before Gradient/Hessian.
  virtual void Update(const GeneralisedState& state) {}
  virtual double Value(const GeneralisedState& state) const = 0;
  // gradient: num_dofs(), accumulated into (rotation rows: dE/dphi at phi = 0).
  virtual void AddGradient(const GeneralisedState& state, Eigen::VectorXd* gradient) const = 0;
  // Adds scale * Hessian (d2E/d(x,phi)2 at phi = 0, symmetric; projected to
  // positive semi-definite where the term documents it).
  virtual void AddHessian(const GeneralisedState& state, double scale, HessianSink* sink) const = 0;
};

// Lumped inertia of a node: its mass and, for a frame node, its rotational
// inertia about the node in the node's body axes (so the spatial inertia is
// R I_body R^T). Elements distribute their mass onto their nodes and say how.
struct NodeInertia {
  double mass_kg = 0;                                      // kg
  Eigen::Matrix3d body_inertia = Eigen::Matrix3d::Zero();  // kg mm^2, body axes
};

// Implemented by element terms that carry mass (shells, frame samples, tets):
// adds each node's share into `inertia` (num_nodes() entries).
class InertiaSource {
 public:
  virtual ~InertiaSource() = default;
  virtual void AddNodeInertia(const GeneralisedState& state,
                              std::vector<NodeInertia>* inertia) const = 0;
};

}  // namespace arreg::mechanics
