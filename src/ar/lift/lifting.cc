#include "ar/lift/lifting.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <string>

#include "core/error.h"

namespace arreg::lift {

bool IntersectRayTriangle(const Ray& ray, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                          const Eigen::Vector3d& c, double t_min, double t_max, double* t,
                          double* u, double* v) {
  const Eigen::Vector3d e1 = b - a, e2 = c - a;
  const Eigen::Vector3d p = ray.direction_in_world.cross(e2);
  const double det = e1.dot(p);
  // Relative tolerance: a ray in the triangle's plane has no single hit.
  if (std::abs(det) <= 1e-14 * e1.norm() * e2.norm()) return false;
  const double inv = 1.0 / det;
  const Eigen::Vector3d s = ray.origin_in_world - a;
  const double uu = s.dot(p) * inv;
  if (uu < 0.0 || uu > 1.0) return false;
  const Eigen::Vector3d q = s.cross(e1);
  const double vv = ray.direction_in_world.dot(q) * inv;
  if (vv < 0.0 || uu + vv > 1.0) return false;
  const double tt = e2.dot(q) * inv;
  if (tt < t_min || tt > t_max) return false;
  *t = tt;
  *u = uu;
  *v = vv;
  return true;
}

void TriangleBvhOptions::Check() const {
  ARREG_CHECK_INPUT(max_leaf_triangles >= 1, "", "bvh.max_leaf_triangles", "must be >= 1, got ",
                    max_leaf_triangles);
}

void TriangleBvh::FaceBox(int face, Eigen::Vector3d* lo, Eigen::Vector3d* hi) const {
  *lo = *hi = vertices_.row(faces_(face, 0)).transpose();
  for (int k = 1; k < 3; ++k) {
    const Eigen::Vector3d p = vertices_.row(faces_(face, k)).transpose();
    *lo = lo->cwiseMin(p);
    *hi = hi->cwiseMax(p);
  }
}

void TriangleBvh::Build(const RowMatX3d& vertices_mm, const RowMatX3i& faces,
                        const TriangleBvhOptions& options) {
  options.Check();
  options_ = options;
  const int nv = static_cast<int>(vertices_mm.rows());
  for (int f = 0; f < faces.rows(); ++f)
    for (int k = 0; k < 3; ++k)
      ARREG_CHECK_INPUT(faces(f, k) >= 0 && faces(f, k) < nv, "", "face " + std::to_string(f),
                        "vertex index ", faces(f, k), " out of range [0, ", nv, ")");
  vertices_ = vertices_mm;
  faces_ = faces;
  nodes_.clear();
  order_.resize(faces.rows());
  std::vector<Eigen::Vector3d> centroids(faces.rows());
  for (int f = 0; f < faces.rows(); ++f) {
    order_[f] = f;
    centroids[f] =
        (vertices_.row(faces(f, 0)) + vertices_.row(faces(f, 1)) + vertices_.row(faces(f, 2)))
            .transpose() /
        3.0;
  }
  if (faces.rows() > 0) BuildNode(0, static_cast<int>(faces.rows()), centroids);
}

int TriangleBvh::BuildNode(int begin, int end, const std::vector<Eigen::Vector3d>& centroids) {
  const int index = static_cast<int>(nodes_.size());
  nodes_.emplace_back();
  Eigen::Vector3d lo, hi, clo, chi;
  FaceBox(order_[begin], &lo, &hi);
  clo = chi = centroids[order_[begin]];
  for (int i = begin + 1; i < end; ++i) {
    Eigen::Vector3d flo, fhi;
    FaceBox(order_[i], &flo, &fhi);
    lo = lo.cwiseMin(flo);
    hi = hi.cwiseMax(fhi);
    clo = clo.cwiseMin(centroids[order_[i]]);
    chi = chi.cwiseMax(centroids[order_[i]]);
  }
  nodes_[index].lo = lo;
  nodes_[index].hi = hi;
  if (end - begin <= options_.max_leaf_triangles) {
    nodes_[index].first = begin;
    nodes_[index].count = end - begin;
    return index;
  }
  int axis = 0;
  (chi - clo).maxCoeff(&axis);
  const int mid = (begin + end) / 2;
  std::nth_element(order_.begin() + begin, order_.begin() + mid, order_.begin() + end,
                   [&](int a, int b) { return centroids[a][axis] < centroids[b][axis]; });
  BuildNode(begin, mid, centroids);  // left child is index + 1
  const int right = BuildNode(mid, end, centroids);
  nodes_[index].first = right;
  nodes_[index].count = 0;
  return index;
}

void TriangleBvh::Refit(const RowMatX3d& vertices_mm) {
  ARREG_CHECK_INPUT(vertices_mm.rows() == vertices_.rows(), "", "TriangleBvh::Refit", "got ",
                    vertices_mm.rows(), " vertices, built with ", vertices_.rows());
  vertices_ = vertices_mm;
  // Children always come after their parent in nodes_, so a reverse sweep sees them first.
  for (int n = static_cast<int>(nodes_.size()) - 1; n >= 0; --n) {
    Node& node = nodes_[n];
    if (node.count > 0) {
      FaceBox(order_[node.first], &node.lo, &node.hi);
      for (int i = node.first + 1; i < node.first + node.count; ++i) {
        Eigen::Vector3d lo, hi;
        FaceBox(order_[i], &lo, &hi);
        node.lo = node.lo.cwiseMin(lo);
        node.hi = node.hi.cwiseMax(hi);
      }
    } else {
      node.lo = nodes_[n + 1].lo.cwiseMin(nodes_[node.first].lo);
      node.hi = nodes_[n + 1].hi.cwiseMax(nodes_[node.first].hi);
    }
  }
}

bool TriangleBvh::TestFace(int face, const Ray& ray, double t_min, double* t_max,
                           RayHit* hit) const {
  double t, u, v;
  if (!IntersectRayTriangle(ray, vertices_.row(faces_(face, 0)).transpose(),
                            vertices_.row(faces_(face, 1)).transpose(),
                            vertices_.row(faces_(face, 2)).transpose(), t_min, *t_max, &t, &u, &v))
    return false;
  // Equal distances (a ray through a shared edge) resolve to the lower face index, so the
  // answer does not depend on the traversal order.
  if (t == *t_max && hit->face >= 0 && face > hit->face) return false;
  *t_max = t;
  hit->t = t;
  hit->face = face;
  hit->barycentric = Eigen::Vector3d(1.0 - u - v, u, v);
  return true;
}

bool TriangleBvh::Intersect(const Ray& ray, RayHit* hit, double t_min, double t_max) const {
  ARREG_ASSERT(hit != nullptr, "");
  hit->face = -1;
  if (nodes_.empty()) return false;
  const Eigen::Vector3d& o = ray.origin_in_world;
  const Eigen::Vector3d inv = ray.direction_in_world.cwiseInverse();
  // Slab test of a node's box against the parameter interval [t_min, upper]; *entry is where
  // the ray enters the box.
  auto box_entry = [&](const Node& node, double upper, double* entry) {
    double t0 = t_min, t1 = upper;
    for (int k = 0; k < 3; ++k) {
      double a = (node.lo[k] - o[k]) * inv[k], b = (node.hi[k] - o[k]) * inv[k];
      if (a > b) std::swap(a, b);
      if (a > t0) t0 = a;
      if (b < t1) t1 = b;
      if (t0 > t1) return false;
    }
    *entry = t0;
    return true;
  };
  double best = t_max;
  constexpr int kStackSize = 128;
  int stack[kStackSize];
  int top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const int index = stack[--top];
    const Node& node = nodes_[index];
    double entry;
    // Tested when popped: a closer hit found meanwhile may rule the box out.
    if (!box_entry(node, best, &entry)) continue;
    if (node.count > 0) {
      for (int i = node.first; i < node.first + node.count; ++i)
        TestFace(order_[i], ray, t_min, &best, hit);
      continue;
    }
    const int left = index + 1, right = node.first;
    double el, er;
    const bool hl = box_entry(nodes_[left], best, &el), hr = box_entry(nodes_[right], best, &er);
    ARREG_ASSERT(top + 2 <= kStackSize, "BVH deeper than the traversal stack");
    // Push the farther child first so that the nearer one is visited first.
    if (hl && hr) {
      if (el <= er) {
        stack[top++] = right;
        stack[top++] = left;
      } else {
        stack[top++] = left;
        stack[top++] = right;
      }
    } else if (hl) {
      stack[top++] = left;
    } else if (hr) {
      stack[top++] = right;
    }
  }
  if (hit->face < 0) return false;
  hit->point_mm = ray.PointAt(hit->t);
  return true;
}

