#include "ar/pipeline/overlay.h"

#include <algorithm>
#include <array>
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
                                     const std::vector<OverlayStructure>& internal,
                                     double organ_opacity, cv::Mat* bgr) {
  internal_layer_.Clear(box);
  organ_layer_.Clear(box);
  const bool contour = options_.style == OverlayStyle::kContour;
  for (const OverlayStructure& s : internal) {
    if (!Visible(s) || (contour && s.outline)) continue;
    ShadeVertices(*s.vertices_mm, *s.faces, s.color.cast<float>());
    render::CoverageDrawOptions draw;
    draw.opacity = static_cast<float>(std::min(1.0, s.opacity));
    internal_layer_.Draw(*s.vertices_mm, *s.faces, vertex_rgb_, draw);
  }
  if (organ_opacity > 0) {
    ShadeVertices(organ_vertices_mm, organ_faces, options_.organ_color.cast<float>());
    render::CoverageDrawOptions draw;
    draw.opacity = static_cast<float>(std::min(1.0, organ_opacity));
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
                                         double organ_opacity, cv::Mat* bgr) const {
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
  const bool contour = options_.style == OverlayStyle::kContour;
  for (const OverlayStructure& s : internal) {
    if (!Visible(s) || (contour && s.outline)) continue;
    render::DrawOptions draw;
    draw.opacity = static_cast<float>(std::min(1.0, s.opacity));
    draw.id = 2;
    draw_gouraud(*s.vertices_mm, *s.faces, s.color.cast<float>(), draw);
  }
  if (organ_opacity > 0) {
    render::DrawOptions draw;
    draw.opacity = static_cast<float>(std::min(1.0, organ_opacity));
    draw.cull_back_faces = true;  // the near side only: structures behind it show through
    draw.id = 1;
    draw_gouraud(organ_vertices_mm, organ_faces, options_.organ_color.cast<float>(), draw);
  }
  target.ResolveBgr().copyTo((*bgr)(roi));
}

namespace {

cv::Scalar Bgr(const Eigen::Vector3d& rgb) {
  return cv::Scalar(255 * rgb[2], 255 * rgb[1], 255 * rgb[0]);
}

}  // namespace

void OverlayRenderer::UpdateEdges(const RowMatX3i& faces) {
  if (faces.rows() == edge_faces_.rows() && faces == edge_faces_) return;
  edge_faces_ = faces;
  edge_quads_.clear();
  // Each directed edge a -> b with the third vertex of its face; an edge shared by exactly two
  // faces appears once in each direction (consistently oriented surface).
  std::vector<std::array<int, 4>> half;  // min, max, third vertex, 1 when a < b
  half.reserve(3 * faces.rows());
  for (int f = 0; f < faces.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      const int a = faces(f, k), b = faces(f, (k + 1) % 3), c = faces(f, (k + 2) % 3);
      half.push_back({std::min(a, b), std::max(a, b), c, a < b ? 1 : 0});
    }
  std::sort(half.begin(), half.end());
  for (size_t i = 0; i < half.size();) {
    size_t j = i;
    while (j < half.size() && half[j][0] == half[i][0] && half[j][1] == half[i][1]) ++j;
    if (j - i == 2 && half[i][3] != half[i + 1][3]) {       // manifold, consistently oriented
      const auto& up = half[i][3] ? half[i] : half[i + 1];  // face with min -> max
      const auto& down = half[i][3] ? half[i + 1] : half[i];
      edge_quads_.emplace_back(up[0], up[1], up[2], down[2]);
    }
    i = j;
  }
}

void OverlayRenderer::DrawContour(const render::PixelRect& box, const RowMatX3d& organ_vertices_mm,
                                  const RowMatX3i& organ_faces, cv::Mat* bgr) {
  // Coverage of the organ's near side at opacity 1: its alpha >= 0.5 is the organ's mask and
  // its depth tells which cut edges are in view.
  organ_layer_.Clear(box);
  vertex_rgb_.setZero(organ_vertices_mm.rows(), 3);
  render::CoverageDrawOptions draw;
  draw.cull_back_faces = true;
  organ_layer_.Draw(organ_vertices_mm, organ_faces, vertex_rgb_, draw);
  // OpenCV's anti-aliased line of thickness t darkens about t + 1 pixels across.
  const int width = std::max(1, options_.contour_width_px - 1);

  // Cut edges: faces meeting at more than cut_edge_angle_deg (the rule is in
  // RenderStageOptions), drawn where in view, before the silhouette so that it stays on top.
  UpdateEdges(organ_faces);
  const double cos_limit = std::cos(options_.cut_edge_angle_deg * M_PI / 180.0);
  const Eigen::Vector3d eye = camera_.CenterInWorld();
  const cv::Scalar cut_colour = Bgr(options_.cut_edge_color);
  const auto depth_at = [&](int x, int y) {  // largest camera depth of the surface near (x, y)
    double deepest = -1;
    for (int dy = -1; dy <= 1; ++dy)
      for (int dx = -1; dx <= 1; ++dx) {
        const int u = x + dx, v = y + dy;
        if (u < box.x0 || v < box.y0 || u >= box.x1 || v >= box.y1) continue;
        const render::CoverageLayer::Pixel& p = organ_layer_.pixel(u, v);
        if (p.alpha > 0 && p.inv_depth > 0) deepest = std::max(deepest, 1.0 / p.inv_depth);
      }
    return deepest;
  };
  // Drawn on a copy of the box and blended back by the organ's coverage, so that a cut edge
  // never shows outside the organ (where the silhouette is drawn).
  const cv::Rect roi(box.x0, box.y0, box.width(), box.height());
  cv::Mat lines = (*bgr)(roi).clone();
  const cv::Point2f origin(static_cast<float>(box.x0), static_cast<float>(box.y0));
  bool any_cut_edge = false;
  for (const Eigen::Vector4i& q : edge_quads_) {
    const Eigen::Vector3d a = organ_vertices_mm.row(q[0]).transpose();
    const Eigen::Vector3d b = organ_vertices_mm.row(q[1]).transpose();
    const Eigen::Vector3d n0 = (b - a).cross(organ_vertices_mm.row(q[2]).transpose() - a);
    const Eigen::Vector3d n1 = (organ_vertices_mm.row(q[3]).transpose() - a).cross(b - a);
    if (n0.norm() == 0 || n1.norm() == 0) continue;
    if (n0.dot(n1) > cos_limit * n0.norm() * n1.norm()) continue;  // smooth there
    if (n0.dot(a - eye) >= 0 && n1.dot(a - eye) >= 0) continue;    // both faces turned away
    // In pieces of about a pixel, each drawn where no surface lies in front of it (a tolerance
    // of 1 % of its depth covers the sampling of the depth at pixel centres).
    bool fa, fb;
    const cv::Point2f pa = ProjectPinhole(raster_, a, &fa), pb = ProjectPinhole(raster_, b, &fb);
    if (!(fa && fb)) continue;
    const int pieces = std::max(1, static_cast<int>(std::ceil(cv::norm(pb - pa))));
    for (int i = 0; i < pieces; ++i) {
      const double t = (i + 0.5) / pieces;
      const Eigen::Vector3d m = a + t * (b - a);
      const double z = (raster_.camera_from_world * m).z();
      bool fm;
      const cv::Point2f pm = ProjectPinhole(raster_, m, &fm);
      const double deepest =
          depth_at(static_cast<int>(std::lround(pm.x)), static_cast<int>(std::lround(pm.y)));
      if (deepest < 0 || z > deepest + 0.01 * z) continue;
      const cv::Point2f p0 = pa + (pb - pa) * static_cast<float>(double(i) / pieces);
      const cv::Point2f p1 = pa + (pb - pa) * static_cast<float>(double(i + 1) / pieces);
      cv::line(lines, p0 - origin, p1 - origin, cut_colour, width, cv::LINE_AA);
      any_cut_edge = true;
    }
  }
  if (any_cut_edge)
    for (int y = box.y0; y < box.y1; ++y) {
      cv::Vec3b* out = bgr->ptr<cv::Vec3b>(y);
      const cv::Vec3b* in = lines.ptr<cv::Vec3b>(y - box.y0);
      for (int x = box.x0; x < box.x1; ++x) {
        const float a = organ_layer_.alpha(x, y);
        for (int c = 0; c < 3; ++c)
          out[x][c] = static_cast<uchar>(out[x][c] + a * (in[x - box.x0][c] - out[x][c]) + 0.5f);
      }
    }

  // Silhouette: the boundary of the mask (outer outlines and holes). Each boundary pixel's
  // centre moves down the coverage gradient to where the coverage, linear at that slope, is
  // 0.5 (the edge to sub-pixel accuracy); then three points are averaged so that the
  // staircase does not show.
  cv::Mat mask(box.height(), box.width(), CV_8U, cv::Scalar(0));
  for (int y = box.y0; y < box.y1; ++y) {
    const render::CoverageLayer::Pixel* row = organ_layer_.row(y);
    uchar* m = mask.ptr<uchar>(y - box.y0);
    for (int x = organ_layer_.row_begin(y); x < organ_layer_.row_end(y); ++x)
      if (x >= box.x0 && x < box.x1 && row[x].alpha >= 0.5f) m[x - box.x0] = 255;
  }
  std::vector<std::vector<cv::Point>> contours;
  cv::findContours(mask, contours, cv::RETR_LIST, cv::CHAIN_APPROX_NONE, cv::Point(box.x0, box.y0));
  // Drawn at 1/16 px (cv::LINE_AA with 4 fractional bits).
  constexpr int kShift = 4;
  const auto alpha = [&](int x, int y) {
    return x < box.x0 || y < box.y0 || x >= box.x1 || y >= box.y1 ? 0.0f : organ_layer_.alpha(x, y);
  };
  std::vector<std::vector<cv::Point>> smooth(contours.size());
  std::vector<cv::Point2f> edge;
  for (size_t c = 0; c < contours.size(); ++c) {
    const std::vector<cv::Point>& in = contours[c];
    const int n = static_cast<int>(in.size());
    edge.resize(n);
    for (int i = 0; i < n; ++i) {
      const int x = in[i].x, y = in[i].y;
      const float gx = 0.5f * (alpha(x + 1, y) - alpha(x - 1, y));
      const float gy = 0.5f * (alpha(x, y + 1) - alpha(x, y - 1));
      const float g = std::hypot(gx, gy);
      const float t = g > 1e-3f ? std::clamp((alpha(x, y) - 0.5f) / g, 0.0f, 1.0f) : 0.0f;
      edge[i] = cv::Point2f(x - t * gx / std::max(g, 1e-3f), y - t * gy / std::max(g, 1e-3f));
    }
    smooth[c].resize(n);
    for (int i = 0; i < n; ++i) {
      const cv::Point2f s = 0.25f * (edge[(i + n - 1) % n] + 2 * edge[i] + edge[(i + 1) % n]);
      smooth[c][i] = cv::Point(static_cast<int>(std::lround(s.x * (1 << kShift))),
                               static_cast<int>(std::lround(s.y * (1 << kShift))));
    }
  }
  cv::polylines(*bgr, smooth, true, Bgr(options_.contour_color), width, cv::LINE_AA, kShift);
}

void OverlayRenderer::DrawLegend(const std::vector<OverlayStructure>& internal, int frame,
                                 cv::Mat* bgr) const {
  // Text scaled with the image height (readable at 480 to 1080 rows).
  const double scale = std::clamp(bgr->rows / 900.0, 0.35, 0.8);
  const int thick = 1, line_h = static_cast<int>(std::lround(34 * scale)) + 4;
  const int pad = static_cast<int>(std::lround(12 * scale)) + 2;
  const cv::Scalar white(255, 255, 255);
  const auto text_width = [&](const std::string& t) {
    int base = 0;
    return cv::getTextSize(t, cv::FONT_HERSHEY_SIMPLEX, scale, thick, &base).width;
  };
  if (options_.legend) {
    std::vector<std::pair<std::string, cv::Scalar>> rows;
    if (options_.style == OverlayStyle::kContour) {
      rows.push_back({"organ outline", Bgr(options_.contour_color)});
      rows.push_back({"cut edges", Bgr(options_.cut_edge_color)});
    } else {
      rows.push_back({"organ", Bgr(options_.organ_color)});
    }
    for (const OverlayStructure& s : internal)
      if (!s.name.empty() && Visible(s)) rows.push_back({s.name, Bgr(s.color)});
    int w = 0;
    for (const auto& r : rows) w = std::max(w, text_width(r.first));
    const int swatch = 2 * line_h / 3;
    const cv::Rect panel(pad, pad, w + swatch + 3 * pad,
                         static_cast<int>(rows.size()) * line_h + pad);
    const cv::Rect clipped = panel & cv::Rect(0, 0, bgr->cols, bgr->rows);
    if (clipped.area() > 0) {
      cv::Mat roi = (*bgr)(clipped);
      roi.convertTo(roi, -1, 0.4, 0);  // darkened, so that the text reads on any frame
    }
    for (size_t i = 0; i < rows.size(); ++i) {
      const int y = pad + static_cast<int>(i) * line_h + line_h / 2 + pad / 2;
      cv::line(*bgr, cv::Point(2 * pad, y), cv::Point(2 * pad + swatch, y), rows[i].second,
               options_.contour_width_px + 2, cv::LINE_AA);
      cv::putText(*bgr, rows[i].first, cv::Point(3 * pad + swatch, y + line_h / 4),
                  cv::FONT_HERSHEY_SIMPLEX, scale, white, thick, cv::LINE_AA);
    }
  }
  if (options_.frame_counter && frame >= 0) {
    const std::string t = "frame " + std::to_string(frame);
    const cv::Point at(pad, bgr->rows - pad);
    cv::putText(*bgr, t, at, cv::FONT_HERSHEY_SIMPLEX, scale, cv::Scalar(0, 0, 0), thick + 2,
                cv::LINE_AA);
    cv::putText(*bgr, t, at, cv::FONT_HERSHEY_SIMPLEX, scale, white, thick, cv::LINE_AA);
  }
}

void OverlayRenderer::DrawOutline(const OverlayStructure& s, cv::Mat* bgr) const {
  // Both sides of a sheet count (no culling), at pixel accuracy: thin structures are small.
  const cv::Mat mask = render::RenderMask(raster_, *s.vertices_mm, *s.faces);
  std::vector<std::vector<cv::Point>> contours;
  cv::findContours(mask, contours, cv::RETR_LIST, cv::CHAIN_APPROX_NONE);
  const int width = std::max(1, options_.contour_width_px - 1);
  cv::Mat lines = bgr->clone();
  cv::polylines(lines, contours, true, Bgr(s.color), width, cv::LINE_AA);
  const double a = std::clamp(s.opacity, 0.0, 1.0);
  cv::addWeighted(lines, a, *bgr, 1.0 - a, 0.0, *bgr);
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
    // The contour style draws no organ surface: the video shows inside the outline.
    const bool contour = options_.style == OverlayStyle::kContour;
    const double organ_opacity = contour ? 0.0 : options_.organ_opacity;
    if (options_.supersampling <= 1)
      RenderCoverage(box, organ_vertices_mm, organ_faces, internal, organ_opacity, bgr);
    else
      RenderSupersampled(box, organ_vertices_mm, organ_faces, internal, organ_opacity, bgr);
    if (contour) {
      DrawContour(box, organ_vertices_mm, organ_faces, bgr);
      for (const OverlayStructure& s : internal)
        if (s.outline && Visible(s)) DrawOutline(s, bgr);
    }
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
  DrawLegend(internal, layers.frame, bgr);
}

}  // namespace arreg::pipeline
