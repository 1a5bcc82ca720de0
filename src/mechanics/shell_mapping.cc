#include "mechanics/shell_mapping.h"

#include <algorithm>
#include <limits>

#include "core/error.h"

namespace arreg::mechanics {

namespace {

// Barycentric coordinates (of a, b, c) of the point of triangle abc closest to p.
Eigen::Vector3d ClosestBarycentric(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                   const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return {1, 0, 0};
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return {0, 1, 0};
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const double v = d1 / (d1 - d3);
    return {1 - v, v, 0};
  }
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return {0, 0, 1};
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const double w = d2 / (d2 - d6);
    return {1 - w, 0, w};
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return {0, 1 - w, w};
  }
  const double denom = 1.0 / (va + vb + vc);
  const double v = vb * denom, w = vc * denom;
  return {1 - v - w, v, w};
}

}  // namespace

ShellMapping::ShellMapping(const BezierShell& shell, std::vector<ShellSurfacePoint> points)
    : shell_(&shell), points_(std::move(points)) {
  weights_.reserve(points_.size());
  std::vector<char> used(shell.num_elements(), 0);
  for (size_t p = 0; p < points_.size(); ++p) {
    const ShellSurfacePoint& s = points_[p];
    if (s.element < 0 || s.element >= shell.num_elements())
      throw Error("", "shell surface point " + std::to_string(p),
                  "element " + std::to_string(s.element) + " out of range");
    if (!(s.xi1 >= -1e-9 && s.xi2 >= -1e-9 && s.xi1 + s.xi2 <= 1 + 1e-9))
      throw Error("", "shell surface point " + std::to_string(p),
                  "barycentric coordinates outside the triangle");
    weights_.push_back(BezierTriangleWeights(s.xi1, s.xi2));
    used[s.element] = 1;
  }
  for (int e = 0; e < shell.num_elements(); ++e)
    if (used[e]) used_elements_.push_back(e);
  control_.resize(shell.num_elements());
  jacobian_.resize(shell.num_elements());
}

ShellMapping ShellMapping::Project(const BezierShell& shell, const GeneralisedState& state,
                                   const RowMatX3d& fine_rest_positions) {
  std::vector<ShellSurfacePoint> points(fine_rest_positions.rows());
  for (int p = 0; p < fine_rest_positions.rows(); ++p) {
    const Eigen::Vector3d x = fine_rest_positions.row(p).transpose();
    double best = std::numeric_limits<double>::infinity();
    for (int e = 0; e < shell.num_elements(); ++e) {
      const Eigen::Vector3i& t = shell.triangle(e);
      const Eigen::Vector3d a = state.rest_positions().row(t[0]).transpose(),
                            b = state.rest_positions().row(t[1]).transpose(),
                            c = state.rest_positions().row(t[2]).transpose();
      const Eigen::Vector3d bary = ClosestBarycentric(x, a, b, c);
      const double d = (bary(0) * a + bary(1) * b + bary(2) * c - x).squaredNorm();
      if (d < best) {
        best = d;
        points[p] = {e, bary(0), bary(1)};
      }
    }
  }
  return ShellMapping(shell, std::move(points));
}

void ShellMapping::ElementControlPoints(const GeneralisedState& state, bool with_jacobian) const {
  if ((cached_jacobian_ || !with_jacobian) && cached_state_.Matches(state)) return;
  cached_state_.Take(state);
  cached_jacobian_ = with_jacobian;
  for (int e : used_elements_)
    shell_->ControlPoints(state, e, &control_[e], with_jacobian ? &jacobian_[e] : nullptr);
}

void ShellMapping::Positions(const GeneralisedState& state, RowMatX3d* positions) const {
  ElementControlPoints(state, false);
  positions->resize(size(), 3);
  for (int p = 0; p < size(); ++p)
    positions->row(p) = weights_[p].transpose() * control_[points_[p].element];
}

void ShellMapping::Velocities(const GeneralisedState& state, RowMatX3d* velocities) const {
  ElementControlPoints(state, true);
  // Control point velocities per element: J (30 x 18) times the nodes' (v, omega).
  std::vector<Eigen::Matrix<double, 10, 3>> cv(shell_->num_elements());
  for (int e : used_elements_) {
    Eigen::Matrix<double, 18, 1> qdot;
    const Eigen::Vector3i& t = shell_->triangle(e);
    for (int i = 0; i < 3; ++i) {
      qdot.segment<3>(6 * i) = state.velocities().row(t[i]).transpose();
      qdot.segment<3>(6 * i + 3) = state.angular_velocities().row(t[i]).transpose();
    }
    const Eigen::Matrix<double, 30, 1> v = jacobian_[e] * qdot;
    for (int k = 0; k < 10; ++k) cv[e].row(k) = v.segment<3>(3 * k).transpose();
  }
  velocities->resize(size(), 3);
  for (int p = 0; p < size(); ++p)
    velocities->row(p) = weights_[p].transpose() * cv[points_[p].element];
}

void ShellMapping::AddForces(const GeneralisedState& state, const RowMatX3d& forces,
                             Eigen::VectorXd* generalised) const {
  if (forces.rows() != size())
    throw Error("", "shell mapping forces",
                std::to_string(forces.rows()) + " rows, the mapping has " + std::to_string(size()));
  ElementControlPoints(state, true);
  // Fine forces onto the control points (n_k f), then J^T onto the nodes.
  std::vector<Eigen::Matrix<double, 30, 1>> cf(shell_->num_elements());
  for (int e : used_elements_) cf[e].setZero();
  for (int p = 0; p < size(); ++p) {
    Eigen::Matrix<double, 30, 1>& f = cf[points_[p].element];
    for (int k = 0; k < 10; ++k) f.segment<3>(3 * k) += weights_[p](k) * forces.row(p).transpose();
  }
  for (int e : used_elements_) {
    const Eigen::Matrix<double, 18, 1> g = jacobian_[e].transpose() * cf[e];
    const Eigen::Vector3i& t = shell_->triangle(e);
    for (int i = 0; i < 3; ++i)
      generalised->segment<6>(state.dof_offset(t[i])) += g.segment<6>(6 * i);
  }
}

}  // namespace arreg::mechanics
