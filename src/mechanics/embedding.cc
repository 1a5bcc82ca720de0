#include "mechanics/embedding.h"
#include "core/geometry.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>

#include "core/error.h"

namespace arreg::mechanics {

void EmbeddingOptions::Check() const {
  ARREG_CHECK_INPUT(std::isfinite(inside_tolerance) && inside_tolerance >= 0, "",
                    "embedding.inside_tolerance", "must be >= 0, got ", inside_tolerance);
  ARREG_CHECK_INPUT(std::isfinite(cells_per_tet_factor) && cells_per_tet_factor > 0, "",
                    "embedding.cells_per_tet_factor", "must be > 0, got ", cells_per_tet_factor);
}

Eigen::Vector4d BarycentricCoordinates(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                       const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                                       const Eigen::Vector3d& d) {
  Eigen::Matrix3d m;
  m << b - a, c - a, d - a;
  const Eigen::Vector3d w = m.partialPivLu().solve(p - a);
  return Eigen::Vector4d(1.0 - w.sum(), w[0], w[1], w[2]);
}

namespace {

Eigen::Vector3d Row(const RowMatX3d& m, int i) { return m.row(i).transpose(); }

// Uniform grid over the bounding boxes of a set of tetrahedra.
class TetGrid {
 public:
  TetGrid(const RowMatX3d& vertices, const RowMatX4i& tets, const std::vector<int>& subset,
          double factor)
      : vertices_(vertices), tets_(tets), subset_(subset) {
    lo_.setConstant(std::numeric_limits<double>::infinity());
    hi_ = -lo_;
    for (int t : subset_)
      for (int a = 0; a < 4; ++a) {
        lo_ = lo_.cwiseMin(Row(vertices_, tets_(t, a)));
        hi_ = hi_.cwiseMax(Row(vertices_, tets_(t, a)));
      }
    const Eigen::Vector3d extent = (hi_ - lo_).cwiseMax(1e-12);
    const double target_cells = std::max(1.0, factor * factor * factor * subset_.size());
    const double h = std::cbrt(extent.prod() / target_cells);
    for (int i = 0; i < 3; ++i)
      dims_[i] = std::clamp(static_cast<int>(std::ceil(extent[i] / std::max(h, 1e-12))), 1, 512);
    cell_size_ = extent.cwiseQuotient(dims_.cast<double>());
    const int ncell = dims_.prod();
    std::vector<int> count(ncell + 1, 0);
    auto for_cells = [&](int t, auto&& fn) {
      Eigen::Vector3d tlo = Row(vertices_, tets_(t, 0)), thi = tlo;
      for (int a = 1; a < 4; ++a) {
        tlo = tlo.cwiseMin(Row(vertices_, tets_(t, a)));
        thi = thi.cwiseMax(Row(vertices_, tets_(t, a)));
      }
      const Eigen::Vector3i c0 = CellOf(tlo), c1 = CellOf(thi);
      for (int k = c0[2]; k <= c1[2]; ++k)
        for (int j = c0[1]; j <= c1[1]; ++j)
          for (int i = c0[0]; i <= c1[0]; ++i) fn(Index(i, j, k));
    };
    for (int t : subset_) for_cells(t, [&](int c) { ++count[c + 1]; });
    for (int c = 0; c < ncell; ++c) count[c + 1] += count[c];
    start_ = count;
    items_.resize(count[ncell]);
    for (int t : subset_) for_cells(t, [&](int c) { items_[count[c]++] = t; });
  }

  Eigen::Vector3i CellOf(const Eigen::Vector3d& p) const {
    Eigen::Vector3i c;
    for (int i = 0; i < 3; ++i)
      c[i] = std::clamp(static_cast<int>(std::floor((p[i] - lo_[i]) / cell_size_[i])), 0,
                        dims_[i] - 1);
    return c;
  }
  int Index(int i, int j, int k) const { return i + dims_[0] * (j + dims_[1] * k); }

  Eigen::Vector4d Bary(int t, const Eigen::Vector3d& p) const {
    return BarycentricCoordinates(p, Row(vertices_, tets_(t, 0)), Row(vertices_, tets_(t, 1)),
                                  Row(vertices_, tets_(t, 2)), Row(vertices_, tets_(t, 3)));
  }

