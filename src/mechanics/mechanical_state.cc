#include "mechanics/mechanical_state.h"

#include <algorithm>
#include <set>
#include <string>

#include "core/error.h"

namespace arreg::mechanics {

namespace {
std::string TetWhere(int tet) { return "tetrahedron " + std::to_string(tet); }
}  // namespace

MechanicalState::MechanicalState(const TetMesh& mesh, const Material& material) {
  Init(mesh, std::vector<Material>(1, material));
}

MechanicalState::MechanicalState(const TetMesh& mesh, const std::vector<Material>& materials) {
  Init(mesh, materials);
}

void MechanicalState::Init(const TetMesh& mesh, const std::vector<Material>& materials) {
  const int nv = mesh.num_vertices(), nt = mesh.num_tetrahedra();
  // An empty state (no vertices, no tetrahedra) stands for the missing organ of a scene of
  // thin structures only; otherwise both are needed.
  ARREG_CHECK_INPUT((nv > 0 && nt > 0) || (nv == 0 && nt == 0), "", "mesh",
                    "needs vertices and tetrahedra (got ", nv, " vertices, ", nt, " tetrahedra)");
  ARREG_CHECK_INPUT(materials.size() == 1 || static_cast<int>(materials.size()) == nt, "",
                    "materials", "expected 1 or ", nt, " materials, got ", materials.size());
  for (const Material& m : materials) m.Check();
  ARREG_CHECK_INPUT(nt == 0 || (mesh.tetrahedra.minCoeff() >= 0 && mesh.tetrahedra.maxCoeff() < nv),
                    "", "mesh.tetrahedra", "vertex index out of range [0, ", nv, ")");
  rest_positions_ = mesh.vertices;
  positions_ = mesh.vertices;
  velocities_ = RowMatX3d::Zero(nv, 3);
  tetrahedra_ = mesh.tetrahedra;
  fixed_.assign(nv, 0);
  materials_.resize(nt);
  rest_data_.resize(nt);
  for (int t = 0; t < nt; ++t) {
    materials_[t] = materials.size() == 1 ? materials[0] : materials[t];
    const bool ok = ComputeTetRestData(rest_positions_.row(tetrahedra_(t, 0)).transpose(),
                                       rest_positions_.row(tetrahedra_(t, 1)).transpose(),
                                       rest_positions_.row(tetrahedra_(t, 2)).transpose(),
                                       rest_positions_.row(tetrahedra_(t, 3)).transpose(),
                                       materials_[t], &rest_data_[t]);
    ARREG_CHECK_INPUT(ok, "", TetWhere(t), "non-positive rest volume ", rest_data_[t].volume_mm3,
                      " mm^3 (inverted or degenerate element; fix the orientation first)");
  }
}

Eigen::VectorXd MechanicalState::LumpedVertexMasses() const {
  Eigen::VectorXd m = Eigen::VectorXd::Zero(num_vertices());
  for (int t = 0; t < num_tetrahedra(); ++t)
    for (int a = 0; a < 4; ++a) m[tetrahedra_(t, a)] += 0.25 * rest_data_[t].mass_kg;
  return m;
}

double MechanicalState::TotalMassKg() const {
  double m = 0.0;
  for (const TetRestData& r : rest_data_) m += r.mass_kg;
  return m;
}

void MechanicalState::SetFixed(int vertex, bool fixed) {
  ARREG_CHECK_INPUT(vertex >= 0 && vertex < num_vertices(), "", "fixed vertex", "index ", vertex,
                    " out of range [0, ", num_vertices(), ")");
  fixed_[vertex] = fixed ? 1 : 0;
  ++constraint_version_;
}

void MechanicalState::SetFixed(const std::vector<int>& vertices) {
  for (int v : vertices) SetFixed(v, true);
}

std::vector<int> MechanicalState::AddVertices(const RowMatX3d& rest, const RowMatX3d& current,
                                              const RowMatX3d& velocity) {
  ARREG_CHECK_INPUT(rest.rows() == current.rows() && rest.rows() == velocity.rows(), "",
                    "AddVertices", "rest, current and velocity row counts differ (", rest.rows(),
                    ", ", current.rows(), ", ", velocity.rows(), ")");
  const int old_n = num_vertices(), add = static_cast<int>(rest.rows());
  auto grow = [&](RowMatX3d* m, const RowMatX3d& extra) {
    RowMatX3d g(old_n + add, 3);
    g.topRows(old_n) = *m;
    g.bottomRows(add) = extra;
    m->swap(g);
  };
  grow(&rest_positions_, rest);
  grow(&positions_, current);
  grow(&velocities_, velocity);
  fixed_.resize(old_n + add, 0);
  std::vector<int> ids(add);
  for (int i = 0; i < add; ++i) ids[i] = old_n + i;
  ++topology_version_;
  ++constraint_version_;
  return ids;
}

std::vector<int> MechanicalState::ReplaceTetrahedra(const std::vector<int>& removed,
                                                    const RowMatX4i& new_tetrahedra,
                                                    const std::vector<Material>& new_materials,
                                                    std::vector<std::pair<int, int>>* moved) {
  const int nt = num_tetrahedra(), nv = num_vertices();
  const int n_new = static_cast<int>(new_tetrahedra.rows());
  std::set<int> holes(removed.begin(), removed.end());
  ARREG_CHECK_INPUT(holes.size() == removed.size(), "", "ReplaceTetrahedra.removed",
                    "contains duplicate indices");
  ARREG_CHECK_INPUT(holes.empty() || (*holes.begin() >= 0 && *holes.rbegin() < nt), "",
                    "ReplaceTetrahedra.removed", "index out of range [0, ", nt, ")");
  ARREG_CHECK_INPUT(
      n_new == 0 || new_materials.size() == 1 || static_cast<int>(new_materials.size()) == n_new,
      "", "ReplaceTetrahedra.new_materials", "expected 1 or ", n_new, " materials, got ",
      new_materials.size());
  ARREG_CHECK_INPUT(
      n_new == 0 || (new_tetrahedra.minCoeff() >= 0 && new_tetrahedra.maxCoeff() < nv), "",
      "ReplaceTetrahedra.new_tetrahedra", "vertex index out of range [0, ", nv, ")");
  // Compute everything that can fail before changing the state.
  std::vector<TetRestData> new_rest(n_new);
  std::vector<Material> mats(n_new);
  for (int k = 0; k < n_new; ++k) {
    mats[k] = new_materials.size() == 1 ? new_materials[0] : new_materials[k];
    mats[k].Check();
    const bool ok = ComputeTetRestData(rest_positions_.row(new_tetrahedra(k, 0)).transpose(),
                                       rest_positions_.row(new_tetrahedra(k, 1)).transpose(),
                                       rest_positions_.row(new_tetrahedra(k, 2)).transpose(),
                                       rest_positions_.row(new_tetrahedra(k, 3)).transpose(),
                                       mats[k], &new_rest[k]);
    ARREG_CHECK_INPUT(ok, "", "ReplaceTetrahedra.new_tetrahedra row " + std::to_string(k),
                      "non-positive rest volume ", new_rest[k].volume_mm3, " mm^3");
  }

  std::vector<int> ids(n_new);
  const int final_count = nt - static_cast<int>(holes.size()) + n_new;
  RowMatX4i tets(std::max(nt, final_count), 4);
  tets.topRows(nt) = tetrahedra_;
  materials_.resize(std::max(nt, final_count));
  rest_data_.resize(std::max(nt, final_count));
  int appended = nt;
  for (int k = 0; k < n_new; ++k) {
    int slot;
    if (!holes.empty()) {
      slot = *holes.begin();
      holes.erase(holes.begin());
    } else {
      slot = appended++;
    }
    tets.row(slot) = new_tetrahedra.row(k);
    materials_[slot] = mats[k];
    rest_data_[slot] = new_rest[k];
    ids[k] = slot;
  }
  // Fill the remaining holes with elements from the end.
  int count = appended;
  while (!holes.empty()) {
    const int last = count - 1;
    if (holes.count(last)) {
      holes.erase(last);
    } else {
      const int hole = *holes.begin();
      holes.erase(holes.begin());
      tets.row(hole) = tets.row(last);
      materials_[hole] = materials_[last];
      rest_data_[hole] = rest_data_[last];
      if (moved) moved->emplace_back(last, hole);
      for (int& id : ids)
        if (id == last) id = hole;
    }
    --count;
  }
  ARREG_ASSERT(count == final_count, "");
  tetrahedra_ = tets.topRows(count);
  materials_.resize(count);
  rest_data_.resize(count);
  ++topology_version_;
  return ids;
}

void MechanicalState::SetRestPositions(const std::vector<int>& vertices, const RowMatX3d& rest) {
  const int nv = num_vertices();
  ARREG_CHECK_INPUT(static_cast<int>(rest.rows()) == static_cast<int>(vertices.size()), "",
                    "SetRestPositions.rest", "expected ", vertices.size(), " rows, got ",
                    rest.rows());
  ARREG_CHECK_INPUT(rest.allFinite(), "", "SetRestPositions.rest", "non-finite position");
  std::vector<char> moved(nv, 0);
  for (int v : vertices) {
    ARREG_CHECK_INPUT(v >= 0 && v < nv, "", "SetRestPositions.vertices", "index ", v,
                      " out of range [0, ", nv, ")");
    ARREG_CHECK_INPUT(!moved[v], "", "SetRestPositions.vertices", "vertex ", v, " repeated");
    moved[v] = 1;
  }
  if (vertices.empty()) return;
  RowMatX3d new_rest = rest_positions_;
  for (size_t i = 0; i < vertices.size(); ++i) new_rest.row(vertices[i]) = rest.row(i);
  // Compute everything that can fail before changing the state.
  std::vector<std::pair<int, TetRestData>> updated;
  for (int t = 0; t < num_tetrahedra(); ++t) {
    if (!moved[tetrahedra_(t, 0)] && !moved[tetrahedra_(t, 1)] && !moved[tetrahedra_(t, 2)] &&
        !moved[tetrahedra_(t, 3)])
      continue;
    TetRestData data;
    const bool ok = ComputeTetRestData(
        new_rest.row(tetrahedra_(t, 0)).transpose(), new_rest.row(tetrahedra_(t, 1)).transpose(),
        new_rest.row(tetrahedra_(t, 2)).transpose(), new_rest.row(tetrahedra_(t, 3)).transpose(),
        materials_[t], &data);
    ARREG_CHECK_INPUT(ok, "", "SetRestPositions: " + TetWhere(t), "non-positive rest volume ",
                      data.volume_mm3, " mm^3 after the move");
    updated.emplace_back(t, data);
  }
  rest_positions_.swap(new_rest);
  for (const auto& [t, data] : updated) rest_data_[t] = data;
  ++topology_version_;
}

TetMesh MechanicalState::CurrentMesh() const {
  TetMesh m;
  m.vertices = positions_;
  m.tetrahedra = tetrahedra_;
  return m;
}

TetMesh MechanicalState::RestMesh() const {
  TetMesh m;
  m.vertices = rest_positions_;
  m.tetrahedra = tetrahedra_;
  return m;
}

}  // namespace arreg::mechanics
