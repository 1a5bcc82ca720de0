// Test meshes built in code: a box of hexahedral cells, each split into conforming,
// positively oriented tetrahedra, and a sphere surface (tests, benchmarks, demos).
#pragma once

#include <Eigen/Core>

#include "core/mesh.h"

namespace arreg {

// How each hexahedral cell of a structured box is cut into tetrahedra.
enum class BoxTetSplit {
  // Kuhn (Freudenthal) split: 6 tetrahedra around the cell's main diagonal
  // (min corner to max corner). Every cell is cut the same way, so faces match.
  kSix,
  // 5 tetrahedra: one central tetrahedron and four corner ones; the pattern is
  // mirrored in every other cell (by i+j+k parity) so face diagonals match.
  kFive,
};

// A box [0, size_mm.x] x [0, size_mm.y] x [0, size_mm.z] (min corner at the
// origin) with cells.x * cells.y * cells.z hexahedral cells.
// Vertex (i, j, k), 0 <= i <= cells.x etc., has index i + (nx+1) * (j + (ny+1) * k)
// and position (i * size.x / nx, j * size.y / ny, k * size.z / nz).
// Every tetrahedron has positive signed volume. `triangles` is left empty.
// Throws arreg::Error when a size is not positive and finite or a cell count < 1.
TetMesh MakeBoxTetMesh(const Eigen::Vector3d& size_mm, const Eigen::Vector3i& cells,
                       BoxTetSplit split = BoxTetSplit::kSix);

// A closed latitude-longitude sphere: two poles and rings - 1 rings of `segments` vertices,
// faces counter-clockwise seen from outside (an internal structure for tests and demos).
// Throws arreg::Error when radius_mm is not positive and finite, rings < 2 or segments < 3.
SurfaceMesh MakeUvSphere(const Eigen::Vector3d& center_mm, double radius_mm, int rings,
                         int segments);

}  // namespace arreg
