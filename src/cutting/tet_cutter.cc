#include "cutting/tet_cutter.h"

#include <algorithm>
#include <cmath>
#include <unordered_map>
#include <utility>

#include "core/error.h"
#include "cutting/predicates.h"
#include "cutting/tet_cut_operation.h"

namespace arreg::cutting {

using cut_internal::CutOperation;
using cut_internal::EdgeKey;
using cut_internal::FaceKey;
using cut_internal::kEdgeLocal;
using cut_internal::kFaceOrder;
using cut_internal::Tet;

const char* RemeshMethodName(RemeshMethod method) { return NameOf(kRemeshMethodNames, method); }

RemeshMethod ParseRemeshMethod(const std::string& name, const std::string& file,
                               const std::string& field) {
  return ParseName(kRemeshMethodNames, name, file, field);
}

void CutOptions::Check() const {
  ARREG_CHECK_INPUT(std::isfinite(snap_epsilon) && snap_epsilon >= 0, "", "CutOptions.snap_epsilon",
                    "must be finite and >= 0, got ", snap_epsilon);
  ARREG_CHECK_INPUT(std::isfinite(on_surface_tolerance) && on_surface_tolerance >= 0, "",
                    "CutOptions.on_surface_tolerance", "must be finite and >= 0, got ",
                    on_surface_tolerance);
  ARREG_CHECK_INPUT(min_barycentric > 0 && min_barycentric < 0.25, "", "CutOptions.min_barycentric",
                    "must be in (0, 0.25), got ", min_barycentric);
  ARREG_CHECK_INPUT(std::isfinite(min_flip_quality) && min_flip_quality >= 0, "",
                    "CutOptions.min_flip_quality", "must be finite and >= 0, got ",
                    min_flip_quality);
  ARREG_CHECK_INPUT(std::isfinite(min_element_quality) && min_element_quality >= 0, "",
                    "CutOptions.min_element_quality", "must be finite and >= 0, got ",
                    min_element_quality);
  ARREG_CHECK_INPUT(feature_angle_deg >= 0 && feature_angle_deg <= 180, "",
                    "CutOptions.feature_angle_deg", "must be in [0, 180], got ", feature_angle_deg);
}

CuttableMesh::CuttableMesh(const TetMesh& rest_mesh) {
  Init(rest_mesh, rest_mesh.vertices, RowMatX3d::Zero(rest_mesh.vertices.rows(), 3));
}

CuttableMesh::CuttableMesh(const TetMesh& rest_mesh, const RowMatX3d& current_positions,
                           const RowMatX3d& velocities) {
  Init(rest_mesh, current_positions, velocities);
}

void CuttableMesh::Init(const TetMesh& mesh, const RowMatX3d& current,
                        const RowMatX3d& velocities) {
  const int nv = mesh.num_vertices();
  ARREG_CHECK_INPUT(current.rows() == nv && velocities.rows() == nv, "", "CuttableMesh",
                    "current positions and velocities need ", nv, " rows");
  ARREG_CHECK_INPUT(nv < (1 << 21), "", "CuttableMesh", "at most 2^21 vertices are supported");
  rest_.resize(nv);
  current_.resize(nv);
  velocity_.resize(nv);
  for (int i = 0; i < nv; ++i) {
    rest_[i] = mesh.vertices.row(i).transpose();
    current_[i] = current.row(i).transpose();
    velocity_[i] = velocities.row(i).transpose();
  }
  tets_.resize(mesh.num_tetrahedra());
  vertex_tets_.assign(nv, {});
  double edge_sum = 0;
  std::unordered_set<std::uint64_t> edges;
  for (int t = 0; t < mesh.num_tetrahedra(); ++t) {
    for (int k = 0; k < 4; ++k) {
      const int v = mesh.tetrahedra(t, k);
      ARREG_CHECK_INPUT(v >= 0 && v < nv, "", "CuttableMesh", "tetrahedron ", t,
                        " refers to vertex ", v, " of ", nv);
      tets_[t][k] = v;
      vertex_tets_[v].push_back(t);
    }
    const Tet& q = tets_[t];
    ARREG_CHECK_INPUT(Orient3d(rest_[q[0]], rest_[q[1]], rest_[q[2]], rest_[q[3]]) > 0, "",
                      "CuttableMesh", "tetrahedron ", t, " has non-positive rest volume");
    for (const auto& e : kEdgeLocal)
      if (edges.insert(EdgeKey(q[e[0]], q[e[1]])).second)
        edge_sum += (rest_[q[e[0]]] - rest_[q[e[1]]]).norm();
  }
  mean_edge_length_ = edges.empty() ? 0.0 : edge_sum / edges.size();
}

void CuttableMesh::SetDeformation(const RowMatX3d& current, const RowMatX3d& velocities) {
  ARREG_CHECK_INPUT(current.rows() == num_vertices() && velocities.rows() == num_vertices(), "",
                    "CuttableMesh::SetDeformation", "current positions and velocities need ",
                    num_vertices(), " rows, got ", current.rows(), " and ", velocities.rows());
  ARREG_CHECK_INPUT(current.allFinite() && velocities.allFinite(), "",
                    "CuttableMesh::SetDeformation", "non-finite position or velocity");
  for (int i = 0; i < num_vertices(); ++i) {
    current_[i] = current.row(i).transpose();
    velocity_[i] = velocities.row(i).transpose();
  }
}

TetMesh CuttableMesh::RestMesh() const {
  TetMesh m;
  m.vertices.resize(num_vertices(), 3);
  for (int i = 0; i < num_vertices(); ++i) m.vertices.row(i) = rest_[i].transpose();
  m.tetrahedra.resize(num_tetrahedra(), 4);
  for (int t = 0; t < num_tetrahedra(); ++t)
    for (int k = 0; k < 4; ++k) m.tetrahedra(t, k) = tets_[t][k];
  return m;
}

TetMesh CuttableMesh::CurrentMesh() const {
  TetMesh m = RestMesh();
  for (int i = 0; i < num_vertices(); ++i) m.vertices.row(i) = current_[i].transpose();
  return m;
}

bool CuttableMesh::BoundaryManifoldAround(const std::vector<int>& vertices) const {
  for (int v : vertices) {
    std::unordered_map<std::uint64_t, int> count;
    std::vector<std::array<int, 3>> outward;
    for (int t : vertex_tets_[v]) {
      const Tet& q = tets_[t];
      for (int lf = 0; lf < 4; ++lf) {
        const int a = q[kFaceOrder[lf][0]], b = q[kFaceOrder[lf][1]], c = q[kFaceOrder[lf][2]];
        if (a != v && b != v && c != v) continue;
        if (count[FaceKey(a, b, c)]++ == 0) outward.push_back({a, c, b});
      }
    }
    // The boundary faces around v must form one fan: their links one cycle.
    std::unordered_map<int, int> next;
    for (const auto& f : outward) {
      if (count[FaceKey(f[0], f[1], f[2])] != 1) continue;
      int k = 0;
      while (f[k] != v) ++k;
      if (!next.emplace(f[(k + 1) % 3], f[(k + 2) % 3]).second) return false;
    }
    if (next.empty()) continue;
    size_t steps = 0;
    const int start = next.begin()->first;
    int c = start;
    do {
      auto it = next.find(c);
      if (it == next.end()) return false;
      c = it->second;
      ++steps;
    } while (c != start && steps <= next.size());
    if (steps != next.size()) return false;
  }
  return true;
}

CutSummary CuttableMesh::Cut(const CutSurface& surface, const CutOptions& options,
                             CutChange* change) {
  options.Check();
  surface.Check();
  CutSummary summary = CutKeepingManifold(surface, options, change);
  CutOptions retry = options;
  for (double tolerance : kSliverRetryTolerances) {
    if (!summary.sliver) break;
    if (tolerance <= retry.on_surface_tolerance) continue;
    retry.on_surface_tolerance = tolerance;
    summary = CutKeepingManifold(surface, retry, change);
  }
  return summary;
}

CutSummary CuttableMesh::CutKeepingManifold(const CutSurface& surface, const CutOptions& options,
                                            CutChange* change) {
  // A snapshot lets an event that would leave a pinched (non-manifold) boundary be
  // undone: it is retried without snapping (the usual cause), then rejected.
  const CuttableMesh before = *this;
  CutOptions opt = options;
  for (int attempt = 0; attempt < 2; ++attempt) {
    CutChange local;
    CutOperation event(this, surface, opt);
    CutSummary summary = event.Run(&local);
    summary.on_surface_tolerance = opt.on_surface_tolerance;
    if (summary.status != CutStatus::kCut) return summary;
    std::vector<int> touched;
    for (int t : local.removed_tetrahedra)
      for (int v : tets_[t]) touched.push_back(v);
    for (int t = local.num_tetrahedra_before; t < num_tetrahedra(); ++t)
      for (int v : tets_[t]) touched.push_back(v);
    std::sort(touched.begin(), touched.end());
    touched.erase(std::unique(touched.begin(), touched.end()), touched.end());
    if (BoundaryManifoldAround(touched)) {
      if (change) *change = std::move(local);
      return summary;
    }
    *this = before;
    if (opt.snap_epsilon == 0 && !opt.move_front_vertices) break;
    opt.snap_epsilon = 0;
    opt.move_front_vertices = false;
  }
  CutSummary rejected;
  rejected.status = CutStatus::kRejected;
  rejected.on_surface_tolerance = opt.on_surface_tolerance;
  rejected.message =
      "the separation would leave a non-manifold boundary (S is not resolved by "
      "the mesh there)";
  return rejected;
}

}  // namespace arreg::cutting
