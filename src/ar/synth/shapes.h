// Tetrahedral meshes of the synthetic benchmark shapes: silicone bands (unions
// of boxes, structured mesher) and a kidney-like organ with an internal
// structure (CGAL Mesh_3 on a labelled implicit domain).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <vector>

#include "core/mesh.h"

namespace arreg::synth {

// A tetrahedral mesh whose tetrahedra carry a subdomain label
// (1 = organ tissue, 2 = internal structure).
struct LabeledTetMesh {
  TetMesh mesh;
  Eigen::VectorXi labels;  // (#T) subdomain label per tetrahedron
};

// Union of axis-aligned boxes meshed on a regular grid: a cell belongs to the
// shape when its centre lies in one of the boxes, and each cell is split into
// 6 (Kuhn) or 5 (alternating) positively oriented tetrahedra that conform
// across cells. Box faces should lie on grid planes (grid origin = the union's
// minimum corner). Every tetrahedron gets label 1.
struct BoxUnionMeshOptions {
  Eigen::Vector3d cell_mm =
      Eigen::Vector3d::Constant(5.0);  // grid spacing per axis (mm), default 5
  int tets_per_cell = 6;               // 6 (Kuhn split, no preferred diagonal) or 5; default 6
  void Check() const;
};
LabeledTetMesh MeshBoxUnion(const std::vector<Eigen::AlignedBox3d>& boxes_mm,
                            const BoxUnionMeshOptions& options);

// A bean-shaped organ centred at the origin, long axis along x, with an
// ellipsoidal internal structure.
struct KidneyShape {
  Eigen::Vector3d size_mm{100.0, 27.0, 55.0};          // organ extent along x, y, z (mm)
  Eigen::Vector3d internal_size_mm{55.0, 11.0, 27.0};  // internal structure extent (mm)
  Eigen::Vector3d internal_center_mm{0.0, 0.0, 2.0};   // internal structure centre (mm)
  double bend_mm = 8.0;       // how far the ends curve towards +z (bean shape), default 8 mm
  double hilum_depth = 0.35;  // strength of the dent on the -z side (dimensionless), default 0.35
  void Check() const;
  // Label of a point: 2 inside the internal structure, 1 elsewhere in the organ, 0 outside.
  int Label(const Eigen::Vector3d& point_mm) const;
};

struct KidneyMeshOptions {
  double cell_size_mm = 2.5;       // upper bound of tetrahedron circumradius (mm), default 2.5
  double facet_size_mm = 2.5;      // upper bound of boundary facet circumradius (mm), default 2.5
  double facet_distance_mm = 0.4;  // surface approximation error bound (mm), default 0.4
  double radius_edge_ratio = 2.5;  // tetrahedron shape bound, default 2.5
  void Check() const;
};
// Deterministic for given options (CGAL's default random generator is reset,
// perturbation and exudation run without time limits).
LabeledTetMesh MeshKidney(const KidneyShape& shape, const KidneyMeshOptions& options);

// Faces of a tetrahedral mesh used by every boundary computation: the face
// opposite local vertex k of tetrahedron t, oriented outwards of t.
inline std::array<int, 3> TetFace(const RowMatX4i& tets, int t, int k) {
  static constexpr int kFace[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};
  return {tets(t, kFace[k][0]), tets(t, kFace[k][1]), tets(t, kFace[k][2])};
}

// Boundary faces (outward) of the tetrahedra selected by `include` (all when
// empty): faces whose vertex triple occurs in exactly one selected tetrahedron.
// Returns (#F x 3); `owner` (if given) receives (tet, local face) per face.
RowMatX3i BoundaryFaces(const RowMatX4i& tets, const std::vector<bool>& include = {},
                        std::vector<std::pair<int, int>>* owner = nullptr);

}  // namespace arreg::synth
