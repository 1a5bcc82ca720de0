#include "ar/eval/hausdorff.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

#include "core/error.h"

namespace arreg::eval {

TriangleDistanceQuery::TriangleDistanceQuery(const RowMatX3d& vertices, const RowMatX3i& faces)
    : vertices_(vertices), faces_(faces) {
  ARREG_CHECK_INPUT(faces.rows() > 0, "", "mesh", "distance query needs at least one triangle");
  const int nv = static_cast<int>(vertices.rows());
  for (int f = 0; f < faces.rows(); ++f)
    for (int k = 0; k < 3; ++k)
      ARREG_CHECK_INPUT(faces(f, k) >= 0 && faces(f, k) < nv, "",
                        internal::Concat("faces[", f, "]"), "vertex index ", faces(f, k),
                        " out of range [0, ", nv, ")");
  const int nf = static_cast<int>(faces.rows());
  order_.resize(nf);
  centroids_.resize(nf);
  for (int f = 0; f < nf; ++f) {
    order_[f] = f;
    centroids_[f] =
        (vertices.row(faces(f, 0)) + vertices.row(faces(f, 1)) + vertices.row(faces(f, 2)))
            .transpose() /
        3.0;
  }
  nodes_.reserve(2 * static_cast<size_t>(nf));
  Build(0, nf);
}

int TriangleDistanceQuery::Build(int first, int count) {
  const int index = static_cast<int>(nodes_.size());
  nodes_.emplace_back();
  Node node;
  node.lo.setConstant(std::numeric_limits<double>::infinity());
  node.hi.setConstant(-std::numeric_limits<double>::infinity());
  Eigen::Vector3d centroid_lo = node.lo, centroid_hi = node.hi;
  for (int i = first; i < first + count; ++i) {
    const int f = order_[i];
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d v = vertices_.row(faces_(f, k)).transpose();
      node.lo = node.lo.cwiseMin(v);
      node.hi = node.hi.cwiseMax(v);
    }
    centroid_lo = centroid_lo.cwiseMin(centroids_[f]);
    centroid_hi = centroid_hi.cwiseMax(centroids_[f]);
  }
  constexpr int kLeafSize = 4;
  if (count <= kLeafSize) {
    node.first = first;
    node.count = count;
    nodes_[index] = node;
    return index;
  }
  int axis = 0;
  (centroid_hi - centroid_lo).maxCoeff(&axis);
  const int half = count / 2;
  std::nth_element(order_.begin() + first, order_.begin() + first + half,
                   order_.begin() + first + count,
                   [&](int x, int y) { return centroids_[x][axis] < centroids_[y][axis]; });
  node.left = Build(first, half);
  node.right = Build(first + half, count - half);
  nodes_[index] = node;
  return index;
}

double TriangleDistanceQuery::BoxDistanceSquared(const Node& node, const Eigen::Vector3d& p) {
  const Eigen::Vector3d d = (node.lo - p).cwiseMax(p - node.hi).cwiseMax(Eigen::Vector3d::Zero());
  return d.squaredNorm();
}

TriangleDistanceQuery::Result TriangleDistanceQuery::Closest(const Eigen::Vector3d& point) const {
  double best_d2 = std::numeric_limits<double>::infinity();
  Result result;
  int stack[128];
  int top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const Node& node = nodes_[stack[--top]];
    if (BoxDistanceSquared(node, point) >= best_d2) continue;
    if (node.count > 0) {
      for (int i = node.first; i < node.first + node.count; ++i) {
        const int f = order_[i];
        const Eigen::Vector3d q = ClosestPointOnTriangle(
            point, vertices_.row(faces_(f, 0)).transpose(), vertices_.row(faces_(f, 1)).transpose(),
            vertices_.row(faces_(f, 2)).transpose());
        const double d2 = (q - point).squaredNorm();
        if (d2 < best_d2) {
          best_d2 = d2;
          result.closest_point = q;
          result.face = f;
        }
      }
      continue;
    }
    // Push the farther child first so that the nearer one is searched first and
    // tightens the bound early.
    const double dl = BoxDistanceSquared(nodes_[node.left], point);
    const double dr = BoxDistanceSquared(nodes_[node.right], point);
    ARREG_ASSERT(top + 2 <= 128, "BVH deeper than the query stack");
    if (dl <= dr) {
      if (dr < best_d2) stack[top++] = node.right;
      if (dl < best_d2) stack[top++] = node.left;
    } else {
      if (dl < best_d2) stack[top++] = node.left;
      if (dr < best_d2) stack[top++] = node.right;
    }
  }
  result.distance = std::sqrt(best_d2);
  return result;
}

void SurfaceSamplingOptions::Check() const {
  ARREG_CHECK_INPUT(std::isfinite(samples_per_area) && samples_per_area >= 0.0, "",
                    "sampling.samples_per_area", "must be finite and >= 0, got ", samples_per_area);
  ARREG_CHECK_INPUT(min_random_samples >= 0, "", "sampling.min_random_samples",
                    "must be >= 0, got ", min_random_samples);
  ARREG_CHECK_INPUT(max_random_samples >= min_random_samples, "", "sampling.max_random_samples",
                    "must be >= min_random_samples (", min_random_samples, "), got ",
                    max_random_samples);
  ARREG_CHECK_INPUT(include_vertices || max_random_samples > 0, "", "sampling",
                    "no samples: include_vertices is false and max_random_samples is 0");
}

