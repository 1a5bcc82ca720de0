#include "mechanics/spring_energy.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"

namespace arreg::mechanics {

void SpringEnergy::CheckId(int id) const {
  ARREG_CHECK_INPUT(id >= 0 && id < size(), "", "spring id", id, " out of range [0, ", size(), ")");
}

int SpringEnergy::Add(const EmbeddedPoint& anchor, const Eigen::Vector3d& target_mm,
                      double stiffness_n_per_m) {
  ARREG_CHECK_INPUT(std::isfinite(stiffness_n_per_m) && stiffness_n_per_m >= 0, "",
                    "spring stiffness_n_per_m", "must be >= 0 and finite, got ", stiffness_n_per_m);
  ARREG_CHECK_INPUT(anchor.tet >= 0, "", "spring anchor", "has no tetrahedron");
  ARREG_CHECK_INPUT(target_mm.allFinite(), "", "spring target", "must be finite");
  springs_.push_back({anchor, target_mm, stiffness_n_per_m, true});
  return size() - 1;
}

void SpringEnergy::Remove(int id) {
  CheckId(id);
  springs_[id].active = false;
}

void SpringEnergy::SetTarget(int id, const Eigen::Vector3d& target_mm) {
  CheckId(id);
  ARREG_CHECK_INPUT(target_mm.allFinite(), "", "spring target", "must be finite");
  springs_[id].target_mm = target_mm;
}

void SpringEnergy::SetStiffness(int id, double stiffness_n_per_m) {
  CheckId(id);
  ARREG_CHECK_INPUT(std::isfinite(stiffness_n_per_m) && stiffness_n_per_m >= 0, "",
                    "spring stiffness_n_per_m", "must be >= 0 and finite, got ", stiffness_n_per_m);
  springs_[id].stiffness_n_per_m = stiffness_n_per_m;
}

void SpringEnergy::SetAnchor(int id, const EmbeddedPoint& anchor) {
  CheckId(id);
  ARREG_CHECK_INPUT(anchor.tet >= 0, "", "spring anchor", "has no tetrahedron");
  springs_[id].anchor = anchor;
}

int SpringEnergy::num_active() const {
  return static_cast<int>(
      std::count_if(springs_.begin(), springs_.end(), [](const Spring& s) { return s.active; }));
}

Eigen::Vector3d SpringEnergy::AnchorPosition(int id, const MechanicalState& state,
                                             const RowMatX3d& x) const {
  const EmbeddedPoint& e = springs_[id].anchor;
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  for (int a = 0; a < 4; ++a)
    p += e.barycentric[a] * x.row(state.tetrahedra()(e.tet, a)).transpose();
  return p;
}

void SpringEnergy::RenumberTetrahedra(const std::vector<std::pair<int, int>>& moved) {
  for (const auto& [from, to] : moved)
    for (Spring& s : springs_)
      if (s.anchor.tet == from) s.anchor.tet = -2 - to;  // mark, so chains do not cascade
  for (Spring& s : springs_)
    if (s.anchor.tet <= -2) s.anchor.tet = -2 - s.anchor.tet;
}

double SpringEnergy::Value(const MechanicalState& state, const RowMatX3d& x) const {
  double e = 0.0;
  for (int id = 0; id < size(); ++id) {
    const Spring& s = springs_[id];
    if (!s.active) continue;
    e += 0.5 * s.stiffness_n_per_m * (AnchorPosition(id, state, x) - s.target_mm).squaredNorm();
  }
  return e;
}

void SpringEnergy::AddGradient(const MechanicalState& state, const RowMatX3d& x,
                               RowMatX3d* gradient) const {
  for (int id = 0; id < size(); ++id) {
    const Spring& s = springs_[id];
    if (!s.active) continue;
    const Eigen::Vector3d g = s.stiffness_n_per_m * (AnchorPosition(id, state, x) - s.target_mm);
    for (int a = 0; a < 4; ++a)
      gradient->row(state.tetrahedra()(s.anchor.tet, a)) += s.anchor.barycentric[a] * g.transpose();
  }
}

void SpringEnergy::AddHessian(const MechanicalState& state, const RowMatX3d& x, double scale,
                              SystemMatrix* hessian) const {
  for (const Spring& s : springs_) {
    if (!s.active) continue;
    const Eigen::Vector4d& w = s.anchor.barycentric;
    for (int a = 0; a < 4; ++a)
      for (int b = a; b < 4; ++b) {
        const double k = scale * s.stiffness_n_per_m * w[a] * w[b];
        // Block k w_a w_b I: only the three diagonal entries of the block.
        const int slot_ab = hessian->BlockSlot(s.anchor.tet, a, b);
        const int stride_b = hessian->column_stride(state.tetrahedra()(s.anchor.tet, b));
        double* v = hessian->values() + slot_ab;
        for (int c = 0; c < 3; ++c) v[c * stride_b + c] += k;
        if (a != b) {
          const int slot_ba = hessian->BlockSlot(s.anchor.tet, b, a);
          const int stride_a = hessian->column_stride(state.tetrahedra()(s.anchor.tet, a));
          double* u = hessian->values() + slot_ba;
          for (int c = 0; c < 3; ++c) u[c * stride_a + c] += k;
        }
      }
  }
}

void GravityEnergy::RefreshMasses(const MechanicalState& state) const {
  if (masses_version_ != state.topology_version() || masses_.size() != state.num_vertices()) {
    masses_ = state.LumpedVertexMasses();
    masses_version_ = state.topology_version();
  }
}

void GravityEnergy::Update(const MechanicalState& state, const RowMatX3d&) { RefreshMasses(state); }

double GravityEnergy::Value(const MechanicalState& state, const RowMatX3d& x) const {
  RefreshMasses(state);
  return -(masses_.transpose() * (x * gravity_)).value();
}

void GravityEnergy::AddGradient(const MechanicalState& state, const RowMatX3d& x,
                                RowMatX3d* gradient) const {
  RefreshMasses(state);
  gradient->noalias() -= masses_ * gravity_.transpose();
}

void PointForceEnergy::AddForce(int vertex, const Eigen::Vector3d& force_mn) {
  ARREG_CHECK_INPUT(vertex >= 0, "", "point force vertex", "must be >= 0, got ", vertex);
  ARREG_CHECK_INPUT(force_mn.allFinite(), "", "point force", "must be finite");
  forces_.emplace_back(vertex, force_mn);
}

double PointForceEnergy::Value(const MechanicalState& state, const RowMatX3d& x) const {
  double e = 0.0;
  for (const auto& [v, f] : forces_) {
    ARREG_CHECK_INPUT(v < state.num_vertices(), "", "point force vertex", v, " out of range");
    e -= f.dot(x.row(v).transpose());
  }
  return e;
}

void PointForceEnergy::AddGradient(const MechanicalState& state, const RowMatX3d& x,
                                   RowMatX3d* gradient) const {
  for (const auto& [v, f] : forces_) {
    ARREG_CHECK_INPUT(v < state.num_vertices(), "", "point force vertex", v, " out of range");
    gradient->row(v) -= f.transpose();
  }
}

void VertexTetherEnergy::Add(int vertex, const Eigen::Vector3d& target_mm,
                             double stiffness_n_per_m) {
  ARREG_CHECK_INPUT(vertex >= 0, "", "tether vertex", "must be >= 0, got ", vertex);
  ARREG_CHECK_INPUT(std::isfinite(stiffness_n_per_m) && stiffness_n_per_m >= 0, "",
                    "tether stiffness_n_per_m", "must be >= 0 and finite, got ", stiffness_n_per_m);
  ARREG_CHECK_INPUT(target_mm.allFinite(), "", "tether target", "must be finite");
  for (const Tether& t : tethers_)
    ARREG_CHECK_INPUT(t.vertex != vertex, "", "tether vertex", vertex, " is tethered twice");
  tethers_.push_back({vertex, target_mm, stiffness_n_per_m});
}

void VertexTetherEnergy::CheckVertices(const MechanicalState& state) const {
  for (const Tether& t : tethers_)
    ARREG_CHECK_INPUT(t.vertex < state.num_vertices(), "", "tether vertex", t.vertex,
                      " out of range [0, ", state.num_vertices(), ")");
}

double VertexTetherEnergy::Value(const MechanicalState& state, const RowMatX3d& x) const {
  CheckVertices(state);
  double e = 0.0;
  for (const Tether& t : tethers_)
    e += 0.5 * t.stiffness_n_per_m * (x.row(t.vertex).transpose() - t.target_mm).squaredNorm();
  return e;
}

void VertexTetherEnergy::AddGradient(const MechanicalState& state, const RowMatX3d& x,
                                     RowMatX3d* gradient) const {
  CheckVertices(state);
  for (const Tether& t : tethers_)
    gradient->row(t.vertex) += t.stiffness_n_per_m * (x.row(t.vertex) - t.target_mm.transpose());
}

void VertexTetherEnergy::AddHessian(const MechanicalState& state, const RowMatX3d&, double scale,
                                    SystemMatrix* hessian) const {
  CheckVertices(state);
  for (const Tether& t : tethers_)
    hessian->AddToVertexDiagonal(t.vertex, scale * t.stiffness_n_per_m);
}

}  // namespace arreg::mechanics
