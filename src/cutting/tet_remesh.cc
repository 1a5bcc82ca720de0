// Remeshing of the crossed region of one cutting event, one function per CutOptions::method:
// both split every crossed element around a vertex (1-4 split) and give crossed faces and edges
// vertices; kFlips first tries a 2-3 flip over each crossed face and an edge removal (general
// flip) of each crossed edge, kBielser subdivides everywhere.
#include <algorithm>
#include <cmath>
#include <limits>
#include <unordered_map>
#include <utility>
#include <vector>

#include "core/error.h"
#include "cutting/predicates.h"
#include "cutting/tet_cut_operation.h"

namespace arreg::cutting::cut_internal {

void CutOperation::Remesh() {
  switch (opt_.method) {
    case RemeshMethod::kFlips:
      RemeshByFlips();
      return;
    case RemeshMethod::kBielser:
      RemeshBySubdivision();
      return;
  }
}

void CutOperation::RemeshByFlips() {
  CrossedRegion region = SplitCrossedTetrahedra();
  // Crossed faces: 2-3 flip when valid, otherwise (and on the boundary) a vertex on the face.
  for (RemeshFace& f : region.faces)
    if (f.num_crossed > 0 && !TryFlipFace(region, &f)) SplitFace(&f);
  FillRegion(region);
  // Crossed edges: general flip (edge removal) or bisection.
  const auto rings = CrossedEdgeRings();
  for (std::uint64_t key : SortedCrossedEdges()) {
    const EdgeLink link = LinkOf(key, rings);
    if (!(EdgeRemovable(region, link) && RemoveEdge(link))) BisectEdge(link);
  }
  ExtendUnsewnSplits();
}

void CutOperation::RemeshBySubdivision() {
  CrossedRegion region = SplitCrossedTetrahedra();
  for (RemeshFace& f : region.faces)
    if (f.num_crossed > 0) SplitFace(&f);
  FillRegion(region);
  const auto rings = CrossedEdgeRings();
  for (std::uint64_t key : SortedCrossedEdges()) BisectEdge(LinkOf(key, rings));
  ExtendUnsewnSplits();
}

CrossedRegion CutOperation::SplitCrossedTetrahedra() {
  CrossedRegion region;
  const int nct = static_cast<int>(crossed_tets_.size());
  for (int i = 0; i < nct; ++i) region.local_of[crossed_tets_[i]] = i;
  // Elements inverted (or flat) in the current configuration are subdivided in place only
  // (no flip or edge removal spans them): their pieces are checked in the rest
  // configuration, where they are positive, and keep the parent's current orientation.
  crossed_inverted_.assign(nct, 0);
  for (int i = 0; i < nct; ++i) crossed_inverted_[i] = !CurrentPositive(m_.tets_[crossed_tets_[i]]);

  // 1-4 split: one vertex per crossed tetrahedron, at the barycentre of the points
  // where S (or, for a partial cut, its tangent plane) meets the edges.
  region.split_vertex.resize(nct);
  for (int i = 0; i < nct; ++i) {
    const Tet& q = m_.tets_[crossed_tets_[i]];
    std::vector<Vec3> points;
    Vec3 normal = Vec3::Zero(), anchor = Vec3::Zero();
    for (const auto& e : kEdgeLocal)
      if (const Crossing* c = EdgeCrossing(q[e[0]], q[e[1]])) {
        points.push_back(c->point);
        normal +=
            points.size() == 1 ? c->normal : (c->normal.dot(normal) < 0 ? -c->normal : c->normal);
        anchor += c->point;
      }
    const int num_crossings = static_cast<int>(points.size());
    anchor /= num_crossings;
    for (int k = 0; k < 4; ++k)
      if (Marked(q[k])) points.push_back(m_.current_[q[k]]);
    bool on_surface = true;
    if (points.size() < 3) {
      // Partial cut: complete with the tangent plane through the crossings.
      on_surface = false;
      normal.normalize();
      for (const auto& e : kEdgeLocal) {
        const int a = q[e[0]], b = q[e[1]];
        if (EdgeCrossing(a, b)) continue;
        const double da = normal.dot(m_.current_[a] - anchor);
        const double db = normal.dot(m_.current_[b] - anchor);
        if ((da < 0 && db > 0) || (da > 0 && db < 0))
          points.push_back(m_.current_[a] + da / (da - db) * (m_.current_[b] - m_.current_[a]));
      }
    }
    Vec3 target = Vec3::Zero();
    for (const Vec3& p : points) target += p;
    target /= static_cast<double>(points.size());
    const std::vector<int> parents(q.begin(), q.end());
    const int p = AddVertex(parents, InteriorWeights(parents, target), on_surface);
    region.split_vertex[i] = p;
    // The tangent-plane point of a partial cut can still lie on S (an S that ends inside the
    // element, e.g. the strip of a growing cut): it is then on S like a crossing, and the
    // faces it makes with the crossings are unsewn.
    if (!on_surface &&
        DistanceToSurface(m_.current_[p], nullptr) <= opt_.on_surface_tolerance * scale_) {
      on_surface = true;
      marked_[p] = 1;
    }
    split_vertices_.emplace_back(p, on_surface);
  }

  // Faces of the crossed tetrahedra.
  region.element_faces.resize(nct);
  for (int i = 0; i < nct; ++i) {
    const Tet& q = m_.tets_[crossed_tets_[i]];
    for (int f = 0; f < 4; ++f) {
      const int u = q[kFaceOrder[f][0]], v = q[kFaceOrder[f][1]], w = q[kFaceOrder[f][2]];
      const std::uint64_t key = FaceKey(u, v, w);
      auto it = region.face_of.find(key);
      if (it != region.face_of.end()) {
        region.faces[it->second].tet1 = i;
        region.element_faces[i][f] = it->second;
        continue;
      }
      RemeshFace fi;
      fi.verts[0] = u;
      fi.verts[1] = v;
      fi.verts[2] = w;
      fi.tet0 = i;
      fi.num_crossed = (EdgeCrossing(u, v) ? 1 : 0) + (EdgeCrossing(v, w) ? 1 : 0) +
                       (EdgeCrossing(w, u) ? 1 : 0);
      fi.unsewn = m_.unsewn_.count(key) > 0;
      region.element_faces[i][f] = static_cast<int>(region.faces.size());
      region.face_of.emplace(key, static_cast<int>(region.faces.size()));
      region.faces.push_back(fi);
    }
  }
  return region;
}

bool CutOperation::TryFlipFace(const CrossedRegion& region, RemeshFace* face) {
  RemeshFace& f = *face;
  if (f.tet1 < 0 || f.unsewn || crossed_inverted_[f.tet0] || crossed_inverted_[f.tet1])
    return false;
  const int p = region.split_vertex[f.tet0], q = region.split_vertex[f.tet1];
  for (int k = 0; k < 3; ++k) {
    const Tet t = {f.verts[k], f.verts[(k + 1) % 3], q, p};
    if (!(Score(t) >= opt_.min_flip_quality)) return false;
  }
  f.flip = true;
  ++summary_.num_flipped_faces;
  return true;
}

void CutOperation::SplitFace(RemeshFace* face) {
  RemeshFace& f = *face;
  std::vector<Vec3> points;
  Vec3 normal = Vec3::Zero();
  for (int k = 0; k < 3; ++k) {
    const int a = f.verts[k], b = f.verts[(k + 1) % 3];
    if (const Crossing* c = EdgeCrossing(a, b)) {
      points.push_back(c->point);
      normal = c->normal;
    }
    if (Marked(a)) points.push_back(m_.current_[a]);
  }
  const bool on_surface = points.size() >= 2;
  if (!on_surface) {
    const Vec3 anchor = points[0];
    for (int k = 0; k < 3; ++k) {
      const int a = f.verts[k], b = f.verts[(k + 1) % 3];
      if (EdgeCrossing(a, b)) continue;
      const double da = normal.dot(m_.current_[a] - anchor);
      const double db = normal.dot(m_.current_[b] - anchor);
      if ((da < 0 && db > 0) || (da > 0 && db < 0))
        points.push_back(m_.current_[a] + da / (da - db) * (m_.current_[b] - m_.current_[a]));
      else if (da == 0)
        points.push_back(m_.current_[a]);
    }
  }
  Vec3 target = Vec3::Zero();
  for (const Vec3& p : points) target += p;
  target /= static_cast<double>(points.size());
  const std::vector<int> parents(f.verts, f.verts + 3);
  f.y = AddVertex(parents, InteriorWeights(parents, target), on_surface);
  ++summary_.num_split_faces;
  if (f.unsewn) unsewn_splits_.emplace_back(f.y, parents);
}

void CutOperation::FillRegion(const CrossedRegion& region) {
  // Elements of the crossed region before the crossed edges are processed.
  for (int i = 0; i < static_cast<int>(crossed_tets_.size()); ++i) {
    const Tet& q = m_.tets_[crossed_tets_[i]];
    const int p = region.split_vertex[i];
    for (int lf = 0; lf < 4; ++lf) {
      const RemeshFace& f = region.faces[region.element_faces[i][lf]];
      const int u = q[kFaceOrder[lf][0]], v = q[kFaceOrder[lf][1]], w = q[kFaceOrder[lf][2]];
      const int cyc[3] = {u, v, w};
      if (f.num_crossed == 0) {
        region_.push_back({u, v, w, p});
        region_parent_.push_back(i);
      } else if (f.y >= 0) {
        for (int k = 0; k < 3; ++k) {
          region_.push_back({cyc[k], cyc[(k + 1) % 3], f.y, p});
          region_parent_.push_back(i);
        }
      } else if (f.flip && f.tet0 == i) {
        const int other = region.split_vertex[f.tet1];
        for (int k = 0; k < 3; ++k) {
          region_.push_back({cyc[k], cyc[(k + 1) % 3], other, p});
          region_parent_.push_back(-1);
        }
      }
    }
  }
  region_alive_.assign(region_.size(), 1);
}

std::unordered_map<std::uint64_t, std::vector<int>> CutOperation::CrossedEdgeRings() const {
  std::unordered_map<std::uint64_t, std::vector<int>> ring_of;
  for (int r = 0; r < static_cast<int>(region_.size()); ++r)
    for (const auto& e : kEdgeLocal) {
      const std::uint64_t key = EdgeKey(region_[r][e[0]], region_[r][e[1]]);
      if (crossings_.count(key)) ring_of[key].push_back(r);
    }
  return ring_of;
}

EdgeLink CutOperation::LinkOf(
    std::uint64_t key, const std::unordered_map<std::uint64_t, std::vector<int>>& rings) const {
  EdgeLink link;
  link.key = key;
  link.a = static_cast<int>(key >> 32);
  link.b = static_cast<int>(key & 0xffffffffu);
  const auto found = rings.find(key);
  ARREG_ASSERT(found != rings.end() && !found->second.empty(), "crossed edge without elements");
  link.ring = &found->second;
  // Link of the edge as oriented segments c -> d of the positive (a, b, c, d).
  std::unordered_map<int, int> next, prev;
  for (int r : *link.ring) {
    const auto cd = OppositeEdgeOriented(region_[r], link.a, link.b);
    next[cd[0]] = cd[1];
    prev[cd[1]] = cd[0];
  }
  int start = next.begin()->first;
  for (const auto& kv : next)
    if (!prev.count(kv.first)) {
      start = kv.first;
      link.open = true;
      break;
    }
  link.polygon = {start};
  for (int c = next[start]; c != start; c = next[c]) {
    link.polygon.push_back(c);
    if (!next.count(c)) break;
  }
  ARREG_ASSERT(static_cast<int>(link.polygon.size()) ==
                   static_cast<int>(link.ring->size()) + (link.open ? 1 : 0),
               "edge link is not a simple chain");
  return link;
}

bool CutOperation::EdgeRemovable(const CrossedRegion& region, const EdgeLink& link) const {
  const int a = link.a, b = link.b;
  for (int t : m_.vertex_tets_[a])
    if (Contains(m_.tets_[t], b)) {
      const auto it = region.local_of.find(t);
      if (it == region.local_of.end() || crossed_inverted_[it->second]) return false;
    }
  // Edges on unsewn faces keep them: no removal.
  for (int t : m_.vertex_tets_[a])
    if (Contains(m_.tets_[t], b))
      for (int k = 0; k < 4; ++k) {
        const int c = m_.tets_[t][k];
        if (c != a && c != b && m_.unsewn_.count(FaceKey(a, b, c))) return false;
      }
  if (!link.open) return true;
  // Boundary edge: removal only where the boundary is flat enough (feature angle).
  std::vector<int> wing;
  for (int t : m_.vertex_tets_[a])
    if (Contains(m_.tets_[t], b))
      for (int k = 0; k < 4; ++k) {
        const int c = m_.tets_[t][k];
        if (c == a || c == b) continue;
        auto it = region.face_of.find(FaceKey(a, b, c));
        if (it != region.face_of.end() && region.faces[it->second].tet1 < 0) wing.push_back(c);
      }
  if (wing.size() != 2) return false;
  if (opt_.feature_angle_deg == 0)
    return Orient3d(m_.rest_[a], m_.rest_[b], m_.rest_[wing[0]], m_.rest_[wing[1]]) == 0 &&
           Orient3d(m_.current_[a], m_.current_[b], m_.current_[wing[0]], m_.current_[wing[1]]) ==
               0;
  const Vec3 e = (m_.rest_[b] - m_.rest_[a]).normalized();
  Vec3 d0 = m_.rest_[wing[0]] - m_.rest_[a], d1 = m_.rest_[wing[1]] - m_.rest_[a];
  d0 -= d0.dot(e) * e;
  d1 -= d1.dot(e) * e;
  const double angle = std::acos(std::clamp(d0.normalized().dot(d1.normalized()), -1.0, 1.0));
  return (kPi - angle) * 180.0 / kPi <= opt_.feature_angle_deg;
}

bool CutOperation::RemoveEdge(const EdgeLink& link) {
  // Best triangulation of the link polygon (max-min quality), O(n^3).
  const int a = link.a, b = link.b;
  const std::vector<int>& poly = link.polygon;
  const int n = static_cast<int>(poly.size());
  const double kNone = -std::numeric_limits<double>::infinity();
  std::vector<double> best(n * n, std::numeric_limits<double>::infinity());
  std::vector<int> split(n * n, -1);
  for (int len = 2; len < n; ++len)
    for (int i = 0; i + len < n; ++i) {
      const int j = i + len;
      double b_ij = kNone;
      for (int k = i + 1; k < j; ++k) {
        const double left =
            (k - i >= 2) ? best[i * n + k] : std::numeric_limits<double>::infinity();
        const double right =
            (j - k >= 2) ? best[k * n + j] : std::numeric_limits<double>::infinity();
        double s = std::min(left, right);
        if (s <= b_ij) continue;
        s = std::min(s, Score({a, poly[i], poly[k], poly[j]}));
        if (s <= b_ij) continue;
        s = std::min(s, Score({b, poly[i], poly[j], poly[k]}));
        if (s > b_ij) {
          b_ij = s;
          split[i * n + j] = k;
        }
      }
      best[i * n + j] = b_ij;
    }
  if (!(n >= 3 && best[n - 1] >= opt_.min_flip_quality && best[n - 1] > kNone)) return false;
  std::vector<std::pair<int, int>> stack = {{0, n - 1}};
  while (!stack.empty()) {
    const auto [i, j] = stack.back();
    stack.pop_back();
    if (j - i < 2) continue;
    const int k = split[i * n + j];
    region_.push_back({a, poly[i], poly[k], poly[j]});
    region_.push_back({b, poly[i], poly[j], poly[k]});
    region_alive_.push_back(1);
    region_alive_.push_back(1);
    region_parent_.push_back(-1);
    region_parent_.push_back(-1);
    stack.emplace_back(i, k);
    stack.emplace_back(k, j);
  }
  for (int r : *link.ring) region_alive_[r] = 0;
  ++summary_.num_removed_edges;
  return true;
}

void CutOperation::BisectEdge(const EdgeLink& link) {
  const int a = link.a, b = link.b;
  Crossing& c = crossings_.at(link.key);
  const std::vector<int> parents = {a, b};
  const double beta = opt_.min_barycentric;
  const double t = std::clamp(c.t, beta, 1 - beta);
  c.x_vertex = AddVertex(parents, {1 - t, t}, true);
  for (int r : *link.ring) {
    const auto cd = OppositeEdgeOriented(region_[r], a, b);
    region_alive_[r] = 0;
    region_.push_back({a, c.x_vertex, cd[0], cd[1]});
    region_.push_back({c.x_vertex, b, cd[0], cd[1]});
    region_alive_.push_back(1);
    region_alive_.push_back(1);
    const int parent = region_parent_[r];
    region_parent_.push_back(parent);
    region_parent_.push_back(parent);
  }
  ++summary_.num_bisected_edges;
}

void CutOperation::ExtendUnsewnSplits() {
  // Boundary points of split unsewn faces (with their bisection vertices) so the
  // pieces stay unsewn.
  for (auto& [y, pts] : unsewn_splits_) {
    const std::vector<int> corners = pts;
    for (int k = 0; k < 3; ++k)
      if (const Crossing* c = EdgeCrossing(corners[k], corners[(k + 1) % 3]))
        if (c->x_vertex >= 0) pts.push_back(c->x_vertex);
  }
}

}  // namespace arreg::cutting::cut_internal
