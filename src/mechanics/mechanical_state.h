// The mechanical state of a tetrahedral body: topology, rest and current
// positions, velocities, per-element materials and rest data, fixed vertices.
// The cutting module changes it locally (new vertices, replaced tetrahedra).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "core/mesh.h"
#include "mechanics/tet_element.h"

namespace arreg::mechanics {

class MechanicalState {
 public:
  // Builds the state from a tetrahedral mesh (rest = current positions, zero
  // velocities) with one material for all elements or one per element.
  // Throws arreg::Error for an empty mesh, an index out of range, a material
  // count that is neither 1 nor #T, or an element with non-positive volume
  // (the message names the tetrahedron).
  MechanicalState(const TetMesh& mesh, const Material& material);
  MechanicalState(const TetMesh& mesh, const std::vector<Material>& materials);

  int num_vertices() const { return static_cast<int>(rest_positions_.rows()); }
  int num_tetrahedra() const { return static_cast<int>(tetrahedra_.rows()); }
  int num_dofs() const { return 3 * num_vertices(); }

  const RowMatX3d& rest_positions() const { return rest_positions_; }  // (#V x 3) mm
  const RowMatX3d& positions() const { return positions_; }            // (#V x 3) mm
  const RowMatX3d& velocities() const { return velocities_; }          // (#V x 3) mm/s
  RowMatX3d& mutable_positions() { return positions_; }
  RowMatX3d& mutable_velocities() { return velocities_; }
  const RowMatX4i& tetrahedra() const { return tetrahedra_; }  // (#T x 4)
  const TetRestData& rest_data(int tet) const { return rest_data_[tet]; }
  const std::vector<TetRestData>& rest_data() const { return rest_data_; }
  const Material& material(int tet) const { return materials_[tet]; }

  // Current positions of the four vertices of `tet` (4 x 3).
  Eigen::Matrix<double, 4, 3> TetPositions(int tet, const RowMatX3d& positions) const {
    Eigen::Matrix<double, 4, 3> x;
    for (int a = 0; a < 4; ++a) x.row(a) = positions.row(tetrahedra_(tet, a));
    return x;
  }

  // Per-vertex state query.
  Eigen::Vector3d rest_position(int v) const { return rest_positions_.row(v).transpose(); }
  Eigen::Vector3d position(int v) const { return positions_.row(v).transpose(); }
  Eigen::Vector3d velocity(int v) const { return velocities_.row(v).transpose(); }
  // Lumped vertex masses in kg (a quarter of each incident element's mass).
  Eigen::VectorXd LumpedVertexMasses() const;
  double TotalMassKg() const;

  // Dirichlet constraints: a fixed vertex keeps its current position (set it
  // through mutable_positions() to prescribe a motion).
  void SetFixed(int vertex, bool fixed);
  void SetFixed(const std::vector<int>& vertices);  // adds to the fixed set
  bool is_fixed(int vertex) const { return fixed_[vertex] != 0; }
  const std::vector<char>& fixed_mask() const { return fixed_; }

  // Local topology changes for cutting. AddVertices appends vertices (rows of
  // the three matrices, same count) and returns their indices.
  std::vector<int> AddVertices(const RowMatX3d& rest, const RowMatX3d& current,
                               const RowMatX3d& velocity);
  // Removes the elements `removed` and adds `new_tetrahedra` (with one
  // material, or one per new element). New elements fill the freed slots
  // first (in the order given), then are appended; the elements that were last
  // move into remaining holes. Only the new elements' rest data are computed.
  // Returns, for each new element, its index. `moved` (optional) receives
  // pairs (old index, new index) for elements that changed index.
  // Throws arreg::Error (state unchanged) for invalid indices or an element of
  // non-positive rest volume.
  std::vector<int> ReplaceTetrahedra(const std::vector<int>& removed,
                                     const RowMatX4i& new_tetrahedra,
                                     const std::vector<Material>& new_materials,
                                     std::vector<std::pair<int, int>>* moved = nullptr);

  // Moves the rest positions of `vertices` to the rows of `rest` (#vertices x 3,
  // mm) and recomputes the rest data of the incident elements only (e.g. after
  // a cut snapped vertices onto the cut surface). Current positions and
  // velocities are left to the caller. Counts as a topology change (the vertex
  // masses change). Throws arreg::Error (state unchanged) for a bad index, a row
  // count mismatch, a repeated vertex or an incident element of non-positive
  // rest volume.
  void SetRestPositions(const std::vector<int>& vertices, const RowMatX3d& rest);

  // Incremented by every change of the element list / vertex count (sparsity
  // patterns are rebuilt when it changes) and of the fixed set.
  std::uint64_t topology_version() const { return topology_version_; }
  std::uint64_t constraint_version() const { return constraint_version_; }

  // The current configuration as a mesh (positions, tetrahedra).
  TetMesh CurrentMesh() const;
  TetMesh RestMesh() const;

 private:
  void Init(const TetMesh& mesh, const std::vector<Material>& materials);

  RowMatX3d rest_positions_, positions_, velocities_;
  RowMatX4i tetrahedra_;
  std::vector<Material> materials_;
  std::vector<TetRestData> rest_data_;
  std::vector<char> fixed_;
  std::uint64_t topology_version_ = 1;
  std::uint64_t constraint_version_ = 1;
};

}  // namespace arreg::mechanics
