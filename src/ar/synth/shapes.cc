#include "ar/synth/shapes.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <unordered_map>

#include "core/error.h"
#include "core/mesh_ops.h"

namespace arreg::synth {

void BoxUnionMeshOptions::Check() const {
  ARREG_CHECK_INPUT((cell_mm.array() > 0).all(), "", "cell_mm", "grid spacing must be positive");
  ARREG_CHECK_INPUT(tets_per_cell == 5 || tets_per_cell == 6, "", "tets_per_cell",
                    "must be 5 or 6, got ", tets_per_cell);
}

LabeledTetMesh MeshBoxUnion(const std::vector<Eigen::AlignedBox3d>& boxes_mm,
                            const BoxUnionMeshOptions& options) {
  options.Check();
  ARREG_CHECK_INPUT(!boxes_mm.empty(), "", "boxes", "need at least one box");
  Eigen::AlignedBox3d bounds;
  for (const auto& b : boxes_mm) {
    ARREG_CHECK_INPUT(!b.isEmpty() && (b.sizes().array() > 0).all(), "", "boxes",
                      "boxes must have positive size");
    bounds.extend(b);
  }
  Eigen::Vector3i dims;
  for (int a = 0; a < 3; ++a)
    dims[a] = std::max(1, static_cast<int>(std::lround(bounds.sizes()[a] / options.cell_mm[a])));
  const Eigen::Vector3d cell = bounds.sizes().cwiseQuotient(dims.cast<double>());
  auto cell_inside = [&](int i, int j, int k) {
    const Eigen::Vector3d centre =
        bounds.min() + cell.cwiseProduct(Eigen::Vector3d(i + 0.5, j + 0.5, k + 0.5));
    for (const auto& b : boxes_mm)
      if (b.contains(centre)) return true;
    return false;
  };
  // Grid nodes are numbered in first-use order so that unused nodes never appear.
  std::vector<int> node_index(static_cast<size_t>(dims[0] + 1) * (dims[1] + 1) * (dims[2] + 1), -1);
  std::vector<Eigen::Vector3d> nodes;
  std::vector<Eigen::Vector4i> tets;
  auto node = [&](int i, int j, int k) {
    const size_t key = (static_cast<size_t>(k) * (dims[1] + 1) + j) * (dims[0] + 1) + i;
    if (node_index[key] < 0) {
      node_index[key] = static_cast<int>(nodes.size());
      nodes.push_back(bounds.min() + cell.cwiseProduct(Eigen::Vector3d(i, j, k)));
    }
    return node_index[key];
  };
  // Corner b of a cell: bit 0 = +x, bit 1 = +y, bit 2 = +z.
  static constexpr int kKuhn[6][4] = {{0, 1, 3, 7}, {0, 1, 5, 7}, {0, 2, 3, 7},
                                      {0, 2, 6, 7}, {0, 4, 5, 7}, {0, 4, 6, 7}};
  static constexpr int kFiveEven[5][4] = {
      {0, 1, 2, 4}, {3, 2, 1, 7}, {5, 4, 7, 1}, {6, 7, 4, 2}, {1, 2, 4, 7}};
  static constexpr int kFiveOdd[5][4] = {
      {1, 0, 3, 5}, {2, 3, 0, 6}, {4, 5, 6, 0}, {7, 6, 5, 3}, {0, 3, 5, 6}};
  for (int k = 0; k < dims[2]; ++k)
    for (int j = 0; j < dims[1]; ++j)
      for (int i = 0; i < dims[0]; ++i) {
        if (!cell_inside(i, j, k)) continue;
        int corner[8];
        for (int b = 0; b < 8; ++b)
          corner[b] = node(i + (b & 1), j + ((b >> 1) & 1), k + ((b >> 2) & 1));
        const int(*split)[4] = options.tets_per_cell == 6 ? kKuhn
                               : ((i + j + k) % 2 == 0)   ? kFiveEven
                                                          : kFiveOdd;
        for (int t = 0; t < options.tets_per_cell; ++t)
          tets.emplace_back(corner[split[t][0]], corner[split[t][1]], corner[split[t][2]],
                            corner[split[t][3]]);
      }
  ARREG_CHECK_INPUT(!tets.empty(), "", "boxes", "no grid cell lies inside the boxes");
  LabeledTetMesh out;
  out.mesh.vertices.resize(nodes.size(), 3);
  for (size_t v = 0; v < nodes.size(); ++v) out.mesh.vertices.row(v) = nodes[v].transpose();
  out.mesh.tetrahedra.resize(tets.size(), 4);
  for (size_t t = 0; t < tets.size(); ++t) out.mesh.tetrahedra.row(t) = tets[t].transpose();
  FixOrientation(&out.mesh);
  out.labels = Eigen::VectorXi::Ones(out.mesh.num_tetrahedra());
  return out;
}

RowMatX3i BoundaryFaces(const RowMatX4i& tets, const std::vector<bool>& include,
                        std::vector<std::pair<int, int>>* owner) {
  struct Entry {
    int count = 0;
    int tet = -1, local = -1;
  };
  std::map<std::array<int, 3>, Entry> faces;
  for (int t = 0; t < tets.rows(); ++t) {
    if (!include.empty() && !include[t]) continue;
    for (int k = 0; k < 4; ++k) {
      std::array<int, 3> key = TetFace(tets, t, k);
      std::sort(key.begin(), key.end());
      Entry& e = faces[key];
      ++e.count;
      e.tet = t;
      e.local = k;
    }
  }
  // Output in (tet, local face) order so the result does not depend on vertex numbering.
  std::vector<std::pair<int, int>> found;
  for (const auto& kv : faces)
    if (kv.second.count == 1) found.emplace_back(kv.second.tet, kv.second.local);
  std::sort(found.begin(), found.end());
  RowMatX3i out(found.size(), 3);
  for (size_t f = 0; f < found.size(); ++f) {
    const auto face = TetFace(tets, found[f].first, found[f].second);
    out.row(f) << face[0], face[1], face[2];
  }
  if (owner) *owner = std::move(found);
  return out;
}

}  // namespace arreg::synth
