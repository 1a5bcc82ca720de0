#include "mechanics/system_matrix.h"

#include <algorithm>

#include "core/error.h"

namespace arreg::mechanics {

SystemMatrix::SystemMatrix(int num_vertices, const RowMatX4i& tetrahedra)
    : num_vertices_(num_vertices) {
  const int nt = static_cast<int>(tetrahedra.rows());
  // Vertex adjacency (including self), sorted per vertex.
  std::vector<std::vector<int>> adjacency(num_vertices);
  for (int v = 0; v < num_vertices; ++v) adjacency[v].push_back(v);
  for (int t = 0; t < nt; ++t)
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b)
        if (a != b) adjacency[tetrahedra(t, b)].push_back(tetrahedra(t, a));
  long long block_nnz = 0;
  for (auto& rows : adjacency) {
    std::sort(rows.begin(), rows.end());
    rows.erase(std::unique(rows.begin(), rows.end()), rows.end());
    block_nnz += static_cast<long long>(rows.size());
  }
  ARREG_CHECK_INPUT(9 * block_nnz < (1LL << 31), "", "system matrix",
                    "too many nonzeros for 32-bit indices");

  const int n = 3 * num_vertices;
  matrix_.resize(n, n);
  matrix_.resizeNonZeros(static_cast<int>(9 * block_nnz));
  int* outer = matrix_.outerIndexPtr();
  int* inner = matrix_.innerIndexPtr();
  column_stride_.resize(num_vertices);
  diagonal_slot_.resize(num_vertices);
  int k = 0;
  for (int v = 0; v < num_vertices; ++v) {
    const auto& rows = adjacency[v];
    column_stride_[v] = 3 * static_cast<int>(rows.size());
    for (int c = 0; c < 3; ++c) {
      outer[3 * v + c] = k;
      for (int u : rows)
        for (int r = 0; r < 3; ++r) inner[k++] = 3 * u + r;
    }
    const int pos = static_cast<int>(std::lower_bound(rows.begin(), rows.end(), v) - rows.begin());
    diagonal_slot_[v] = outer[3 * v] + 3 * pos;
  }
  outer[n] = k;
  std::fill(matrix_.valuePtr(), matrix_.valuePtr() + k, 0.0);

  element_slots_.resize(16 * static_cast<size_t>(nt));
  element_vertex_.resize(4 * static_cast<size_t>(nt));
  for (int t = 0; t < nt; ++t)
    for (int b = 0; b < 4; ++b) {
      const int vb = tetrahedra(t, b);
      element_vertex_[4 * t + b] = vb;
      const auto& rows = adjacency[vb];
      for (int a = 0; a < 4; ++a) {
        const int va = tetrahedra(t, a);
        const int pos =
            static_cast<int>(std::lower_bound(rows.begin(), rows.end(), va) - rows.begin());
        element_slots_[16 * t + 4 * b + a] = outer[3 * vb] + 3 * pos;
      }
    }
}

void SystemMatrix::ApplyDirichlet(const std::vector<char>& fixed_mask) {
  ARREG_ASSERT(static_cast<int>(fixed_mask.size()) == num_vertices_, "");
  if (std::find(fixed_mask.begin(), fixed_mask.end(), 1) == fixed_mask.end()) return;
  const int n = num_dofs();
  const int* outer = matrix_.outerIndexPtr();
  const int* inner = matrix_.innerIndexPtr();
  double* v = values();
  for (int col = 0; col < n; ++col) {
    const bool col_fixed = fixed_mask[col / 3] != 0;
    for (int k = outer[col]; k < outer[col + 1]; ++k) {
      const int row = inner[k];
      if (col_fixed || fixed_mask[row / 3]) v[k] = (row == col) ? 1.0 : 0.0;
    }
  }
}

}  // namespace arreg::mechanics
