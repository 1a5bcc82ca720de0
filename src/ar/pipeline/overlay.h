// The overlay render stage: the deformed organ (its silhouette and cut edges as lines, or a
// translucent shaded surface) and the internal structures, z-buffered and anti-aliased,
// composited over the video frame, with an optional legend and frame counter.
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "ar/pipeline/pipeline_options.h"
#include "ar/render/coverage_layer.h"
#include "ar/render/rasterizer.h"
#include "core/camera.h"
#include "core/mesh.h"

namespace arreg::pipeline {

// The overlay of a camera with lens distortion is drawn with its pinhole part
// (render::ToRasterCamera; see docs/overlay.md).
using render::ToRasterCamera;

struct OverlayStructure {
  const RowMatX3d* vertices_mm = nullptr;            // (#V x 3) world
  const RowMatX3i* faces = nullptr;                  // (#F x 3)
  Eigen::Vector3d color = Eigen::Vector3d(1, 1, 0);  // linear RGB in [0, 1]
  double opacity = 1.0;
  std::string name;  // shown in the legend; "" leaves it out
  // In the contour style: drawn as the outline of its silhouette in its colour instead of
  // filled (thin structures: a sheet over the organ would hide it). Default false.
  bool outline = false;
};

// Optional annotation layers (pixels, world points).
struct OverlayLayers {
  const RowMatX2d* feature_pixels = nullptr;  // (#F x 2)
  const RowMatX3d* targets_mm = nullptr;      // (#F x 3)
  const RowMatX3d* anchors_mm = nullptr;      // (#F x 3)
  const std::vector<char>* alive = nullptr;   // (#F) rows drawn
  int frame = -1;                             // shown by the frame counter; -1: none
};

class OverlayRenderer {
 public:
  // Warns once when the camera has lens distortion (drawn as a pinhole camera).
  OverlayRenderer(const PinholeCamera& camera, const RenderStageOptions& options);

  // Draws over `bgr` (CV_8UC3, camera size) in place. Only the projected bounding box of the
  // organ and the internal structures is rasterised, so the cost follows the organ's size.
  // options.supersampling 1 draws with render::CoverageLayer (one sample per pixel,
  // analytic coverage on silhouette edges); >= 2 with the reference render::RenderTarget at
  // that many samples per pixel and axis.
  void Render(const RowMatX3d& organ_vertices_mm, const RowMatX3i& organ_faces,
              const std::vector<OverlayStructure>& internal, const OverlayLayers& layers,
              cv::Mat* bgr);

 private:
  using RowMatX3f = Eigen::Matrix<float, Eigen::Dynamic, 3, Eigen::RowMajor>;
  void RenderCoverage(const render::PixelRect& box, const RowMatX3d& organ_vertices_mm,
                      const RowMatX3i& organ_faces, const std::vector<OverlayStructure>& internal,
                      double organ_opacity, cv::Mat* bgr);
  void RenderSupersampled(const render::PixelRect& box, const RowMatX3d& organ_vertices_mm,
                          const RowMatX3i& organ_faces,
                          const std::vector<OverlayStructure>& internal, double organ_opacity,
                          cv::Mat* bgr) const;
  // Contour style: the organ's silhouette (the boundary of its coverage mask, drawn into
  // organ_layer_) and its visible cut edges (options_.cut_edge_angle_deg) as lines.
  void DrawContour(const render::PixelRect& box, const RowMatX3d& organ_vertices_mm,
                   const RowMatX3i& organ_faces, cv::Mat* bgr);
  // The surface's edges shared by two faces (edge_quads_), recomputed only when the faces change.
  void UpdateEdges(const RowMatX3i& faces);
  // The outline of one structure's silhouette (OverlayStructure::outline), in its colour.
  void DrawOutline(const OverlayStructure& s, cv::Mat* bgr) const;
  void DrawLegend(const std::vector<OverlayStructure>& internal, int frame, cv::Mat* bgr) const;
  // Blinn-Phong at the vertices (Gouraud) into vertex_rgb_.
  void ShadeVertices(const RowMatX3d& vertices, const RowMatX3i& faces,
                     const Eigen::Vector3f& albedo);

  PinholeCamera camera_;
  render::RasterCamera raster_;
  RenderStageOptions options_;
  // Kept between frames (no per-frame allocation once sized).
  render::CoverageLayer internal_layer_, organ_layer_;
  RowMatX3d normals_;
  RowMatX3f vertex_rgb_;
  RowMatX3i edge_faces_;  // the faces edge_quads_ was computed for
  // Per edge shared by two faces: its vertices a, b, and the third vertex of the face with the
  // edge a -> b, then of the face with b -> a.
  std::vector<Eigen::Vector4i> edge_quads_;
};

}  // namespace arreg::pipeline
