// A linear tetrahedral mesh raised to Bernstein-Bezier degree k: the control
// points of every element (vertices, edges, faces, interior), those on a shared
// edge or face shared between the elements that meet there.
#pragma once

#include <Eigen/Core>
#include <array>
#include <string>
#include <vector>

#include "core/mesh.h"

namespace arreg::mechanics {

// Multi-indices alpha = (a0, a1, a2, a3), a0 + a1 + a2 + a3 = degree, of the
// Bernstein polynomials B_alpha = degree! / (a0! a1! a2! a3!) L0^a0 L1^a1 L2^a2 L3^a3
// of one tetrahedron in the order every element's control points use:
// lexicographically descending, so the vertex points degree * e_i come as
// 0 = (k,0,0,0), ..., and degree 1 is the vertex order of the tetrahedron.
std::vector<std::array<int, 4>> BernsteinIndices(int degree);
// (degree + 1)(degree + 2)(degree + 3) / 6: 4, 10, 20 for degree 1, 2, 3.
int BernsteinCount(int degree);

struct HighOrderTetMesh {
  int degree = 1;
  // Rest positions of the control points (#N x 3, mm); the first num_vertices are
  // the linear mesh's vertices in their order.
  RowMatX3d nodes;
  int num_vertices = 0;
  // Per element, its control points' node indices in BernsteinIndices(degree) order
  // (#T x BernsteinCount(degree)).
  RowMatXi elements;
  int num_elements() const { return static_cast<int>(elements.rows()); }
  int num_nodes() const { return static_cast<int>(nodes.rows()); }
};

// Raises `mesh` to `degree` (1, 2 or 3). The control point of multi-index alpha
// of tetrahedron (v0, v1, v2, v3) sits at sum_i alpha_i / degree * v_i (the
// Bezier points of the affine map: the rest geometry stays the linear mesh's);
// two elements share it when they share the vertices it is spanned by with the
// same multiplicities (a shared edge or face). Throws arreg::Error naming
// "degree" outside 1..3 or "tetrahedra" for a vertex index out of range.
HighOrderTetMesh RaiseTetMesh(const TetMesh& mesh, int degree);

// A mesh of 10-node (quadratic Lagrange) tetrahedra, TetMesh::high_order_nodes set (Gmsh
// .msh element type 11, VTK quadratic tetra), as Bernstein degree 2: the corner vertices
// (those `tetrahedra` use, in their order) first, then one control point per edge,
// b = 2 x_mid - (x_a + x_b) / 2, the Bezier point of the quadratic through x_a, x_mid,
// x_b at t = 0, 1/2, 1. Throws arreg::Error naming `file` (may be empty) and
// "high_order_nodes" when the table is not one row of 6 per tetrahedron, an index is out
// of range, or two tetrahedra give one edge mid-nodes at different positions.
HighOrderTetMesh HighOrderFromQuadraticTetMesh(const TetMesh& mesh, const std::string& file = "");

// Reads a tetrahedral mesh file (ReadTetMesh: Gmsh .msh 1/2.2/4.1 ASCII, VTK) with every
// tetrahedron turned positive (FixOrientation): 10-node tetrahedra become degree 2
// (HighOrderFromQuadraticTetMesh), linear ones are raised to `linear_degree` (straight).
// Throws arreg::Error naming the file (and the line, for malformed content).
HighOrderTetMesh ReadHighOrderTetMesh(const std::string& path, int linear_degree = 1);

}  // namespace arreg::mechanics
