#include "core/mesh_generators.h"

#include <Eigen/Geometry>
#include <cmath>
#include <string>

#include "core/error.h"

namespace arreg {

namespace {

// Signed 6x volume, enough to decide orientation of a generated tetrahedron.
double Orient(const RowMatX3d& v, int a, int b, int c, int d) {
  const Eigen::Vector3d pa = v.row(a).transpose();
  const Eigen::Vector3d pb = v.row(b).transpose();
  const Eigen::Vector3d pc = v.row(c).transpose();
  const Eigen::Vector3d pd = v.row(d).transpose();
  return (pb - pa).cross(pc - pa).dot(pd - pa);
}

}  // namespace

TetMesh MakeBoxTetMesh(const Eigen::Vector3d& size_mm, const Eigen::Vector3i& cells,
                       BoxTetSplit split) {
  const char* axis_names[3] = {"x", "y", "z"};
  for (int a = 0; a < 3; ++a) {
    ARREG_CHECK_INPUT(std::isfinite(size_mm[a]) && size_mm[a] > 0, "",
                      std::string("size_mm.") + axis_names[a],
                      "box size must be positive and finite, got ", size_mm[a]);
    ARREG_CHECK_INPUT(cells[a] >= 1 && cells[a] <= 2000, "", std::string("cells.") + axis_names[a],
                      "cell count must be in [1, 2000], got ", cells[a]);
  }
  const int nx = cells.x(), ny = cells.y(), nz = cells.z();
  const long long num_vertices = static_cast<long long>(nx + 1) * (ny + 1) * (nz + 1);
  const long long num_cells = static_cast<long long>(nx) * ny * nz;
  const int per_cell = split == BoxTetSplit::kSix ? 6 : 5;
  ARREG_CHECK_INPUT(num_cells * per_cell < (1LL << 31) && num_vertices < (1LL << 31), "", "cells",
                    "too many cells (", num_cells, ")");

  TetMesh mesh;
  mesh.vertices.resize(num_vertices, 3);
  auto index = [&](int i, int j, int k) { return i + (nx + 1) * (j + (ny + 1) * k); };
  for (int k = 0; k <= nz; ++k)
    for (int j = 0; j <= ny; ++j)
      for (int i = 0; i <= nx; ++i) {
        // Computed as i * size / n so the far faces land exactly on size_mm.
        mesh.vertices.row(index(i, j, k)) << size_mm.x() * i / nx, size_mm.y() * j / ny,
            size_mm.z() * k / nz;
      }

  // Local corner c = bx + 2 * by + 4 * bz (bits select the max side per axis).
  static const int kKuhn[6][4] = {
      // Paths 0 -> 7 along the axes in every order: (x,y,z), (x,z,y), (y,x,z), ...
      {0, 1, 3, 7}, {0, 1, 5, 7}, {0, 2, 3, 7}, {0, 2, 6, 7}, {0, 4, 5, 7}, {0, 4, 6, 7}};
  // Central tetrahedron on the even corners {0,3,5,6} and the four odd corners'
  // caps; the mirrored pattern swaps even and odd corners.
  static const int kFiveEven[5][4] = {
      {0, 3, 5, 6}, {1, 0, 3, 5}, {2, 0, 3, 6}, {4, 0, 5, 6}, {7, 3, 5, 6}};
  static const int kFiveOdd[5][4] = {
      {1, 2, 4, 7}, {0, 1, 2, 4}, {3, 1, 2, 7}, {5, 1, 4, 7}, {6, 2, 4, 7}};

  mesh.tetrahedra.resize(num_cells * per_cell, 4);
  int t = 0;
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) {
        int corner[8];
        for (int c = 0; c < 8; ++c)
          corner[c] = index(i + (c & 1), j + ((c >> 1) & 1), k + (c >> 2));
        const int(*pattern)[4] = split == BoxTetSplit::kSix ? kKuhn
                                 : ((i + j + k) % 2 == 0)   ? kFiveEven
                                                            : kFiveOdd;
        for (int p = 0; p < per_cell; ++p, ++t) {
          int a = corner[pattern[p][0]], b = corner[pattern[p][1]];
          int c = corner[pattern[p][2]], d = corner[pattern[p][3]];
          // Orientation follows from the corner permutation; fixing it from the
          // actual coordinates keeps the tables free of sign bookkeeping.
          if (Orient(mesh.vertices, a, b, c, d) < 0) std::swap(c, d);
          mesh.tetrahedra.row(t) << a, b, c, d;
        }
      }
  return mesh;
}

SurfaceMesh MakeUvSphere(const Eigen::Vector3d& center_mm, double radius_mm, int rings,
                         int segments) {
  ARREG_CHECK_INPUT(std::isfinite(radius_mm) && radius_mm > 0, "", "radius_mm",
                    "must be positive and finite, got ", radius_mm);
  ARREG_CHECK_INPUT(rings >= 2, "", "rings", "must be at least 2, got ", rings);
  ARREG_CHECK_INPUT(segments >= 3, "", "segments", "must be at least 3, got ", segments);
  SurfaceMesh s;
  s.vertices.resize(2 + (rings - 1) * segments, 3);
  s.vertices.row(0) = (center_mm + Eigen::Vector3d(0, 0, radius_mm)).transpose();
  s.vertices.row(1) = (center_mm - Eigen::Vector3d(0, 0, radius_mm)).transpose();
  const auto ring = [&](int i, int j) { return 2 + (i - 1) * segments + j % segments; };
  for (int i = 1; i < rings; ++i)
    for (int j = 0; j < segments; ++j) {
      const double theta = M_PI * i / rings, phi = 2 * M_PI * j / segments;
      s.vertices.row(ring(i, j)) =
          (center_mm + radius_mm * Eigen::Vector3d(std::sin(theta) * std::cos(phi),
                                                   std::sin(theta) * std::sin(phi),
                                                   std::cos(theta)))
              .transpose();
    }
  s.faces.resize(2 * segments * (rings - 1), 3);
  int f = 0;
  for (int j = 0; j < segments; ++j) {
    s.faces.row(f++) << 0, ring(1, j), ring(1, j + 1);
    s.faces.row(f++) << 1, ring(rings - 1, j + 1), ring(rings - 1, j);
    for (int i = 1; i + 1 < rings; ++i) {
      s.faces.row(f++) << ring(i, j), ring(i + 1, j), ring(i + 1, j + 1);
      s.faces.row(f++) << ring(i, j), ring(i + 1, j + 1), ring(i, j + 1);
    }
  }
  return s;
}

}  // namespace arreg