bool TriangleBvh::IntersectBruteForce(const Ray& ray, RayHit* hit, double t_min,
                                      double t_max) const {
  ARREG_ASSERT(hit != nullptr, "");
  hit->face = -1;
  double best = t_max;
  for (int f = 0; f < num_faces(); ++f) TestFace(f, ray, t_min, &best, hit);
  if (hit->face < 0) return false;
  hit->point_mm = ray.PointAt(hit->t);
  return true;
}

Plane FitPlane(const RowMatX3d& points_mm) {
  ARREG_CHECK_INPUT(points_mm.rows() >= 3, "", "FitPlane", "needs >= 3 points, got ",
                    points_mm.rows());
  const Eigen::Vector3d centroid = points_mm.colwise().mean().transpose();
  const Eigen::MatrixXd centred = points_mm.rowwise() - centroid.transpose();
  const Eigen::Matrix3d cov = centred.transpose() * centred;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
  // Collinear points leave two eigenvalues ~0: the plane is not determined.
  ARREG_CHECK_INPUT(eig.eigenvalues()(1) > 1e-12 * std::max(1.0, eig.eigenvalues()(2)), "",
                    "FitPlane", "points are collinear or coincident");
  Plane plane;
  plane.point_mm = centroid;
  plane.normal = eig.eigenvectors().col(0).normalized();
  return plane;
}

