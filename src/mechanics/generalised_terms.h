// Energy terms over generalised DOFs that every model shares: tetrahedral
// corotational elasticity on point nodes, zero-length springs between points
// of nodes (with body-frame offsets on frame nodes) and fixed targets, and
// gravity on the nodes' lumped masses.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "mechanics/elastic_energy.h"
#include "mechanics/generalised_state.h"
#include "mechanics/mechanical_state.h"
#include "mechanics/system_matrix.h"

namespace arreg::mechanics {

// Appends one point node per vertex of `body` (rest and current positions and
// velocities copied, fixed vertices get a fixed translation); returns
// vertex -> node (#V).
std::vector<int> AddTetVertexNodes(const MechanicalState& body, GeneralisedState* state);

// Sums the nodes' lumped inertia over the sources (num_nodes() entries).
std::vector<NodeInertia> CollectNodeInertia(const GeneralisedState& state,
                                            const std::vector<const InertiaSource*>& sources);

// An EnergyTerm of a tet body (energy.h: CorotationalElasticity, SpringEnergy with
// its embedded anchors, GravityEnergy, PointForceEnergy) as a generalised term, with
// vertex v of `body` on point node vertex_node[v]: the term's own code computes energy,
// gradient and Hessian at the vertex positions gathered from the nodes. `body` gives
// topology and rest data; its own positions are not used. Stencils: the tetrahedra.
// After the body's elements change (a cut), the solvers' pattern needs InvalidatePattern().
class TetBodyTerm : public GeneralisedEnergyTerm {
 public:
  // `body` and `term` must outlive this; vertex_node: one point node per vertex.
  TetBodyTerm(const MechanicalState* body, std::vector<int> vertex_node, EnergyTerm* term);
  std::string name() const override { return term_->name(); }
  void AppendStencils(std::vector<std::vector<int>>* stencils) const override;
  void Update(const GeneralisedState& state) override;
  double Value(const GeneralisedState& state) const override;
  void AddGradient(const GeneralisedState& state, Eigen::VectorXd* gradient) const override;
  void AddHessian(const GeneralisedState& state, double scale, HessianSink* sink) const override;

  const MechanicalState& body() const { return *body_; }
  const std::vector<int>& vertex_node() const { return vertex_node_; }
  // The body's vertex positions (#V x 3) gathered from the nodes.
  RowMatX3d VertexPositions(const GeneralisedState& state) const;

 protected:
  void CheckNodes(const GeneralisedState& state) const;

 private:
  const MechanicalState* body_;
  std::vector<int> vertex_node_;
  EnergyTerm* term_;
  // Assembly target of the term's blocks (the body's vertex pattern), scattered to the sink.
  mutable SystemMatrix hessian_;
  mutable std::uint64_t hessian_version_ = 0;
};

// CorotationalElasticity (elastic_energy.h) of the tetrahedra of `body` on point
// nodes (TetBodyTerm): the same element code, energy, gradient and warped-stiffness
// Hessian (positive semi-definite per element). It carries the tetrahedra's lumped
// masses (a quarter of each element's mass per vertex, as
// MechanicalState::LumpedVertexMasses); no rotational inertia (point nodes).
class TetElasticityTerm : public TetBodyTerm, public InertiaSource {
 public:
  TetElasticityTerm(const MechanicalState* body, std::vector<int> vertex_node,
                    const CorotationalOptions& options = {});
  std::string name() const override { return "tet-corotational"; }
  void AddNodeInertia(const GeneralisedState& state,
                      std::vector<NodeInertia>* inertia) const override;
  const CorotationalElasticity& elasticity() const { return elastic_; }

