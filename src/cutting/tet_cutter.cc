#include "cutting/tet_cutter.h"
#include "core/geometry.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <map>
#include <numeric>
#include <unordered_map>
#include <utility>

#include "core/error.h"
#include "cutting/predicates.h"

namespace arreg::cutting {

namespace {

using Vec3 = Eigen::Vector3d;
using Tet = std::array<int, 4>;

constexpr double kPi = 3.14159265358979323846;

std::uint64_t EdgeKey(int a, int b) {
  if (a > b) std::swap(a, b);
  return (static_cast<std::uint64_t>(a) << 32) | static_cast<std::uint32_t>(b);
}

// Faces are keyed by their sorted vertex triple, 21 bits per index.
std::uint64_t FaceKey(int a, int b, int c) {
  int v[3] = {a, b, c};
  std::sort(v, v + 3);
  return (static_cast<std::uint64_t>(v[0]) << 42) | (static_cast<std::uint64_t>(v[1]) << 21) |
         static_cast<std::uint64_t>(v[2]);
}

// Local vertex orders (u, v, w) of the face opposite vertex i such that
// (u, v, w, opposite) is an even permutation of (0, 1, 2, 3).
constexpr int kFaceOrder[4][3] = {{1, 3, 2}, {0, 2, 3}, {0, 3, 1}, {0, 1, 2}};
constexpr int kEdgeLocal[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};

bool Contains(const Tet& t, int v) { return t[0] == v || t[1] == v || t[2] == v || t[3] == v; }

// Reorders a positive tetrahedron containing a and b as (a, b, c, d), still positive.
std::array<int, 2> OppositeEdgeOriented(const Tet& t, int a, int b) {
  int ia = -1, ib = -1;
  for (int k = 0; k < 4; ++k) {
    if (t[k] == a) ia = k;
    if (t[k] == b) ib = k;
  }
  int rest[2], n = 0;
  for (int k = 0; k < 4; ++k)
    if (k != ia && k != ib) rest[n++] = k;
  int perm[4] = {ia, ib, rest[0], rest[1]};
  int inversions = 0;
  for (int i = 0; i < 4; ++i)
    for (int j = i + 1; j < 4; ++j)
      if (perm[i] > perm[j]) ++inversions;
  if (inversions % 2 == 0) return {t[rest[0]], t[rest[1]]};
  return {t[rest[1]], t[rest[0]]};
}

struct STriangle {
  Vec3 p[3];
  Vec3 normal;  // unit
  Vec3 lo, hi;
};

struct Crossing {
  double t = 0;  // parameter along the edge from its smaller to its larger vertex index
  Vec3 point;
  Vec3 normal;
  int x_vertex = -1;
};

}  // namespace

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

// One cutting event: all the state of the steps of CuttableMesh::Cut().
class CutEvent {
 public:
  CutEvent(CuttableMesh* mesh, const CutSurface& surface, const CutOptions& options)
      : m_(*mesh), opt_(options) {
    for (int f = 0; f < surface.num_triangles(); ++f) {
      STriangle s;
      for (int k = 0; k < 3; ++k)
        s.p[k] = surface.vertices.row(surface.triangles(f, k)).transpose();
      const Vec3 n = (s.p[1] - s.p[0]).cross(s.p[2] - s.p[0]);
      if (!(n.norm() > 0)) continue;  // degenerate triangles cannot be crossed
      s.normal = n.normalized();
      s.lo = s.p[0].cwiseMin(s.p[1]).cwiseMin(s.p[2]);
      s.hi = s.p[0].cwiseMax(s.p[1]).cwiseMax(s.p[2]);
      surface_.push_back(s);
    }
    scale_ = m_.mean_edge_length_;
  }

  CutSummary Run(CutChange* change);

