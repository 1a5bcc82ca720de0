// Cross-check of PinholeCamera against OpenCV itself (the reference for the
// distortion model). Only this test links OpenCV; arreg_core does not.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <random>

#include "core/camera.h"

namespace arreg {
namespace {

PinholeCamera RationalCamera() {
  PinholeCamera c;
  c.width = 1280;
  c.height = 720;
  c.fx = 1050.3;
  c.fy = 1049.8;
  c.cx = 641.2;
  c.cy = 358.9;
  c.distortion = Distortion::FromVector({-0.31, 0.11, 9e-4, -4e-4, 0.02, 0.05, -0.01, 0.002});
  c.camera_from_world.linear() =
      Eigen::AngleAxisd(0.4, Eigen::Vector3d(0.3, -1.0, 0.2).normalized()).toRotationMatrix();
  c.camera_from_world.translation() = Eigen::Vector3d(5.0, -12.0, 140.0);
  return c;
}

cv::Mat CameraMatrix(const PinholeCamera& c) {
  return (cv::Mat_<double>(3, 3) << c.fx, 0, c.cx, 0, c.fy, c.cy, 0, 0, 1);
}

cv::Mat DistCoeffs(const PinholeCamera& c) {
  const std::vector<double> d = c.distortion.ToVector();
  return cv::Mat(d, true).reshape(1, 1);
}

TEST(PinholeCameraVsOpenCv, ProjectMatchesCvProjectPoints) {
  const PinholeCamera c = RationalCamera();
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> xy(-60.0, 60.0), z(-40.0, 40.0);
  std::vector<cv::Point3d> points;
  for (int i = 0; i < 300; ++i) points.emplace_back(xy(rng), xy(rng), z(rng));
  cv::Mat r(3, 3, CV_64F);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) r.at<double>(i, j) = c.camera_from_world.linear()(i, j);
  cv::Mat rvec;
  cv::Rodrigues(r, rvec);
  const Eigen::Vector3d t = c.camera_from_world.translation();
  const cv::Mat tvec = (cv::Mat_<double>(3, 1) << t.x(), t.y(), t.z());
  std::vector<cv::Point2d> expected;
  cv::projectPoints(points, rvec, tvec, CameraMatrix(c), DistCoeffs(c), expected);
  for (std::size_t i = 0; i < points.size(); ++i) {
    const Eigen::Vector2d uv = c.Project(Eigen::Vector3d(points[i].x, points[i].y, points[i].z));
    EXPECT_NEAR(uv.x(), expected[i].x, 1e-8);
    EXPECT_NEAR(uv.y(), expected[i].y, 1e-8);
  }
}

TEST(PinholeCameraVsOpenCv, UndistortMatchesCvUndistortPointsAtConvergence) {
  const PinholeCamera c = RationalCamera();
  std::vector<cv::Point2d> pixels;
  for (double u = 0; u < c.width; u += 97.0)
    for (double v = 0; v < c.height; v += 61.0) pixels.emplace_back(u, v);
  std::vector<cv::Point2d> expected;
  // Run OpenCV's iteration to convergence (its default of 5 iterations is coarse).
  cv::undistortPoints(pixels, expected, CameraMatrix(c), DistCoeffs(c), cv::noArray(),
                      cv::noArray(), cv::TermCriteria(cv::TermCriteria::COUNT, 500, 0.0));
  double worst = 0.0;
  for (std::size_t i = 0; i < pixels.size(); ++i) {
    UndistortSummary s;
    const Eigen::Vector2d n = c.PixelToNormalized(Eigen::Vector2d(pixels[i].x, pixels[i].y), &s);
    EXPECT_TRUE(s.converged);
    worst = std::max(worst, (n - Eigen::Vector2d(expected[i].x, expected[i].y)).norm());
  }
  // Normalized units; 1e-9 is ~1e-6 px at fx = 1050 px.
  EXPECT_LT(worst, 1e-9);
}

}  // namespace
}  // namespace arreg
