// The steps of one cutting event of CuttableMesh::Cut() and the mesh helpers they share.
// Internal to the cutting module (tet_cutter.cc, tet_cut_operation.cc, tet_remesh.cc,
// tet_separation.cc).
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cstdint>
#include <limits>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "core/geometry.h"
#include "cutting/predicates.h"
#include "cutting/tet_cutter.h"

namespace arreg::cutting::cut_internal {

using Vec3 = Eigen::Vector3d;
using Tet = std::array<int, 4>;

constexpr double kPi = 3.14159265358979323846;

inline std::uint64_t EdgeKey(int a, int b) {
  if (a > b) std::swap(a, b);
  return (static_cast<std::uint64_t>(a) << 32) | static_cast<std::uint32_t>(b);
}

// Faces are keyed by their sorted vertex triple, 21 bits per index.
inline std::uint64_t FaceKey(int a, int b, int c) {
  int v[3] = {a, b, c};
  std::sort(v, v + 3);
  return (static_cast<std::uint64_t>(v[0]) << 42) | (static_cast<std::uint64_t>(v[1]) << 21) |
         static_cast<std::uint64_t>(v[2]);
}

// Local vertex orders (u, v, w) of the face opposite vertex i such that
// (u, v, w, opposite) is an even permutation of (0, 1, 2, 3).
constexpr int kFaceOrder[4][3] = {{1, 3, 2}, {0, 2, 3}, {0, 3, 1}, {0, 1, 2}};
constexpr int kEdgeLocal[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};

inline bool Contains(const Tet& t, int v) {
  return t[0] == v || t[1] == v || t[2] == v || t[3] == v;
}

// Reorders a positive tetrahedron containing a and b as (a, b, c, d), still positive.
inline std::array<int, 2> OppositeEdgeOriented(const Tet& t, int a, int b) {
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

// A face of the crossed tetrahedra during remeshing.
struct RemeshFace {
  int verts[3];              // oriented from the side of tet0
  int tet0 = -1, tet1 = -1;  // indices into the crossed elements (tet1 = -1: boundary face)
  int num_crossed = 0;
  bool flip = false;
  int y = -1;  // vertex inserted on the face
  bool unsewn = false;
};

// The crossed elements as remeshing sees them: their 1-4 split vertices and their faces.
struct CrossedRegion {
  std::unordered_map<int, int> local_of;  // element index -> index among the crossed ones
  std::vector<int> split_vertex;          // per crossed element: its 1-4 split vertex
  std::vector<RemeshFace> faces;
  std::unordered_map<std::uint64_t, int> face_of;  // face key -> index into faces
  std::vector<std::array<int, 4>> element_faces;   // per crossed element: its faces (by local face)
};

// A crossed edge (a, b) and its link: the elements of region_ around it and the polygon of
// their opposite edges (a chain when the edge is on the boundary, `open`).
struct EdgeLink {
  std::uint64_t key = 0;
  int a = -1, b = -1;
  const std::vector<int>* ring = nullptr;  // indices into region_
  std::vector<int> polygon;
  bool open = false;
};

// One cutting event: all the state of the steps of CuttableMesh::Cut() (tet_cut_operation.cc:
// crossings, snapping, verification, commit; tet_remesh.cc; tet_separation.cc).
class CutOperation {
 public:
  CutOperation(CuttableMesh* mesh, const CutSurface& surface, const CutOptions& options)
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
  // Keys of the crossed edges in increasing order, so that no step depends on the hash order.
  std::vector<std::uint64_t> SortedCrossedEdges() const {
    std::vector<std::uint64_t> keys;
    for (const auto& kv : crossings_) keys.push_back(kv.first);
    std::sort(keys.begin(), keys.end());
    return keys;
  }
  bool Marked(int v) const { return v < static_cast<int>(marked_.size()) && marked_[v]; }

  // --- steps ---
  void ComputeCrossings(const std::vector<int>& candidate_tets);
  void Snap();
  void MoveFrontVertices();
  // Remeshing of the crossed region, one function per CutOptions::method (tet_remesh.cc).
  void Remesh();
  void RemeshByFlips();
  void RemeshBySubdivision();
  // Shared steps of the methods, in the order they run.
  CrossedRegion SplitCrossedTetrahedra();
  bool TryFlipFace(const CrossedRegion& region, RemeshFace* face);
  void SplitFace(RemeshFace* face);
  void FillRegion(const CrossedRegion& region);
  // Per crossed edge key: the elements of region_ around it (before any edge is processed).
  std::unordered_map<std::uint64_t, std::vector<int>> CrossedEdgeRings() const;
  EdgeLink LinkOf(std::uint64_t key,
                  const std::unordered_map<std::uint64_t, std::vector<int>>& rings) const;
  bool EdgeRemovable(const CrossedRegion& region, const EdgeLink& link) const;
  bool RemoveEdge(const EdgeLink& link);
  void BisectEdge(const EdgeLink& link);
  void ExtendUnsewnSplits();
  // False (with the reason, and whether it is a sliver) when the event must be rejected.
  bool Verify(std::string* why, bool* sliver) const;
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

}  // namespace arreg::cutting::cut_internal
