// The separation surface S of a cut: a triangulated surface in the frame of
// the mesh positions being cut, with builders for planes, strips and grids.
#pragma once

#include <Eigen/Core>
#include <functional>
#include <vector>

#include "core/mesh.h"

namespace arreg::cutting {

// A triangle soup/mesh approximating S. Orientation of the triangles does not
// matter for crossing tests; normals are only used for snapping and sides.
struct CutSurface {
  RowMatX3d vertices;   // (#S x 3) positions, same frame and unit as the cut mesh
  RowMatX3i triangles;  // (#F x 3) indices into vertices

  int num_triangles() const { return static_cast<int>(triangles.rows()); }
  // Throws arreg::Error (field named) on out-of-range indices or non-finite points.
  void Check() const;
};

// Rectangle through `point` with unit `normal`, spanning [-half_u, half_u] x
// [-half_v, half_v] along two axes perpendicular to the normal (u is the one
// closest to `u_hint`), tessellated into 2 * n * n triangles.
CutSurface MakePlaneSurface(const Eigen::Vector3d& point, const Eigen::Vector3d& normal,
                            double half_u, double half_v, const Eigen::Vector3d& u_hint, int n = 1);

// A parametric sheet p(u, v), u, v in [0, 1], sampled on an (nu+1) x (nv+1) grid.
CutSurface MakeGridSurface(const std::function<Eigen::Vector3d(double, double)>& p, int nu, int nv);

// A cut polyline (#P x 3, P >= 2) extruded along per-point directions (#P x 3,
// e.g. camera rays) from -depth_before to +depth_after: a triangle strip.
CutSurface ExtrudePolyline(const RowMatX3d& polyline, const RowMatX3d& directions,
                           double depth_before, double depth_after);

// True when the segment [a, b] crosses a triangle of S (endpoints strictly on
// both sides of its plane; exact predicates).
bool SegmentCrossesSurface(const CutSurface& surface, const Eigen::Vector3d& a,
                           const Eigen::Vector3d& b);

}  // namespace arreg::cutting
