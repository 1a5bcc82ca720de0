#include "ar/eval/dice.h"

#include "core/error.h"

namespace arreg::eval {

namespace {

void CheckMaskPair(const cv::Mat& mask_a, const cv::Mat& mask_b) {
  ARREG_CHECK_INPUT(mask_a.type() == CV_8UC1 && mask_b.type() == CV_8UC1, "", "mask",
                    "Dice needs single-channel 8-bit masks");
  ARREG_CHECK_INPUT(mask_a.size() == mask_b.size(), "", "mask", "Dice of masks of different size (",
                    mask_a.cols, "x", mask_a.rows, " vs ", mask_b.cols, "x", mask_b.rows, ")");
}

}  // namespace

cv::Mat OverlapImage(const cv::Mat& truth, const cv::Mat& model) {
  CheckMaskPair(truth, model);
  cv::Mat out(truth.size(), CV_8UC3, cv::Scalar(0, 0, 0));
  for (int y = 0; y < truth.rows; ++y) {
    const uint8_t* t = truth.ptr<uint8_t>(y);
    const uint8_t* m = model.ptr<uint8_t>(y);
    cv::Vec3b* o = out.ptr<cv::Vec3b>(y);
    for (int x = 0; x < truth.cols; ++x) {
      if (t[x] && m[x])
        o[x] = kOverlapBoth;
      else if (t[x])
        o[x] = kOverlapTruthOnly;
      else if (m[x])
        o[x] = kOverlapModelOnly;
    }
  }
  return out;
}

DiceCounts ComputeDice(const cv::Mat& mask_a, const cv::Mat& mask_b) {
  CheckMaskPair(mask_a, mask_b);
  DiceCounts counts;
  for (int y = 0; y < mask_a.rows; ++y) {
    const uint8_t* a = mask_a.ptr<uint8_t>(y);
    const uint8_t* b = mask_b.ptr<uint8_t>(y);
    for (int x = 0; x < mask_a.cols; ++x) {
      const bool in_a = a[x] != 0, in_b = b[x] != 0;
      counts.area_a += in_a;
      counts.area_b += in_b;
      counts.intersection += in_a && in_b;
    }
  }
  const int64_t total = counts.area_a + counts.area_b;
  counts.dice = total > 0 ? 2.0 * static_cast<double>(counts.intersection) / total : 1.0;
  return counts;
}

render::RasterCamera RasterCameraFor(const PinholeCamera& camera) {
  // PointsForRaster gives camera-frame points, so the pose is the identity.
  render::RasterCamera raster = render::ToRasterCamera(camera);
  raster.camera_from_world = Eigen::Isometry3d::Identity();
  return raster;
}

RowMatX3d PointsForRaster(const PinholeCamera& camera, const RowMatX3d& vertices_in_world) {
  RowMatX3d out(vertices_in_world.rows(), 3);
  const bool distorted = !camera.distortion.IsZero();
  for (int i = 0; i < vertices_in_world.rows(); ++i) {
    const Eigen::Vector3d p = camera.camera_from_world * vertices_in_world.row(i).transpose();
    if (!distorted || p.z() <= 0.0) {
      out.row(i) = p.transpose();
      continue;
    }
    const Eigen::Vector2d pixel = camera.ProjectFromCamera(p);
    out.row(i) << p.z() * (pixel.x() - camera.cx) / camera.fx,
        p.z() * (pixel.y() - camera.cy) / camera.fy, p.z();
  }
  return out;
}

cv::Mat RenderSilhouette(const PinholeCamera& camera, const SurfaceMesh& mesh) {
  return render::RenderMask(RasterCameraFor(camera), PointsForRaster(camera, mesh.vertices),
                            mesh.faces);
}

}  // namespace arreg::eval
