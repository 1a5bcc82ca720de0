// The curved boundary of a HighOrderTetMesh: its faces tessellated into a watertight
// triangle mesh on the Bezier map (overlay, silhouette, evaluation), and raising a
// linear tet mesh onto a smooth surface (boundary control points interpolating the
// surface, interior ones relaxed by a linear elastic solve).
#pragma once

#include <Eigen/Core>
#include <functional>
#include <vector>

#include "core/mesh.h"
#include "mechanics/curved_tet.h"
#include "mechanics/high_order_mesh.h"

namespace arreg::mechanics {

// A face of exactly one element: the element and its local vertex (0..3) opposite it.
struct HighOrderBoundaryFace {
  int element = -1;
  int opposite = -1;
};
// The boundary faces, found by their vertex nodes (the first four control points).
std::vector<HighOrderBoundaryFace> HighOrderBoundaryFaces(const HighOrderTetMesh& mesh);

struct CurvedBoundary {
  // Evaluated at the node positions given to TessellateBoundary; faces counter-clockwise
  // seen from outside (each element's own orientation, the sign of det J at its centre).
  SurfaceMesh surface;
  // Every surface vertex as element + barycentric coordinates: Positions(nodes) moves the
  // surface with deformed control points.
  HighOrderEmbedding vertices;
  std::vector<HighOrderBoundaryFace> faces;
  std::vector<int> face_of_triangle;  // (#triangles) index into faces
  // The surface at node positions `nodes` (#N x 3).
  SurfaceMesh Evaluate(const RowMatX3d& nodes) const;
};

// Each boundary face subdivided into subdivisions^2 triangles (its lattice of
// `subdivisions` steps per edge) evaluated on the Bezier map of `nodes` (#N x 3).
// Watertight by construction: a lattice point on a mesh edge or vertex is one surface
// vertex shared by every face there (identified by the edge's vertex nodes and the step
// from the smaller one). Throws arreg::Error naming "subdivisions" below 1.
CurvedBoundary TessellateBoundary(const HighOrderTetMesh& mesh, const RowMatX3d& nodes,
                                  int subdivisions);

// Closest point on a triangle mesh (brute force over its faces: O(#faces) per query, for
// the few thousand boundary lattice points of a raise). Throws arreg::Error naming
// "surface" when it has no faces.
std::function<Eigen::Vector3d(const Eigen::Vector3d&)> ClosestPointProjector(SurfaceMesh surface);

struct SurfaceRaiseOptions {
  // Maps a point to the smooth surface (closest point, mm -> mm). Required.
  std::function<Eigen::Vector3d(const Eigen::Vector3d&)> project;
  // Move the interior control points by a linear elastic solve with the boundary control
  // points' displacement as Dirichlet data (Mezger et al.; the thesis, chapter 6.1);
  // false keeps them at their straight positions. Default true.
  bool relax_interior = true;
  // Poisson ratio of the relaxation (Young's modulus drops out); default 0.3.
  double poisson_ratio = 0.3;
  void Check() const;
};

struct SurfaceRaiseSummary {
  int num_boundary_faces = 0;
  int num_boundary_nodes = 0;       // control points on boundary faces (moved onto the surface)
  double max_boundary_move_mm = 0;  // largest move of a boundary control point
  double max_interior_move_mm = 0;  // largest relaxation move of an interior control point
  // Per element the ratio of det J (JacobianBounds) to the straight element's 6 V:
  double min_sampled_ratio = 0;      // smallest sampled ratio over all elements
  double min_coefficient_ratio = 0;  // smallest Bernstein-coefficient ratio (a lower bound)
  int num_inverted = 0;              // elements with a negative sampled det J
  int num_undecided = 0;             // no negative sample, but a negative coefficient
};

// RaiseTetMesh(mesh, degree), then every boundary face's control points set so that the
// face interpolates project() at its lattice points (projected straight lattice points,
// vertices included; Bernstein collocation on the face, so a shared edge gets the same
// points from both faces), then, with relax_interior, the interior control points moved by
// the elastic solve on the straight elements (BernsteinStiffnessMatrix). Expected outcomes
// (inverted or undecided elements) are in the summary; nothing throws for them. Throws
// arreg::Error naming the option for bad options, as RaiseTetMesh for a bad mesh.
HighOrderTetMesh RaiseTetMeshOntoSurface(const TetMesh& mesh, int degree,
                                         const SurfaceRaiseOptions& options,
                                         SurfaceRaiseSummary* summary = nullptr);

}  // namespace arreg::mechanics
