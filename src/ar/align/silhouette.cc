#include "ar/align/silhouette.h"

#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <utility>

#include "core/error.h"
#include "core/file_util.h"
#include "core/json_reader.h"
#include "core/mesh_ops.h"

namespace arreg::align {

Eigen::Isometry3d ModelPose::Rigid() const {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() = rotation;
  t.translation() = translation_mm;
  return t;
}

ModelPose ModelPose::FromRigid(const Eigen::Isometry3d& world_from_model) {
  ModelPose p;
  p.rotation = world_from_model.linear();
  p.translation_mm = world_from_model.translation();
  return p;
}

double RotationErrorDeg(const ModelPose& a, const ModelPose& b) {
  const Eigen::AngleAxisd d(a.rotation * b.rotation.transpose());
  return std::fabs(d.angle()) * 180.0 / M_PI;
}

double PointErrorMm(const ModelPose& a, const ModelPose& b, const Eigen::Vector3d& point) {
  return (a.Apply(point) - b.Apply(point)).norm();
}

// ---------------------------------------------------------------------------
// Outline

Outline OutlineFromMask(const cv::Mat& input, const PinholeCamera& camera, double spacing_px,
                        const std::string& file) {
  ARREG_CHECK_INPUT(!input.empty() && input.type() == CV_8U, file, "",
                    "outline mask must be an 8-bit image");
  ARREG_CHECK_INPUT(input.cols == camera.width && input.rows == camera.height, file, "",
                    "outline is ", input.cols, "x", input.rows, " px, the camera is ", camera.width,
                    "x", camera.height);
  ARREG_CHECK_INPUT(spacing_px >= 1.0, "", "outline spacing_px", "must be >= 1, got ", spacing_px);
  Outline o;
  cv::threshold(input, o.mask, 127, 255, cv::THRESH_BINARY);
  const int inside = cv::countNonZero(o.mask);
  ARREG_CHECK_INPUT(inside > 0, file, "", "outline mask is empty (no pixel > 127)");
  ARREG_CHECK_INPUT(inside < o.mask.rows * o.mask.cols, file, "",
                    "outline mask covers the whole image: it has no boundary");
  const cv::Moments m = cv::moments(o.mask, true);
  o.area_px = m.m00;
  o.centroid_px = Eigen::Vector2d(m.m10 / m.m00, m.m01 / m.m00);

  // Distances between pixel centres; the boundary lies half a pixel beyond the last inside
  // centre. The image border is no boundary: inside pixels only measure to outside pixels.
  cv::Mat outside = 255 - o.mask, d_in, d_out;
  cv::distanceTransform(o.mask, d_in, cv::DIST_L2, cv::DIST_MASK_PRECISE, CV_32F);
  cv::distanceTransform(outside, d_out, cv::DIST_L2, cv::DIST_MASK_PRECISE, CV_32F);
  o.signed_distance_px.create(o.mask.size(), CV_64F);
  for (int y = 0; y < o.mask.rows; ++y)
    for (int x = 0; x < o.mask.cols; ++x)
      o.signed_distance_px.at<double>(y, x) =
          o.mask.at<uint8_t>(y, x) ? -(d_in.at<float>(y, x) - 0.5) : d_out.at<float>(y, x) - 0.5;

  auto sdt = [&](int x, int y) {
    x = std::clamp(x, 0, o.mask.cols - 1);
    y = std::clamp(y, 0, o.mask.rows - 1);
    return o.signed_distance_px.at<double>(y, x);
  };
  std::vector<std::vector<cv::Point>> contours;
  cv::findContours(o.mask, contours, cv::RETR_LIST, cv::CHAIN_APPROX_NONE);
  std::vector<Eigen::Vector2d> points, normals;
  for (const auto& contour : contours) {
    double since_last = spacing_px;  // take the first point
    for (size_t i = 0; i < contour.size(); ++i) {
      if (i > 0) {
        const cv::Point d = contour[i] - contour[i - 1];
        since_last += std::sqrt(static_cast<double>(d.x * d.x + d.y * d.y));
      }
      if (since_last < spacing_px) continue;
      const int x = contour[i].x, y = contour[i].y;
      if (x <= 0 || y <= 0 || x >= o.mask.cols - 1 || y >= o.mask.rows - 1) continue;
      // Sobel-like gradient over a 5 x 5 neighbourhood: the distances of a binary mask are
      // quantised, a 3-point difference gives directions off by up to 30 degrees.
      Eigen::Vector2d g = Eigen::Vector2d::Zero();
      for (int k = -2; k <= 2; ++k) {
        const double w = 3 - std::abs(k);
        g.x() += w * (sdt(x + 2, y + k) - sdt(x - 2, y + k));
        g.y() += w * (sdt(x + k, y + 2) - sdt(x + k, y - 2));
      }
      if (g.norm() < 1e-9) continue;
      g.normalize();
      since_last = 0;
      points.push_back(Eigen::Vector2d(x, y) - sdt(x, y) * g);
      normals.push_back(g);
    }
  }
  ARREG_CHECK_INPUT(points.size() >= 8, file, "",
                    "outline has too little boundary inside the image (", points.size(),
                    " samples)");
  o.boundary_px.resize(static_cast<int>(points.size()), 2);
  o.normals.resize(static_cast<int>(points.size()), 2);
  for (size_t i = 0; i < points.size(); ++i) {
    o.boundary_px.row(static_cast<int>(i)) = points[i].transpose();
    o.normals.row(static_cast<int>(i)) = normals[i].transpose();
  }
  return o;
}

Outline ReadOutline(const std::string& path, const PinholeCamera& camera, double spacing_px) {
  ARREG_CHECK_INPUT(FileExists(path), path, "", "outline file does not exist");
  std::string ext = path.size() >= 5 ? path.substr(path.size() - 5) : "";
  std::transform(ext.begin(), ext.end(), ext.begin(), ::tolower);
  if (ext != ".json") {
    const cv::Mat mask = cv::imread(path, cv::IMREAD_GRAYSCALE);
    ARREG_CHECK_INPUT(!mask.empty(), path, "", "cannot read the outline image");
    return OutlineFromMask(mask, camera, spacing_px, path);
  }
  const nlohmann::json json = ParseJsonFile(path);
  JsonObjectReader reader(json, path, "");
  nlohmann::json polygons;
  reader.Required("polygons", &polygons);
  reader.Finish();
  ARREG_CHECK_INPUT(polygons.is_array() && !polygons.empty(), path, "polygons",
                    "expected a non-empty array of polygons [[[u, v], ...], ...]");
  std::vector<std::vector<cv::Point>> filled;
  constexpr int kShift = 4;  // sub-pixel vertices: 1/16 px
  for (size_t p = 0; p < polygons.size(); ++p) {
    const std::string where = "polygons[" + std::to_string(p) + "]";
    ARREG_CHECK_INPUT(polygons[p].is_array() && polygons[p].size() >= 3, path, where,
                      "a polygon needs 3 or more [u, v] points");
    std::vector<cv::Point> poly;
    for (size_t i = 0; i < polygons[p].size(); ++i) {
      Eigen::Vector2d uv;
      ReadJsonValue(polygons[p][i], path, where + "[" + std::to_string(i) + "]", &uv);
      poly.emplace_back(static_cast<int>(std::lround(uv.x() * (1 << kShift))),
                        static_cast<int>(std::lround(uv.y() * (1 << kShift))));
    }
    filled.push_back(std::move(poly));
  }
  cv::Mat mask = cv::Mat::zeros(camera.height, camera.width, CV_8U);
  cv::fillPoly(mask, filled, cv::Scalar(255), cv::LINE_8, kShift);
  return OutlineFromMask(mask, camera, spacing_px, path);
}

// ---------------------------------------------------------------------------
// Model surface

ModelSurface::ModelSurface(const SurfaceMesh& input) {
  SurfaceMesh s = input;
  RemoveUnreferencedVertices(&s);
  ARREG_CHECK_INPUT(s.num_faces() >= 4, "", "model", "surface has fewer than 4 triangles");
  vertices_ = s.vertices;
  faces_ = s.faces;
  face_normals_.resize(faces_.rows(), 3);
  double area = 0;
  Eigen::Vector3d weighted = Eigen::Vector3d::Zero();
  std::map<std::pair<int, int>, std::vector<std::pair<int, int>>> by_edge;  // -> (face, corner)
  for (int f = 0; f < faces_.rows(); ++f) {
    const Eigen::Vector3d a = vertices_.row(faces_(f, 0)), b = vertices_.row(faces_(f, 1)),
                          c = vertices_.row(faces_(f, 2));
    const Eigen::Vector3d n = (b - a).cross(c - a);
    const double face_area = 0.5 * n.norm();
    face_normals_.row(f) =
        face_area > 0 ? Eigen::RowVector3d((n / n.norm()).transpose()) : Eigen::RowVector3d::Zero();
    area += face_area;
    weighted += face_area * (a + b + c) / 3.0;
    for (int k = 0; k < 3; ++k) {
      const int u = faces_(f, k), v = faces_(f, (k + 1) % 3);
      by_edge[{std::min(u, v), std::max(u, v)}].push_back({f, (k + 2) % 3});
    }
  }
  ARREG_CHECK_INPUT(area > 0, "", "model", "surface has zero area");
  area_mm2_ = area;
  centroid_ = weighted / area;
  const Eigen::Vector3d lo = vertices_.colwise().minCoeff(), hi = vertices_.colwise().maxCoeff();
  radius_mm_ = 0.5 * (hi - lo).norm();
  // Edges of a closed surface have two faces; others (open or non-manifold parts) never
  // separate a front from a back face cleanly and are left out of the contour.
  const double cos_crease = std::cos(kCreaseDeg * M_PI / 180.0);
  for (const auto& [key, faces] : by_edge) {
    if (faces.size() != 2) continue;
    const int f0 = faces[0].first, f1 = faces[1].first;
    edges_.push_back({key.first, key.second, f0, f1,
                      face_normals_.row(f0).dot(face_normals_.row(f1)) < cos_crease});
  }
  vertex_normals_ = RowMatX3d::Zero(vertices_.rows(), 3);
  for (int f = 0; f < faces_.rows(); ++f) {
    const Eigen::Vector3d a = vertices_.row(faces_(f, 0)), b = vertices_.row(faces_(f, 1)),
                          c = vertices_.row(faces_(f, 2));
    const Eigen::RowVector3d n = (b - a).cross(c - a).transpose();  // length: twice the area
    for (int k = 0; k < 3; ++k) vertex_normals_.row(faces_(f, k)) += n;
  }
  for (int i = 0; i < vertex_normals_.rows(); ++i) {
    const double norm = vertex_normals_.row(i).norm();
    if (norm > 0) vertex_normals_.row(i) /= norm;
  }
}

Eigen::Vector3d ModelSurface::EdgePoint(const Edge& e, double t) const {
  const Eigen::Vector3d a = vertices_.row(e.a).transpose(), b = vertices_.row(e.b).transpose();
  const Eigen::Vector3d chord = (1 - t) * a + t * b;
  if (e.crease) return chord;
  const double h = (b - a).norm();
  if (!(h > 0)) return chord;
  const Eigen::Vector3d d = (b - a) / h;
  const Eigen::Vector3d na = vertex_normals_.row(e.a).transpose(),
                        nb = vertex_normals_.row(e.b).transpose();
  return chord + 0.5 * t * (1 - t) * h * (d.dot(nb) * nb - d.dot(na) * na);
}

// ---------------------------------------------------------------------------
// Projection

namespace {

constexpr double kNearMm = 1.0;   // the model must lie this far in front of the camera
constexpr double kProbePx = 2.0;  // how far beside a contour sample the mask is probed

// Sets the pixels of `mask` whose centre lies in the triangle (p0, p1, p2) (pixel centres at
// integer coordinates, as the ground-truth masks of render::RenderMask; OpenCV's polygon fill
// also sets pixels the edges only touch, which would grow the silhouette by half a pixel).
void FillTriangle(const Eigen::Vector2d& p0, const Eigen::Vector2d& p1, const Eigen::Vector2d& p2,
                  cv::Mat* mask) {
  const double area = (p1 - p0).x() * (p2 - p0).y() - (p1 - p0).y() * (p2 - p0).x();
  if (area == 0) return;
  const double sign = area > 0 ? 1.0 : -1.0;
  const int x0 = std::max(0, static_cast<int>(std::ceil(std::min({p0.x(), p1.x(), p2.x()}))));
  const int x1 =
      std::min(mask->cols - 1, static_cast<int>(std::floor(std::max({p0.x(), p1.x(), p2.x()}))));
  const int y0 = std::max(0, static_cast<int>(std::ceil(std::min({p0.y(), p1.y(), p2.y()}))));
  const int y1 =
      std::min(mask->rows - 1, static_cast<int>(std::floor(std::max({p0.y(), p1.y(), p2.y()}))));
  auto edge = [&](const Eigen::Vector2d& a, const Eigen::Vector2d& b, double x, double y) {
    return sign * ((b.x() - a.x()) * (y - a.y()) - (b.y() - a.y()) * (x - a.x()));
  };
  for (int y = y0; y <= y1; ++y) {
    uint8_t* row = mask->ptr<uint8_t>(y);
    for (int x = x0; x <= x1; ++x)
      if (edge(p0, p1, x, y) >= 0 && edge(p1, p2, x, y) >= 0 && edge(p2, p0, x, y) >= 0)
        row[x] = 255;
  }
}

}  // namespace

ProjectedModel ProjectModel(const ModelSurface& surface, const PinholeCamera& camera,
                            const ModelPose& pose, double spacing_px, double scale_px,
                            bool with_contour, bool smooth_contour) {
  ProjectedModel out;
  const Eigen::Matrix3d a = pose.scale * camera.camera_from_world.linear() * pose.rotation;
  const Eigen::Vector3d b = camera.camera_from_world * pose.translation_mm;
  const Eigen::Vector3d eye_in_model = -a.inverse() * b;
  const RowMatX3d& v = surface.vertices();
  const int n = static_cast<int>(v.rows());
  RowMatX2d pixels(n, 2);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d p = a * v.row(i).transpose() + b;
    if (!(p.z() > kNearMm)) return out;
    pixels.row(i) = camera.ProjectFromCamera(p).transpose();
  }
  out.valid = true;
  const int width = std::max(1, static_cast<int>(std::lround(camera.width * scale_px)));
  const int height = std::max(1, static_cast<int>(std::lround(camera.height * scale_px)));
  out.mask = cv::Mat::zeros(height, width, CV_8U);
  const RowMatX3i& f = surface.faces();
  std::vector<char> front(f.rows());
  const double offset = 0.5 * scale_px - 0.5;  // pixel centres: u' = (u + 0.5) s - 0.5
  // Image-plane extent beyond which faces are not drawn (distortion far outside the field of
  // view is meaningless).
  const double limit = 4.0 * std::max(camera.width, camera.height);
  for (int k = 0; k < f.rows(); ++k) {
    const Eigen::Vector3d n_k = surface.face_normals().row(k).transpose();
    front[k] = n_k.dot(eye_in_model - v.row(f(k, 0)).transpose()) > 0;
    if (!front[k]) continue;
    Eigen::Vector2d pts[3];
    bool drawable = true;
    for (int c = 0; c < 3; ++c) {
      const Eigen::Vector2d p = pixels.row(f(k, c)).transpose();
      if (std::fabs(p.x()) > limit || std::fabs(p.y()) > limit) drawable = false;
      pts[c] = p * scale_px + Eigen::Vector2d::Constant(offset);
    }
    if (drawable) FillTriangle(pts[0], pts[1], pts[2], &out.mask);
  }
  if (!with_contour || scale_px != 1.0) return out;

