// 2D -> 3D lifting of tracked features (thesis 7.4.2): rays through the feature pixels meet a
// plane (p_FP) or the deformed model surface (p_FS, via a BVH), with the intercept theorem (7.1).
#pragma once

#include <Eigen/Core>
#include <limits>
#include <optional>
#include <vector>

#include "core/camera.h"
#include "core/enum_names.h"
#include "core/mesh.h"

namespace arreg::lift {

// Closest intersection of a ray with a triangle mesh.
struct RayHit {
  double t = 0.0;               // distance along the (unit) ray direction [mm]
  int face = -1;                // triangle index
  Eigen::Vector3d barycentric;  // weights of the face's vertices 0, 1, 2
  Eigen::Vector3d point_mm;     // origin + t * direction
};

// Moller-Trumbore, both faces. On a hit with t in [t_min, t_max] sets *t and the barycentric
// weights (1-u-v, u, v) of (a, b, c).
bool IntersectRayTriangle(const Ray& ray, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                          const Eigen::Vector3d& c, double t_min, double t_max, double* t,
                          double* u, double* v);

struct TriangleBvhOptions {
  int max_leaf_triangles = 4;  // triangles per leaf at most [count]; default 4
  void Check() const;
};

// Bounding-volume hierarchy of axis-aligned boxes over triangles, split at the median centroid
// along the widest axis. Refit() follows a deforming mesh of fixed connectivity in O(#F), which
// is what the per-frame cast against the current model needs.
class TriangleBvh {
 public:
  // vertices_mm: (#V x 3), faces: (#F x 3). Throws arreg::Error on out-of-range indices.
  void Build(const RowMatX3d& vertices_mm, const RowMatX3i& faces,
             const TriangleBvhOptions& options = {});
  // Moves the vertices (same count and faces as Build) and updates the boxes.
  void Refit(const RowMatX3d& vertices_mm);
  // Closest hit with t in [t_min, t_max]; false when none.
  bool Intersect(const Ray& ray, RayHit* hit, double t_min = 0.0,
                 double t_max = std::numeric_limits<double>::infinity()) const;
  // Reference answer: every triangle tested (for tests and tiny meshes).
  bool IntersectBruteForce(const Ray& ray, RayHit* hit, double t_min = 0.0,
                           double t_max = std::numeric_limits<double>::infinity()) const;

  // Unit normal of triangle `face` as the vertices stand (zero for a degenerate triangle).
  Eigen::Vector3d FaceNormal(int face) const;
  int num_faces() const { return static_cast<int>(faces_.rows()); }
  int num_nodes() const { return static_cast<int>(nodes_.size()); }

 private:
  struct Node {
    Eigen::Vector3d lo, hi;
    int first = 0;  // leaf: first index into order_; inner: index of the right child
    int count = 0;  // leaf: triangle count; inner: 0 (left child is the next node)
  };
  int BuildNode(int begin, int end, const std::vector<Eigen::Vector3d>& centroids);
  void FaceBox(int face, Eigen::Vector3d* lo, Eigen::Vector3d* hi) const;
  bool TestFace(int face, const Ray& ray, double t_min, double* t_max, RayHit* hit) const;

  TriangleBvhOptions options_;
  RowMatX3d vertices_;
  RowMatX3i faces_;
  std::vector<int> order_;  // faces in leaf order
  std::vector<Node> nodes_;
};

// Plane {x : normal . (x - point) = 0}.
struct Plane {
  Eigen::Vector3d point_mm = Eigen::Vector3d::Zero();
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  // unit length
};

// Least-squares plane through points_mm (#P x 3, P >= 3, not collinear): centroid and the
// eigenvector of the smallest covariance eigenvalue. Throws arreg::Error when degenerate.
Plane FitPlane(const RowMatX3d& points_mm);

// Distance t >= t_min along the ray to the plane, or nullopt when parallel or behind.
std::optional<double> IntersectRayPlane(const Ray& ray, const Plane& plane, double t_min = 0.0);

// Where the virtual features are placed (thesis 7.4.2).
enum class LiftTarget {
  kPlane,    // p_FP: the plane the video "leans against"
  kSurface,  // p_FS: the model surface, moved by the intercept theorem (eq. 7.1)
};
// The spelling in scene files, options and records: "surface", "plane".
inline constexpr EnumName<LiftTarget> kLiftTargetNames[] = {{LiftTarget::kSurface, "surface"},
                                                            {LiftTarget::kPlane, "plane"}};

// How the surface targets p^1_FS are updated after frame 0.
enum class SurfaceUpdate {
  // Eq. 7.1 for every feature (the thesis): a direct projection is unreliable once the real
  // object moves beyond the virtual one's silhouette.
  kInterceptTheorem,
  // Cast the ray against the current model surface; eq. 7.1 where it misses, or where the hit
  // jumps in depth by more than max_depth_jump_mm (the ray went past the silhouette to another
  // part of the surface).
  kRayCastWithFallback,
};
// The spelling in scene files, options and records: "intercept", "raycast".
inline constexpr EnumName<SurfaceUpdate> kSurfaceUpdateNames[] = {
    {SurfaceUpdate::kInterceptTheorem, "intercept"},
    {SurfaceUpdate::kRayCastWithFallback, "raycast"}};

struct FeatureLifterOptions {
  LiftTarget target = LiftTarget::kSurface;                         // default: model surface
  SurfaceUpdate surface_update = SurfaceUpdate::kInterceptTheorem;  // default: thesis eq. 7.1
  // [mm] largest change of the ray distance accepted from a cast hit (kRayCastWithFallback).
  // Default 10.
  double max_depth_jump_mm = 10.0;
  // [mm] hits closer to the camera than this are ignored (the near plane). Default 1e-6.
  double min_ray_distance_mm = 1e-6;
  // kInterceptTheorem only: move each target along its ray by the change of the model's
  // half-thickness along that ray since the feature was attached (the first and second
  // crossing of the ray with the current model surface). Eq. 7.1 carries the front face at
  // the depth of the projection plane's motion; a body that thins under stretch recedes on
  // both faces, which the image cannot see but the model's material predicts. Default false.
  bool follow_model_thinning = false;
  TriangleBvhOptions bvh;
  void Check() const;
};

// How a feature's target was found this frame.
enum class LiftStatus {
  kNotAttached,   // its frame-0 ray missed (surface or plane): never a target
  kLost,          // not tracked this frame: target kept
  kSurfaceHit,    // ray hit the model surface
  kPlaneHit,      // ray hit the plane (plane variant)
  kIntercept,     // eq. 7.1 from the previous target
  kCarriedDepth,  // the plane was parallel to the ray: previous ray distance kept
};

struct FeatureAttachment {
  bool attached = false;
  Eigen::Vector3d point_mm = Eigen::Vector3d::Zero();     // p^0_F
  int face = -1;                                          // surface triangle (kSurface), else -1
  Eigen::Vector3d barycentric = Eigen::Vector3d::Zero();  // on that triangle
  double ray_distance_mm = 0.0;                           // |p^0_F - camera centre|
};

struct LiftSummary {
  int surface_hits = 0;
  int plane_hits = 0;
  int intercepts = 0;
  int carried = 0;
  int lost = 0;
};

// Keeps the per-feature targets p^1_F from frame to frame. Rows of all per-feature inputs
// follow the order given to Attach.
class FeatureLifter {
 public:
  explicit FeatureLifter(const FeatureLifterOptions& options = {});

