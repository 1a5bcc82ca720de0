#include "ar/pipeline/overlay.h"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/log.h"

namespace arreg::pipeline {

OverlayRenderer::OverlayRenderer(const PinholeCamera& camera, const RenderStageOptions& options)
    : camera_(camera),
      raster_(ToRasterCamera(camera)),
      options_(options),
      internal_layer_(raster_),
      organ_layer_(raster_) {
  options_.Check();
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

// Grows the pixel bounds by the projections of the vertices used by `faces`; false when one is
// behind the near plane (its projection bounds nothing).
bool GrowBounds(const render::RasterCamera& c, const RowMatX3d& vertices, const RowMatX3i& faces,
                double* lo_u, double* lo_v, double* hi_u, double* hi_v) {
  for (int f = 0; f < faces.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      bool front = true;
      const cv::Point2f q = ProjectPinhole(c, vertices.row(faces(f, k)).transpose(), &front);
      if (!front) return false;
      *lo_u = std::min(*lo_u, double(q.x));
      *hi_u = std::max(*hi_u, double(q.x));
      *lo_v = std::min(*lo_v, double(q.y));
      *hi_v = std::max(*hi_v, double(q.y));
    }
  return true;
}

bool Visible(const OverlayStructure& s) {
  // Opacity 0 hides a structure (the rasterizers only blend opacities in (0, 1]).
  return s.vertices_mm != nullptr && s.faces != nullptr && s.faces->rows() > 0 && s.opacity > 0;
}

}  // namespace

void OverlayRenderer::ShadeVertices(const RowMatX3d& vertices, const RowMatX3i& faces,
                                    const Eigen::Vector3f& albedo) {
  render::VertexNormals(vertices, faces, &normals_);
  render::ShadeVertices(vertices, normals_, raster_.camera_from_world, albedo,
                        render::ShadingOptions(), &vertex_rgb_);
}

void OverlayRenderer::RenderCoverage(const render::PixelRect& box,
                                     const RowMatX3d& organ_vertices_mm,
                                     const RowMatX3i& organ_faces,
                                     const std::vector<OverlayStructure>& internal, cv::Mat* bgr) {
  internal_layer_.Clear(box);
  organ_layer_.Clear(box);
  for (const OverlayStructure& s : internal) {
    if (!Visible(s)) continue;
    ShadeVertices(*s.vertices_mm, *s.faces, s.color.cast<float>());
    render::CoverageDrawOptions draw;
    draw.opacity = static_cast<float>(std::min(1.0, s.opacity));
    internal_layer_.Draw(*s.vertices_mm, *s.faces, vertex_rgb_, draw);
  }
  if (options_.organ_opacity > 0) {
    ShadeVertices(organ_vertices_mm, organ_faces, options_.organ_color.cast<float>());
    render::CoverageDrawOptions draw;
    draw.opacity = static_cast<float>(std::min(1.0, options_.organ_opacity));
    draw.cull_back_faces = true;  // the near side only: structures behind it show through
    organ_layer_.Draw(organ_vertices_mm, organ_faces, vertex_rgb_, draw);
  }
  // Composite: the internal layer over the frame, the organ over both, unless a structure
  // lies in front of the organ's surface (it pokes out), which then goes on top.
  // In 8-bit units, so that the frame's pixels need no scaling.
  using Pixel = render::CoverageLayer::Pixel;
  const auto over = [](const Pixel& p, float* rgb) {
    rgb[0] += p.alpha * (255.0f * p.r - rgb[0]);
    rgb[1] += p.alpha * (255.0f * p.g - rgb[1]);
    rgb[2] += p.alpha * (255.0f * p.b - rgb[2]);
  };
  const auto store = [](const float* rgb, cv::Vec3b* px) {
    for (int c = 0; c < 3; ++c)
      (*px)[2 - c] = static_cast<uchar>(std::clamp(rgb[c], 0.0f, 255.0f) + 0.5f);
  };
  for (int y = box.y0; y < box.y1; ++y) {
    auto* out = bgr->ptr<cv::Vec3b>(y);
    const Pixel* in_row = internal_layer_.row(y);
    const Pixel* organ_row = organ_layer_.row(y);
    const int si0 = internal_layer_.row_begin(y), si1 = internal_layer_.row_end(y);
    const int so0 = organ_layer_.row_begin(y), so1 = organ_layer_.row_end(y);
    if (si0 >= si1) {  // the organ alone in this row (the common case)
      for (int x = so0; x < so1; ++x) {
        const Pixel& o = organ_row[x];
        if (o.alpha == 0) continue;
        float rgb[3] = {float(out[x][2]), float(out[x][1]), float(out[x][0])};
        over(o, rgb);
        store(rgb, &out[x]);
      }
      continue;
    }
    for (int x = std::min(si0, so0); x < std::max(si1, so1); ++x) {
      const Pixel& s = in_row[x];
      const Pixel& o = organ_row[x];
      if (s.alpha == 0 && o.alpha == 0) continue;
      float rgb[3] = {float(out[x][2]), float(out[x][1]), float(out[x][0])};
      if (s.alpha > 0 && o.alpha > 0 && s.inv_depth > o.inv_depth) {
        over(o, rgb);
        over(s, rgb);
      } else {
        over(s, rgb);  // alpha 0 leaves the colour as it is
        over(o, rgb);
      }
      store(rgb, &out[x]);
    }
  }
}

void OverlayRenderer::RenderSupersampled(const render::PixelRect& box,
                                         const RowMatX3d& organ_vertices_mm,
                                         const RowMatX3i& organ_faces,
                                         const std::vector<OverlayStructure>& internal,
                                         cv::Mat* bgr) const {
  render::RasterCamera crop = raster_;
  crop.width = box.width();
  crop.height = box.height();
  crop.cx -= box.x0;
  crop.cy -= box.y0;
  render::RenderTarget target(crop, options_.supersampling);
  // The frame under the box as linear RGB floats, read once per pixel, not per sample.
  const cv::Rect roi(box.x0, box.y0, crop.width, crop.height);
  cv::Mat rgb;
  (*bgr)(roi).convertTo(rgb, CV_32FC3, 1.0 / 255.0);
  target.ClearWith([&](double u, double v) {
    // Sample centres lie in [-0.5, size - 0.5): rounding picks the pixel that holds them.
    const int x = std::min(static_cast<int>(u + 0.5), crop.width - 1);
    const int y = std::min(static_cast<int>(v + 0.5), crop.height - 1);
    const cv::Vec3f& p = rgb.at<cv::Vec3f>(y, x);
    return Eigen::Vector3f(p[2], p[1], p[0]);
  });
  auto draw_gouraud = [&](const RowMatX3d& vertices, const RowMatX3i& faces,
                          const Eigen::Vector3f& albedo, const render::DrawOptions& draw) {
    RowMatX3f colors;
    render::ShadeVertices(vertices, render::VertexNormals(vertices, faces), crop.camera_from_world,
                          albedo, render::ShadingOptions(), &colors);
    target.Draw(
        vertices, faces, RowMatX3d(),
        [&](const render::Fragment& fr) {
          const Eigen::Vector3f b = fr.barycentric.cast<float>();
          return Eigen::Vector3f(b[0] * colors.row(faces(fr.face, 0)) +
                                 b[1] * colors.row(faces(fr.face, 1)) +
                                 b[2] * colors.row(faces(fr.face, 2)));
        },
        draw);
  };
  for (const OverlayStructure& s : internal) {
    if (!Visible(s)) continue;
    render::DrawOptions draw;
    draw.opacity = static_cast<float>(std::min(1.0, s.opacity));
    draw.id = 2;
    draw_gouraud(*s.vertices_mm, *s.faces, s.color.cast<float>(), draw);
  }
  if (options_.organ_opacity > 0) {
    render::DrawOptions draw;
    draw.opacity = static_cast<float>(std::min(1.0, options_.organ_opacity));
    draw.cull_back_faces = true;  // the near side only: structures behind it show through
    draw.id = 1;
    draw_gouraud(organ_vertices_mm, organ_faces, options_.organ_color.cast<float>(), draw);
  }
  target.ResolveBgr().copyTo((*bgr)(roi));
}

void OverlayRenderer::Render(const RowMatX3d& organ_vertices_mm, const RowMatX3i& organ_faces,
                             const std::vector<OverlayStructure>& internal,
                             const OverlayLayers& layers, cv::Mat* bgr) {
  ARREG_ASSERT(bgr != nullptr && bgr->type() == CV_8UC3 && bgr->cols == raster_.width &&
                   bgr->rows == raster_.height,
               "overlay: frame must be CV_8UC3 of the camera size");
  if (organ_faces.rows() == 0) return;
  // Bounding box of the projected organ and structures; a vertex behind the near plane makes
  // the whole image the box.
  double lo_u = 1e300, lo_v = 1e300, hi_u = -1e300, hi_v = -1e300;
  bool bounded = GrowBounds(raster_, organ_vertices_mm, organ_faces, &lo_u, &lo_v, &hi_u, &hi_v);
  for (const OverlayStructure& s : internal)
    if (bounded && Visible(s))
      bounded = GrowBounds(raster_, *s.vertices_mm, *s.faces, &lo_u, &lo_v, &hi_u, &hi_v);
  render::PixelRect box{0, 0, raster_.width, raster_.height};
  if (bounded) {
    // Clamped in floating point first: a projection far off-screen must not overflow an int.
    const auto clamp_px = [](double v, int hi) {
      return static_cast<int>(std::clamp(v, -1.0, static_cast<double>(hi) + 1));
    };
    box.x0 = std::max(0, clamp_px(std::floor(lo_u), raster_.width) - 2);
    box.y0 = std::max(0, clamp_px(std::floor(lo_v), raster_.height) - 2);
    box.x1 = std::min(raster_.width, clamp_px(std::ceil(hi_u), raster_.width) + 3);
    box.y1 = std::min(raster_.height, clamp_px(std::ceil(hi_v), raster_.height) + 3);
  }
  if (!box.empty()) {
    if (options_.supersampling <= 1)
      RenderCoverage(box, organ_vertices_mm, organ_faces, internal, bgr);
    else
      RenderSupersampled(box, organ_vertices_mm, organ_faces, internal, bgr);
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
