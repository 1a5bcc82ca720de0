#include "mechanics/generalised_system.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <string>

#include "core/error.h"

namespace arreg::mechanics {

void GeneralisedSystem::Build(const GeneralisedState& state,
                              const std::vector<GeneralisedEnergyTerm*>& terms) {
  const int nn = state.num_nodes();
  std::vector<std::vector<int>> adjacency(nn);
  for (int v = 0; v < nn; ++v) adjacency[v].push_back(v);
  std::vector<std::vector<int>> stencils;
  for (const GeneralisedEnergyTerm* term : terms) {
    stencils.clear();
    term->AppendStencils(&stencils);
    for (const std::vector<int>& s : stencils) {
      for (const int a : s)
        ARREG_CHECK_INPUT(a >= 0 && a < nn, "", term->name() + " stencil",
                          "node index " + std::to_string(a) + " out of range (", nn, " nodes)");
      for (const int a : s)
        for (const int b : s)
          if (a != b) adjacency[b].push_back(a);
    }
  }
  node_dofs_.resize(nn);
  column_stride_.resize(nn);
  neighbour_begin_.assign(nn + 1, 0);
  neighbours_.clear();
  long long nnz = 0;
  for (int v = 0; v < nn; ++v) {
    std::vector<int>& rows = adjacency[v];
    std::sort(rows.begin(), rows.end());
    rows.erase(std::unique(rows.begin(), rows.end()), rows.end());
    node_dofs_[v] = state.node_dofs(v);
    int stride = 0;
    for (const int u : rows) stride += state.node_dofs(u);
    column_stride_[v] = stride;
    nnz += static_cast<long long>(stride) * node_dofs_[v];
    neighbours_.insert(neighbours_.end(), rows.begin(), rows.end());
    neighbour_begin_[v + 1] = static_cast<int>(neighbours_.size());
  }
  ARREG_CHECK_INPUT(nnz < (1LL << 31), "", "generalised system",
                    "too many nonzeros for 32-bit indices");

  const int n = state.num_dofs();
  matrix_.resize(n, n);
  matrix_.resizeNonZeros(static_cast<int>(nnz));
  int* outer = matrix_.outerIndexPtr();
  int* inner = matrix_.innerIndexPtr();
  neighbour_slot_.resize(neighbours_.size());
  int k = 0;
  for (int v = 0; v < nn; ++v) {
    const int o = state.dof_offset(v);
    for (int c = 0; c < node_dofs_[v]; ++c) {
      outer[o + c] = k;
      for (int i = neighbour_begin_[v]; i < neighbour_begin_[v + 1]; ++i) {
        const int u = neighbours_[i];
        if (c == 0) neighbour_slot_[i] = k;
        for (int r = 0; r < node_dofs_[u]; ++r) inner[k++] = state.dof_offset(u) + r;
      }
    }
  }
  outer[n] = k;
  SetZero();
  dirichlet_mask_.clear();
  built_ = true;
  topology_version_ = state.topology_version();
  terms_.assign(terms.begin(), terms.end());
}

bool GeneralisedSystem::Refresh(const GeneralisedState& state,
                                const std::vector<GeneralisedEnergyTerm*>& terms) {
  const bool same_terms =
      terms.size() == terms_.size() && std::equal(terms.begin(), terms.end(), terms_.begin());
  if (built_ && same_terms && topology_version_ == state.topology_version() &&
      num_nodes() == state.num_nodes())
    return false;
  Build(state, terms);
  return true;
}

int GeneralisedSystem::BlockSlot(int node_a, int node_b) const {
  const int* begin = neighbours_.data() + neighbour_begin_[node_b];
  const int* end = neighbours_.data() + neighbour_begin_[node_b + 1];
  const int* it = std::lower_bound(begin, end, node_a);
  if (it == end || *it != node_a) return -1;
  return neighbour_slot_[it - neighbours_.data()];
}

void GeneralisedSystem::AddBlock(int node_a, int node_b,
                                 const Eigen::Ref<const Eigen::MatrixXd>& block, double scale) {
  ARREG_CHECK_INPUT(node_a >= 0 && node_a < num_nodes() && node_b >= 0 && node_b < num_nodes(), "",
                    "Hessian block", "node pair (", node_a, ", ", node_b, ") out of range");
  const int da = node_dofs_[node_a], db = node_dofs_[node_b];
  ARREG_CHECK_INPUT(block.rows() == da && block.cols() == db, "", "Hessian block", "block (",
                    node_a, ", ", node_b, ") is ", block.rows(), " x ", block.cols(),
                    ", the nodes have ", da, " and ", db, " DOFs");
  const int ab = BlockSlot(node_a, node_b);
  ARREG_CHECK_INPUT(ab >= 0, "", "Hessian block", "node pair (", node_a, ", ", node_b,
                    ") is in no stencil (pattern not rebuilt after a stencil change?)");
  double* v = values();
  const int sb = column_stride_[node_b];
  for (int c = 0; c < db; ++c)
    for (int r = 0; r < da; ++r) v[ab + c * sb + r] += scale * block(r, c);
  if (node_a == node_b) return;
  const int ba = BlockSlot(node_b, node_a);
  const int sa = column_stride_[node_a];
  for (int c = 0; c < da; ++c)
    for (int r = 0; r < db; ++r) v[ba + c * sa + r] += scale * block(c, r);
}

void GeneralisedSystem::ApplyDirichlet(const std::vector<char>& fixed_dof_mask) {
  ARREG_ASSERT(static_cast<int>(fixed_dof_mask.size()) == num_dofs(), "");
  if (fixed_dof_mask != dirichlet_mask_) {
    dirichlet_mask_ = fixed_dof_mask;
    dirichlet_zero_.clear();
    dirichlet_one_.clear();
    const int n = num_dofs();
    const int* outer = matrix_.outerIndexPtr();
    const int* inner = matrix_.innerIndexPtr();
    for (int col = 0; col < n; ++col) {
      const bool col_fixed = fixed_dof_mask[col] != 0;
      for (int k = outer[col]; k < outer[col + 1]; ++k) {
        const int row = inner[k];
        if (col_fixed || fixed_dof_mask[row])
          (row == col ? dirichlet_one_ : dirichlet_zero_).push_back(k);
      }
    }
  }
  double* v = values();
  for (const int k : dirichlet_zero_) v[k] = 0.0;
  for (const int k : dirichlet_one_) v[k] = 1.0;
}

void ProjectToPsd(Eigen::Ref<Eigen::MatrixXd> block) {
  ARREG_ASSERT(block.rows() == block.cols(), "");
  const Eigen::MatrixXd sym = 0.5 * (block + block.transpose());
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(sym);
  if (eig.eigenvalues().minCoeff() >= 0.0) {
    block = sym;
    return;
  }
  const Eigen::VectorXd clamped = eig.eigenvalues().cwiseMax(0.0);
  block = eig.eigenvectors() * clamped.asDiagonal() * eig.eigenvectors().transpose();
}

}  // namespace arreg::mechanics
