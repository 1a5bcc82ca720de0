// The detected cut polyline turned into a separation surface S (thesis 7.5.3): extrusion along
// the camera rays into a triangle strip, and the springs that lie closer than a margin to S.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "core/geometry.h"
#include "core/mesh.h"

namespace arreg::cutting {

struct CutExtrusionOptions {
  // [mm] extent of the strip from each polyline point towards the camera, along its ray.
  // Default 100; choose it to cover the object (see CutExtrusionCovering).
  double extent_towards_camera_mm = 100.0;
  // [mm] extent from each polyline point away from the camera. Default 100.
  double extent_away_from_camera_mm = 100.0;
  // Extrusion direction: zero (default) extrudes along the rays from the camera centre; a
  // non-zero vector extrudes every point along this one direction (thesis: "or a predefined
  // vector"), its length ignored.
  Eigen::Vector3d fixed_direction = Eigen::Vector3d::Zero();

  // Throws arreg::Error naming the offending field.
  void Check() const;
};

// Triangle strip S. Vertex 2i is polyline point i moved towards the camera, 2i+1 moved away;
// per segment the faces (2i, 2i+1, 2j) and (2i+1, 2j+1, 2j), j the next distinct point
// (repeated points add no faces). Needs >= 2 distinct points, none at the camera centre;
// throws arreg::Error otherwise. The result converts to cutting::CutSurface as
// {vertices, faces}.
//   polyline_mm: points in the frame of camera_centre_mm (world, or model at rest with the
//   frame-0 camera centre).
SurfaceMesh ExtrudeCutPolyline(const std::vector<Eigen::Vector3d>& polyline_mm,
                               const Eigen::Vector3d& camera_centre_mm,
                               const CutExtrusionOptions& options = {});

// Extents (towards, away) [mm] such that the extrusion of every polyline point spans the whole
// distance range of `object_points_mm` (#P x 3) from the camera, plus `margin_mm` on each side.
CutExtrusionOptions CutExtrusionCovering(const std::vector<Eigen::Vector3d>& polyline_mm,
                                         const Eigen::Vector3d& camera_centre_mm,
                                         const RowMatX3d& object_points_mm, double margin_mm);

// Closest point on a triangle (core/geometry.h).
using ::arreg::ClosestPointOnTriangle;

// Distance [mm] from p to the surface (infinity for a surface without faces).
double DistanceToSurface(const SurfaceMesh& surface, const Eigen::Vector3d& p);

// Indices (ascending) of the rows of points_mm (#P x 3) closer than margin_mm to the surface
// (thesis 7.5.3: springs whose current surface point lies within the margin r are deleted so
// that they cannot pull the cut closed).
std::vector<int> PointsWithinMargin(const SurfaceMesh& surface, const RowMatX3d& points_mm,
                                    double margin_mm);

}  // namespace arreg::cutting