void HausdorffOptions::Check() const { sampling.Check(); }

RowMatX3d SampleSurface(const SurfaceMesh& mesh, const SurfaceSamplingOptions& options) {
  options.Check();
  const int nf = mesh.num_faces();
  std::vector<char> used(mesh.num_vertices(), 0);
  std::vector<double> cumulative_area(nf);
  double area = 0.0;
  for (int f = 0; f < nf; ++f) {
    const Eigen::Vector3d a = mesh.vertices.row(mesh.faces(f, 0)).transpose();
    const Eigen::Vector3d b = mesh.vertices.row(mesh.faces(f, 1)).transpose();
    const Eigen::Vector3d c = mesh.vertices.row(mesh.faces(f, 2)).transpose();
    area += 0.5 * (b - a).cross(c - a).norm();
    cumulative_area[f] = area;
    for (int k = 0; k < 3; ++k) used[mesh.faces(f, k)] = 1;
  }
  int num_vertices = 0;
  if (options.include_vertices)
    for (char u : used) num_vertices += u;
  const double wanted = std::ceil(options.samples_per_area * area);
  int num_random = static_cast<int>(
      std::clamp(wanted, double(options.min_random_samples), double(options.max_random_samples)));
  if (!(area > 0.0)) num_random = 0;

  RowMatX3d samples(num_vertices + num_random, 3);
  int row = 0;
  if (options.include_vertices)
    for (int v = 0; v < mesh.num_vertices(); ++v)
      if (used[v]) samples.row(row++) = mesh.vertices.row(v);

  std::mt19937_64 rng(options.seed);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  for (int s = 0; s < num_random; ++s) {
    const double target = uniform(rng) * area;
    int f =
        static_cast<int>(std::upper_bound(cumulative_area.begin(), cumulative_area.end(), target) -
                         cumulative_area.begin());
    f = std::min(f, nf - 1);
    // Uniform point in a triangle: fold the unit square onto the lower triangle.
    double r1 = uniform(rng), r2 = uniform(rng);
    if (r1 + r2 > 1.0) {
      r1 = 1.0 - r1;
      r2 = 1.0 - r2;
    }
    const Eigen::RowVector3d a = mesh.vertices.row(mesh.faces(f, 0));
    const Eigen::RowVector3d b = mesh.vertices.row(mesh.faces(f, 1));
    const Eigen::RowVector3d c = mesh.vertices.row(mesh.faces(f, 2));
    samples.row(row++) = a + r1 * (b - a) + r2 * (c - a);
  }
  return samples;
}

namespace {

struct Directed {
  double mean = 0.0, max = 0.0;
  int count = 0;
};

Directed DirectedDistances(const RowMatX3d& samples, const TriangleDistanceQuery& query) {
  Directed out;
  out.count = static_cast<int>(samples.rows());
  // Kahan-free summation is enough: at most a few 1e5 terms of similar size.
  double sum = 0.0;
  for (int i = 0; i < samples.rows(); ++i) {
    const double d = query.Distance(samples.row(i).transpose());
    sum += d;
    out.max = std::max(out.max, d);
  }
  out.mean = out.count > 0 ? sum / out.count : 0.0;
  return out;
}

Eigen::VectorXd VertexDistances(const SurfaceMesh& mesh, const TriangleDistanceQuery& query) {
  std::vector<char> used(mesh.num_vertices(), 0);
  for (int f = 0; f < mesh.num_faces(); ++f)
    for (int k = 0; k < 3; ++k) used[mesh.faces(f, k)] = 1;
  Eigen::VectorXd out = Eigen::VectorXd::Zero(mesh.num_vertices());
  for (int v = 0; v < mesh.num_vertices(); ++v)
    if (used[v]) out[v] = query.Distance(mesh.vertices.row(v).transpose());
  return out;
}

}  // namespace

HausdorffResult ComputeHausdorff(const SurfaceMesh& model, const SurfaceMesh& gt,
                                 const HausdorffOptions& options) {
  options.Check();
  ARREG_CHECK_INPUT(model.num_faces() > 0, "", "model", "surface has no triangles");
  ARREG_CHECK_INPUT(gt.num_faces() > 0, "", "ground truth", "surface has no triangles");
  const TriangleDistanceQuery to_gt(gt.vertices, gt.faces);
  const TriangleDistanceQuery to_model(model.vertices, model.faces);

  const Directed a = DirectedDistances(SampleSurface(model, options.sampling), to_gt);
  const Directed b = DirectedDistances(SampleSurface(gt, options.sampling), to_model);
  HausdorffResult r;
  r.mean_model_to_gt = a.mean;
  r.max_model_to_gt = a.max;
  r.samples_model = a.count;
  r.mean_gt_to_model = b.mean;
  r.max_gt_to_model = b.max;
  r.samples_gt = b.count;
  r.max = std::max(a.max, b.max);
  r.model_vertex_distances = VertexDistances(model, to_gt);
  r.gt_vertex_distances = VertexDistances(gt, to_model);
  return r;
}

}  // namespace arreg::eval