std::optional<double> IntersectRayPlane(const Ray& ray, const Plane& plane, double t_min) {
  const double denom = plane.normal.dot(ray.direction_in_world);
  if (std::abs(denom) < 1e-12) return std::nullopt;
  const double t = plane.normal.dot(plane.point_mm - ray.origin_in_world) / denom;
  if (!(t >= t_min)) return std::nullopt;
  return t;
}

void FeatureLifterOptions::Check() const {
  ARREG_CHECK_INPUT(std::isfinite(max_depth_jump_mm) && max_depth_jump_mm > 0.0, "",
                    "lift.max_depth_jump_mm", "must be > 0, got ", max_depth_jump_mm);
  ARREG_CHECK_INPUT(std::isfinite(min_ray_distance_mm) && min_ray_distance_mm >= 0.0, "",
                    "lift.min_ray_distance_mm", "must be >= 0, got ", min_ray_distance_mm);
  ARREG_CHECK_INPUT(!follow_model_thinning || surface_update == SurfaceUpdate::kInterceptTheorem,
                    "", "lift.follow_model_thinning", "needs the intercept-theorem update");
  bvh.Check();
}

FeatureLifter::FeatureLifter(const FeatureLifterOptions& options) : options_(options) {
  options_.Check();
}

std::vector<Ray> RaysThroughPixels(const PinholeCamera& camera, const RowMatX2d& pixels) {
  std::vector<Ray> rays(pixels.rows());
  for (int i = 0; i < pixels.rows(); ++i) {
    ARREG_CHECK_INPUT(pixels.row(i).allFinite(), "", "feature " + std::to_string(i),
                      "pixel must be finite");
    rays[i] = camera.RayThroughPixel(pixels.row(i).transpose());
  }
  return rays;
}

