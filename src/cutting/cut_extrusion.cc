#include "cutting/cut_extrusion.h"
#include "core/geometry.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "core/error.h"

namespace arreg::cutting {

namespace {

Eigen::Vector3d ExtrusionDirection(const Eigen::Vector3d& point, const Eigen::Vector3d& centre,
                                   const CutExtrusionOptions& options, int index) {
  if (options.fixed_direction.squaredNorm() > 0.0) return options.fixed_direction.normalized();
  const Eigen::Vector3d ray = point - centre;
  ARREG_CHECK_INPUT(ray.norm() > 0.0, "", "cut polyline point " + std::to_string(index),
                    "coincides with the camera centre");
  return ray.normalized();
}

}  // namespace

void CutExtrusionOptions::Check() const {
  ARREG_CHECK_INPUT(std::isfinite(extent_towards_camera_mm) && extent_towards_camera_mm >= 0.0, "",
                    "cut_extrusion.extent_towards_camera_mm", "must be >= 0, got ",
                    extent_towards_camera_mm);
  ARREG_CHECK_INPUT(std::isfinite(extent_away_from_camera_mm) && extent_away_from_camera_mm >= 0.0,
                    "", "cut_extrusion.extent_away_from_camera_mm", "must be >= 0, got ",
                    extent_away_from_camera_mm);
  ARREG_CHECK_INPUT(extent_towards_camera_mm + extent_away_from_camera_mm > 0.0, "",
                    "cut_extrusion.extent_towards_camera_mm",
                    "and extent_away_from_camera_mm must not both be 0");
  ARREG_CHECK_INPUT(fixed_direction.allFinite(), "", "cut_extrusion.fixed_direction",
                    "must be finite");
}

SurfaceMesh ExtrudeCutPolyline(const std::vector<Eigen::Vector3d>& polyline_mm,
                               const Eigen::Vector3d& camera_centre_mm,
                               const CutExtrusionOptions& options) {
  options.Check();
  const int n = static_cast<int>(polyline_mm.size());
  ARREG_CHECK_INPUT(n >= 2, "", "cut polyline", "needs at least 2 points, got ", n);
  SurfaceMesh s;
  s.vertices.resize(2 * n, 3);
  for (int i = 0; i < n; ++i) {
    ARREG_CHECK_INPUT(polyline_mm[i].allFinite(), "", "cut polyline point " + std::to_string(i),
                      "must be finite");
    const Eigen::Vector3d u = ExtrusionDirection(polyline_mm[i], camera_centre_mm, options, i);
    s.vertices.row(2 * i) = polyline_mm[i] - options.extent_towards_camera_mm * u;
    s.vertices.row(2 * i + 1) = polyline_mm[i] + options.extent_away_from_camera_mm * u;
  }
  // Repeated points would give degenerate quads; they are skipped, not rejected, since a lagging
  // detector can insert a point at an extremity's position.
  std::vector<Eigen::Vector3i> faces;
  int last = 0;
  for (int i = 1; i < n; ++i) {
    if ((polyline_mm[i] - polyline_mm[last]).norm() == 0.0) continue;
    faces.emplace_back(2 * last, 2 * last + 1, 2 * i);
    faces.emplace_back(2 * last + 1, 2 * i + 1, 2 * i);
    last = i;
  }
  ARREG_CHECK_INPUT(!faces.empty(), "", "cut polyline", "all points coincide");
  s.faces.resize(static_cast<int>(faces.size()), 3);
  for (size_t f = 0; f < faces.size(); ++f) s.faces.row(static_cast<int>(f)) = faces[f].transpose();
  return s;
}

CutExtrusionOptions CutExtrusionCovering(const std::vector<Eigen::Vector3d>& polyline_mm,
                                         const Eigen::Vector3d& camera_centre_mm,
                                         const RowMatX3d& object_points_mm, double margin_mm) {
  ARREG_CHECK_INPUT(object_points_mm.rows() > 0, "", "object points", "must not be empty");
  ARREG_CHECK_INPUT(std::isfinite(margin_mm) && margin_mm >= 0.0, "", "margin_mm",
                    "must be >= 0, got ", margin_mm);
  // Along any ray the object lies within its distance range from the camera centre.
  double near = std::numeric_limits<double>::infinity(), far = 0.0;
  for (int i = 0; i < object_points_mm.rows(); ++i) {
    const double d = (object_points_mm.row(i).transpose() - camera_centre_mm).norm();
    near = std::min(near, d);
    far = std::max(far, d);
  }
  CutExtrusionOptions options;
  options.extent_towards_camera_mm = 0.0;
  options.extent_away_from_camera_mm = 0.0;
  for (const Eigen::Vector3d& p : polyline_mm) {
    const double d = (p - camera_centre_mm).norm();
    options.extent_towards_camera_mm =
        std::max(options.extent_towards_camera_mm, std::max(0.0, d - near) + margin_mm);
    options.extent_away_from_camera_mm =
        std::max(options.extent_away_from_camera_mm, std::max(0.0, far - d) + margin_mm);
  }
  return options;
}

double DistanceToSurface(const SurfaceMesh& surface, const Eigen::Vector3d& p) {
  double best = std::numeric_limits<double>::infinity();
  for (int f = 0; f < surface.num_faces(); ++f) {
    const Eigen::Vector3d a = surface.vertices.row(surface.faces(f, 0));
    const Eigen::Vector3d b = surface.vertices.row(surface.faces(f, 1));
    const Eigen::Vector3d c = surface.vertices.row(surface.faces(f, 2));
    best = std::min(best, (ClosestPointOnTriangle(p, a, b, c) - p).squaredNorm());
  }
  return std::sqrt(best);
}

std::vector<int> PointsWithinMargin(const SurfaceMesh& surface, const RowMatX3d& points_mm,
                                    double margin_mm) {
  ARREG_CHECK_INPUT(std::isfinite(margin_mm) && margin_mm >= 0.0, "", "margin_mm",
                    "must be >= 0, got ", margin_mm);
  const int nf = surface.num_faces();
  // Per-triangle boxes grown by the margin reject most point/triangle tests.
  std::vector<Eigen::Vector3d> lo(nf), hi(nf);
  for (int f = 0; f < nf; ++f) {
    lo[f] = hi[f] = surface.vertices.row(surface.faces(f, 0)).transpose();
    for (int k = 1; k < 3; ++k) {
      const Eigen::Vector3d v = surface.vertices.row(surface.faces(f, k));
      lo[f] = lo[f].cwiseMin(v);
      hi[f] = hi[f].cwiseMax(v);
    }
    lo[f].array() -= margin_mm;
    hi[f].array() += margin_mm;
  }
  const double r2 = margin_mm * margin_mm;
  std::vector<int> out;
  for (int i = 0; i < points_mm.rows(); ++i) {
    const Eigen::Vector3d p = points_mm.row(i);
    for (int f = 0; f < nf; ++f) {
      if ((p.array() < lo[f].array()).any() || (p.array() > hi[f].array()).any()) continue;
      const Eigen::Vector3d a = surface.vertices.row(surface.faces(f, 0));
      const Eigen::Vector3d b = surface.vertices.row(surface.faces(f, 1));
      const Eigen::Vector3d c = surface.vertices.row(surface.faces(f, 2));
      if ((ClosestPointOnTriangle(p, a, b, c) - p).squaredNorm() < r2) {
        out.push_back(i);
        break;
      }
    }
  }
  return out;
}

}  // namespace arreg::cutting
