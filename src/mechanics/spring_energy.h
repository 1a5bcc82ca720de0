// Zero-length springs between embedded points of the body and fixed targets
// (the image coupling of the registration, thesis eq. 7.2).
#pragma once

#include <Eigen/Core>
#include <vector>

#include "mechanics/embedding.h"
#include "mechanics/energy.h"

namespace arreg::mechanics {

// E = sum_l 1/2 k_l |p_l(x) - t_l|^2, p_l(x) = sum_a w_la x_{tet_l(a)}.
// Springs have stable ids; removed ones stay as inactive entries so that ids
// held elsewhere (features) keep their meaning between frames.
class SpringEnergy : public EnergyTerm {
 public:
  struct Spring {
    EmbeddedPoint anchor;
    Eigen::Vector3d target_mm = Eigen::Vector3d::Zero();
    double stiffness_n_per_m = 0.0;  // = mN/mm in internal units
    bool active = true;
  };

  std::string name() const override { return "springs"; }

  // Adds a spring; returns its id. Throws arreg::Error for a negative or
  // non-finite stiffness or an anchor without tetrahedron.
  int Add(const EmbeddedPoint& anchor, const Eigen::Vector3d& target_mm, double stiffness_n_per_m);
  void Remove(int id);  // deactivates
  void SetTarget(int id, const Eigen::Vector3d& target_mm);
  void SetStiffness(int id, double stiffness_n_per_m);
  void SetAnchor(int id, const EmbeddedPoint& anchor);  // after re-embedding (cuts)
  void Clear() { springs_.clear(); }

  int size() const { return static_cast<int>(springs_.size()); }
  int num_active() const;
  const Spring& spring(int id) const { return springs_[id]; }
  // Current anchor position of spring `id` (mm).
  Eigen::Vector3d AnchorPosition(int id, const MechanicalState& state, const RowMatX3d& x) const;
  // Applies an element renumbering (old -> new) from MechanicalState::ReplaceTetrahedra.
  void RenumberTetrahedra(const std::vector<std::pair<int, int>>& moved);

  double Value(const MechanicalState& state, const RowMatX3d& x) const override;
  void AddGradient(const MechanicalState& state, const RowMatX3d& x,
                   RowMatX3d* gradient) const override;
  void AddHessian(const MechanicalState& state, const RowMatX3d& x, double scale,
                  SystemMatrix* hessian) const override;

 private:
  void CheckId(int id) const;
  std::vector<Spring> springs_;
};

// Uniform gravity on the lumped vertex masses: E = -sum_v m_v g . x_v.
// (The consistent-mass body force gives the same nodal loads for linear tetrahedra.)
class GravityEnergy : public EnergyTerm {
 public:
  explicit GravityEnergy(const Eigen::Vector3d& gravity_mm_per_s2) : gravity_(gravity_mm_per_s2) {}
  std::string name() const override { return "gravity"; }
  void Update(const MechanicalState& state, const RowMatX3d& x) override;
  double Value(const MechanicalState& state, const RowMatX3d& x) const override;
  void AddGradient(const MechanicalState& state, const RowMatX3d& x,
                   RowMatX3d* gradient) const override;
  void AddHessian(const MechanicalState&, const RowMatX3d&, double, SystemMatrix*) const override {}
  const Eigen::Vector3d& gravity_mm_per_s2() const { return gravity_; }

 private:
  void RefreshMasses(const MechanicalState& state) const;
  Eigen::Vector3d gravity_;
  mutable Eigen::VectorXd masses_;
  mutable std::uint64_t masses_version_ = 0;
};

// Constant forces on vertices: E = -sum_v f_v . x_v.
class PointForceEnergy : public EnergyTerm {
 public:
  std::string name() const override { return "point-forces"; }
  // Adds (accumulates) force_mn on vertex v.
  void AddForce(int vertex, const Eigen::Vector3d& force_mn);
  void Clear() { forces_.clear(); }
  double Value(const MechanicalState& state, const RowMatX3d& x) const override;
  void AddGradient(const MechanicalState& state, const RowMatX3d& x,
                   RowMatX3d* gradient) const override;
  void AddHessian(const MechanicalState&, const RowMatX3d&, double, SystemMatrix*) const override {}

 private:
  std::vector<std::pair<int, Eigen::Vector3d>> forces_;
};

// Zero-length springs from vertices to fixed points: E = sum_i 1/2 k_i |x_{v_i} - t_i|^2.
// A vertex may be listed once. Vertex indices outside the state (a state that lost vertices)
// are an error; vertices added later (cuts append them) carry no tether.
class VertexTetherEnergy : public EnergyTerm {
 public:
  std::string name() const override { return "vertex-tethers"; }
  // Tethers vertex v to target_mm with stiffness k [N/m = mN/mm]. Throws arreg::Error for a
  // negative index, a vertex tethered twice, a non-finite target or a negative or non-finite k.
  void Add(int vertex, const Eigen::Vector3d& target_mm, double stiffness_n_per_m);
  void Clear() { tethers_.clear(); }
  int size() const { return static_cast<int>(tethers_.size()); }
  double Value(const MechanicalState& state, const RowMatX3d& x) const override;
  void AddGradient(const MechanicalState& state, const RowMatX3d& x,
                   RowMatX3d* gradient) const override;
  void AddHessian(const MechanicalState& state, const RowMatX3d& x, double scale,
                  SystemMatrix* hessian) const override;

 private:
  struct Tether {
    int vertex = -1;
    Eigen::Vector3d target_mm = Eigen::Vector3d::Zero();
    double stiffness_n_per_m = 0.0;
  };
  void CheckVertices(const MechanicalState& state) const;
  std::vector<Tether> tethers_;
};

}  // namespace arreg::mechanics
