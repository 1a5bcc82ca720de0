#include "cutting/predicates.h"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>

#include <Eigen/Geometry>

#include <cmath>

namespace arreg::cutting {

namespace {
using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
Kernel::Point_3 P(const Eigen::Vector3d& v) { return Kernel::Point_3(v.x(), v.y(), v.z()); }
}  // namespace

int Orient3d(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
             const Eigen::Vector3d& d) {
  // CGAL::orientation(p, q, r, s) is POSITIVE when det(q - p, r - p, s - p) > 0.
  return static_cast<int>(CGAL::orientation(P(a), P(b), P(c), P(d)));
}

double TetVolume(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                 const Eigen::Vector3d& d) {
  return (b - a).cross(c - a).dot(d - a) / 6.0;
}

double TetQuality(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                  const Eigen::Vector3d& d) {
  const double l2 = ((b - a).squaredNorm() + (c - a).squaredNorm() + (d - a).squaredNorm() +
                     (c - b).squaredNorm() + (d - b).squaredNorm() + (d - c).squaredNorm()) /
                    6.0;
  if (!(l2 > 0)) return 0.0;
  return 6.0 * std::sqrt(2.0) * TetVolume(a, b, c, d) / (l2 * std::sqrt(l2));
}

}  // namespace arreg::cutting
