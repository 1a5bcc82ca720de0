#include "cutting/quadratic_cutter.h"

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <limits>
#include <tuple>
#include <unordered_set>
#include <utility>

#include "core/error.h"
#include "cutting/tet_cut_operation.h"
#include "mechanics/bernstein_nonlinear.h"
#include "mechanics/curved_tet.h"

namespace arreg::cutting {

namespace {

using Vec3 = Eigen::Vector3d;
using Tet = std::array<int, 4>;

using cut_internal::EdgeKey;

// The control points of a degree-2 element in BernsteinIndices(2) order: each is a corner
// (corner = i, other = -1) or the edge between two corners (i < j).
struct ControlSlot {
  int i = -1, j = -1;  // j = -1: the corner i
};
const std::vector<ControlSlot>& QuadraticSlots() {
  static const std::vector<ControlSlot> slots = [] {
    std::vector<ControlSlot> out;
    for (const std::array<int, 4>& alpha : mechanics::BernsteinIndices(2)) {
      ControlSlot s;
      for (int k = 0; k < 4; ++k) {
        if (alpha[k] == 2) s.i = k;
        if (alpha[k] == 1) (s.i < 0 ? s.i : s.j) = k;
      }
      out.push_back(s);
    }
    return out;
  }();
  return slots;
}

constexpr int kEdgePairs[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};

// The corner mesh of a degree-2 mesh.
TetMesh CornerMesh(const mechanics::HighOrderTetMesh& mesh) {
  ARREG_CHECK_INPUT(mesh.degree == 2, "", "degree", "quadratic cutting needs degree 2, got ",
                    mesh.degree);
  const std::vector<ControlSlot>& slots = QuadraticSlots();
  TetMesh corners;
  corners.vertices = mesh.nodes.topRows(mesh.num_vertices);
  corners.tetrahedra.resize(mesh.num_elements(), 4);
  for (int t = 0; t < mesh.num_elements(); ++t)
    for (size_t k = 0; k < slots.size(); ++k)
      if (slots[k].j < 0) corners.tetrahedra(t, slots[k].i) = mesh.elements(t, k);
  return corners;
}

}  // namespace

QuadraticControlNet::QuadraticControlNet(const mechanics::HighOrderTetMesh& mesh,
                                         const RowMatX3d& positions, const RowMatX3d& velocities) {
  const TetMesh corners = CornerMesh(mesh);
  ARREG_CHECK_INPUT(positions.rows() == mesh.num_nodes(), "", "positions", "expected ",
                    mesh.num_nodes(), " rows, got ", positions.rows());
  ARREG_CHECK_INPUT(velocities.rows() == mesh.num_nodes(), "", "velocities", "expected ",
                    mesh.num_nodes(), " rows, got ", velocities.rows());
  const int nv = mesh.num_vertices;
  const std::vector<ControlSlot>& slots = QuadraticSlots();
  tets_.resize(mesh.num_elements());
  for (int t = 0; t < mesh.num_elements(); ++t)
    for (int i = 0; i < 4; ++i) {
      tets_[t][i] = corners.tetrahedra(t, i);
      ARREG_CHECK_INPUT(tets_[t][i] >= 0 && tets_[t][i] < nv, "", "elements", "element ", t,
                        " has corner ", tets_[t][i], " outside the ", nv, " vertices");
    }
  corners_.resize(nv);
  reference_.resize(nv);
  for (int v = 0; v < nv; ++v) {
    corners_[v] = {mesh.nodes.row(v).transpose(), positions.row(v).transpose(),
                   velocities.row(v).transpose()};
    reference_[v] = corners_[v].rest;
  }
  // Edge control points in the order of their node indices, so that RestMesh() gives the
  // input's numbering back before any cut.
  std::vector<std::pair<int, std::uint64_t>> node_edges;
  std::unordered_map<std::uint64_t, int> node_of_edge;
  for (int t = 0; t < mesh.num_elements(); ++t)
    for (size_t k = 0; k < slots.size(); ++k) {
      if (slots[k].j < 0) continue;
      const int a = tets_[t][slots[k].i], b = tets_[t][slots[k].j];
      const int node = mesh.elements(t, k);
      ARREG_CHECK_INPUT(node >= nv && node < mesh.num_nodes(), "", "elements", "element ", t,
                        " has edge control point ", node, " outside the edge nodes");
      const auto [it, inserted] = node_of_edge.emplace(EdgeKey(a, b), node);
      ARREG_CHECK_INPUT(it->second == node, "", "elements", "elements around edge (", a, ", ", b,
                        ") give it control points ", it->second, " and ", node);
      if (inserted) node_edges.emplace_back(node, EdgeKey(a, b));
    }
  std::sort(node_edges.begin(), node_edges.end());
  for (const auto& [node, key] : node_edges) {
    EdgeNode e;
    e.a = static_cast<int>(key >> 32);
    e.b = static_cast<int>(key & 0xffffffffu);
    e.data = {mesh.nodes.row(node).transpose(), positions.row(node).transpose(),
              velocities.row(node).transpose()};
    const Vec3 straight = 0.5 * (corners_[e.a].rest + corners_[e.b].rest);
    if ((e.data.rest - straight).norm() > 1e-10 * (corners_[e.a].rest - corners_[e.b].rest).norm())
      curved_ = true;
    edge_of_.emplace(key, static_cast<int>(edges_.size()));
    edges_.push_back(e);
  }
}

QuadraticCuttableMesh::QuadraticCuttableMesh(const mechanics::HighOrderTetMesh& mesh)
    : QuadraticCuttableMesh(mesh, mesh.nodes, RowMatX3d::Zero(mesh.num_nodes(), 3)) {}

QuadraticCuttableMesh::QuadraticCuttableMesh(const mechanics::HighOrderTetMesh& mesh,
                                             const RowMatX3d& positions,
                                             const RowMatX3d& velocities)
    : net_(mesh, positions, velocities),  // checks the mesh and the row counts first
      skeleton_(CornerMesh(mesh), positions.topRows(mesh.num_vertices),
                velocities.topRows(mesh.num_vertices)) {}

int QuadraticControlNet::EdgeNodeIndex(int a, int b) const {
  const auto it = edge_of_.find(EdgeKey(a, b));
  ARREG_ASSERT(it != edge_of_.end(), "edge (", a, ", ", b, ") has no control point");
  return it->second;
}

namespace {

// The elements an event removed, in the reference space (the skeleton's rest positions before
// the event), with their Bezier maps: where the event's new control points are evaluated.
class OldElements {
 public:
  OldElements(std::vector<Tet> tets, const std::vector<Vec3>& skeleton_rest,
              std::vector<std::array<Eigen::MatrixX3d, 3>> maps)
      : tets_(std::move(tets)), maps_(std::move(maps)) {
    origin_.resize(tets_.size());
    inverse_.resize(tets_.size());
    for (int e = 0; e < static_cast<int>(tets_.size()); ++e) {
      const Tet& t = tets_[e];
      Eigen::Matrix3d m;
      m << skeleton_rest[t[1]] - skeleton_rest[t[0]], skeleton_rest[t[2]] - skeleton_rest[t[0]],
          skeleton_rest[t[3]] - skeleton_rest[t[0]];
      origin_[e] = skeleton_rest[t[0]];
      inverse_[e] = m.inverse();  // the skeleton's elements have positive rest volume
      for (int v : t) around_[v].push_back(e);
    }
  }

