// A fine surface (rendering, features, contacts) carried by Bezier shell
// elements: each fine point sits at barycentric coordinates of one element and
// follows its cubic surface (seed 000 section 4). Velocities and the force
// projection use the same Jacobian, so the projected forces and torques do the
// virtual work of the fine forces (seed eq. 32-40).
#pragma once

#include <Eigen/Core>
#include <vector>

#include "mechanics/bezier_shell.h"

namespace arreg::mechanics {

struct ShellSurfacePoint {
  int element = -1;  // BezierShell element index
  double xi1 = 0,
         xi2 = 0;  // barycentric weights of the element's corners 1 and 2 (xi3 = 1 - xi1 - xi2)
};

// Keeps a pointer to the shell (which must outlive it); not thread-safe (the
// per-state caches are filled by the const queries).
class ShellMapping {
 public:
  // Points given directly. Throws arreg::Error for an element out of range or
  // barycentric coordinates outside the triangle (beyond 1e-9).
  ShellMapping(const BezierShell& shell, std::vector<ShellSurfacePoint> points);
  // Each fine vertex (#P x 3, rest, mm) takes the barycentric coordinates of its
  // closest point on the closest element's rest corner triangle (seed section 4.1).
  static ShellMapping Project(const BezierShell& shell, const GeneralisedState& state,
                              const RowMatX3d& fine_rest_positions);

  int size() const { return static_cast<int>(points_.size()); }
  const ShellSurfacePoint& point(int p) const { return points_[p]; }

  // Current positions (#P x 3, mm) on the Bezier surfaces (seed eq. 5).
  void Positions(const GeneralisedState& state, RowMatX3d* positions) const;
  // Velocities (#P x 3, mm/s) from the nodes' linear and angular velocities (seed eq. 32-34).
  void Velocities(const GeneralisedState& state, RowMatX3d* velocities) const;
  // Adds the generalised forces of fine point forces (#P x 3, mN): forces on
  // the translation rows and torques (mN mm) on the rotation rows of
  // `generalised` (num_dofs()), seed eq. 35-40. A gradient of an energy of the
  // fine positions is projected the same way.
  void AddForces(const GeneralisedState& state, const RowMatX3d& forces,
                 Eigen::VectorXd* generalised) const;

 private:
  // Control points and their Jacobian of every element that carries a point,
  // computed once per state (positions, velocities and forces of one state share them).
  void ElementControlPoints(const GeneralisedState& state, bool with_jacobian) const;

  const BezierShell* shell_;
  std::vector<ShellSurfacePoint> points_;
  std::vector<Eigen::Matrix<double, 10, 1>> weights_;  // Bernstein weights per point
  std::vector<int> used_elements_;
  mutable std::vector<Eigen::Matrix<double, 10, 3>> control_;
  mutable std::vector<Eigen::Matrix<double, 30, 18>> jacobian_;
  mutable StateSnapshot cached_state_;  // the state control_ (and jacobian_) belong to
  mutable bool cached_jacobian_ = false;
};

}  // namespace arreg::mechanics
