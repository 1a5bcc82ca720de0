// Software z-buffer rasterizer for triangle meshes seen by a pinhole camera:
// used to render synthetic video, ground-truth masks, overlays and Dice masks.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <functional>
#include <opencv2/core.hpp>
#include <vector>

#include "core/camera.h"
#include "core/mesh.h"

namespace arreg::render {

// Distortion-free pinhole projection in OpenCV's convention: pixel (u, v) has
// its centre at integer coordinates, u = fx X/Z + cx, v = fy Y/Z + cy with
// (X, Y, Z) in the camera frame (Z forward, Y down).
struct RasterCamera {
  int width = 640;                // image width (px)
  int height = 512;               // image height (px)
  double fx = 600, fy = 600;      // focal lengths (px)
  double cx = 319.5, cy = 255.5;  // principal point (px)
  Eigen::Isometry3d camera_from_world = Eigen::Isometry3d::Identity();
  double near_mm = 1.0;  // triangles are clipped at this camera depth (scene units)

  void Check() const;
};

// The rasterizer's distortion-free camera for a PinholeCamera (same size,
// intrinsics and pose). Lens distortion is not applied: callers that need it
// move the vertices to their distorted positions first (eval::PointsForRaster).
RasterCamera ToRasterCamera(const PinholeCamera& camera);

// What a fragment shader sees for one covered sample.
struct Fragment {
  int x = 0, y = 0;                  // sample position in the render target (samples, not pixels)
  int face = 0;                      // face index in the drawn mesh
  Eigen::Vector3d barycentric;       // perspective-correct, w.r.t. the face's three vertices
  Eigen::Vector3d point_in_camera;   // interpolated position (scene units)
  Eigen::Vector3d normal_in_camera;  // unit; interpolated vertex normals or the face normal
  bool front_facing = true;          // face oriented towards the camera
};

// Returns linear RGB in [0, 1] for a fragment.
using FragmentShader = std::function<Eigen::Vector3f(const Fragment&)>;

struct DrawOptions {
  bool depth_test = true;        // reject fragments behind the stored depth
  bool depth_write = true;       // store the fragment's depth
  bool cull_back_faces = false;  // skip faces whose front side points away from the camera
  float opacity = 1.0f;          // < 1 blends over what is already drawn (translucency)
  int id = 1;  // written to the id buffer (silhouettes, picking); 0 means background
};

// Colour, depth and id buffers rendered at `supersampling` x the camera's
// resolution (anti-aliasing); Resolve* average back to camera pixels.
class RenderTarget {
 public:
  // `supersampling` >= 1 samples per pixel along each axis.
  RenderTarget(const RasterCamera& camera, int supersampling = 1);

  void Clear(const Eigen::Vector3f& background_rgb);
  // Sets every sample's background colour from a per-pixel function of the pixel (u, v).
  void ClearWith(const std::function<Eigen::Vector3f(double u, double v)>& background_rgb);

  // Draws triangles. vertices_in_world (#V x 3), faces (#F x 3) counter-clockwise
  // seen from outside; normals (#V x 3) may be empty (flat shading). Returns the
  // number of samples written.
  int64_t Draw(const RowMatX3d& vertices_in_world, const RowMatX3i& faces, const RowMatX3d& normals,
               const FragmentShader& shader, const DrawOptions& options = {});

  // 8-bit BGR image (camera resolution), box-filtered over the samples; colour
  // is clamped to [0, 1].
  cv::Mat ResolveBgr() const;
  // 8-bit mask (camera resolution): 255 where the sample at the pixel centre
  // (or the majority of samples, when supersampled) has id `id`, or any id > 0 when id < 0.
  cv::Mat ResolveMask(int id = -1) const;

  const RasterCamera& camera() const { return camera_; }
  int supersampling() const { return ss_; }
  int sample_width() const { return sw_; }
  int sample_height() const { return sh_; }
  float depth(int sx, int sy) const { return depth_[Index(sx, sy)]; }
  int id(int sx, int sy) const { return id_[Index(sx, sy)]; }
  const Eigen::Vector3f& color(int sx, int sy) const { return color_[Index(sx, sy)]; }

 private:
  size_t Index(int sx, int sy) const { return static_cast<size_t>(sy) * sw_ + sx; }
  void DrawTriangleInCamera(const Eigen::Vector3d p[3], const Eigen::Vector3d n[3],
                            const double bary_of_vertex[3][3], int face, bool front_facing,
                            const FragmentShader& shader, const DrawOptions& options,
                            int64_t* written);

  RasterCamera camera_;
  int ss_, sw_, sh_;
  std::vector<float> depth_;            // camera z per sample, +inf when empty
  std::vector<int32_t> id_;             // DrawOptions::id of the visible surface, 0 when empty
  std::vector<Eigen::Vector3f> color_;  // linear RGB per sample
};

// Silhouette of a mesh as an 8-bit mask (255 inside): a pixel is inside when
// its centre is covered by a triangle (top-left fill rule, so a pixel on a
// shared edge counts once and a watertight mesh has no cracks).
cv::Mat RenderMask(const RasterCamera& camera, const RowMatX3d& vertices_in_world,
                   const RowMatX3i& faces);

// Blinn-Phong lighting with the light at the camera centre (endoscope light).
struct ShadingOptions {
  float ambient = 0.15f;    // ambient fraction of the albedo, default 0.15
  float diffuse = 0.85f;    // Lambert weight, default 0.85
  float specular = 0.35f;   // highlight weight (white light), default 0.35
  float shininess = 40.0f;  // Blinn-Phong exponent, default 40
  bool two_sided = true;    // light back faces as if they faced the camera
};
Eigen::Vector3f ShadeBlinnPhong(const Eigen::Vector3f& albedo, const Fragment& fragment,
                                const ShadingOptions& options);

// Per-vertex unit normals of a triangle mesh, area-weighted (#V x 3; zero at
// vertices of no face or of degenerate faces only).
RowMatX3d VertexNormals(const RowMatX3d& vertices, const RowMatX3i& faces);
// The same into *normals, reusing its buffer (callers drawing every frame).
void VertexNormals(const RowMatX3d& vertices, const RowMatX3i& faces, RowMatX3d* normals);

// Gouraud shading input: the Blinn-Phong colour (linear RGB) at each vertex of a
// surface of one albedo, with world-frame vertex normals `normals`, seen by a
// camera at camera_from_world (vertices without a normal face the camera).
// Into *rgb (#V x 3), reusing its buffer.
void ShadeVertices(const RowMatX3d& vertices, const RowMatX3d& normals,
                   const Eigen::Isometry3d& camera_from_world, const Eigen::Vector3f& albedo,
                   const ShadingOptions& options,
                   Eigen::Matrix<float, Eigen::Dynamic, 3, Eigen::RowMajor>* rgb);

}  // namespace arreg::render