  // The old element holding the reference point y and its coordinates there. Candidates are the
  // elements around `near` (old vertices the query was made from); among those holding y, the
  // one with most of `ancestors` among its corners wins: a point on an earlier crack is held by
  // the elements of both sides, and the side is the one whose vertices the query was made from.
  std::pair<int, Eigen::Vector4d> Locate(const Vec3& y, const std::vector<int>& near,
                                         const std::vector<int>& ancestors) const {
    std::vector<int> candidates;
    for (int v : near) {
      const auto it = around_.find(v);
      if (it != around_.end())
        candidates.insert(candidates.end(), it->second.begin(), it->second.end());
    }
    std::sort(candidates.begin(), candidates.end());
    candidates.erase(std::unique(candidates.begin(), candidates.end()), candidates.end());
    auto best = Best(y, ancestors, candidates);
    if (best.first < 0 || best.second.minCoeff() < -1e-6) {
      std::vector<int> all(tets_.size());
      for (int e = 0; e < static_cast<int>(all.size()); ++e) all[e] = e;
      best = Best(y, ancestors, all);
    }
    return best;
  }

  // Element e's maps (rest, current, velocity) at L.
  std::array<Vec3, 3> Evaluate(int e, const Eigen::Vector4d& L) const {
    std::array<Vec3, 3> out;
    for (int m = 0; m < 3; ++m) out[m] = mechanics::BezierTetPoint(2, maps_[e][m], L);
    return out;
  }