Eigen::Vector3d TriangleBvh::FaceNormal(int face) const {
  const Eigen::Vector3d a = vertices_.row(faces_(face, 0)).transpose();
  const Eigen::Vector3d n = (vertices_.row(faces_(face, 1)).transpose() - a)
                                .cross(vertices_.row(faces_(face, 2)).transpose() - a);
  const double length = n.norm();
  return length > 0 ? Eigen::Vector3d(n / length) : Eigen::Vector3d::Zero();
}

std::optional<double> FeatureLifter::HalfThickness(const Ray& ray) const {
  RayHit front, back;
  if (!bvh_.Intersect(ray, &front, options_.min_ray_distance_mm)) return std::nullopt;
  // Past the front triangle's plane by a hair, so an edge shared with the front triangle is not
  // counted again.
  if (!bvh_.Intersect(ray, &back, front.t + 1e-6 * (1.0 + front.t))) return std::nullopt;
  if (std::abs(bvh_.FaceNormal(front.face).dot(bvh_.FaceNormal(back.face))) < std::cos(M_PI / 6))
    return std::nullopt;
  return 0.5 * (back.t - front.t);
}

FeatureAttachment FeatureLifter::AttachAt(int row, const Eigen::Vector3d& point_mm,
                                          double ray_distance_mm, LiftStatus how) {
  attached_[row] = 1;
  targets_.row(row) = point_mm.transpose();
  intercept_targets_.row(row) = point_mm.transpose();
  status_[row] = how;
  FeatureAttachment a;
  a.attached = true;
  a.point_mm = point_mm;
  a.ray_distance_mm = ray_distance_mm;
  return a;
}

std::vector<FeatureAttachment> FeatureLifter::Attach(const PinholeCamera& camera,
                                                     const RowMatX2d& pixels,
                                                     const SurfaceMesh* surface,
                                                     const std::optional<Plane>& plane) {
  return Attach(RaysThroughPixels(camera, pixels), surface, plane);
}

std::vector<FeatureAttachment> FeatureLifter::Attach(const std::vector<Ray>& rays,
                                                     const SurfaceMesh* surface,
                                                     const std::optional<Plane>& plane) {
  const int n = static_cast<int>(rays.size());
  const bool on_surface = options_.target == LiftTarget::kSurface;
  ARREG_CHECK_INPUT(!on_surface || surface != nullptr, "", "FeatureLifter::Attach",
                    "the surface variant needs the model surface");
  ARREG_CHECK_INPUT(on_surface || plane.has_value(), "", "FeatureLifter::Attach",
                    "the plane variant needs a plane");
  have_surface_ = surface != nullptr;
  if (have_surface_) bvh_.Build(surface->vertices, surface->faces, options_.bvh);
  std::vector<FeatureAttachment> out(n);
  targets_.setZero(n, 3);
  plane_targets_.setZero(n, 3);
  intercept_targets_.setZero(n, 3);
  half_thickness_.assign(n, std::numeric_limits<double>::quiet_NaN());
  plane_valid_.assign(n, 0);
  attached_.assign(n, 0);
  status_.assign(n, LiftStatus::kNotAttached);
  if (on_surface) {
    for (int i = 0; i < n; ++i) {
      RayHit hit;
      if (!bvh_.Intersect(rays[i], &hit, options_.min_ray_distance_mm)) continue;
      out[i] = AttachAt(i, hit.point_mm, hit.t, LiftStatus::kSurfaceHit);
      if (options_.follow_model_thinning)
        half_thickness_[i] = HalfThickness(rays[i]).value_or(half_thickness_[i]);
      out[i].face = hit.face;
      out[i].barycentric = hit.barycentric;
    }
    if (plane) {
      plane_ = *plane;
    } else {
      std::vector<int> hits;
      for (int i = 0; i < n; ++i)
        if (attached_[i]) hits.push_back(i);
      ARREG_CHECK_INPUT(hits.size() >= 3, "", "FeatureLifter::Attach",
                        "fitting the projection plane needs >= 3 attached features, got ",
                        hits.size());
      RowMatX3d points(hits.size(), 3);
      for (size_t k = 0; k < hits.size(); ++k) points.row(k) = targets_.row(hits[k]);
      plane_ = FitPlane(points);
    }
  } else {
    plane_ = *plane;
  }
  ARREG_CHECK_INPUT(std::abs(plane_.normal.norm() - 1.0) < 1e-9, "", "plane.normal",
                    "must have unit length");
  for (int i = 0; i < n; ++i) {
    const std::optional<double> t =
        IntersectRayPlane(rays[i], plane_, options_.min_ray_distance_mm);
    if (!t) continue;
    plane_targets_.row(i) = rays[i].PointAt(*t).transpose();
    plane_valid_[i] = 1;
    if (!on_surface) out[i] = AttachAt(i, rays[i].PointAt(*t), *t, LiftStatus::kPlaneHit);
  }
  return out;
}

