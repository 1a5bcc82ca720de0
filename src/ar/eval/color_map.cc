#include "ar/eval/color_map.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <opencv2/imgproc.hpp>

#include "ar/eval/dice.h"
#include "ar/render/rasterizer.h"
#include "core/error.h"
#include "core/mesh_io.h"

namespace arreg::eval {

Eigen::Vector3f ViridisColor(double t) {
  // Nine samples of matplotlib's viridis (sRGB), linearly interpolated.
  static const float kTable[9][3] = {
      {0.267f, 0.005f, 0.329f}, {0.279f, 0.175f, 0.483f}, {0.230f, 0.322f, 0.546f},
      {0.173f, 0.449f, 0.558f}, {0.128f, 0.567f, 0.551f}, {0.153f, 0.680f, 0.504f},
      {0.361f, 0.786f, 0.388f}, {0.668f, 0.862f, 0.196f}, {0.993f, 0.906f, 0.144f}};
  if (!std::isfinite(t)) t = 1.0;
  const double s = std::clamp(t, 0.0, 1.0) * 8.0;
  const int i = std::min(7, static_cast<int>(std::floor(s)));
  const float w = static_cast<float>(s - i);
  Eigen::Vector3f c;
  for (int k = 0; k < 3; ++k) c[k] = (1.0f - w) * kTable[i][k] + w * kTable[i + 1][k];
  return c;
}

SurfaceMesh ColorByDistance(const SurfaceMesh& mesh, const Eigen::VectorXd& distances,
                            double max_distance) {
  ARREG_CHECK_INPUT(distances.size() == mesh.num_vertices(), "", "distances",
                    "need one distance per vertex (", mesh.num_vertices(), "), got ",
                    distances.size());
  ARREG_CHECK_INPUT(max_distance > 0.0 && std::isfinite(max_distance), "", "max_distance",
                    "must be positive and finite, got ", max_distance);
  SurfaceMesh out = mesh;
  out.colors.resize(mesh.num_vertices(), 3);
  for (int v = 0; v < mesh.num_vertices(); ++v)
    out.colors.row(v) = ViridisColor(distances[v] / max_distance).cast<double>().transpose();
  return out;
}

void WriteColoredObj(const std::string& path, const SurfaceMesh& mesh) {
  ARREG_CHECK_INPUT(mesh.colors.rows() == mesh.vertices.rows(), path, "colors",
                    "need one colour per vertex");
  ARREG_CHECK_INPUT(MeshFileExtension(path) == ".obj", path, "", "colour maps are written as .obj");
  // core's OBJ writer emits "v x y z r g b" when every vertex has a colour.
  MeshWriteOptions options;
  options.precision = 7;  // 1e-4 mm at 100 mm and colours without float noise
  WriteSurfaceMesh(path, mesh, options);
}

void ColorMapImageOptions::Check() const {
  ARREG_CHECK_INPUT(max_distance > 0.0 && std::isfinite(max_distance), "", "colormap.max_distance",
                    "must be positive and finite, got ", max_distance);
  ARREG_CHECK_INPUT(supersampling >= 1 && supersampling <= 8, "", "colormap.supersampling",
                    "must be in [1, 8], got ", supersampling);
  ARREG_CHECK_INPUT(legend_width_px >= 60, "", "colormap.legend_width_px", "must be >= 60, got ",
                    legend_width_px);
}

namespace {

cv::Scalar ToBgr(const Eigen::Vector3f& rgb) {
  return cv::Scalar(255.0 * rgb[2], 255.0 * rgb[1], 255.0 * rgb[0]);
}

std::string FormatMm(double value) {
  char text[32];
  std::snprintf(text, sizeof(text), value < 10.0 ? "%.2f mm" : "%.1f mm", value);
  return text;
}

}  // namespace

cv::Mat RenderDistanceImage(const PinholeCamera& camera, const SurfaceMesh& mesh,
                            const Eigen::VectorXd& distances, const ColorMapImageOptions& options) {
  options.Check();
  ARREG_CHECK_INPUT(distances.size() == mesh.num_vertices(), "", "distances",
                    "need one distance per vertex (", mesh.num_vertices(), "), got ",
                    distances.size());
  render::RenderTarget target(RasterCameraFor(camera), options.supersampling);
  const Eigen::Vector3f background(0.08f, 0.08f, 0.10f);
  target.Clear(background);
  const RowMatX3d points = PointsForRaster(camera, mesh.vertices);
  const RowMatX3d normals = render::VertexNormals(points, mesh.faces);
  render::ShadingOptions shading;
  shading.specular = 0.1f;
  const double max_distance = options.max_distance;
  target.Draw(points, mesh.faces, normals, [&](const render::Fragment& fragment) {
    const Eigen::Vector3i f = mesh.faces.row(fragment.face).transpose();
    const double d = fragment.barycentric[0] * distances[f[0]] +
                     fragment.barycentric[1] * distances[f[1]] +
                     fragment.barycentric[2] * distances[f[2]];
    return render::ShadeBlinnPhong(ViridisColor(d / max_distance), fragment, shading);
  });
  const cv::Mat view = target.ResolveBgr();

  const int legend = options.legend_width_px;
  cv::Mat image(view.rows, view.cols + legend, CV_8UC3, ToBgr(background));
  view.copyTo(image(cv::Rect(0, 0, view.cols, view.rows)));
  const int margin = std::max(10, view.rows / 12);
  const int bar_top = margin, bar_bottom = view.rows - margin;
  const int bar_x0 = view.cols + 12, bar_x1 = bar_x0 + 18;
  for (int y = bar_top; y <= bar_bottom; ++y) {
    const double t = 1.0 - double(y - bar_top) / std::max(1, bar_bottom - bar_top);
    cv::line(image, {bar_x0, y}, {bar_x1, y}, ToBgr(ViridisColor(t)));
  }
  const double font = std::clamp(view.rows / 900.0, 0.35, 0.8);
  const cv::Scalar white(235, 235, 235);
  for (int k = 0; k <= 2; ++k) {
    const double t = k / 2.0;
    const int y = bar_bottom - static_cast<int>(std::lround(t * (bar_bottom - bar_top)));
    cv::line(image, {bar_x1, y}, {bar_x1 + 5, y}, white);
    cv::putText(image, FormatMm(t * max_distance), {bar_x1 + 8, y + 4}, cv::FONT_HERSHEY_SIMPLEX,
                font, white, 1, cv::LINE_AA);
  }
  if (!options.title.empty()) {
    // Shrink the title until it fits beside the legend.
    double title_font = font * 1.2;
    int baseline = 0;
    while (
        title_font > 0.2 &&
        cv::getTextSize(options.title, cv::FONT_HERSHEY_SIMPLEX, title_font, 1, &baseline).width >
            view.cols - 16)
      title_font *= 0.9;
    cv::putText(image, options.title, {8, 8 + static_cast<int>(20 * title_font)},
                cv::FONT_HERSHEY_SIMPLEX, title_font, white, 1, cv::LINE_AA);
  }
  return image;
}

}  // namespace arreg::eval