 private:
  std::pair<int, Eigen::Vector4d> Best(const Vec3& y, const std::vector<int>& ancestors,
                                       const std::vector<int>& candidates) const {
    constexpr double kInside = -1e-9;
    // Ranked by: holds y; then, among those holding it, the shared ancestors; then the smallest
    // coordinate (the deepest inside, or the least outside).
    using Rank = std::tuple<bool, int, double>;
    int best = -1;
    Rank best_rank;
    Eigen::Vector4d best_l = Eigen::Vector4d::Zero();
    for (int e : candidates) {
      const Vec3 xi = inverse_[e] * (y - origin_[e]);
      const Eigen::Vector4d l(1 - xi.sum(), xi[0], xi[1], xi[2]);
      const bool inside = l.minCoeff() >= kInside;
      int score = 0;
      if (inside)
        for (int a : ancestors) score += std::count(tets_[e].begin(), tets_[e].end(), a) > 0;
      const Rank rank{inside, score, l.minCoeff()};
      if (best < 0 || rank > best_rank) {
        best = e;
        best_rank = rank;
        best_l = l;
      }
    }
    return {best, best_l};
  }

  std::vector<Tet> tets_;
  std::vector<Vec3> origin_;
  std::vector<Eigen::Matrix3d> inverse_;
  std::vector<std::array<Eigen::MatrixX3d, 3>> maps_;  // rest, current, velocity control points
  std::unordered_map<int, std::vector<int>> around_;
};

}  // namespace

CutSummary QuadraticCuttableMesh::Cut(const CutSurface& surface, const CutOptions& options,
                                      QuadraticCutChange* change) {
  CutOptions opt = options;
  if (net_.curved()) {
    opt.min_flip_quality = std::numeric_limits<double>::max();
    opt.snap_epsilon = 0;
    opt.move_front_vertices = false;
  }
  CutChange cc;
  CutSummary summary = skeleton_.Cut(surface, opt, &cc);
  if (summary.status != CutStatus::kCut) return summary;
  net_.Follow(skeleton_.tetrahedra(), skeleton_.rest_positions(), cc, change);
  // The skeleton placed new corners on straight edges: give it the curved positions.
  const int nv = skeleton_.num_vertices();
  skeleton_.SetDeformation(net_.Positions().topRows(nv), net_.Velocities().topRows(nv));
  if (change) change->corners = std::move(cc);
  return summary;
}

void QuadraticControlNet::Follow(const std::vector<Tet>& tetrahedra,
                                 const std::vector<Vec3>& reference, const CutChange& cc,
                                 QuadraticCutChange* change) {
  const std::vector<Tet> old_tets = std::move(tets_);
  const std::vector<Vec3> old_rest = std::move(reference_);
  tets_ = tetrahedra;
  reference_ = reference;
  const int nv0 = static_cast<int>(old_rest.size());
  const int nt0 = static_cast<int>(old_tets.size());
  ARREG_ASSERT(cc.num_vertices_before == nv0 && cc.num_tetrahedra_before == nt0,
               "the control net does not follow this corner mesh");
  const std::vector<Tet>& tets = tets_;
  std::unordered_set<int> snapped;
  for (const SnappedVertex& s : cc.snapped) snapped.insert(s.index);
  const auto moved = [&](const Tet& t) {
    return std::any_of(t.begin(), t.end(), [&](int v) { return snapped.count(v) > 0; });
  };
  // The old elements whose slot changed (or that a snapped vertex reshaped), with their maps.
  std::vector<Tet> removed;
  std::vector<std::array<Eigen::MatrixX3d, 3>> maps;
  const std::vector<ControlSlot>& slots = QuadraticSlots();
  for (int t = 0; t < nt0; ++t) {
    if (tets[t] == old_tets[t] && !moved(old_tets[t])) continue;
    std::array<Eigen::MatrixX3d, 3> m;
    for (Eigen::MatrixX3d& x : m) x.resize(static_cast<Eigen::Index>(slots.size()), 3);
    for (size_t k = 0; k < slots.size(); ++k) {
      const ControlSlot& s = slots[k];
      const NodeData& d = s.j < 0 ? corners_[old_tets[t][s.i]]
                                  : edges_[EdgeNodeIndex(old_tets[t][s.i], old_tets[t][s.j])].data;
      m[0].row(k) = d.rest.transpose();
      m[1].row(k) = d.current.transpose();
      m[2].row(k) = d.velocity.transpose();
    }
    removed.push_back(old_tets[t]);
    maps.push_back(std::move(m));
  }
  const OldElements old(std::move(removed), old_rest, std::move(maps));

  // Every vertex's ancestors: the old vertices it was made from.
  const int nv = static_cast<int>(reference_.size());
  std::vector<std::vector<int>> ancestors(nv);
  for (int v = 0; v < nv0; ++v) ancestors[v] = {v};
  for (const NewVertex& n : cc.new_vertices)
    for (int p : n.parents)
      ancestors[n.index].insert(ancestors[n.index].end(), ancestors[p].begin(), ancestors[p].end());
  for (const SnappedVertex& s : cc.snapped) ancestors[s.index] = {s.index, s.a, s.b};
  for (const DuplicatedVertex& d : cc.duplicated) ancestors[d.index] = ancestors[d.original];
  for (std::vector<int>& a : ancestors) {
    std::sort(a.begin(), a.end());
    a.erase(std::unique(a.begin(), a.end()), a.end());
  }

  const std::vector<Vec3>& rest = reference_;
  const auto evaluate = [&](const Vec3& y, const std::vector<int>& near,
                            const std::vector<int>& from) {
    const auto [e, l] = old.Locate(y, near, from);
    ARREG_ASSERT(e >= 0, "no old element to place a new control point in");
    const std::array<Vec3, 3> x = old.Evaluate(e, l);
    return NodeData{x[0], x[1], x[2]};
  };
  // Corners: new and snapped vertices on the old maps, duplicates as copies.
  corners_.resize(nv);
  for (const NewVertex& n : cc.new_vertices)
    corners_[n.index] = evaluate(rest[n.index], ancestors[n.index], ancestors[n.index]);
  for (const SnappedVertex& s : cc.snapped)
    corners_[s.index] = evaluate(rest[s.index], ancestors[s.index], ancestors[s.index]);
  for (const DuplicatedVertex& d : cc.duplicated) corners_[d.index] = corners_[d.original];

  // Edges: kept when they were there with both ends in place, else made on the old map.
  std::unordered_set<std::uint64_t> used;
  for (const Tet& t : tets)
    for (const auto& pair : kEdgePairs) used.insert(EdgeKey(t[pair[0]], t[pair[1]]));
  std::vector<EdgeNode> edges;
  std::unordered_map<std::uint64_t, int> edge_of;
  std::vector<int> node_from_old(nv0 + edges_.size(), -1);
  for (int v = 0; v < nv0; ++v) node_from_old[v] = v;
  for (size_t k = 0; k < edges_.size(); ++k) {
    const EdgeNode& e = edges_[k];
    const std::uint64_t key = EdgeKey(e.a, e.b);
    if (!used.count(key) || snapped.count(e.a) || snapped.count(e.b)) continue;
    node_from_old[nv0 + k] = nv + static_cast<int>(edges.size());
    edge_of.emplace(key, static_cast<int>(edges.size()));
    edges.push_back(e);
  }
  const int kept = static_cast<int>(edges.size());
  for (const Tet& t : tets) {
    std::vector<int> from;
    for (int v : t) from.insert(from.end(), ancestors[v].begin(), ancestors[v].end());
    for (const auto& pair : kEdgePairs) {
      const int a = t[pair[0]], b = t[pair[1]];
      if (edge_of.count(EdgeKey(a, b))) continue;
      std::vector<int> near = ancestors[a];
      near.insert(near.end(), ancestors[b].begin(), ancestors[b].end());
      const NodeData mid = evaluate(0.5 * (rest[a] + rest[b]), near, from);
      EdgeNode e;
      e.a = std::min(a, b);
      e.b = std::max(a, b);
      const NodeData &da = corners_[a], &db = corners_[b];
      e.data = {2 * mid.rest - 0.5 * (da.rest + db.rest),
                2 * mid.current - 0.5 * (da.current + db.current),
                2 * mid.velocity - 0.5 * (da.velocity + db.velocity)};
      edge_of.emplace(EdgeKey(a, b), static_cast<int>(edges.size()));
      edges.push_back(e);
    }
  }
  const int num_old_edges = static_cast<int>(edges_.size());
  edges_ = std::move(edges);
  edge_of_ = std::move(edge_of);

  if (change) {
    change->node_from_old = std::move(node_from_old);
    change->num_new_edge_nodes = static_cast<int>(edges_.size()) - kept;
    change->num_removed_edge_nodes = num_old_edges - kept;
  }
}

void QuadraticControlNet::SetDeformation(const RowMatX3d& positions, const RowMatX3d& velocities) {
  ARREG_CHECK_INPUT(positions.rows() == num_nodes() && velocities.rows() == num_nodes(), "",
                    "positions", "expected ", num_nodes(), " rows, got ", positions.rows(), " and ",
                    velocities.rows());
  ARREG_CHECK_INPUT(positions.allFinite() && velocities.allFinite(), "", "positions",
                    "non-finite position or velocity");
  const int nv = num_corners();
  for (int i = 0; i < nv; ++i) {
    corners_[i].current = positions.row(i).transpose();
    corners_[i].velocity = velocities.row(i).transpose();
  }
  for (size_t k = 0; k < edges_.size(); ++k) {
    edges_[k].data.current = positions.row(nv + k).transpose();
    edges_[k].data.velocity = velocities.row(nv + k).transpose();
  }
}

void QuadraticCuttableMesh::SetDeformation(const RowMatX3d& positions,
                                           const RowMatX3d& velocities) {
  net_.SetDeformation(positions, velocities);
  const int nv = skeleton_.num_vertices();
  skeleton_.SetDeformation(positions.topRows(nv), velocities.topRows(nv));
}

mechanics::HighOrderTetMesh QuadraticControlNet::RestMesh() const {
  mechanics::HighOrderTetMesh out;
  out.degree = 2;
  const int nv = num_corners();
  out.num_vertices = nv;
  out.nodes.resize(num_nodes(), 3);
  for (int i = 0; i < nv; ++i) out.nodes.row(i) = corners_[i].rest.transpose();
  for (size_t k = 0; k < edges_.size(); ++k)
    out.nodes.row(nv + k) = edges_[k].data.rest.transpose();
  const std::vector<ControlSlot>& slots = QuadraticSlots();
  const std::vector<Tet>& tets = tets_;
  out.elements.resize(static_cast<int>(tets_.size()), static_cast<int>(slots.size()));
  for (int t = 0; t < static_cast<int>(tets_.size()); ++t)
    for (size_t k = 0; k < slots.size(); ++k)
      out.elements(t, k) = slots[k].j < 0
                               ? tets[t][slots[k].i]
                               : nv + EdgeNodeIndex(tets[t][slots[k].i], tets[t][slots[k].j]);
  return out;
}

RowMatX3d QuadraticControlNet::Gather(Eigen::Vector3d NodeData::*field) const {
  const int nv = num_corners();
  RowMatX3d x(num_nodes(), 3);
  for (int i = 0; i < nv; ++i) x.row(i) = (corners_[i].*field).transpose();
  for (size_t k = 0; k < edges_.size(); ++k) x.row(nv + k) = (edges_[k].data.*field).transpose();
  return x;
}

RowMatX3d QuadraticControlNet::Positions() const { return Gather(&NodeData::current); }

RowMatX3d QuadraticControlNet::Velocities() const { return Gather(&NodeData::velocity); }

QuadraticMeshInvariants CheckQuadraticMesh(const mechanics::HighOrderTetMesh& mesh) {
  ARREG_CHECK_INPUT(mesh.degree == 2, "", "degree", "expected degree 2, got ", mesh.degree);
  QuadraticMeshInvariants out;
  const std::vector<ControlSlot>& slots = QuadraticSlots();
  std::unordered_map<std::uint64_t, int> node_of_edge;
  std::unordered_map<int, std::uint64_t> edge_of_node;
  std::vector<double> quadrature_weights;
  std::vector<Eigen::Vector4d> points;
  mechanics::TetQuadrature(3, &points, &quadrature_weights);
  std::vector<double> weights = quadrature_weights;
  for (int i = 0; i < 4; ++i) {  // the corners, sampled with no weight
    points.push_back(Eigen::Vector4d::Unit(i));
    weights.push_back(0);
  }
  out.min_jacobian_ratio = std::numeric_limits<double>::infinity();
  for (int t = 0; t < mesh.num_elements(); ++t) {
    Tet c{};
    for (size_t k = 0; k < slots.size(); ++k)
      if (slots[k].j < 0) c[slots[k].i] = mesh.elements(t, k);
    bool mismatch = false;
    for (size_t k = 0; k < slots.size(); ++k) {
      if (slots[k].j < 0) continue;
      const std::uint64_t key = EdgeKey(c[slots[k].i], c[slots[k].j]);
      const int node = mesh.elements(t, k);
      const auto [it, inserted] = node_of_edge.emplace(key, node);
      mismatch |= it->second != node;
      if (inserted) {
        const auto [jt, fresh] = edge_of_node.emplace(node, key);
        out.num_shared_edge_nodes += !fresh || node < mesh.num_vertices;
      }
    }
    out.num_edge_mismatches += mismatch;
    const Eigen::MatrixX3d control = mechanics::ElementControlPoints(mesh, mesh.nodes, t);
    const Vec3 p0 = mesh.nodes.row(c[0]), p1 = mesh.nodes.row(c[1]), p2 = mesh.nodes.row(c[2]),
               p3 = mesh.nodes.row(c[3]);
    const double six_v = (p1 - p0).dot((p2 - p0).cross(p3 - p0));
    bool nonpositive = false;
    for (size_t q = 0; q < points.size(); ++q) {
      const double det = mechanics::BezierTetJacobian(2, control, points[q]).determinant();
      nonpositive |= !(det > 0);
      out.volume += weights[q] * det / 6;
      out.min_jacobian_ratio = std::min(out.min_jacobian_ratio, det / six_v);
    }
    out.num_nonpositive_jacobians += nonpositive;
  }
  return out;
}

}  // namespace arreg::cutting
