// A symmetric sparse matrix over 3-D vertex DOFs with a fixed pattern built
// once from the tetrahedra; element blocks are added through precomputed
// value slots, so assembly never rebuilds triplets or searches indices.
#pragma once

#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <vector>

#include "core/mesh.h"

namespace arreg::mechanics {

using SparseMatrixd = Eigen::SparseMatrix<double, Eigen::ColMajor, int>;

class SystemMatrix {
 public:
  SystemMatrix() = default;
  // Pattern: for every tetrahedron, all 3x3 blocks between its vertices (and
  // each vertex's diagonal block). Both triangles are stored (full symmetric
  // CSC), so the matrix can be multiplied directly and handed to CHOLMOD.
  SystemMatrix(int num_vertices, const RowMatX4i& tetrahedra);

  int num_vertices() const { return num_vertices_; }
  int num_dofs() const { return 3 * num_vertices_; }
  int nonzeros() const { return static_cast<int>(matrix_.nonZeros()); }
  const SparseMatrixd& matrix() const { return matrix_; }
  SparseMatrixd& mutable_matrix() { return matrix_; }
  double* values() { return matrix_.valuePtr(); }
  const double* values() const { return matrix_.valuePtr(); }

  void SetZero() { std::fill(values(), values() + nonzeros(), 0.0); }

  // Index of the value of entry (3*row_vertex + 0, 3*col_vertex + 0) for block
  // (a, b) of tetrahedron `tet`; entry (r, c) of the block is at
  // BlockSlot(...) + c * column_stride(col_vertex) + r.
  int BlockSlot(int tet, int a, int b) const { return element_slots_[16 * tet + 4 * b + a]; }
  int column_stride(int vertex) const { return column_stride_[vertex]; }

  // Adds s * block to block (a, b) of tetrahedron `tet` (only that block; the
  // caller adds the transposed block at (b, a) for a != b).
  void AddElementBlock(int tet, int a, int b, const Eigen::Matrix3d& block, double scale = 1.0) {
    double* v = values() + BlockSlot(tet, a, b);
    const int stride = column_stride(element_vertex_[4 * tet + b]);
    for (int c = 0; c < 3; ++c)
      for (int r = 0; r < 3; ++r) v[c * stride + r] += scale * block(r, c);
  }
  // Adds s * block to the block (a, b) and s * block^T to (b, a) (a != b), or
  // s * block to (a, a).
  void AddSymmetricElementBlock(int tet, int a, int b, const Eigen::Matrix3d& block,
                                double scale = 1.0) {
    AddElementBlock(tet, a, b, block, scale);
    if (a != b) AddElementBlock(tet, b, a, block.transpose(), scale);
  }
  // Adds s to the diagonal of vertex v's 3x3 diagonal block.
  void AddToVertexDiagonal(int vertex, double s) {
    double* d = values() + diagonal_slot_[vertex];
    const int stride = column_stride_[vertex];
    for (int c = 0; c < 3; ++c) d[c * stride + c] += s;
  }
  // Value index of the diagonal entry of DOF i.
  int DiagonalSlot(int dof) const {
    return diagonal_slot_[dof / 3] + (dof % 3) * (column_stride_[dof / 3] + 1);
  }

  // Replaces every row and column of a fixed vertex's DOFs by those of the
  // identity (Dirichlet elimination with zero increment).
  void ApplyDirichlet(const std::vector<char>& fixed_mask);

 private:
  int num_vertices_ = 0;
  SparseMatrixd matrix_;
  std::vector<int> element_slots_;   // 16 per tetrahedron, [b][a]
  std::vector<int> element_vertex_;  // 4 per tetrahedron
  std::vector<int> column_stride_;   // nonzeros per scalar column of each vertex block column
  std::vector<int> diagonal_slot_;   // slot of block (v, v)
};

}  // namespace arreg::mechanics
