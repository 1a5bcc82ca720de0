// Barycentric embedding of arbitrary point sets (features, internal
// structures) in a tetrahedral mesh, and their positions as the mesh deforms.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "core/mesh.h"

namespace arreg::mechanics {

// A point carried by one tetrahedron: p = sum_a w_a x_{tet(a)}. The weights
// sum to one; they may be slightly negative for points outside the mesh
// (extrapolated from the closest tetrahedron).
struct EmbeddedPoint {
  int tet = -1;
  Eigen::Vector4d barycentric = Eigen::Vector4d::Zero();
};

struct EmbeddingOptions {
  // A point counts as inside a tetrahedron when every barycentric weight is
  // >= -inside_tolerance (dimensionless); default 1e-9.
  double inside_tolerance = 1e-9;
  // Grid cells per axis scale: about cells_per_tet_factor * #T^(1/3) cells per
  // axis of the bounding box; default 1.0.
  double cells_per_tet_factor = 1.0;
  void Check() const;
};

// Barycentric coordinates of p in the tetrahedron (a, b, c, d) (non-degenerate).
Eigen::Vector4d BarycentricCoordinates(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                       const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                                       const Eigen::Vector3d& d);

// Euclidean distance from p to the closed tetrahedron (0 inside).
double PointTetDistance(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                        const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                        const Eigen::Vector3d& d);

// A set of embedded points with its embedding statistics.
class EmbeddedPoints {
 public:
  EmbeddedPoints() = default;

  // Embeds points (#P x 3) in the mesh (vertices #V x 3, tetrahedra #T x 4),
  // using a uniform grid over the tetrahedra's bounding boxes. Points outside
  // every tetrahedron take the closest one (extrapolated weights).
  static EmbeddedPoints Embed(const RowMatX3d& points, const RowMatX3d& vertices,
                              const RowMatX4i& tetrahedra, const EmbeddingOptions& options = {});

  // Re-embeds only the points `point_ids` (given their reference positions
  // `points`, #P x 3 for all points) among the tetrahedra `candidate_tets`
  // (e.g. those created by a cut), leaving the others untouched. An empty
  // candidate list means all tetrahedra.
  void Reembed(const std::vector<int>& point_ids, const RowMatX3d& points,
               const RowMatX3d& vertices, const RowMatX4i& tetrahedra,
               const std::vector<int>& candidate_tets, const EmbeddingOptions& options = {});

  // Positions of all points for vertex positions `vertices` (#P x 3).
  RowMatX3d Positions(const RowMatX3d& vertices, const RowMatX4i& tetrahedra) const;
  void Positions(const RowMatX3d& vertices, const RowMatX4i& tetrahedra, RowMatX3d* out) const;

  int size() const { return static_cast<int>(points_.size()); }
  // Keeps the first n points (n < size()) or appends unembedded ones (tet -1) for Reembed.
  void Resize(int n);
  const EmbeddedPoint& operator[](int i) const { return points_[i]; }
  EmbeddedPoint& operator[](int i) { return points_[i]; }
  const std::vector<EmbeddedPoint>& points() const { return points_; }
  // Distance (mm) from each point to its tetrahedron at embedding time (0 inside).
  const std::vector<double>& outside_distance() const { return outside_distance_; }
  int num_outside() const;

  // Applies an element renumbering (old -> new, from ReplaceTetrahedra's moved list).
  void RenumberTetrahedra(const std::vector<std::pair<int, int>>& moved);

 private:
  std::vector<EmbeddedPoint> points_;
  std::vector<double> outside_distance_;
};

}  // namespace arreg::mechanics
