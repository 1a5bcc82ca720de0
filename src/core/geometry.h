// Small geometric kernels shared by the modules (distances between points and
// simplices); exact predicates stay in the cutting module.
#pragma once

#include <Eigen/Core>

namespace arreg {

// Closest point of the closed triangle (a, b, c) to p (Ericson, Real-Time
// Collision Detection 5.1.5). Degenerate triangles are handled: the result is
// then a closest point of their edges or vertices.
Eigen::Vector3d ClosestPointOnTriangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                       const Eigen::Vector3d& b, const Eigen::Vector3d& c);

}  // namespace arreg