  // Frame 0. `surface` is the model surface in world coordinates (needed for kSurface);
  // `plane` is the projection plane; when absent it is fitted to the surface hits (kSurface)
  // and required otherwise. A feature is attached only if its ray hits the target.
  std::vector<FeatureAttachment> Attach(const std::vector<Ray>& rays, const SurfaceMesh* surface,
                                        const std::optional<Plane>& plane);
  std::vector<FeatureAttachment> Attach(const PinholeCamera& camera, const RowMatX2d& pixels,
                                        const SurfaceMesh* surface,
                                        const std::optional<Plane>& plane);

  // Features that join after frame 0: their rays are cast against the current model surface
  // (`surface_vertices_mm`, #V x 3, the connectivity of Attach's surface; kSurface) or the
  // plane, and they are appended as rows after the existing ones, attached where the ray hits.
  // Their plane targets start on this frame's ray, so eq. 7.1 carries them from here.
  std::vector<FeatureAttachment> AttachMore(const std::vector<Ray>& rays,
                                            const RowMatX3d* surface_vertices_mm);

  // Next frame. `surface_vertices_mm` (#V x 3, connectivity of Attach's surface) is the current
  // deformed model; needed only for kRayCastWithFallback. `tracked` (#F, may be empty = all)
  // marks features the tracker still has. Updates and returns targets().
  LiftSummary Update(const std::vector<Ray>& rays, const std::vector<char>& tracked,
                     const RowMatX3d* surface_vertices_mm);
  LiftSummary Update(const PinholeCamera& camera, const RowMatX2d& pixels,
                     const std::vector<char>& tracked, const RowMatX3d* surface_vertices_mm);

  const RowMatX3d& targets_mm() const { return targets_; }              // (#F x 3) p^1_F
  const RowMatX3d& plane_targets_mm() const { return plane_targets_; }  // (#F x 3) p^1_FP
  const std::vector<LiftStatus>& status() const { return status_; }
  const Plane& plane() const { return plane_; }

 private:
  // Marks row `row` attached at point_mm (its target) found `how`; the attachment without a
  // face (the caller adds the surface hit's face and weights).
  FeatureAttachment AttachAt(int row, const Eigen::Vector3d& point_mm, double ray_distance_mm,
                             LiftStatus how);

  FeatureLifterOptions options_;
  // Half the distance between the first two crossings of `ray` with the BVH's surface, or
  // nullopt when the ray does not cross it twice or the two faces it crosses are not within
  // 30 degrees of parallel (near an edge the ray leaves through a side, and that chord is no
  // thickness).
  std::optional<double> HalfThickness(const Ray& ray) const;

  TriangleBvh bvh_;
  bool have_surface_ = false;
  Plane plane_;
  RowMatX3d targets_;                   // p^1_F (surface or plane variant)
  RowMatX3d plane_targets_;             // p^1_FP(t), for eq. 7.1
  RowMatX3d intercept_targets_;         // eq. 7.1 alone (follow_model_thinning)
  std::vector<double> half_thickness_;  // at attachment [mm]; NaN: unknown
  std::vector<char> plane_valid_;
  std::vector<char> attached_;
  std::vector<LiftStatus> status_;
};

// Rays through pixels (#F x 2) of a camera.
std::vector<Ray> RaysThroughPixels(const PinholeCamera& camera, const RowMatX2d& pixels);

}  // namespace arreg::lift
