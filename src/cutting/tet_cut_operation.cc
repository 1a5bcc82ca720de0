#include "cutting/tet_cut_operation.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <unordered_map>
#include <utility>

#include "core/error.h"
#include "core/geometry.h"
#include "cutting/predicates.h"

namespace arreg::cutting::cut_internal {

double CutOperation::DistanceToSurface(const Vec3& p, const STriangle** nearest) const {
  double best = std::numeric_limits<double>::infinity();
  for (const STriangle& s : surface_) {
    const Vec3 q = (p - (s.lo + s.hi) / 2).cwiseAbs() - (s.hi - s.lo) / 2;
    if (q.cwiseMax(0.0).norm() >= best) continue;
    const double d = (ClosestPointOnTriangle(p, s.p[0], s.p[1], s.p[2]) - p).norm();
    if (d < best) {
      best = d;
      if (nearest) *nearest = &s;
    }
  }
  return best;
}

bool CutOperation::FindCrossing(int a, int b, Crossing* c) const {
  if (a > b) std::swap(a, b);
  const Vec3& pa = m_.current_[a];
  const Vec3& pb = m_.current_[b];
  const Vec3 lo = pa.cwiseMin(pb), hi = pa.cwiseMax(pb);
  for (const STriangle& s : surface_) {
    if ((lo.array() > s.hi.array()).any() || (hi.array() < s.lo.array()).any()) continue;
    const int oa = Orient3d(s.p[0], s.p[1], s.p[2], pa);
    const int ob = Orient3d(s.p[0], s.p[1], s.p[2], pb);
    if (oa * ob >= 0) continue;
    const int s0 = Orient3d(pa, pb, s.p[0], s.p[1]);
    const int s1 = Orient3d(pa, pb, s.p[1], s.p[2]);
    const int s2 = Orient3d(pa, pb, s.p[2], s.p[0]);
    const bool hit = (s0 >= 0 && s1 >= 0 && s2 >= 0) || (s0 <= 0 && s1 <= 0 && s2 <= 0);
    if (!hit) continue;
    const double da = s.normal.dot(pa - s.p[0]), db = s.normal.dot(pb - s.p[0]);
    c->t = std::clamp(da / (da - db), 0.0, 1.0);
    c->point = pa + c->t * (pb - pa);
    c->normal = s.normal;
    return true;
  }
  return false;
}

int CutOperation::AddVertex(const std::vector<int>& parents, std::vector<double> weights,
                            bool on_surface) {
  Vec3 r = Vec3::Zero(), x = Vec3::Zero(), v = Vec3::Zero();
  for (size_t i = 0; i < parents.size(); ++i) {
    r += weights[i] * m_.rest_[parents[i]];
    x += weights[i] * m_.current_[parents[i]];
    v += weights[i] * m_.velocity_[parents[i]];
  }
  const int index = static_cast<int>(m_.rest_.size());
  m_.rest_.push_back(r);
  m_.current_.push_back(x);
  m_.velocity_.push_back(v);
  m_.vertex_tets_.emplace_back();
  marked_.push_back(on_surface ? 1 : 0);
  NewVertex nv;
  nv.index = index;
  nv.parents = parents;
  nv.weights = std::move(weights);
  nv.on_surface = on_surface;
  new_vertices_.push_back(std::move(nv));
  return index;
}

std::vector<double> CutOperation::InteriorWeights(const std::vector<int>& parents,
                                                  const Vec3& target) const {
  const int n = static_cast<int>(parents.size());
  std::vector<double> w(n, 1.0 / n);
  // Barycentric coordinates of target in the simplex (least squares for a face or an edge).
  Eigen::MatrixXd A(3, n - 1);
  for (int i = 1; i < n; ++i) A.col(i - 1) = m_.current_[parents[i]] - m_.current_[parents[0]];
  const Eigen::VectorXd tail = A.colPivHouseholderQr().solve(target - m_.current_[parents[0]]);
  std::vector<double> b(n);
  b[0] = 1.0 - tail.sum();
  for (int i = 1; i < n; ++i) b[i] = tail(i - 1);
  // Pull towards the centroid just enough that every coordinate is >= beta.
  const double beta = opt_.min_barycentric, c = 1.0 / n;
  double s = 1.0;
  for (int i = 0; i < n; ++i)
    if (b[i] < beta) s = std::min(s, (c - beta) / (c - b[i]));
  for (int i = 0; i < n; ++i) w[i] = c + s * (b[i] - c);
  return w;
}

bool CutOperation::TrySnap(int v, int a, int b, const Crossing& c) {
  const double t = c.t;
  // On the boundary, S must cross the boundary at v (neighbours on the boundary on
  // both sides of S); otherwise snapping would make S touch the boundary in a single
  // point and pinch the remaining piece (non-manifold boundary).
  {
    std::unordered_map<std::uint64_t, int> count;
    std::vector<std::array<int, 3>> vertex_faces;
    for (int ti : m_.vertex_tets_[v]) {
      const Tet& q = m_.tets_[ti];
      for (int lf = 0; lf < 4; ++lf) {
        const int x = q[kFaceOrder[lf][0]], y = q[kFaceOrder[lf][1]], z = q[kFaceOrder[lf][2]];
        if (x != v && y != v && z != v) continue;
        if (count[FaceKey(x, y, z)]++ == 0) vertex_faces.push_back({x, y, z});
      }
    }
    bool boundary = false, below = false, above = false;
    for (const auto& f : vertex_faces) {
      if (count[FaceKey(f[0], f[1], f[2])] != 1) continue;
      boundary = true;
      for (int w : f) {
        if (w == v || Marked(w)) continue;
        // Side of S (signed distance to the nearest point of S).
        const STriangle* nearest = nullptr;
        DistanceToSurface(m_.current_[w], &nearest);
        const double side =
            nearest ? nearest->normal.dot(m_.current_[w] -
                                          ClosestPointOnTriangle(m_.current_[w], nearest->p[0],
                                                                 nearest->p[1], nearest->p[2]))
                    : 0.0;
        below = below || side < 0;
        above = above || side > 0;
      }
    }
    if (boundary && !(below && above)) return false;
  }
  const Vec3 rest_new = (1 - t) * m_.rest_[a] + t * m_.rest_[b];
  const Vec3 cur_new = (1 - t) * m_.current_[a] + t * m_.current_[b];
  const Vec3 vel_new = (1 - t) * m_.velocity_[a] + t * m_.velocity_[b];
  double volume_before = 0, volume_after = 0, abs_before = 0;
  for (int ti : m_.vertex_tets_[v]) {
    const Tet& q = m_.tets_[ti];
    const double vb = TetVolume(m_.rest_[q[0]], m_.rest_[q[1]], m_.rest_[q[2]], m_.rest_[q[3]]);
    volume_before += vb;
    abs_before += std::abs(vb);
  }
  const Vec3 rest_old = m_.rest_[v], cur_old = m_.current_[v], vel_old = m_.velocity_[v];
  m_.rest_[v] = rest_new;
  m_.current_[v] = cur_new;
  bool ok = true;
  for (int ti : m_.vertex_tets_[v]) {
    const Tet& q = m_.tets_[ti];
    if (!TetValid(q) || Quality(q) < opt_.min_flip_quality) {
      ok = false;
      break;
    }
    volume_after += TetVolume(m_.rest_[q[0]], m_.rest_[q[1]], m_.rest_[q[2]], m_.rest_[q[3]]);
  }
  // A boundary vertex may only slide within a flat part of the boundary.
  if (ok && std::abs(volume_after - volume_before) > 1e-12 * abs_before) ok = false;
  if (!ok) {
    m_.rest_[v] = rest_old;
    m_.current_[v] = cur_old;
    return false;
  }
  m_.velocity_[v] = vel_new;
  snapped_rest_backup_.emplace_back(v, rest_old);
  snapped_current_backup_.emplace_back(v, cur_old);
  snapped_velocity_backup_.emplace_back(v, vel_old);
  SnappedVertex s;
  s.index = v;
  s.a = a;
  s.b = b;
  s.t = t;
  snapped_.push_back(s);
  marked_[v] = 1;
  return true;
}

void CutOperation::Rollback() {
  for (auto it = snapped_rest_backup_.rbegin(); it != snapped_rest_backup_.rend(); ++it)
    m_.rest_[it->first] = it->second;
  for (auto it = snapped_current_backup_.rbegin(); it != snapped_current_backup_.rend(); ++it)
    m_.current_[it->first] = it->second;
  for (auto it = snapped_velocity_backup_.rbegin(); it != snapped_velocity_backup_.rend(); ++it)
    m_.velocity_[it->first] = it->second;
  m_.rest_.resize(nv0_);
  m_.current_.resize(nv0_);
  m_.velocity_.resize(nv0_);
  m_.vertex_tets_.resize(nv0_);
}

void CutOperation::ComputeCrossings(const std::vector<int>& candidate_tets) {
  crossings_.clear();
  for (int t : candidate_tets) {
    const Tet& q = m_.tets_[t];
    for (const auto& e : kEdgeLocal) {
      const int a = q[e[0]], b = q[e[1]];
      if (Marked(a) || Marked(b)) continue;
      const std::uint64_t key = EdgeKey(a, b);
      if (crossings_.count(key)) continue;
      Crossing c;
      if (FindCrossing(a, b, &c)) crossings_.emplace(key, c);
    }
  }
}

void CutOperation::MoveFrontVertices() {
  if (!opt_.move_front_vertices || m_.front_vertices_.empty()) return;
  // Per front vertex, its crossed edges by the distance it would move (shortest first).
  std::map<int, std::vector<std::pair<double, std::uint64_t>>> moves;
  for (const auto& [key, c] : crossings_) {
    const int a = static_cast<int>(key >> 32), b = static_cast<int>(key & 0xffffffffu);
    for (int v : {a, b})
      if (m_.front_vertices_.count(v))
        moves[v].emplace_back((m_.current_[v] - c.point).norm(), key);
  }
  for (auto& [v, list] : moves) {
    std::sort(list.begin(), list.end());
    for (const auto& [distance, key] : list) {
      const int a = static_cast<int>(key >> 32), b = static_cast<int>(key & 0xffffffffu);
      if (Marked(a) || Marked(b)) continue;
      if (TrySnap(v, a, b, crossings_.at(key))) {
        ++summary_.num_moved_front_vertices;
        break;
      }
    }
  }
}

void CutOperation::Snap() {
  MoveFrontVertices();
  const double threshold = opt_.snap_epsilon * scale_;
  for (std::uint64_t key : SortedCrossedEdges()) {
    const int a = static_cast<int>(key >> 32), b = static_cast<int>(key & 0xffffffffu);
    if (Marked(a) || Marked(b)) continue;
    const Crossing& c = crossings_.at(key);
    const double da = std::abs(c.normal.dot(m_.current_[a] - c.point));
    const double db = std::abs(c.normal.dot(m_.current_[b] - c.point));
    const int v = da <= db ? a : b;
    if (!(threshold > 0) || std::min(da, db) >= threshold) continue;
    TrySnap(v, a, b, c);
  }
  for (auto it = crossings_.begin(); it != crossings_.end();) {
    const int a = static_cast<int>(it->first >> 32), b = static_cast<int>(it->first & 0xffffffffu);
    if (Marked(a) || Marked(b))
      it = crossings_.erase(it);
    else
      ++it;
  }
  summary_.num_snapped_vertices = static_cast<int>(snapped_.size());
}

bool CutOperation::Verify(std::string* why, bool* sliver) const {
  *sliver = false;
  double removed_volume = 0, added_volume = 0, scale = 0;
  for (int t : crossed_tets_) {
    const Tet& q = m_.tets_[t];
    const double v = TetVolume(m_.rest_[q[0]], m_.rest_[q[1]], m_.rest_[q[2]], m_.rest_[q[3]]);
    removed_volume += v;
    scale += std::abs(v);
  }
  for (size_t r = 0; r < region_.size(); ++r) {
    if (!region_alive_[r]) continue;
    const Tet& q = region_[r];
    const int parent = region_parent_[r];
    const bool in_inverted = parent >= 0 && crossed_inverted_[parent];
    if (!(in_inverted ? RestPositive(q) : TetValid(q))) {
      *why = "an inserted element would be inverted or flat";
      return false;
    }
    // The exact orientation can be positive while the rest volume the mechanics compute
    // (mechanics::ComputeTetRestData: det of the edge vectors from the first vertex, rounded) is
    // not: such an element is flat for the simulation, which refuses it.
    if (!(RestDeterminant(q) > 0)) {
      *why = "an inserted element would have a non-positive rest volume in floating point";
      return false;
    }
    const double quality =
        TetQuality(m_.rest_[q[0]], m_.rest_[q[1]], m_.rest_[q[2]], m_.rest_[q[3]]);
    if (quality < opt_.min_element_quality) {
      char text[128];
      std::snprintf(text, sizeof(text),
                    "an inserted element would be a sliver (normalised volume %.3g < %.3g, "
                    "min_element_quality)",
                    quality, opt_.min_element_quality);
      *why = text;
      *sliver = true;
      return false;
    }
    added_volume += TetVolume(m_.rest_[q[0]], m_.rest_[q[1]], m_.rest_[q[2]], m_.rest_[q[3]]);
  }
  // Boundary general flips over non-flat faces change the volume on purpose.
  if (opt_.feature_angle_deg == 0 && std::abs(added_volume - removed_volume) > 1e-10 * scale) {
    *why = "the new elements do not fill the crossed ones exactly";
    return false;
  }
  return true;
}

void CutOperation::Commit(CutChange* change) {
  std::vector<int> slots = crossed_tets_;
  std::vector<Tet> added;
  for (size_t r = 0; r < region_.size(); ++r)
    if (region_alive_[r]) added.push_back(region_[r]);
  std::sort(slots.begin(), slots.end());
  for (int t : slots)
    for (int k = 0; k < 4; ++k) {
      auto& list = m_.vertex_tets_[m_.tets_[t][k]];
      list.erase(std::find(list.begin(), list.end(), t));
    }
  for (size_t i = 0; i < added.size(); ++i) {
    int slot;
    if (i < slots.size()) {
      slot = slots[i];
      m_.tets_[slot] = added[i];
    } else {
      slot = static_cast<int>(m_.tets_.size());
      m_.tets_.push_back(added[i]);
    }
    for (int v : added[i]) m_.vertex_tets_[v].push_back(slot);
  }
  changed_slots_ = slots;
  // Elements around snapped vertices changed shape (rest data to recompute).
  for (const SnappedVertex& s : snapped_)
    for (int t : m_.vertex_tets_[s.index])
      if (t < nt0_) changed_slots_.push_back(t);
  (void)change;
}

CutSummary CutOperation::Run(CutChange* change) {
  nv0_ = m_.num_vertices();
  nt0_ = m_.num_tetrahedra();
  marked_.assign(nv0_, 0);
  if (surface_.empty() || m_.tets_.empty()) {
    summary_.message = "empty surface or mesh";
    return summary_;
  }
  // Candidate elements: bounding boxes overlapping S (grown by the snapping distance).
  Vec3 lo = surface_[0].lo, hi = surface_[0].hi;
  for (const STriangle& s : surface_) {
    lo = lo.cwiseMin(s.lo);
    hi = hi.cwiseMax(s.hi);
  }
  const double margin = (opt_.snap_epsilon + opt_.on_surface_tolerance) * scale_;
  lo.array() -= margin;
  hi.array() += margin;
  std::vector<int> candidates;
  for (int t = 0; t < nt0_; ++t) {
    const Tet& q = m_.tets_[t];
    Vec3 tlo = m_.current_[q[0]], thi = tlo;
    for (int k = 1; k < 4; ++k) {
      tlo = tlo.cwiseMin(m_.current_[q[k]]);
      thi = thi.cwiseMax(m_.current_[q[k]]);
    }
    if ((tlo.array() <= hi.array()).all() && (thi.array() >= lo.array()).all())
      candidates.push_back(t);
  }
  // Vertices already on S.
  const double on_tol = opt_.on_surface_tolerance * scale_;
  for (int t : candidates)
    for (int v : m_.tets_[t])
      if (!marked_[v] && DistanceToSurface(m_.current_[v], nullptr) <= on_tol) marked_[v] = 1;
  // A vertex closer to S than min_barycentric x its shortest edge counts as on S as well: no
  // crossing can be placed nearer to it (crossings and inserted vertices are kept at barycentric
  // coordinates >= min_barycentric), and crossing its edges there nests such pieces into
  // elements of normalised volume ~min_barycentric^2 in one event, which the mechanics cannot
  // solve (CHOLMOD finds the matrix not positive definite).
  {
    std::unordered_map<int, double> shortest;
    for (int t : candidates) {
      const Tet& q = m_.tets_[t];
      for (const auto& e : kEdgeLocal) {
        const double l = (m_.current_[q[e[0]]] - m_.current_[q[e[1]]]).norm();
        for (int v : {q[e[0]], q[e[1]]}) {
          auto it = shortest.emplace(v, l).first;
          it->second = std::min(it->second, l);
        }
      }
    }
    for (const auto& [v, l] : shortest)
      if (!marked_[v] && DistanceToSurface(m_.current_[v], nullptr) <= opt_.min_barycentric * l)
        marked_[v] = 1;
  }
  // An element whose four vertices all count as on S lies inside the tolerance slab: S runs
  // through it, but Separate never unsews a face of such an element, so it would bridge the
  // two sides (a spanning S leaving the body in one piece). Its vertex farthest from S is
  // then not taken as on S (the exact test, tolerance 0, never marks a whole element).
  for (bool changed = true; changed;) {
    changed = false;
    for (int t : candidates) {
      const Tet& q = m_.tets_[t];
      if (!(marked_[q[0]] && marked_[q[1]] && marked_[q[2]] && marked_[q[3]])) continue;
      int farthest = q[0];
      double farthest_mm = -1.0;
      for (int v : q) {
        const double d = DistanceToSurface(m_.current_[v], nullptr);
        if (d > farthest_mm) farthest_mm = d, farthest = v;
      }
      marked_[farthest] = 0;
      changed = true;
    }
  }

  ComputeCrossings(candidates);
  Snap();
  summary_.num_crossed_edges = static_cast<int>(crossings_.size());
  for (int t : candidates) {
    const Tet& q = m_.tets_[t];
    for (const auto& e : kEdgeLocal)
      if (EdgeCrossing(q[e[0]], q[e[1]])) {
        crossed_tets_.push_back(t);
        break;
      }
  }
  summary_.num_crossed_tetrahedra = static_cast<int>(crossed_tets_.size());
  bool any_marked = false;
  for (char c : marked_) any_marked = any_marked || c;
  if (crossed_tets_.empty() && !any_marked) {
    summary_.status = CutStatus::kNoCrossing;
    summary_.message = "S crosses no edge of the mesh";
    return summary_;
  }
  if (!crossed_tets_.empty()) {
    Remesh();
    std::string why;
    bool sliver = false;
    if (!Verify(&why, &sliver)) {
      Rollback();
      summary_ = CutSummary();
      summary_.status = CutStatus::kRejected;
      summary_.message = why;
      summary_.sliver = sliver;
      return summary_;
    }
  }
  Commit(change);
  if (opt_.separate) Separate();
  for (int v = 0; v < nv0_; ++v)
    if (marked_[v]) m_.front_vertices_.erase(v);  // on S now (snapped, moved or met by S)
  for (const auto& [v, on_surface] : split_vertices_)
    if (!on_surface) m_.front_vertices_.insert(v);
  summary_.status = CutStatus::kCut;
  summary_.num_new_vertices = static_cast<int>(new_vertices_.size());
  summary_.num_tetrahedra_added = m_.num_tetrahedra() - nt0_;

  if (change) {
    *change = CutChange();
    change->num_vertices_before = nv0_;
    change->num_tetrahedra_before = nt0_;
    change->new_vertices = new_vertices_;
    change->duplicated = duplicated_;
    change->snapped = snapped_;
    change->separated_faces = separated_faces_;
    std::vector<int> slots;
    for (int t : changed_slots_)
      if (t < nt0_) slots.push_back(t);
    std::sort(slots.begin(), slots.end());
    slots.erase(std::unique(slots.begin(), slots.end()), slots.end());
    change->removed_tetrahedra = slots;
    const int num_new = static_cast<int>(slots.size()) + m_.num_tetrahedra() - nt0_;
    change->new_tetrahedra.resize(num_new, 4);
    int row = 0;
    auto emit = [&](int t) {
      for (int k = 0; k < 4; ++k) change->new_tetrahedra(row, k) = m_.tets_[t][k];
      ++row;
    };
    for (int t : slots) emit(t);
    for (int t = nt0_; t < m_.num_tetrahedra(); ++t) emit(t);
  }
  return summary_;
}

}  // namespace arreg::cutting::cut_internal