 private:
  // --- geometry helpers ---
  bool RestPositive(const Tet& t) const {
    return Orient3d(m_.rest_[t[0]], m_.rest_[t[1]], m_.rest_[t[2]], m_.rest_[t[3]]) > 0;
  }
  bool CurrentPositive(const Tet& t) const {
    return Orient3d(m_.current_[t[0]], m_.current_[t[1]], m_.current_[t[2]], m_.current_[t[3]]) > 0;
  }
  bool TetValid(const Tet& t) const { return RestPositive(t) && CurrentPositive(t); }
  // det [x1 - x0, x2 - x0, x3 - x0] of the rest positions, computed like
  // mechanics::ComputeTetRestData (the rest volume the simulation uses, x 6).
  double RestDeterminant(const Tet& t) const {
    Eigen::Matrix3d dm;
    for (int k = 0; k < 3; ++k) dm.col(k) = m_.rest_[t[k + 1]] - m_.rest_[t[0]];
    return dm.determinant();
  }
  double Quality(const Tet& t) const {
    return std::min(
        TetQuality(m_.rest_[t[0]], m_.rest_[t[1]], m_.rest_[t[2]], m_.rest_[t[3]]),
        TetQuality(m_.current_[t[0]], m_.current_[t[1]], m_.current_[t[2]], m_.current_[t[3]]));
  }
  // Quality if valid, -infinity otherwise.
  double Score(const Tet& t) const {
    return TetValid(t) ? Quality(t) : -std::numeric_limits<double>::infinity();
  }
  double DistanceToSurface(const Vec3& p, const STriangle** nearest) const;
  bool FindCrossing(int a, int b, Crossing* c) const;
  int AddVertex(const std::vector<int>& parents, std::vector<double> weights, bool on_surface);
  // Convex combination of `parents` (current positions) with all weights >= beta, close to
  // `target`.
  std::vector<double> InteriorWeights(const std::vector<int>& parents, const Vec3& target) const;
  bool TrySnap(int v, int a, int b, const Crossing& c);
  void Rollback();

  const Crossing* EdgeCrossing(int a, int b) const {
    auto it = crossings_.find(EdgeKey(a, b));
    return it == crossings_.end() ? nullptr : &it->second;
  }
  bool Marked(int v) const { return v < static_cast<int>(marked_.size()) && marked_[v]; }

  // --- steps ---
  void ComputeCrossings(const std::vector<int>& candidate_tets);
  void Snap();
  void MoveFrontVertices();
  void Remesh();
  bool Verify(std::string* why) const;
  void Commit(CutChange* change);
  void Separate();

  CuttableMesh& m_;
  const CutOptions& opt_;
  std::vector<STriangle> surface_;
  double scale_ = 0;
  CutSummary summary_;