std::vector<FeatureAttachment> FeatureLifter::AttachMore(const std::vector<Ray>& rays,
                                                         const RowMatX3d* surface_vertices_mm) {
  const int old_n = static_cast<int>(attached_.size());
  const int added = static_cast<int>(rays.size());
  const bool on_surface = options_.target == LiftTarget::kSurface;
  ARREG_CHECK_INPUT(!on_surface || (surface_vertices_mm != nullptr && have_surface_), "",
                    "FeatureLifter::AttachMore", "the surface variant needs the current surface");
  if (on_surface) bvh_.Refit(*surface_vertices_mm);
  targets_.conservativeResize(old_n + added, 3);
  plane_targets_.conservativeResize(old_n + added, 3);
  intercept_targets_.conservativeResize(old_n + added, 3);
  targets_.bottomRows(added).setZero();
  plane_targets_.bottomRows(added).setZero();
  intercept_targets_.bottomRows(added).setZero();
  half_thickness_.resize(old_n + added, std::numeric_limits<double>::quiet_NaN());
  plane_valid_.resize(old_n + added, 0);
  attached_.resize(old_n + added, 0);
  status_.resize(old_n + added, LiftStatus::kNotAttached);
  std::vector<FeatureAttachment> out(added);
  for (int k = 0; k < added; ++k) {
    const int i = old_n + k;
    const std::optional<double> t_plane =
        IntersectRayPlane(rays[k], plane_, options_.min_ray_distance_mm);
    if (t_plane) {
      plane_targets_.row(i) = rays[k].PointAt(*t_plane).transpose();
      plane_valid_[i] = 1;
    }
    if (on_surface) {
      RayHit hit;
      if (!bvh_.Intersect(rays[k], &hit, options_.min_ray_distance_mm)) continue;
      out[k] = AttachAt(i, hit.point_mm, hit.t, LiftStatus::kSurfaceHit);
      if (options_.follow_model_thinning)
        half_thickness_[i] = HalfThickness(rays[k]).value_or(half_thickness_[i]);
      out[k].face = hit.face;
      out[k].barycentric = hit.barycentric;
    } else if (t_plane) {
      out[k] = AttachAt(i, rays[k].PointAt(*t_plane), *t_plane, LiftStatus::kPlaneHit);
    }
  }
  return out;
}

LiftSummary FeatureLifter::Update(const PinholeCamera& camera, const RowMatX2d& pixels,
                                  const std::vector<char>& tracked,
                                  const RowMatX3d* surface_vertices_mm) {
  return Update(RaysThroughPixels(camera, pixels), tracked, surface_vertices_mm);
}