  // Tetrahedron containing p (largest minimum weight), or -1.
  int FindContaining(const Eigen::Vector3d& p, double tol, Eigen::Vector4d* bary) const {
    if ((p.array() < lo_.array() - 1e-9).any() || (p.array() > hi_.array() + 1e-9).any()) return -1;
    const Eigen::Vector3i c = CellOf(p);
    const int cell = Index(c[0], c[1], c[2]);
    int best = -1;
    double best_min = -std::numeric_limits<double>::infinity();
    for (int k = start_[cell]; k < start_[cell + 1]; ++k) {
      const Eigen::Vector4d w = Bary(items_[k], p);
      const double m = w.minCoeff();
      if (m >= -tol && m > best_min) {
        best_min = m;
        best = items_[k];
        *bary = w;
      }
    }
    return best;
  }

  // Closest tetrahedron by Euclidean distance, searching rings of cells.
  int FindClosest(const Eigen::Vector3d& p, double* distance) const {
    const Eigen::Vector3i c = CellOf(p);
    int best = -1;
    double best_d = std::numeric_limits<double>::infinity();
    const int max_ring = dims_.maxCoeff();
    std::vector<char> tested;  // lazily sized on first use
    for (int r = 0; r <= max_ring; ++r) {
      const Eigen::Vector3i lo = (c.array() - r).max(0),
                            hi = (c.array() + r).min(dims_.array() - 1);
      for (int k = lo[2]; k <= hi[2]; ++k)
        for (int j = lo[1]; j <= hi[1]; ++j)
          for (int i = lo[0]; i <= hi[0]; ++i) {
            const bool on_ring =
                std::abs(i - c[0]) == r || std::abs(j - c[1]) == r || std::abs(k - c[2]) == r;
            if (!on_ring) continue;
            const int cell = Index(i, j, k);
            for (int s = start_[cell]; s < start_[cell + 1]; ++s) {
              const int t = items_[s];
              const double d =
                  PointTetDistance(p, Row(vertices_, tets_(t, 0)), Row(vertices_, tets_(t, 1)),
                                   Row(vertices_, tets_(t, 2)), Row(vertices_, tets_(t, 3)));
              if (d < best_d) {
                best_d = d;
                best = t;
              }
            }
          }
      // Any tetrahedron not yet tested lies outside the visited box of cells.
      double bound = std::numeric_limits<double>::infinity();
      for (int i = 0; i < 3; ++i) {
        if (lo[i] > 0)
          bound = std::min(bound, std::max(0.0, p[i] - (lo_[i] + lo[i] * cell_size_[i])));
        if (hi[i] < dims_[i] - 1)
          bound = std::min(bound, std::max(0.0, lo_[i] + (hi[i] + 1) * cell_size_[i] - p[i]));
      }
      if (best >= 0 && best_d <= bound) break;
    }
    *distance = best_d;
    return best;
  }

