// The sparse symmetric system matrix over generalised DOFs (point nodes with 3,
// frame nodes with 6): its pattern is the union of the energy terms' stencils,
// and terms add dense node blocks through precomputed slots (HessianSink).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "mechanics/generalised_state.h"
#include "mechanics/system_matrix.h"

namespace arreg::mechanics {

// Full symmetric CSC (both triangles stored, like SystemMatrix), so LinearSolver
// (CHOLMOD, CG) takes matrix() as it is. Column c of node b holds, for every
// node a coupled to b (sorted by index, b itself included), dofs(a) rows; the
// value of entry (dof_offset(a) + r, dof_offset(b) + c) is at
// BlockSlot(a, b) + c * column_stride(b) + r.
class GeneralisedSystem : public HessianSink {
 public:
  GeneralisedSystem() = default;

  // Builds the pattern: each node's diagonal block and every block between two
  // nodes of one stencil of a term. Throws arreg::Error for a stencil node out
  // of range. Values are zero afterwards.
  void Build(const GeneralisedState& state, const std::vector<GeneralisedEnergyTerm*>& terms);
  // Builds when never built, when the state's topology_version changed or the
  // list of terms differs from the last Build; returns true when it built.
  // A term whose stencils change without a new node (a cut replacing elements)
  // needs Invalidate() first.
  bool Refresh(const GeneralisedState& state, const std::vector<GeneralisedEnergyTerm*>& terms);
  void Invalidate() { built_ = false; }

  int num_nodes() const { return static_cast<int>(node_dofs_.size()); }
  int num_dofs() const { return static_cast<int>(matrix_.rows()); }
  int nonzeros() const { return static_cast<int>(matrix_.nonZeros()); }
  const SparseMatrixd& matrix() const { return matrix_; }
  double* values() { return matrix_.valuePtr(); }
  const double* values() const { return matrix_.valuePtr(); }
  void SetZero() { std::fill(values(), values() + nonzeros(), 0.0); }

  // Slot of block (a, b) (see above), or -1 when the pair is outside the pattern.
  // A binary search in b's sorted neighbour list (a dozen entries on a tet mesh).
  int BlockSlot(int node_a, int node_b) const;
  int column_stride(int node) const { return column_stride_[node]; }

  // HessianSink: adds scale * block at (a, b) and scale * block^T at (b, a)
  // (a != b); at (a, a) the block is added as given (terms pass it symmetric).
  // Throws arreg::Error for a pair outside the pattern or a block of the wrong size.
  void AddBlock(int node_a, int node_b, const Eigen::Ref<const Eigen::MatrixXd>& block,
                double scale) override;

  // Replaces every row and column of a fixed DOF (mask from
  // GeneralisedState::FixedDofMask) by those of the identity: Dirichlet
  // elimination with zero increment. The affected entries are found once per
  // mask and pattern (a scan of every nonzero), then only they are written.
  void ApplyDirichlet(const std::vector<char>& fixed_dof_mask);

 private:
  SparseMatrixd matrix_;
  std::vector<int> node_dofs_;        // 3 or 6 per node
  std::vector<int> column_stride_;    // nonzeros per scalar column of each node's columns
  std::vector<int> neighbour_begin_;  // CSR over nodes: neighbours of b in [begin[b], begin[b+1])
  std::vector<int> neighbours_;       // sorted neighbour node indices (b included)
  std::vector<int> neighbour_slot_;   // BlockSlot of (neighbours_[k], b)
  std::vector<char> dirichlet_mask_;  // the mask dirichlet_zero_/_one_ were found for
  std::vector<int> dirichlet_zero_;   // value indices set to 0 (fixed row or column, off-diagonal)
  std::vector<int> dirichlet_one_;    // value indices of fixed diagonal entries (set to 1)
  bool built_ = false;
  std::uint64_t topology_version_ = 0;
  std::vector<const GeneralisedEnergyTerm*> terms_;  // the terms of the last Build
};

// Replaces a symmetric dense block (an element Hessian) by its projection onto
// the positive semi-definite matrices: eigenvalues below zero are set to zero
// (the nearest PSD matrix in the Frobenius norm). The block is symmetrised
// first. For element terms whose geometric stiffness can be indefinite.
void ProjectToPsd(Eigen::Ref<Eigen::MatrixXd> block);

}  // namespace arreg::mechanics