 private:
  CorotationalElasticity elastic_;  // constructed after the base, which only keeps its address
};

// A point carried by a node, x_n + R_n r with the offset r in the node's body
// axes (R_n = identity for point nodes), or a fixed point in space.
struct SpringAnchor {
  int node = -1;                                       // -1: the fixed point `point_mm`
  Eigen::Vector3d point_mm = Eigen::Vector3d::Zero();  // body offset r (mm), or world point
  static SpringAnchor Fixed(const Eigen::Vector3d& world_mm) { return {-1, world_mm}; }
  static SpringAnchor AtNode(int node) { return {node, Eigen::Vector3d::Zero()}; }
  static SpringAnchor AtOffset(int node, const Eigen::Vector3d& body_offset_mm) {
    return {node, body_offset_mm};
  }
};

// E = sum_l k_l/2 |p_A(l) - p_B(l)|^2 between two anchors: a node (or a point
// offset on a frame node) to a fixed target, node to node, a frame point to a
// tet vertex node (coupling models), a feature pulling a shell. Ids are stable
// (removed springs stay as inactive entries).
// Derivatives at phi = 0 with s = R r: dp = dx - s x phi + 1/2 phi x (phi x s);
// the Hessian is k J^T J (J = [I, -[s]x] per anchor) plus, on each anchor's
// rotation block, G = k (sym(d s^T) - (s . d) I) with d = p_A - p_B (-d for B).
// G is indefinite unless d is antiparallel to s (a hanging pendulum at rest) or
// zero; with project_psd (default) its negative eigenvalues are set to zero, so
// the spring's Hessian is positive semi-definite, the translation rows stay
// exact (a spring on a node with fixed rotation is solved in one Newton step) and
// the stable equilibria keep the exact Hessian.
class ZeroLengthSpringTerm : public GeneralisedEnergyTerm {
 public:
  struct Spring {
    SpringAnchor a, b;
    double stiffness_n_per_m = 0;  // = mN/mm
    bool active = true;
  };
  explicit ZeroLengthSpringTerm(bool project_psd = true) : project_psd_(project_psd) {}
  std::string name() const override { return "zero-length-springs"; }

  // Returns the id. Throws arreg::Error for a negative or non-finite stiffness,
  // two fixed anchors, or both anchors on one node.
  int Add(const SpringAnchor& a, const SpringAnchor& b, double stiffness_n_per_m);
  void Remove(int id);  // deactivates
  // Moves a fixed anchor (b when `second`, else a); for targets that follow an image.
  void SetFixedPoint(int id, const Eigen::Vector3d& world_mm, bool second = true);
  void SetStiffness(int id, double stiffness_n_per_m);
  int size() const { return static_cast<int>(springs_.size()); }
  const Spring& spring(int id) const { return springs_.at(id); }
  static Eigen::Vector3d AnchorPosition(const GeneralisedState& state, const SpringAnchor& anchor);

  void AppendStencils(std::vector<std::vector<int>>* stencils) const override;
  double Value(const GeneralisedState& state) const override;
  void AddGradient(const GeneralisedState& state, Eigen::VectorXd* gradient) const override;
  void AddHessian(const GeneralisedState& state, double scale, HessianSink* sink) const override;

 private:
  void CheckId(int id) const;
  bool project_psd_;
  std::vector<Spring> springs_;
};

// Uniform gravity on the nodes' lumped masses: E = -sum_n m_n g . x_n (the
// mass of a frame node sits at the node). Zero Hessian.
class GravityTerm : public GeneralisedEnergyTerm {
 public:
  // inertia: num_nodes() entries (CollectNodeInertia); g in mm/s^2.
  GravityTerm(const std::vector<NodeInertia>& inertia, const Eigen::Vector3d& gravity_mm_per_s2);
  std::string name() const override { return "gravity"; }
  void SetMasses(const std::vector<NodeInertia>& inertia);
  void AppendStencils(std::vector<std::vector<int>>*) const override {}
  double Value(const GeneralisedState& state) const override;
  void AddGradient(const GeneralisedState& state, Eigen::VectorXd* gradient) const override;
  void AddHessian(const GeneralisedState&, double, HessianSink*) const override {}

 private:
  void CheckNodes(const GeneralisedState& state) const;
  Eigen::VectorXd masses_;  // (#N) kg
  Eigen::Vector3d gravity_;
};

}  // namespace arreg::mechanics