 private:
  const RowMatX3d& vertices_;
  const RowMatX4i& tets_;
  std::vector<int> subset_;
  Eigen::Vector3d lo_, hi_, cell_size_;
  Eigen::Vector3i dims_;
  std::vector<int> start_, items_;
};

void EmbedInto(const TetGrid& grid, const RowMatX3d& points, const std::vector<int>& ids,
               const EmbeddingOptions& options, std::vector<EmbeddedPoint>* out,
               std::vector<double>* distance) {
  for (int id : ids) {
    const Eigen::Vector3d p = points.row(id).transpose();
    EmbeddedPoint& e = (*out)[id];
    e.tet = grid.FindContaining(p, options.inside_tolerance, &e.barycentric);
    (*distance)[id] = 0.0;
    if (e.tet < 0) {
      e.tet = grid.FindClosest(p, &(*distance)[id]);
      ARREG_ASSERT(e.tet >= 0, "");
      e.barycentric = grid.Bary(e.tet, p);
    }
  }
}

void CheckMesh(const RowMatX3d& vertices, const RowMatX4i& tetrahedra) {
  ARREG_CHECK_INPUT(tetrahedra.rows() > 0, "", "embedding", "the mesh has no tetrahedra");
  ARREG_CHECK_INPUT(tetrahedra.minCoeff() >= 0 && tetrahedra.maxCoeff() < vertices.rows(), "",
                    "embedding", "tetrahedron vertex index out of range");
}

}  // namespace

double PointTetDistance(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                        const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                        const Eigen::Vector3d& d) {
  if (BarycentricCoordinates(p, a, b, c, d).minCoeff() >= 0.0) return 0.0;
  const Eigen::Vector3d* v[4] = {&a, &b, &c, &d};
  static const int kFaces[4][3] = {{1, 2, 3}, {0, 2, 3}, {0, 1, 3}, {0, 1, 2}};
  double best = std::numeric_limits<double>::infinity();
  for (const auto& f : kFaces)
    best = std::min(best, (ClosestPointOnTriangle(p, *v[f[0]], *v[f[1]], *v[f[2]]) - p).norm());
  return best;
}

EmbeddedPoints EmbeddedPoints::Embed(const RowMatX3d& points, const RowMatX3d& vertices,
                                     const RowMatX4i& tetrahedra, const EmbeddingOptions& options) {
  options.Check();
  CheckMesh(vertices, tetrahedra);
  std::vector<int> all_tets(tetrahedra.rows());
  for (int t = 0; t < tetrahedra.rows(); ++t) all_tets[t] = t;
  const TetGrid grid(vertices, tetrahedra, all_tets, options.cells_per_tet_factor);
  EmbeddedPoints result;
  result.points_.resize(points.rows());
  result.outside_distance_.resize(points.rows());
  std::vector<int> ids(points.rows());
  for (int i = 0; i < points.rows(); ++i) ids[i] = i;
  EmbedInto(grid, points, ids, options, &result.points_, &result.outside_distance_);
  return result;
}

void EmbeddedPoints::Reembed(const std::vector<int>& point_ids, const RowMatX3d& points,
                             const RowMatX3d& vertices, const RowMatX4i& tetrahedra,
                             const std::vector<int>& candidate_tets,
                             const EmbeddingOptions& options) {
  options.Check();
  CheckMesh(vertices, tetrahedra);
  ARREG_CHECK_INPUT(points.rows() == size(), "", "Reembed.points", "expected ", size(),
                    " rows, got ", points.rows());
  for (int id : point_ids)
    ARREG_CHECK_INPUT(id >= 0 && id < size(), "", "Reembed.point_ids", "index ", id,
                      " out of range");
  std::vector<int> subset = candidate_tets;
  if (subset.empty()) {
    subset.resize(tetrahedra.rows());
    for (int t = 0; t < tetrahedra.rows(); ++t) subset[t] = t;
  }
  for (int t : subset)
    ARREG_CHECK_INPUT(t >= 0 && t < tetrahedra.rows(), "", "Reembed.candidate_tets", "index ", t,
                      " out of range");
  const TetGrid grid(vertices, tetrahedra, subset, options.cells_per_tet_factor);
  EmbedInto(grid, points, point_ids, options, &points_, &outside_distance_);
}

RowMatX3d EmbeddedPoints::Positions(const RowMatX3d& vertices, const RowMatX4i& tetrahedra) const {
  RowMatX3d out;
  Positions(vertices, tetrahedra, &out);
  return out;
}

void EmbeddedPoints::Positions(const RowMatX3d& vertices, const RowMatX4i& tetrahedra,
                               RowMatX3d* out) const {
  out->resize(size(), 3);
  for (int i = 0; i < size(); ++i) {
    const EmbeddedPoint& e = points_[i];
    out->row(i) = e.barycentric[0] * vertices.row(tetrahedra(e.tet, 0)) +
                  e.barycentric[1] * vertices.row(tetrahedra(e.tet, 1)) +
                  e.barycentric[2] * vertices.row(tetrahedra(e.tet, 2)) +
                  e.barycentric[3] * vertices.row(tetrahedra(e.tet, 3));
  }
}

int EmbeddedPoints::num_outside() const {
  return static_cast<int>(std::count_if(outside_distance_.begin(), outside_distance_.end(),
                                        [](double d) { return d > 0.0; }));
}

void EmbeddedPoints::Resize(int n) {
  ARREG_CHECK_INPUT(n >= 0, "", "EmbeddedPoints::Resize", "negative size ", n);
  points_.resize(n);
  outside_distance_.resize(n, 0.0);
}

void EmbeddedPoints::RenumberTetrahedra(const std::vector<std::pair<int, int>>& moved) {
  if (moved.empty()) return;
  std::vector<std::pair<int, int>> sorted = moved;
  std::sort(sorted.begin(), sorted.end());
  for (EmbeddedPoint& e : points_) {
    auto it = std::lower_bound(sorted.begin(), sorted.end(), std::make_pair(e.tet, -1));
    if (it != sorted.end() && it->first == e.tet) e.tet = it->second;
  }
}

}  // namespace arreg::mechanics
