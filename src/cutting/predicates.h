// Exact geometric predicates (CGAL's filtered exact orientation) and small
// element measures used by the remesher and its checks.
#pragma once

#include <Eigen/Core>

namespace arreg::cutting {

// Sign (+1, 0, -1) of det(b - a, c - a, d - a), computed exactly for the given doubles.
// +1 means (a, b, c, d) is a positively oriented tetrahedron.
int Orient3d(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
             const Eigen::Vector3d& d);

// Signed volume det(b - a, c - a, d - a) / 6 (floating point).
double TetVolume(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                 const Eigen::Vector3d& d);

// Normalised volume 6 sqrt(2) V / l_rms^3: 1 for the regular tetrahedron, 0 for a
// flat one, negative when inverted.
double TetQuality(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                  const Eigen::Vector3d& d);

}  // namespace arreg::cutting
