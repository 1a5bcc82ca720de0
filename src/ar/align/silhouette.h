// Silhouettes for `arreg align`: the target outline of one frame (mask, signed distance
// transform, boundary points) and the model's projected occluding contour at a pose.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/camera.h"
#include "core/mesh.h"

namespace arreg::align {

// A similarity placing the model in the world: point_in_world = scale * rotation * p + translation.
struct ModelPose {
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d translation_mm = Eigen::Vector3d::Zero();
  double scale = 1.0;  // dimensionless, 1 for a rigid pose

  Eigen::Vector3d Apply(const Eigen::Vector3d& point_in_model) const {
    return scale * (rotation * point_in_model) + translation_mm;
  }
  // The rigid part (scale left out), as the scene's world_from_model.
  Eigen::Isometry3d Rigid() const;
  static ModelPose FromRigid(const Eigen::Isometry3d& world_from_model);
};

// Rotation angle (deg) of a_R b_R^T and distance (mm) between where the two poses put `point`.
double RotationErrorDeg(const ModelPose& a, const ModelPose& b);
double PointErrorMm(const ModelPose& a, const ModelPose& b, const Eigen::Vector3d& point_in_model);

// The organ outline in one frame: a binary mask of the camera's size, its signed distance
// transform (px; negative inside, 0 on the boundary between inside and outside pixel centres)
// and sample points on its boundary. Boundary parts on the image border are not outline (the
// organ continues beyond the image) and carry no points.
struct Outline {
  cv::Mat mask;                // CV_8U, 255 inside, camera size
  cv::Mat signed_distance_px;  // CV_64F, camera size
  RowMatX2d boundary_px;       // (#B x 2) points on the outline, pixels
  RowMatX2d normals;           // (#B x 2) unit outward normals at boundary_px
  double area_px = 0;          // inside pixels
  Eigen::Vector2d centroid_px = Eigen::Vector2d::Zero();
};

// `mask`: CV_8U, inside where > 127. `spacing_px`: distance between boundary samples (>= 1).
// Throws arreg::Error naming `file` when the mask is empty or of another size than the camera.
Outline OutlineFromMask(const cv::Mat& mask, const PinholeCamera& camera, double spacing_px,
                        const std::string& file);
// Reads an outline: a PNG/other image read as grey (inside > 127), or a JSON file
// {"polygons": [[[u, v], ...], ...]} of closed polygons in pixels (each filled).
Outline ReadOutline(const std::string& path, const PinholeCamera& camera, double spacing_px);

// The closed boundary surface of the model with its edge-face adjacency, in the model frame (mm).
class ModelSurface {
 public:
  // `surface`: closed triangle mesh, faces counter-clockwise seen from outside.
  explicit ModelSurface(const SurfaceMesh& surface);

  const RowMatX3d& vertices() const { return vertices_; }
  const RowMatX3i& faces() const { return faces_; }
  // Area-weighted centroid of the surface, model frame (mm).
  const Eigen::Vector3d& centroid() const { return centroid_; }
  double area_mm2() const { return area_mm2_; }
  // Half the largest bounding-box diagonal: a length for relative tolerances (mm).
  double radius_mm() const { return radius_mm_; }

  struct Edge {
    int a, b;          // vertices
    int face0, face1;  // the two faces sharing it
    bool crease;       // the faces meet at more than kCreaseDeg: a real edge of the organ
  };
  static constexpr double kCreaseDeg = 30.0;
  const std::vector<Edge>& edges() const { return edges_; }
  const RowMatX3d& face_normals() const { return face_normals_; }  // (#F x 3) unit, model frame
  const RowMatX3d& vertex_normals() const {
    return vertex_normals_;
  }  // (#V x 3) unit, area-weighted
  // Point at parameter t in [0, 1] of edge e on the smooth surface the mesh samples: the
  // vertices lie on the organ, the chord between them sags inside it (by about t (1 - t) h^2 / 2R
  // on a surface of radius R), so smooth edges are bent out to the circle through a and b
  // normal to their vertex normals (half the Phong-tessellation displacement, exact to first
  // order on a sphere). Creases stay straight.
  Eigen::Vector3d EdgePoint(const Edge& e, double t) const;

 private:
  RowMatX3d vertices_;
  RowMatX3i faces_;
  RowMatX3d face_normals_, vertex_normals_;
  std::vector<Edge> edges_;
  Eigen::Vector3d centroid_ = Eigen::Vector3d::Zero();
  double area_mm2_ = 0, radius_mm_ = 0;
};

// Points on the model's occluding contour as seen at a pose: samples along the mesh edges
// between a front- and a back-facing face whose image lies on the boundary of the model's
// projected silhouette (so contour parts hidden behind the model itself are left out).
struct ContourSamples {
  RowMatX3d points_in_model;  // (#C x 3) mm
  RowMatX2d pixels;           // (#C x 2) where they project, px
  RowMatX2d normals;          // (#C x 2) unit outward normals of the silhouette, image
};

struct ProjectedModel {
  bool valid = false;  // false when part of the model lies behind the camera's near plane
  cv::Mat mask;        // CV_8U, 255 where the model projects (union of front faces)
  ContourSamples contour;
};

// Projects the model with lens distortion (vertices are distorted, faces drawn straight
// between them) at `pose` and extracts the contour, one sample per `spacing_px` of edge
// length. `scale_px` < 1 renders a reduced mask (factor of the camera's size; contour
// sampling is then skipped), for the coarse pose search.
// `smooth_contour`: samples on ModelSurface::EdgePoint instead of the straight chords.
ProjectedModel ProjectModel(const ModelSurface& surface, const PinholeCamera& camera,
                            const ModelPose& pose, double spacing_px, double scale_px = 1.0,
                            bool with_contour = true, bool smooth_contour = false);

// Intersection over union of two masks of equal size (0 when both are empty).
double MaskIou(const cv::Mat& a, const cv::Mat& b);

}  // namespace arreg::align
