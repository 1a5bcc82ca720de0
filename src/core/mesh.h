// Mesh value types shared by every module: a tetrahedral volume mesh and a
// triangle surface mesh. Plain data (Eigen matrices, row-major); algorithms on
// them live in mesh_ops.h, file formats in mesh_io.h.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

namespace arreg {

using RowMatX3d = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;
using RowMatX2d = Eigen::Matrix<double, Eigen::Dynamic, 2, Eigen::RowMajor>;
using RowMatX3i = Eigen::Matrix<int, Eigen::Dynamic, 3, Eigen::RowMajor>;
using RowMatX4i = Eigen::Matrix<int, Eigen::Dynamic, 4, Eigen::RowMajor>;
using RowMatXi = Eigen::Matrix<int, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// Linear tetrahedral mesh. Vertex order of a tetrahedron (a,b,c,d) is positive
// when (b-a) x (c-a) . (d-a) > 0. Units are those of the scene (mm by default).
struct TetMesh {
  RowMatX3d vertices;    // (#V x 3) rest positions
  RowMatX4i tetrahedra;  // (#T x 4) vertex indices, 0-based
  // Higher-order elements: extra nodes appended to `vertices` and, per
  // tetrahedron, the indices of its edge nodes in the order
  // (ab, ac, ad, bc, bd, cd). Empty for linear meshes.
  RowMatXi high_order_nodes;  // (#T x 6) for quadratic tetrahedra, else 0 x 0
  // Boundary triangles given explicitly by the file (e.g. Gmsh surface
  // elements); boundary extraction does not depend on them.
  RowMatX3i triangles;  // (#F x 3)

  int num_vertices() const { return static_cast<int>(vertices.rows()); }
  int num_tetrahedra() const { return static_cast<int>(tetrahedra.rows()); }
};

// Triangle surface mesh with optional texture coordinates and normals.
struct SurfaceMesh {
  RowMatX3d vertices;  // (#V x 3) positions
  RowMatX3i faces;     // (#F x 3) vertex indices, counter-clockwise seen from outside
  RowMatX2d uvs;       // (#UV x 2) texture coordinates, may be empty
  RowMatX3i face_uvs;  // (#F x 3) indices into uvs, empty when uvs is empty
  RowMatX3d normals;   // (#V x 3) per-vertex normals, may be empty
  RowMatX3d colors;    // (#V x 3) per-vertex RGB in [0,1], may be empty

  int num_vertices() const { return static_cast<int>(vertices.rows()); }
  int num_faces() const { return static_cast<int>(faces.rows()); }
};

}  // namespace arreg
