#include "ar/pipeline/overlay.h"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/log.h"

namespace arreg::pipeline {

OverlayRenderer::OverlayRenderer(const PinholeCamera& camera, const RenderStageOptions& options)
    : camera_(camera), raster_(ToRasterCamera(camera)), options_(options) {
  options_.Check();
  raster_.Check();
  if (!camera.distortion.IsZero())
    ARREG_LOG_WARNING(
        "overlay: the camera has lens distortion; the overlay is drawn with its pinhole part "
        "(distortion not applied)");
}

namespace {

cv::Point2f ProjectPinhole(const render::RasterCamera& c, const Eigen::Vector3d& p_world,
                           bool* in_front) {
  const Eigen::Vector3d p = c.camera_from_world * p_world;
  *in_front = p.z() > c.near_mm;
  const double z = std::max(p.z(), 1e-9);
  return {static_cast<float>(c.fx * p.x() / z + c.cx), static_cast<float>(c.fy * p.y() / z + c.cy)};
}

// Blinn-Phong evaluated once per vertex (Gouraud): the per-sample shader then only
// interpolates, which keeps the supersampled overlay cheap.
std::vector<Eigen::Vector3f> ShadeVertices(const render::RasterCamera& c, const RowMatX3d& vertices,
                                           const RowMatX3i& faces, const Eigen::Vector3f& albedo) {
  const RowMatX3d normals = render::VertexNormals(vertices, faces);
  const render::ShadingOptions shading;
  const Eigen::Matrix3d r = c.camera_from_world.linear();
  std::vector<Eigen::Vector3f> colors(vertices.rows());
  render::Fragment f;
  for (int v = 0; v < vertices.rows(); ++v) {
    f.point_in_camera = c.camera_from_world * vertices.row(v).transpose();
    const Eigen::Vector3d n = r * normals.row(v).transpose();
    f.normal_in_camera = n.squaredNorm() > 0 ? n.normalized() : Eigen::Vector3d(0, 0, -1);
    f.front_facing = true;
    colors[v] = render::ShadeBlinnPhong(albedo, f, shading);
  }
  return colors;
}

void DrawGouraud(const RowMatX3d& vertices, const RowMatX3i& faces, const Eigen::Vector3f& albedo,
                 const render::DrawOptions& draw, render::RenderTarget* target) {
  const std::vector<Eigen::Vector3f> colors =
      ShadeVertices(target->camera(), vertices, faces, albedo);
  target->Draw(
      vertices, faces, RowMatX3d(),
      [&](const render::Fragment& fr) {
        return Eigen::Vector3f(fr.barycentric.cast<float>()[0] * colors[faces(fr.face, 0)] +
                               fr.barycentric.cast<float>()[1] * colors[faces(fr.face, 1)] +
                               fr.barycentric.cast<float>()[2] * colors[faces(fr.face, 2)]);
      },
      draw);
}

}  // namespace

void OverlayRenderer::Render(const RowMatX3d& organ_vertices_mm, const RowMatX3i& organ_faces,
                             const std::vector<OverlayStructure>& internal,
                             const OverlayLayers& layers, cv::Mat* bgr) const {
  ARREG_ASSERT(bgr != nullptr && bgr->type() == CV_8UC3 && bgr->cols == raster_.width &&
                   bgr->rows == raster_.height,
               "overlay: frame must be CV_8UC3 of the camera size");
  // Bounding box of the projected organ (vertices used by faces); a vertex behind the near
  // plane makes the whole image the box.
  double lo_u = 1e300, lo_v = 1e300, hi_u = -1e300, hi_v = -1e300;
  bool behind = false;
  for (int f = 0; f < organ_faces.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      bool front = true;
      const cv::Point2f q =
          ProjectPinhole(raster_, organ_vertices_mm.row(organ_faces(f, k)).transpose(), &front);
      if (!front) behind = true;
      lo_u = std::min(lo_u, double(q.x));
      hi_u = std::max(hi_u, double(q.x));
      lo_v = std::min(lo_v, double(q.y));
      hi_v = std::max(hi_v, double(q.y));
    }
  if (organ_faces.rows() == 0) return;
  int x0 = 0, y0 = 0, x1 = raster_.width - 1, y1 = raster_.height - 1;
  if (!behind) {
    x0 = std::max(0, static_cast<int>(std::floor(lo_u)) - 2);
    y0 = std::max(0, static_cast<int>(std::floor(lo_v)) - 2);
    x1 = std::min(raster_.width - 1, static_cast<int>(std::ceil(hi_u)) + 2);
    y1 = std::min(raster_.height - 1, static_cast<int>(std::ceil(hi_v)) + 2);
  }
  if (x1 >= x0 && y1 >= y0) {
    render::RasterCamera crop = raster_;
    crop.width = x1 - x0 + 1;
    crop.height = y1 - y0 + 1;
    crop.cx -= x0;
    crop.cy -= y0;
    render::RenderTarget target(crop, options_.supersampling);
    // The frame under the box as linear RGB floats, read once per pixel, not per sample.
    cv::Mat rgb;
    (*bgr)(cv::Rect(x0, y0, crop.width, crop.height)).convertTo(rgb, CV_32FC3, 1.0 / 255.0);
    target.ClearWith([&](double u, double v) {
      // Sample centres lie in [-0.5, size - 0.5): rounding picks the pixel that holds them.
      const int x = std::min(static_cast<int>(u + 0.5), crop.width - 1);
      const int y = std::min(static_cast<int>(v + 0.5), crop.height - 1);
      const cv::Vec3f& p = rgb.at<cv::Vec3f>(y, x);
      return Eigen::Vector3f(p[2], p[1], p[0]);
    });
    for (const OverlayStructure& s : internal) {
      // Opacity 0 hides a structure (the rasterizer only blends opacities in (0, 1]).
      if (s.vertices_mm == nullptr || s.faces == nullptr || s.faces->rows() == 0 || s.opacity <= 0)
        continue;
      render::DrawOptions draw;
      draw.opacity = static_cast<float>(s.opacity);
      draw.id = 2;
      DrawGouraud(*s.vertices_mm, *s.faces, s.color.cast<float>(), draw, &target);
    }
    render::DrawOptions draw;
    draw.opacity = static_cast<float>(options_.organ_opacity);
    draw.cull_back_faces = true;  // the near side only: structures behind it show through
    draw.id = 1;
    if (options_.organ_opacity > 0)
      DrawGouraud(organ_vertices_mm, organ_faces, options_.organ_color.cast<float>(), draw,
                  &target);
    target.ResolveBgr().copyTo((*bgr)(cv::Rect(x0, y0, crop.width, crop.height)));
  }

  if (options_.wireframe) {
    const Eigen::Vector3d eye = camera_.CenterInWorld();
    for (int f = 0; f < organ_faces.rows(); ++f) {
      const Eigen::Vector3d a = organ_vertices_mm.row(organ_faces(f, 0)).transpose();
      const Eigen::Vector3d b = organ_vertices_mm.row(organ_faces(f, 1)).transpose();
      const Eigen::Vector3d c = organ_vertices_mm.row(organ_faces(f, 2)).transpose();
      if ((b - a).cross(c - a).dot(a - eye) >= 0) continue;  // back face
      bool fa, fb, fc;
      const cv::Point2f pa = ProjectPinhole(raster_, a, &fa), pb = ProjectPinhole(raster_, b, &fb),
                        pc = ProjectPinhole(raster_, c, &fc);
      if (!(fa && fb && fc)) continue;
      const cv::Scalar colour(255, 255, 255);
      cv::line(*bgr, pa, pb, colour, 1, cv::LINE_AA);
      cv::line(*bgr, pb, pc, colour, 1, cv::LINE_AA);
      cv::line(*bgr, pc, pa, colour, 1, cv::LINE_AA);
    }
  }
  const int rows = layers.alive ? static_cast<int>(layers.alive->size()) : 0;
  for (int r = 0; r < rows; ++r) {
    if (!(*layers.alive)[r]) continue;
    bool front_t = false, front_a = false;
    cv::Point2f target_px, anchor_px;
    if (layers.targets_mm) target_px = ProjectPinhole(raster_, layers.targets_mm->row(r), &front_t);
    if (layers.anchors_mm) anchor_px = ProjectPinhole(raster_, layers.anchors_mm->row(r), &front_a);
    if (options_.show_springs && front_t && front_a)
      cv::line(*bgr, anchor_px, target_px, cv::Scalar(0, 255, 255), 1, cv::LINE_AA);
    if (options_.show_targets && front_t)
      cv::circle(*bgr, target_px, 2, cv::Scalar(255, 128, 0), cv::FILLED, cv::LINE_AA);
    if (options_.show_features && layers.feature_pixels) {
      const cv::Point2f p(static_cast<float>((*layers.feature_pixels)(r, 0)),
                          static_cast<float>((*layers.feature_pixels)(r, 1)));
      cv::circle(*bgr, p, 2, cv::Scalar(0, 220, 0), cv::FILLED, cv::LINE_AA);
    }
  }
}

}  // namespace arreg::pipeline