  int nv0_ = 0, nt0_ = 0;
  std::vector<char> marked_;
  std::unordered_map<std::uint64_t, Crossing> crossings_;
  std::vector<SnappedVertex> snapped_;
  std::vector<std::pair<int, Vec3>> snapped_rest_backup_, snapped_current_backup_,
      snapped_velocity_backup_;
  std::vector<NewVertex> new_vertices_;
  std::vector<int> crossed_tets_;
  std::vector<Tet> region_;  // new elements replacing crossed_tets_
  std::vector<char> region_alive_;
  // Per region element: the crossed element (index into crossed_tets_) it lies in, or -1
  // when it spans several (flips, edge removal; only over elements positive in both
  // configurations).
  std::vector<int> region_parent_;
  std::vector<char> crossed_inverted_;  // per crossed element: non-positive in current
  std::vector<std::pair<int, bool>> split_vertices_;  // 1-4 vertices, on S
  std::vector<std::pair<int, std::vector<int>>>
      unsewn_splits_;  // y vertex, boundary points of the face
  std::vector<int> changed_slots_;
  std::vector<DuplicatedVertex> duplicated_;
  std::vector<std::array<int, 3>> separated_faces_;
};

double CutEvent::DistanceToSurface(const Vec3& p, const STriangle** nearest) const {
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

bool CutEvent::FindCrossing(int a, int b, Crossing* c) const {
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

int CutEvent::AddVertex(const std::vector<int>& parents, std::vector<double> weights,
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

std::vector<double> CutEvent::InteriorWeights(const std::vector<int>& parents,
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

bool CutEvent::TrySnap(int v, int a, int b, const Crossing& c) {
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

void CutEvent::Rollback() {
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

void CutEvent::ComputeCrossings(const std::vector<int>& candidate_tets) {
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

void CutEvent::MoveFrontVertices() {
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

void CutEvent::Snap() {
  MoveFrontVertices();
  const double threshold = opt_.snap_epsilon * scale_;
  std::vector<std::uint64_t> keys;
  for (const auto& kv : crossings_) keys.push_back(kv.first);
  std::sort(keys.begin(), keys.end());
  for (std::uint64_t key : keys) {
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

namespace {

struct FaceInfo {
  int verts[3];              // oriented from the side of tet0
  int tet0 = -1, tet1 = -1;  // indices into crossed_tets_ (tet1 = -1: boundary face)
  int num_crossed = 0;
  bool flip = false;
  int y = -1;  // vertex inserted on the face
  bool unsewn = false;
};

}  // namespace

void CutEvent::Remesh() {
  const bool bielser = opt_.method == RemeshMethod::kBielser;
  const int nct = static_cast<int>(crossed_tets_.size());
  std::unordered_map<int, int> local_of;
  for (int i = 0; i < nct; ++i) local_of[crossed_tets_[i]] = i;
  // Elements inverted (or flat) in the current configuration are subdivided in place only
  // (no flip or edge removal spans them): their pieces are checked in the rest
  // configuration, where they are positive, and keep the parent's current orientation.
  crossed_inverted_.assign(nct, 0);
  for (int i = 0; i < nct; ++i) crossed_inverted_[i] = !CurrentPositive(m_.tets_[crossed_tets_[i]]);

  // 1-4 split: one vertex per crossed tetrahedron, at the barycentre of the points
  // where S (or, for a partial cut, its tangent plane) meets the edges.
  std::vector<int> p_of(nct);
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
    p_of[i] = AddVertex(parents, InteriorWeights(parents, target), on_surface);
    // The tangent-plane point of a partial cut can still lie on S (an S that ends inside the
    // element, e.g. the strip of a growing cut): it is then on S like a crossing, and the
    // faces it makes with the crossings are unsewn.
    if (!on_surface &&
        DistanceToSurface(m_.current_[p_of[i]], nullptr) <= opt_.on_surface_tolerance * scale_) {
      on_surface = true;
      marked_[p_of[i]] = 1;
    }
    split_vertices_.emplace_back(p_of[i], on_surface);
  }

  // Faces of the crossed tetrahedra.
  std::vector<FaceInfo> faces;
  std::unordered_map<std::uint64_t, int> face_of;
  std::vector<std::array<int, 4>> tet_faces(nct);
  for (int i = 0; i < nct; ++i) {
    const Tet& q = m_.tets_[crossed_tets_[i]];
    for (int f = 0; f < 4; ++f) {
      const int u = q[kFaceOrder[f][0]], v = q[kFaceOrder[f][1]], w = q[kFaceOrder[f][2]];
      const std::uint64_t key = FaceKey(u, v, w);
      auto it = face_of.find(key);
      if (it != face_of.end()) {
        faces[it->second].tet1 = i;
        tet_faces[i][f] = it->second;
        continue;
      }
      FaceInfo fi;
      fi.verts[0] = u;
      fi.verts[1] = v;
      fi.verts[2] = w;
      fi.tet0 = i;
      fi.num_crossed = (EdgeCrossing(u, v) ? 1 : 0) + (EdgeCrossing(v, w) ? 1 : 0) +
                       (EdgeCrossing(w, u) ? 1 : 0);
      fi.unsewn = m_.unsewn_.count(key) > 0;
      tet_faces[i][f] = static_cast<int>(faces.size());
      face_of.emplace(key, static_cast<int>(faces.size()));
      faces.push_back(fi);
    }
  }

  // Crossed faces: 2-3 flip when valid, otherwise (and on the boundary) a vertex on the face.
  for (FaceInfo& f : faces) {
    if (f.num_crossed == 0) continue;
    if (!bielser && f.tet1 >= 0 && !f.unsewn && !crossed_inverted_[f.tet0] &&
        !crossed_inverted_[f.tet1]) {
      const int p = p_of[f.tet0], q = p_of[f.tet1];
      bool ok = true;
      for (int k = 0; k < 3 && ok; ++k) {
        const Tet t = {f.verts[k], f.verts[(k + 1) % 3], q, p};
        ok = Score(t) >= opt_.min_flip_quality;
      }
      if (ok) {
        f.flip = true;
        ++summary_.num_flipped_faces;
        continue;
      }
    }
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
    bool on_surface = points.size() >= 2;
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

  // Elements of the crossed region before the crossed edges are processed.
  for (int i = 0; i < nct; ++i) {
    const Tet& q = m_.tets_[crossed_tets_[i]];
    const int p = p_of[i];
    for (int lf = 0; lf < 4; ++lf) {
      const FaceInfo& f = faces[tet_faces[i][lf]];
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
        const int other = p_of[f.tet1];
        for (int k = 0; k < 3; ++k) {
          region_.push_back({cyc[k], cyc[(k + 1) % 3], other, p});
          region_parent_.push_back(-1);
        }
      }
    }
  }
  region_alive_.assign(region_.size(), 1);

  // Crossed edges: general flip (edge removal) or bisection.
  std::unordered_map<std::uint64_t, std::vector<int>> ring_of;
  for (int r = 0; r < static_cast<int>(region_.size()); ++r)
    for (const auto& e : kEdgeLocal) {
      const std::uint64_t key = EdgeKey(region_[r][e[0]], region_[r][e[1]]);
      if (crossings_.count(key)) ring_of[key].push_back(r);
    }
  std::vector<std::uint64_t> keys;
  for (const auto& kv : crossings_) keys.push_back(kv.first);
  std::sort(keys.begin(), keys.end());
  for (std::uint64_t key : keys) {
    const int a = static_cast<int>(key >> 32), b = static_cast<int>(key & 0xffffffffu);
    const std::vector<int>& ring = ring_of[key];
    ARREG_ASSERT(!ring.empty(), "crossed edge without elements");
    // Link of the edge as oriented segments c -> d of the positive (a, b, c, d).
    std::unordered_map<int, int> next, prev;
    for (int r : ring) {
      const auto cd = OppositeEdgeOriented(region_[r], a, b);
      next[cd[0]] = cd[1];
      prev[cd[1]] = cd[0];
    }
    int start = next.begin()->first;
    bool open = false;
    for (const auto& kv : next)
      if (!prev.count(kv.first)) {
        start = kv.first;
        open = true;
        break;
      }
    std::vector<int> poly = {start};
    for (int c = next[start]; c != start; c = next[c]) {
      poly.push_back(c);
      if (!next.count(c)) break;
    }
    ARREG_ASSERT(static_cast<int>(poly.size()) == static_cast<int>(ring.size()) + (open ? 1 : 0),
                 "edge link is not a simple chain");
    bool try_removal = !bielser;
    for (int t : m_.vertex_tets_[a])
      if (try_removal && Contains(m_.tets_[t], b)) {
        const auto it = local_of.find(t);
        if (it == local_of.end() || crossed_inverted_[it->second]) try_removal = false;
      }
    // Edges on unsewn faces keep them: no removal.
    for (int t : m_.vertex_tets_[a])
      if (try_removal && Contains(m_.tets_[t], b))
        for (int k = 0; k < 4; ++k) {
          const int c = m_.tets_[t][k];
          if (c != a && c != b && m_.unsewn_.count(FaceKey(a, b, c))) try_removal = false;
        }
    if (try_removal && open) {
      // Boundary edge: removal only where the boundary is flat enough (feature angle).
      std::vector<int> wing;
      for (int t : m_.vertex_tets_[a])
        if (Contains(m_.tets_[t], b))
          for (int k = 0; k < 4; ++k) {
            const int c = m_.tets_[t][k];
            if (c == a || c == b) continue;
            auto it = face_of.find(FaceKey(a, b, c));
            if (it != face_of.end() && faces[it->second].tet1 < 0) wing.push_back(c);
          }
      if (wing.size() != 2) {
        try_removal = false;
      } else if (opt_.feature_angle_deg == 0) {
        try_removal =
            Orient3d(m_.rest_[a], m_.rest_[b], m_.rest_[wing[0]], m_.rest_[wing[1]]) == 0 &&
            Orient3d(m_.current_[a], m_.current_[b], m_.current_[wing[0]], m_.current_[wing[1]]) ==
                0;
      } else {
        const Vec3 e = (m_.rest_[b] - m_.rest_[a]).normalized();
        Vec3 d0 = m_.rest_[wing[0]] - m_.rest_[a], d1 = m_.rest_[wing[1]] - m_.rest_[a];
        d0 -= d0.dot(e) * e;
        d1 -= d1.dot(e) * e;
        const double angle = std::acos(std::clamp(d0.normalized().dot(d1.normalized()), -1.0, 1.0));
        try_removal = (kPi - angle) * 180.0 / kPi <= opt_.feature_angle_deg;
      }
    }
    bool removed = false;
    if (try_removal) {
      // Best triangulation of the link polygon (max-min quality), O(n^3).
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
      if (n >= 3 && best[n - 1] >= opt_.min_flip_quality && best[n - 1] > kNone) {
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
        for (int r : ring) region_alive_[r] = 0;
        removed = true;
        ++summary_.num_removed_edges;
      }
    }
    if (!removed) {
      Crossing& c = crossings_.at(key);
      const std::vector<int> parents = {a, b};
      const double beta = opt_.min_barycentric;
      const double t = std::clamp(c.t, beta, 1 - beta);
      c.x_vertex = AddVertex(parents, {1 - t, t}, true);
      for (int r : ring) {
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
  }
  // Boundary points of split unsewn faces (with their bisection vertices) so the
  // pieces stay unsewn.
  for (auto& [y, pts] : unsewn_splits_) {
    const std::vector<int> corners = pts;
    for (int k = 0; k < 3; ++k)
      if (const Crossing* c = EdgeCrossing(corners[k], corners[(k + 1) % 3]))
        if (c->x_vertex >= 0) pts.push_back(c->x_vertex);
  }
}

bool CutEvent::Verify(std::string* why) const {
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
    added_volume += TetVolume(m_.rest_[q[0]], m_.rest_[q[1]], m_.rest_[q[2]], m_.rest_[q[3]]);
  }
  // Boundary general flips over non-flat faces change the volume on purpose.
  if (opt_.feature_angle_deg == 0 && std::abs(added_volume - removed_volume) > 1e-10 * scale) {
    *why = "the new elements do not fill the crossed ones exactly";
    return false;
  }
  return true;
}

void CutEvent::Commit(CutChange* change) {
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

void CutEvent::Separate() {
  // Unsew faces whose three vertices are marked (on S).
  std::vector<int> marked_list;
  for (int v = 0; v < static_cast<int>(marked_.size()); ++v)
    if (marked_[v]) marked_list.push_back(v);
  auto all_marked = [&](const Tet& t) {
    return Marked(t[0]) && Marked(t[1]) && Marked(t[2]) && Marked(t[3]);
  };
  for (int v : marked_list)
    for (int t : m_.vertex_tets_[v]) {
      const Tet& q = m_.tets_[t];
      if (all_marked(q)) continue;
      for (int lf = 0; lf < 4; ++lf) {
        const int a = q[kFaceOrder[lf][0]], b = q[kFaceOrder[lf][1]], c = q[kFaceOrder[lf][2]];
        if (std::min({a, b, c}) != v || !Marked(a) || !Marked(b) || !Marked(c)) continue;
        const std::uint64_t key = FaceKey(a, b, c);
        if (m_.unsewn_.count(key)) continue;
        int other = -1;
        for (int t2 : m_.vertex_tets_[a])
          if (t2 != t && Contains(m_.tets_[t2], b) && Contains(m_.tets_[t2], c)) other = t2;
        if (other < 0 || all_marked(m_.tets_[other])) continue;
        m_.unsewn_.insert(key);
        separated_faces_.push_back({a, b, c});
      }
    }
  // Pieces of split unsewn faces.
  for (const auto& [y, pts] : unsewn_splits_)
    for (int t : m_.vertex_tets_[y]) {
      const Tet& q = m_.tets_[t];
      for (int lf = 0; lf < 4; ++lf) {
        const int a = q[kFaceOrder[lf][0]], b = q[kFaceOrder[lf][1]], c = q[kFaceOrder[lf][2]];
        int in = 0;
        bool has_y = false;
        for (int x : {a, b, c}) {
          if (x == y)
            has_y = true;
          else if (std::find(pts.begin(), pts.end(), x) != pts.end())
            ++in;
        }
        if (has_y && in == 2) m_.unsewn_.insert(FaceKey(a, b, c));
      }
    }
  // Duplicate vertices whose elements fall apart into several groups across unsewn faces.
  std::vector<int> candidates;
  for (std::uint64_t key : m_.unsewn_) {
    candidates.push_back(static_cast<int>(key >> 42));
    candidates.push_back(static_cast<int>((key >> 21) & 0x1fffff));
    candidates.push_back(static_cast<int>(key & 0x1fffff));
  }
  std::sort(candidates.begin(), candidates.end());
  candidates.erase(std::unique(candidates.begin(), candidates.end()), candidates.end());
  for (int v : candidates) {
    const std::vector<int> around = m_.vertex_tets_[v];
    const int n = static_cast<int>(around.size());
    std::vector<int> parent(n);
    std::iota(parent.begin(), parent.end(), 0);
    std::function<int(int)> find = [&](int i) {
      return parent[i] == i ? i : parent[i] = find(parent[i]);
    };
    std::unordered_map<std::uint64_t, int> first;
    for (int i = 0; i < n; ++i) {
      const Tet& q = m_.tets_[around[i]];
      for (int lf = 0; lf < 4; ++lf) {
        const int a = q[kFaceOrder[lf][0]], b = q[kFaceOrder[lf][1]], c = q[kFaceOrder[lf][2]];
        if (a != v && b != v && c != v) continue;
        const std::uint64_t key = FaceKey(a, b, c);
        auto it = first.find(key);
        if (it == first.end()) {
          first.emplace(key, i);
        } else if (!m_.unsewn_.count(key)) {
          parent[find(i)] = find(it->second);
        }
      }
    }
    std::vector<int> roots;
    for (int i = 0; i < n; ++i)
      if (find(i) == i) roots.push_back(i);
    if (roots.size() < 2) continue;
    const STriangle* nearest = nullptr;
    DistanceToSurface(m_.current_[v], &nearest);
    // The group holding the lowest element index keeps the vertex.
    for (size_t g = 1; g < roots.size(); ++g) {
      const int root = find(roots[g]);
      const int copy = static_cast<int>(m_.rest_.size());
      m_.rest_.push_back(m_.rest_[v]);
      m_.current_.push_back(m_.current_[v]);
      m_.velocity_.push_back(m_.velocity_[v]);
      m_.vertex_tets_.emplace_back();
      marked_.push_back(marked_[v]);
      Vec3 centroid = Vec3::Zero();
      int count = 0;
      for (int i = 0; i < n; ++i) {
        if (find(i) != root) continue;
        const int t = around[i];
        Tet& q = m_.tets_[t];
        for (int k = 0; k < 4; ++k) {
          centroid += m_.current_[q[k]];
          if (q[k] == v) q[k] = copy;
        }
        ++count;
        m_.vertex_tets_[copy].push_back(t);
        auto& list = m_.vertex_tets_[v];
        list.erase(std::find(list.begin(), list.end(), t));
        changed_slots_.push_back(t);
      }
      centroid /= 4.0 * count;
      DuplicatedVertex d;
      d.index = copy;
      d.original = v;
      d.side = (nearest && nearest->normal.dot(centroid - m_.current_[v]) < 0) ? -1 : 1;
      duplicated_.push_back(d);
    }
  }
  summary_.num_duplicated_vertices = static_cast<int>(duplicated_.size());
  // Faces that are now true boundary no longer need to be remembered.
  for (auto it = m_.unsewn_.begin(); it != m_.unsewn_.end();) {
    const int a = static_cast<int>(*it >> 42), b = static_cast<int>((*it >> 21) & 0x1fffff),
              c = static_cast<int>(*it & 0x1fffff);
    int count = 0;
    for (int t : m_.vertex_tets_[a])
      if (Contains(m_.tets_[t], b) && Contains(m_.tets_[t], c)) ++count;
    if (count < 2)
      it = m_.unsewn_.erase(it);
    else
      ++it;
  }
}

CutSummary CutEvent::Run(CutChange* change) {
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
    if (!Verify(&why)) {
      Rollback();
      summary_ = CutSummary();
      summary_.status = CutStatus::kRejected;
      summary_.message = why;
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
  // A snapshot lets an event that would leave a pinched (non-manifold) boundary be
  // undone: it is retried without snapping (the usual cause), then rejected.
  const CuttableMesh before = *this;
  CutOptions opt = options;
  for (int attempt = 0; attempt < 2; ++attempt) {
    CutChange local;
    CutEvent event(this, surface, opt);
    CutSummary summary = event.Run(&local);
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
  rejected.message =
      "the separation would leave a non-manifold boundary (S is not resolved by "
      "the mesh there)";
  return rejected;
}

}  // namespace arreg::cutting
