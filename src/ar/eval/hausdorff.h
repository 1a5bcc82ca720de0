// Surface-to-surface distances for the accuracy evaluation: exact point-to-triangle
// distances through a bounding-volume hierarchy, dense surface sampling, Hausdorff parts.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "core/geometry.h"
#include "core/mesh.h"

namespace arreg::eval {

// Closest point on a triangle (core/geometry.h).
using ::arreg::ClosestPointOnTriangle;

// Answers nearest-point queries on a triangle mesh: an axis-aligned bounding box
// hierarchy over the faces (median split on the longest axis, <= 4 faces per
// leaf), searched nearest child first with box-distance pruning, so a query
// returns the exact distance to the closest triangle.
class TriangleDistanceQuery {
 public:
  // vertices (#V x 3), faces (#F x 3) with valid indices; at least one face.
  // Throws arreg::Error when the mesh has no faces or an index is out of range.
  TriangleDistanceQuery(const RowMatX3d& vertices, const RowMatX3i& faces);

  struct Result {
    double distance = 0.0;          // Euclidean distance (mesh units)
    Eigen::Vector3d closest_point;  // on the mesh
    int face = -1;                  // index of the face holding closest_point
  };
  Result Closest(const Eigen::Vector3d& point) const;
  double Distance(const Eigen::Vector3d& point) const { return Closest(point).distance; }

  int num_faces() const { return static_cast<int>(faces_.rows()); }

 private:
  struct Node {
    Eigen::Vector3d lo, hi;  // bounding box
    int first = 0;           // leaf: range [first, first + count) of order_
    int count = 0;           // 0 for inner nodes
    int left = -1, right = -1;
  };
  int Build(int first, int count);
  static double BoxDistanceSquared(const Node& node, const Eigen::Vector3d& p);

  RowMatX3d vertices_;
  RowMatX3i faces_;
  std::vector<int> order_;  // face indices, permuted so that leaves hold ranges
  std::vector<Eigen::Vector3d> centroids_;
  std::vector<Node> nodes_;
};

// Dense sampling of a surface for directed distances: all vertices that some
// face uses, plus random points uniformly distributed by area (face chosen with
// probability proportional to its area, uniform barycentric point in it).
struct SurfaceSamplingOptions {
  // Random samples per unit area (per mm^2 for mm meshes); default 4, i.e. a
  // mean spacing of about 0.5 mm.
  double samples_per_area = 4.0;
  int min_random_samples = 20000;   // lower bound on the random count; default 20000
  int max_random_samples = 400000;  // upper bound on the random count; default 400000
  bool include_vertices = true;     // add every referenced vertex; default true
  uint64_t seed = 1;                // random generator seed; default 1
  void Check() const;
};

// (#S x 3) sample points: referenced vertices first (when included), then the
// random samples. Deterministic for a given seed.
RowMatX3d SampleSurface(const SurfaceMesh& mesh, const SurfaceSamplingOptions& options);

// Both directed parts of the Hausdorff distance between a model surface A and a
// ground-truth surface B. "model_to_gt" distances are taken from samples of A to
// the triangles of B, and the other way round.
struct HausdorffOptions {
  SurfaceSamplingOptions sampling;  // samples on both surfaces (same options, same seed)
  void Check() const;
};

struct HausdorffResult {
  double mean_model_to_gt = 0.0;  // mean over A's samples of the distance to B
  double mean_gt_to_model = 0.0;  // mean over B's samples of the distance to A
  double max_model_to_gt = 0.0;   // directed Hausdorff h(A, B) over the samples
  double max_gt_to_model = 0.0;   // directed Hausdorff h(B, A)
  double max = 0.0;               // symmetric Hausdorff max(h(A,B), h(B,A))
  int samples_model = 0;          // sample counts actually used
  int samples_gt = 0;
  // (#V_A) distance from each vertex of A to B, and (#V_B) from each vertex of
  // B to A (colour maps); unreferenced vertices get 0.
  Eigen::VectorXd model_vertex_distances;
  Eigen::VectorXd gt_vertex_distances;
};

// Throws arreg::Error when either mesh has no faces.
HausdorffResult ComputeHausdorff(const SurfaceMesh& model, const SurfaceMesh& gt,
                                 const HausdorffOptions& options = {});

}  // namespace arreg::eval