  auto outside = [&](const Eigen::Vector2d& p) {
    const int x = static_cast<int>(std::lround(p.x())), y = static_cast<int>(std::lround(p.y()));
    if (x < 0 || y < 0 || x >= width || y >= height) return true;
    return out.mask.at<uint8_t>(y, x) == 0;
  };
  std::vector<Eigen::Vector3d> points;
  std::vector<Eigen::Vector2d> sample_pixels, normals;
  for (const ModelSurface::Edge& e : surface.edges()) {
    if (front[e.face0] == front[e.face1]) continue;
    const Eigen::Vector2d pa = pixels.row(e.a).transpose(), pb = pixels.row(e.b).transpose();
    const double length = (pb - pa).norm();
    if (!(length > 1e-9) || length > limit) continue;
    const Eigen::Vector2d d = (pb - pa) / length;
    const Eigen::Vector2d normal(d.y(), -d.x());
    const int count = std::max(1, static_cast<int>(std::lround(length / spacing_px)));
    for (int j = 0; j < count; ++j) {
      const double t = (j + 0.5) / count;
      const Eigen::Vector2d p = (1 - t) * pa + t * pb;
      if (!camera.IsInImage(p, kProbePx)) continue;
      // On the outer contour exactly one side of the sample is outside the silhouette.
      const bool plus = outside(p + kProbePx * normal), minus = outside(p - kProbePx * normal);
      if (plus == minus) continue;
      const Eigen::Vector3d point =
          smooth_contour
              ? surface.EdgePoint(e, t)
              : Eigen::Vector3d((1 - t) * v.row(e.a).transpose() + t * v.row(e.b).transpose());
      points.push_back(point);
      // The exact image of the sample (a straight 3D edge is curved by perspective and
      // distortion; the probe above only needs the chord).
      sample_pixels.push_back(camera.ProjectFromCamera(a * point + b));
      normals.push_back(plus ? normal : Eigen::Vector2d(-normal));
    }
  }
  const int m = static_cast<int>(points.size());
  out.contour.points_in_model.resize(m, 3);
  out.contour.pixels.resize(m, 2);
  out.contour.normals.resize(m, 2);
  for (int i = 0; i < m; ++i) {
    out.contour.points_in_model.row(i) = points[i].transpose();
    out.contour.pixels.row(i) = sample_pixels[i].transpose();
    out.contour.normals.row(i) = normals[i].transpose();
  }
  return out;
}

double MaskIou(const cv::Mat& a, const cv::Mat& b) {
  ARREG_ASSERT(a.size() == b.size() && a.type() == CV_8U && b.type() == CV_8U, "masks differ");
  cv::Mat both, either;
  cv::bitwise_and(a, b, both);
  cv::bitwise_or(a, b, either);
  const int u = cv::countNonZero(either);
  return u > 0 ? static_cast<double>(cv::countNonZero(both)) / u : 0.0;
}

}  // namespace arreg::align
