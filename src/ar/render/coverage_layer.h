// Fast overlay rasterizer: Gouraud-coloured triangle meshes at one sample per pixel with
// analytic anti-aliasing of silhouette edges, kept as a layer to composite over a video frame.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "ar/render/rasterizer.h"
#include "core/mesh.h"

namespace arreg::render {

// Pixel rectangle [x0, x1) x [y0, y1) of a camera image.
struct PixelRect {
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  int width() const { return x1 - x0; }
  int height() const { return y1 - y0; }
  bool empty() const { return x1 <= x0 || y1 <= y0; }
};

struct CoverageDrawOptions {
  // Skip faces turned away from the camera; default false (both sides are drawn).
  bool cull_back_faces = false;
  // Analytic coverage on silhouette edges (shared with a face of the other facing, with a
  // culled face, or with no face); interior edges use the pixel-centre test with the top-left
  // fill rule, so a mesh has neither cracks nor double coverage inside. Default true.
  bool antialias = true;
  // Multiplies the coverage (translucency), in (0, 1]; default 1.
  float opacity = 1.0f;

  void Check() const;  // throws arreg::Error naming the field
};

// One surface layer at camera resolution, valid inside rect(): per pixel the colour of the
// nearest surface drawn there, its alpha (covered fraction of the pixel times opacity) and its
// inverse camera depth. Fragments of one pixel merge by taking the larger alpha, the
// nearer fragment in front (exact for an opaque fragment behind any other; for two
// fragments of one silhouette edge, the front and back face of a fold, it avoids counting
// the edge's coverage twice).
//
// Costs: one sample per pixel, fixed-point (1/256 px) edge functions evaluated
// incrementally over each triangle's row spans, Gouraud colours interpolated
// perspective-correctly; no allocation after the first frames (buffers are kept); clearing
// and compositing visit only the row spans drawn.
class CoverageLayer {
 public:
  struct Pixel {
    float alpha;      // 0: empty
    float inv_depth;  // 1 / camera z (larger is nearer)
    float r, g, b;    // linear RGB
  };

  // Allocates (and empties) buffers for the whole image once.
  explicit CoverageLayer(const RasterCamera& camera);

  // Empties the pixels drawn since the last Clear (cost follows their number, not the image
  // size) and makes `rect` (clipped to the image) the area later draws are clipped to.
  void Clear(const PixelRect& rect);

  // Draws a triangle mesh: vertices_in_world (#V x 3), faces (#F x 3, counter-clockwise seen
  // from outside), vertex_rgb (#V x 3 linear RGB in [0, 1], interpolated over each face).
  // Triangles are clipped at the camera's near plane. Returns the number of fragments merged.
  int64_t Draw(const RowMatX3d& vertices_in_world, const RowMatX3i& faces,
               const Eigen::Matrix<float, Eigen::Dynamic, 3, Eigen::RowMajor>& vertex_rgb,
               const CoverageDrawOptions& options);

  const RasterCamera& camera() const { return camera_; }
  const PixelRect& rect() const { return rect_; }
  // Pixel (x, y) of the image (empty outside what was drawn).
  const Pixel& pixel(int x, int y) const { return pixels_[Index(x, y)]; }
  float alpha(int x, int y) const { return pixel(x, y).alpha; }
  float inverse_depth(int x, int y) const { return pixel(x, y).inv_depth; }
  Eigen::Vector3f rgb(int x, int y) const {
    const Pixel& p = pixel(x, y);
    return Eigen::Vector3f(p.r, p.g, p.b);
  }
  // Image row y and the columns [row_begin(y), row_end(y)) drawn in it since the last Clear
  // (an empty range when none).
  const Pixel* row(int y) const { return &pixels_[Index(0, y)]; }
  int row_begin(int y) const { return row_begin_[y]; }
  int row_end(int y) const { return row_end_[y]; }
  // Sum of alpha over the image (coverage area in pixels at opacity 1).
  double CoveredArea() const;

 private:
  struct Vertex {  // a (possibly clipped) triangle corner
    Eigen::Vector3d p_cam;
    Eigen::Vector3f rgb;
  };
  // Adjacency of one face array, cached between frames while the faces are unchanged.
  struct Adjacency {
    RowMatX3i faces;
    std::vector<int> neighbour;  // (#F x 3) face across edge (k, k+1), -1: none or non-manifold
  };

  size_t Index(int x, int y) const { return static_cast<size_t>(y) * camera_.width + x; }
  const Adjacency& AdjacencyOf(const RowMatX3i& faces);
  int64_t DrawTriangle(const Vertex v[3], const bool smooth_edge[3], float opacity);

  RasterCamera camera_;
  PixelRect rect_;
  std::vector<Pixel> pixels_;             // the whole image, row-major
  std::vector<int> row_begin_, row_end_;  // per row: columns drawn since the last Clear
  // Scratch kept between calls.
  std::vector<Eigen::Vector3d> p_cam_;
  std::vector<signed char> facing_;  // per face: 1 front, -1 back, 0 degenerate
  std::vector<Adjacency> adjacency_cache_;
  size_t adjacency_next_ = 0;  // round-robin replacement in the cache
  std::vector<std::pair<int64_t, int>> edge_keys_;
};

}  // namespace arreg::render