LiftSummary FeatureLifter::Update(const std::vector<Ray>& rays, const std::vector<char>& tracked,
                                  const RowMatX3d* surface_vertices_mm) {
  const int n = static_cast<int>(attached_.size());
  ARREG_CHECK_INPUT(static_cast<int>(rays.size()) == n, "", "FeatureLifter::Update", "got ",
                    rays.size(), " rays for ", n, " features");
  ARREG_CHECK_INPUT(tracked.empty() || static_cast<int>(tracked.size()) == n, "",
                    "FeatureLifter::Update", "tracked has ", tracked.size(), " entries for ", n,
                    " features");
  const bool on_surface = options_.target == LiftTarget::kSurface;
  const bool cast = on_surface && options_.surface_update == SurfaceUpdate::kRayCastWithFallback;
  const bool thinning = on_surface && options_.follow_model_thinning;
  if (cast || thinning) {
    ARREG_CHECK_INPUT(surface_vertices_mm != nullptr && have_surface_, "", "FeatureLifter::Update",
                      "ray casting needs the current surface vertices");
    bvh_.Refit(*surface_vertices_mm);
  }
  LiftSummary summary;
  for (int i = 0; i < n; ++i) {
    if (!attached_[i]) continue;
    if (!tracked.empty() && !tracked[i]) {
      status_[i] = LiftStatus::kLost;
      ++summary.lost;
      continue;
    }
    const Ray& ray = rays[i];
    const Eigen::Vector3d v = ray.origin_in_world;
    const std::optional<double> t_plane =
        IntersectRayPlane(ray, plane_, options_.min_ray_distance_mm);
    const Eigen::Vector3d previous =
        thinning ? intercept_targets_.row(i).transpose() : targets_.row(i).transpose();
    if (!on_surface) {
      if (t_plane) {
        targets_.row(i) = ray.PointAt(*t_plane).transpose();
        status_[i] = LiftStatus::kPlaneHit;
        ++summary.plane_hits;
      } else {
        targets_.row(i) = ray.PointAt((previous - v).norm()).transpose();
        status_[i] = LiftStatus::kCarriedDepth;
        ++summary.carried;
      }
    } else {
      // Eq. 7.1 (intercept theorem): the plane displacement scaled by the ratio of the distances
      // of the surface and plane targets from the camera keeps p_FS on the new ray.
      Eigen::Vector3d predicted;
      LiftStatus how;
      const Eigen::Vector3d previous_plane = plane_targets_.row(i).transpose();
      const double plane_distance = (previous_plane - v).norm();
      if (t_plane && plane_valid_[i] && plane_distance > 0.0) {
        const double ratio = (previous - v).norm() / plane_distance;
        predicted = previous + ratio * (ray.PointAt(*t_plane) - previous_plane);
        how = LiftStatus::kIntercept;
      } else {
        predicted = ray.PointAt((previous - v).norm());
        how = LiftStatus::kCarriedDepth;
      }
      if (cast) {
        RayHit hit;
        if (bvh_.Intersect(ray, &hit, options_.min_ray_distance_mm) &&
            std::abs(hit.t - (predicted - v).norm()) <= options_.max_depth_jump_mm) {
          predicted = hit.point_mm;
          how = LiftStatus::kSurfaceHit;
        }
      }
      intercept_targets_.row(i) = predicted.transpose();
      if (thinning && std::isfinite(half_thickness_[i])) {
        const std::optional<double> half = HalfThickness(ray);
        // A change beyond max_depth_jump_mm is a ray that left the body's edge, not thinning.
        if (half && std::abs(half_thickness_[i] - *half) <= options_.max_depth_jump_mm)
          predicted += (half_thickness_[i] - *half) * ray.direction_in_world;
      }
      targets_.row(i) = predicted.transpose();
      status_[i] = how;
      if (how == LiftStatus::kSurfaceHit)
        ++summary.surface_hits;
      else if (how == LiftStatus::kIntercept)
        ++summary.intercepts;
      else
        ++summary.carried;
    }
    if (t_plane) {
      plane_targets_.row(i) = ray.PointAt(*t_plane).transpose();
      plane_valid_[i] = 1;
    } else {
      plane_valid_[i] = 0;
    }
  }
  return summary;
}

}  // namespace arreg::lift
