// Cutting of a linear tetrahedral mesh along a separation surface S (thesis
// ch. 5): local remeshing by splits/flips (or Bielser-style subdivision) and separation.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <string>
#include <unordered_set>
#include <vector>

#include "core/enum_names.h"
#include "core/mesh.h"
#include "cutting/cut_surface.h"

namespace arreg::cutting {

namespace cut_internal {
class CutOperation;  // the steps of one Cut() (tet_cut_operation.h)
}  // namespace cut_internal

enum class RemeshMethod {
  // 1-4 split of crossed tetrahedra, 2-3 flips over crossed faces, general
  // flip (edge removal) over crossed edges, 1-3 split of boundary faces and
  // bisection of boundary feature edges (thesis 5.1).
  kFlips,
  // Baseline: every crossed edge and face gets a vertex (Bielser 1:17 style);
  // fully crossed tetrahedra are split without an interior vertex, partially
  // crossed ones around a vertex inside them (see docs/cutting.md).
  kBielser,
};
// The spelling in scene files and records: "flips", "bielser".
inline constexpr EnumName<RemeshMethod> kRemeshMethodNames[] = {
    {RemeshMethod::kFlips, "flips"}, {RemeshMethod::kBielser, "bielser"}};
const char* RemeshMethodName(RemeshMethod method);
// Inverse of RemeshMethodName; throws arreg::Error naming `file` and `field` for any other name.
RemeshMethod ParseRemeshMethod(const std::string& name, const std::string& file,
                               const std::string& field);

struct CutOptions {
  RemeshMethod method = RemeshMethod::kFlips;
  // Snapping threshold eps (unitless, >= 0; default 0.1): a vertex of a crossed
  // edge moves onto S when its distance to the tangent plane of S at the crossing
  // is below eps x (mean rest edge length) and below the other end's distance.
  double snap_epsilon = 0.1;
  // Vertices closer to S than this x (mean rest edge length) count as lying on S
  // (unitless, >= 0; default 1e-9). They are marked for separation and their edges
  // are never crossed.
  double on_surface_tolerance = 1e-9;
  // Smallest barycentric coordinate of an inserted vertex in the simplex it is
  // placed in (unitless, (0, 0.25); default 1e-6): keeps new elements non-degenerate.
  double min_barycentric = 1e-6;
  // A 2-3 flip or general flip is used only when every tetrahedron it makes has a
  // normalised volume 6 sqrt(2) V / l_rms^3 of at least this (unitless, >= 0;
  // default 1e-4); otherwise the face gets a vertex / the edge is bisected.
  double min_flip_quality = 1e-4;
  // Smallest normalised volume (rest configuration) of an element the event inserts (unitless,
  // >= 0; default 1e-10); below it the event is rejected. A sliver of normalised volume q is
  // about 1/q times stiffer across its thin direction than along it, and near q ~ 1e-12 the
  // implicit step's Cholesky factorisation loses definiteness in double precision: the default
  // keeps two orders of magnitude from there. Such elements come from S grazing a vertex, edge
  // or face closer than min_barycentric allows for; see Cut for the retry.
  double min_element_quality = 1e-10;
  // Boundary edges whose incident boundary faces deviate from flat by more than this
  // (degrees, >= 0; default 0 = only exactly coplanar faces) are features and are
  // bisected; others are removed by a general flip, which changes the enclosed
  // volume unless the faces are coplanar.
  double feature_angle_deg = 0.0;
  // Separate the mesh along S (unsew faces, duplicate vertices); default true.
  bool separate = true;
  // Free 1-4 vertices left inside the front of an earlier partial cut (not on S) are moved
  // onto S along a crossed edge, whatever their distance (thesis 5.1.4: the existing vertex
  // moves instead of the front being remeshed again); default true. Refused like a snap
  // when an incident element would become inverted or worse than min_flip_quality.
  bool move_front_vertices = true;

