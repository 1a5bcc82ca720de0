// Image-space overlap for the accuracy evaluation: the Dice coefficient of two
// binary masks and the silhouette of a mesh seen by the (distorted) run camera.
#pragma once

#include <cstdint>
#include <opencv2/core.hpp>

#include "ar/render/rasterizer.h"
#include "core/camera.h"
#include "core/mesh.h"

namespace arreg::eval {

struct DiceCounts {
  int64_t intersection = 0;  // pixels inside both masks
  int64_t area_a = 0;        // pixels inside mask A
  int64_t area_b = 0;        // pixels inside mask B
  // 2 |A n B| / (|A| + |B|); 1 when both masks are empty (they agree exactly).
  double dice = 1.0;
};

// Dice coefficient of two single-channel 8-bit masks of the same size; a pixel
// is inside when it is non-zero. Throws arreg::Error when the types or sizes differ.
DiceCounts ComputeDice(const cv::Mat& mask_a, const cv::Mat& mask_b);

// Colours (BGR) of OverlapImage: pixels inside both masks, inside the truth only (the model
// misses them) and inside the model only; pixels inside neither are black.
inline const cv::Vec3b kOverlapBoth(160, 160, 160), kOverlapTruthOnly(40, 40, 230),
    kOverlapModelOnly(230, 120, 30);

// An 8-bit BGR image of the true mask against the model's silhouette (single-channel masks of
// the same size, non-zero inside): where the registration lags (truth only) and where it
// overshoots (model only). Throws arreg::Error when the types or sizes differ.
cv::Mat OverlapImage(const cv::Mat& truth, const cv::Mat& model);

// The camera's intrinsics as a distortion-free raster camera placed at the
// world origin (identity pose): pair it with PointsForRaster.
render::RasterCamera RasterCameraFor(const PinholeCamera& camera);

// Moves world points into a camera frame in which a distortion-free pinhole
// projection with RasterCameraFor(camera) lands on the camera's *distorted*
// pixel: X' = z (u - cx) / fx, Y' = z (v - cy) / fy, Z' = z, where (u, v, z)
// is PinholeCamera::ProjectWithDepth. Lens distortion is thus applied exactly
// at the vertices and linearly along triangle edges, which is what the
// rasterizer can draw; points behind the camera keep their undistorted
// camera coordinates so that near-plane clipping still works. (#V x 3) in, (#V x 3) out.
RowMatX3d PointsForRaster(const PinholeCamera& camera, const RowMatX3d& vertices_in_world);

// 8-bit mask (camera resolution, 255 inside) of the pixels whose centre the
// mesh covers, as seen by `camera` with its lens distortion.
cv::Mat RenderSilhouette(const PinholeCamera& camera, const SurfaceMesh& mesh);

}  // namespace arreg::eval