  void Check() const;
};

enum class CutStatus {
  kCut,         // S crossed the mesh; remeshed (and separated when asked)
  kNoCrossing,  // S does not cross any edge and lies on no face: mesh unchanged
  kRejected,    // an operation would have produced an inverted/degenerate element,
                // changed the volume or pinched the boundary (non-manifold), also
                // without snapping; the mesh is unchanged (message says why)
};

// A vertex created by the event: a convex combination of existing vertices
// (same weights for rest position, current position and velocity).
struct NewVertex {
  int index = -1;
  std::vector<int> parents;
  std::vector<double> weights;  // sum to 1
  bool on_surface = false;      // lies on S (marked for separation)
};

// A vertex split off by the separation: a copy of `original` (same rest/current
// position and velocity) taken by the elements on one side of S.
struct DuplicatedVertex {
  int index = -1;
  int original = -1;
  int side = 0;  // +1 / -1: side of S (along the S normal) of the elements that took it
};

// A vertex moved onto S by snapping: its new position is the convex combination
// (1 - t) * a + t * b of its crossed edge (rest, current, velocity alike).
struct SnappedVertex {
  int index = -1;
  int a = -1, b = -1;
  double t = 0;
};

// What one event changed, in the terms of mechanics::MechanicalState:
// AddVertices(new vertices then duplicated ones, in index order), then
// ReplaceTetrahedra(removed_tetrahedra, new_tetrahedra): new elements fill the
// removed slots in order, then are appended (there are never fewer new than removed).
struct CutChange {
  int num_vertices_before = 0;
  int num_tetrahedra_before = 0;
  std::vector<NewVertex> new_vertices;              // indices num_vertices_before...
  std::vector<DuplicatedVertex> duplicated;         // indices after the new vertices
  std::vector<SnappedVertex> snapped;               // existing vertices that moved
  std::vector<int> removed_tetrahedra;              // old slots whose element changed
  RowMatX4i new_tetrahedra;                         // (#new x 4)
  std::vector<std::array<int, 3>> separated_faces;  // faces unsewn by this event
};

// The on-surface tolerances (x mean rest edge length) an event that would insert a sliver is
// retried with, in turn: S moved by at most 0.1 %, then 1 % of an edge length onto the vertices
// it grazes, far below the accuracy of a cut surface from video (~ 0.5 mm).
inline constexpr double kSliverRetryTolerances[] = {1e-3, 1e-2};

struct CutSummary {
  CutStatus status = CutStatus::kNoCrossing;
  std::string message;
  // kRejected because an inserted element would have been below min_element_quality.
  bool sliver = false;
  // The on-surface tolerance the event was made with: options.on_surface_tolerance, or the
  // larger one a sliver made Cut retry with.
  double on_surface_tolerance = 0.0;
  int num_crossed_edges = 0;
  int num_crossed_tetrahedra = 0;  // n(v)
  int num_snapped_vertices = 0;    // snapped vertices and moved front vertices
  int num_moved_front_vertices = 0;
  int num_flipped_faces = 0;  // 2-3 flips
  int num_split_faces = 0;    // faces that got a vertex (boundary 1-3 splits included)
  int num_removed_edges = 0;  // general flips
  int num_bisected_edges = 0;
  int num_new_vertices = 0;         // remeshing only
  int num_duplicated_vertices = 0;  // separation
  int num_tetrahedra_added = 0;     // #T after - #T before
};

// A tetrahedral mesh that can be cut repeatedly. Keeps vertex -> element
// incidence and the set of unsewn faces (faces on S whose vertices are not yet
// all duplicated, e.g. at the front of a partial cut) so successive cuts continue
// earlier ones. Geometry decisions use the current positions; every new element is
// positive in the rest configuration and, unless it subdivides an element that is already
// inverted (or flat) in the current configuration, in the current one too: an inverted
// element does not stop a cut (see docs/cutting.md).
class CuttableMesh {
 public:
  // Throws arreg::Error for bad indices or an element of non-positive rest volume (the
  // current configuration may have inverted elements).
  explicit CuttableMesh(const TetMesh& rest_mesh);
  CuttableMesh(const TetMesh& rest_mesh, const RowMatX3d& current_positions,
               const RowMatX3d& velocities);

  // Replaces the current positions and velocities (#V x 3 each, same numbering), e.g. from
  // the mechanical state before the next event; the topology, unsewn faces and front
  // vertices are kept. Throws arreg::Error on a row count mismatch or non-finite values.
  void SetDeformation(const RowMatX3d& current_positions, const RowMatX3d& velocities);

  // One cutting event along S (in the frame of the current positions). An event that would
  // insert a sliver (CutOptions::min_element_quality) is retried with vertices within
  // kSliverRetryTolerances x (mean rest edge length) of S counted as on it, then rejected.
  CutSummary Cut(const CutSurface& surface, const CutOptions& options, CutChange* change = nullptr);

  int num_vertices() const { return static_cast<int>(rest_.size()); }
  int num_tetrahedra() const { return static_cast<int>(tets_.size()); }
  const std::vector<Eigen::Vector3d>& rest_positions() const { return rest_; }
  const std::vector<Eigen::Vector3d>& positions() const { return current_; }
  const std::vector<Eigen::Vector3d>& velocities() const { return velocity_; }
  const std::vector<std::array<int, 4>>& tetrahedra() const { return tets_; }
  // Mean rest edge length of the mesh given to the constructor (the snapping scale).
  double mean_rest_edge_length() const { return mean_edge_length_; }
  int num_unsewn_faces() const { return static_cast<int>(unsewn_.size()); }
  // Free 1-4 vertices at the front of partial cuts (see CutOptions::move_front_vertices).
  int num_front_vertices() const { return static_cast<int>(front_vertices_.size()); }

  TetMesh RestMesh() const;
  TetMesh CurrentMesh() const;

 private:
  // One attempt with these options; an event that would leave a pinched (non-manifold)
  // boundary is retried without snapping, then rejected.
  CutSummary CutKeepingManifold(const CutSurface& surface, const CutOptions& options,
                                CutChange* change);
  friend class cut_internal::CutOperation;
  void Init(const TetMesh& rest_mesh, const RowMatX3d& current, const RowMatX3d& velocities);
  bool BoundaryManifoldAround(const std::vector<int>& vertices) const;

  std::vector<Eigen::Vector3d> rest_, current_, velocity_;
  std::vector<std::array<int, 4>> tets_;
  std::vector<std::vector<int>> vertex_tets_;
  std::unordered_set<std::uint64_t> unsewn_;  // face keys (see FaceKey in tet_cut_operation.h)
  std::unordered_set<int> front_vertices_;    // 1-4 vertices of partial cuts, not on S
  double mean_edge_length_ = 0;
};

}  // namespace arreg::cutting
