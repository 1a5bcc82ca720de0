#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <fstream>
#include <random>

#include "core/camera.h"
#include "core/error.h"
#include "core/json_reader.h"
#include "test_util.h"

namespace arreg {
namespace {

// A 640x480 laparoscope-like camera with the realistic distortion of the brief.
PinholeCamera DistortedCamera() {
  PinholeCamera c;
  c.width = 640;
  c.height = 480;
  c.fx = 520.0;
  c.fy = 515.0;
  c.cx = 322.5;
  c.cy = 241.0;
  c.distortion.k1 = -0.3;
  c.distortion.k2 = 0.1;
  c.distortion.p1 = 1e-3;
  c.distortion.p2 = -5e-4;
  return c;
}

Eigen::Isometry3d SomePose() {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() = (Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()) *
                Eigen::AngleAxisd(-0.7, Eigen::Vector3d::UnitY()))
                   .toRotationMatrix();
  t.translation() = Eigen::Vector3d(12.0, -30.0, 150.0);
  return t;
}

void WriteText(const std::string& path, const std::string& text) { std::ofstream(path) << text; }

// Expects `f` to throw arreg::Error whose message contains every one of `parts`.
template <typename F>
void ExpectErrorMentions(F f, const std::vector<std::string>& parts) {
  try {
    f();
    FAIL() << "no arreg::Error thrown";
  } catch (const Error& e) {
    for (const std::string& p : parts)
      EXPECT_NE(std::string(e.what()).find(p), std::string::npos)
          << "message \"" << e.what() << "\" lacks \"" << p << "\"";
  }
}

TEST(PinholeCamera, OpticalAxisProjectsToPrincipalPoint) {
  PinholeCamera c = DistortedCamera();
  const Eigen::Vector2d uv = c.Project(Eigen::Vector3d(0, 0, 87.0));
  EXPECT_NEAR(uv.x(), c.cx, 1e-12);
  EXPECT_NEAR(uv.y(), c.cy, 1e-12);
}

TEST(PinholeCamera, UndistortedProjectionIsFocalTimesRatioPlusCentre) {
  PinholeCamera c = DistortedCamera();
  c.distortion = Distortion();
  const Eigen::Vector3d p(13.0, -7.5, 95.0);
  const Eigen::Vector3d uvz = c.ProjectWithDepth(p);
  EXPECT_NEAR(uvz.x(), c.fx * 13.0 / 95.0 + c.cx, 1e-12);
  EXPECT_NEAR(uvz.y(), c.fy * -7.5 / 95.0 + c.cy, 1e-12);
  EXPECT_DOUBLE_EQ(uvz.z(), 95.0);
  // K applied to the point gives the same pixel in homogeneous form.
  const Eigen::Vector3d h = c.K() * p;
  EXPECT_NEAR(h.x() / h.z(), uvz.x(), 1e-12);
  EXPECT_NEAR(h.y() / h.z(), uvz.y(), 1e-12);
}

TEST(PinholeCamera, DistortionMatchesHandComputedOpenCvFormula) {
  PinholeCamera c = DistortedCamera();
  // Values from the OpenCV formula evaluated by hand (see camera.h) at (0.3, -0.2).
  Eigen::Vector2d d = c.Distort(Eigen::Vector2d(0.3, -0.2));
  EXPECT_NEAR(d.x(), 0.288532, 1e-12);
  EXPECT_NEAR(d.y(), -0.192268, 1e-12);
  // Rational model with k3..k6.
  c.distortion.k3 = 0.02;
  c.distortion.k4 = 0.05;
  c.distortion.k5 = -0.01;
  c.distortion.k6 = 0.002;
  d = c.Distort(Eigen::Vector2d(0.3, -0.2));
  EXPECT_NEAR(d.x(), 0.2867269118099308, 1e-12);
  EXPECT_NEAR(d.y(), -0.19106460787328725, 1e-12);
  // Pixel = f * distorted + c.
  const Eigen::Vector2d uv = c.ProjectFromCamera(Eigen::Vector3d(0.3, -0.2, 1.0) * 40.0);
  EXPECT_NEAR(uv.x(), c.fx * 0.2867269118099308 + c.cx, 1e-9);
  EXPECT_NEAR(uv.y(), c.fy * -0.19106460787328725 + c.cy, 1e-9);
}

TEST(PinholeCamera, DistortJacobianMatchesFiniteDifferences) {
  PinholeCamera c = DistortedCamera();
  c.distortion.k3 = 0.02;
  c.distortion.k4 = 0.05;
  c.distortion.k5 = -0.01;
  c.distortion.k6 = 0.002;
  const Eigen::Vector2d x(0.41, -0.27);
  const Eigen::Matrix2d j = c.DistortJacobian(x);
  const double h = 1e-6;
  for (int k = 0; k < 2; ++k) {
    Eigen::Vector2d e = Eigen::Vector2d::Zero();
    e[k] = h;
    const Eigen::Vector2d fd = (c.Distort(x + e) - c.Distort(x - e)) / (2 * h);
    EXPECT_NEAR(j(0, k), fd.x(), 1e-8);
    EXPECT_NEAR(j(1, k), fd.y(), 1e-8);
  }
}

TEST(PinholeCamera, UndistortInvertsDistortAcrossTheImage) {
  PinholeCamera c = DistortedCamera();
  // Corners of the image are the hardest case (largest radius).
  for (double u : {-0.5, 0.0, 100.0, 322.5, 500.0, 639.5}) {
    for (double v : {-0.5, 0.0, 120.0, 241.0, 400.0, 479.5}) {
      const Eigen::Vector2d distorted((u - c.cx) / c.fx, (v - c.cy) / c.fy);
      UndistortSummary s;
      const Eigen::Vector2d n = c.Undistort(distorted, &s);
      EXPECT_TRUE(s.converged) << u << "," << v;
      EXPECT_LT((c.Distort(n) - distorted).norm(), 1e-12) << u << "," << v;
    }
  }
}

TEST(PinholeCamera, ProjectUnprojectRoundTripWithoutDistortion) {
  PinholeCamera c = DistortedCamera();
  c.distortion = Distortion();
  c.camera_from_world = SomePose();
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-0.5, 639.5), v(-0.5, 479.5), z(20.0, 300.0);
  for (int i = 0; i < 200; ++i) {
    const Eigen::Vector2d pixel(u(rng), v(rng));
    const double depth = z(rng);
    const Eigen::Vector3d p = c.Unproject(pixel, depth);
    const Eigen::Vector3d uvz = c.ProjectWithDepth(p);
    EXPECT_LT((uvz.head<2>() - pixel).norm(), 1e-9);
    EXPECT_NEAR(uvz.z(), depth, 1e-9);
  }
}

TEST(PinholeCamera, ProjectUnprojectRoundTripWithDistortion) {
  PinholeCamera c = DistortedCamera();
  c.camera_from_world = SomePose();
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-0.5, 639.5), v(-0.5, 479.5), z(20.0, 300.0);
  double worst = 0.0;
  for (int i = 0; i < 500; ++i) {
    const Eigen::Vector2d pixel(u(rng), v(rng));
    const double depth = z(rng);
    UndistortSummary s;
    const Eigen::Vector3d p = c.Unproject(pixel, depth, &s);
    EXPECT_TRUE(s.converged);
    const Eigen::Vector3d uvz = c.ProjectWithDepth(p);
    worst = std::max(worst, (uvz.head<2>() - pixel).norm());
    EXPECT_NEAR(uvz.z(), depth, 1e-9);
  }
  EXPECT_LT(worst, 1e-6);
}

TEST(PinholeCamera, RayThroughPixelPassesThroughTheProjectedPoint) {
  PinholeCamera c = DistortedCamera();
  c.camera_from_world = SomePose();
  const Eigen::Vector3d center = c.CenterInWorld();
  // The centre maps to the camera origin.
  EXPECT_LT((c.camera_from_world * center).norm(), 1e-12);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0.0, 639.0), v(0.0, 479.0), z(30.0, 200.0);
  for (int i = 0; i < 50; ++i) {
    const Eigen::Vector3d p = c.Unproject(Eigen::Vector2d(u(rng), v(rng)), z(rng));
    const Ray ray = c.RayThroughPixel(c.Project(p));
    EXPECT_NEAR(ray.direction_in_world.norm(), 1.0, 1e-12);
    EXPECT_LT((ray.origin_in_world - center).norm(), 1e-12);
    const double t = (p - ray.origin_in_world).dot(ray.direction_in_world);
    EXPECT_GT(t, 0.0);
    EXPECT_LT((ray.PointAt(t) - p).norm(), 1e-7 * t);
  }
}

TEST(PinholeCamera, CameraFromWorldRotationIsApplied) {
  PinholeCamera c = DistortedCamera();
  c.distortion = Distortion();
  // Camera at world (0, 0, -100) rotated 90 degrees about world y: the camera
  // looks along world -x... build it and check a known point.
  Eigen::Isometry3d world_from_camera = Eigen::Isometry3d::Identity();
  world_from_camera.linear() =
      Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitY()).toRotationMatrix();
  world_from_camera.translation() = Eigen::Vector3d(0, 0, -100);
  c.camera_from_world = world_from_camera.inverse();
  // Camera z axis in world = R_y(90) * (0,0,1) = (1, 0, 0). A point 50 mm ahead
  // and 10 mm "down" (camera +y = world +y) projects below the centre.
  const Eigen::Vector3d p(50.0, 10.0, -100.0);
  const Eigen::Vector3d uvz = c.ProjectWithDepth(p);
  EXPECT_NEAR(uvz.z(), 50.0, 1e-12);
  EXPECT_NEAR(uvz.x(), c.cx, 1e-9);
  EXPECT_NEAR(uvz.y(), c.cy + c.fy * 10.0 / 50.0, 1e-9);
  EXPECT_LT((c.CenterInWorld() - Eigen::Vector3d(0, 0, -100)).norm(), 1e-12);
}

TEST(PinholeCamera, LookAtPointsTheOpticalAxisAtTheTarget) {
  PinholeCamera c = PinholeCamera::FromFieldOfView(640, 480, 70.0);
  const Eigen::Vector3d eye(100, 50, -200), target(10, -5, 30), up(0, 0, 1);
  c.LookAt(eye, target, up);
  const Eigen::Vector3d uvz = c.ProjectWithDepth(target);
  EXPECT_NEAR(uvz.x(), c.cx, 1e-9);
  EXPECT_NEAR(uvz.y(), c.cy, 1e-9);
  EXPECT_NEAR(uvz.z(), (target - eye).norm(), 1e-9);
  // A point above the target (along `up`) appears higher in the image (smaller v).
  EXPECT_LT(c.Project(target + 10.0 * up).y(), c.cy);
  EXPECT_NO_THROW(c.Check());
  EXPECT_THROW(c.LookAt(eye, eye, up), Error);
  EXPECT_THROW(c.LookAt(eye, target, target - eye), Error);
}

TEST(PinholeCamera, FieldOfViewAndScaling) {
  const PinholeCamera c = PinholeCamera::FromFieldOfView(640, 480, 90.0);
  EXPECT_NEAR(c.fx, 320.0, 1e-9);  // tan(45 deg) = 1
  // Image edge (pixel -0.5 / 639.5 at the border) is at 45 degrees.
  EXPECT_NEAR(c.Project(Eigen::Vector3d(1.0, 0, 1.0)).x(), 639.5, 1e-9);
  const PinholeCamera half = c.Scaled(0.5);
  EXPECT_EQ(half.width, 320);
  EXPECT_EQ(half.height, 240);
  // The same 3D point lands on the corresponding pixel of the half-size image.
  const Eigen::Vector3d p(12, -8, 90);
  const Eigen::Vector2d full = c.Project(p), small = half.Project(p);
  EXPECT_NEAR(small.x(), (full.x() + 0.5) * 0.5 - 0.5, 1e-9);
  EXPECT_NEAR(small.y(), (full.y() + 0.5) * 0.5 - 0.5, 1e-9);
}

TEST(PinholeCamera, IsInImageUsesPixelCentreConvention) {
  const PinholeCamera c = DistortedCamera();
  EXPECT_TRUE(c.IsInImage(Eigen::Vector2d(-0.5, -0.5)));
  EXPECT_TRUE(c.IsInImage(Eigen::Vector2d(639.5, 479.5)));
  EXPECT_FALSE(c.IsInImage(Eigen::Vector2d(639.6, 10)));
  EXPECT_FALSE(c.IsInImage(Eigen::Vector2d(10, -0.6)));
  EXPECT_FALSE(c.IsInImage(Eigen::Vector2d(5, 5), 10.0));
  EXPECT_TRUE(c.IsInImage(Eigen::Vector2d(320, 240), 10.0));
}

TEST(PinholeCamera, CheckNamesTheInvalidField) {
  PinholeCamera c = DistortedCamera();
  c.fx = 0.0;
  ExpectErrorMentions([&] { c.Check("cam.json", "scene.camera"); },
                      {"cam.json", "scene.camera.fx"});
  c = DistortedCamera();
  c.height = 0;
  ExpectErrorMentions([&] { c.Check(); }, {"camera.height"});
  c = DistortedCamera();
  c.camera_from_world.linear() = Eigen::Matrix3d::Identity() * 2.0;
  ExpectErrorMentions([&] { c.Check(); }, {"camera.camera_from_world.rotation"});
  c = DistortedCamera();
  c.undistort_options.tolerance = 0.0;
  ExpectErrorMentions([&] { c.Check(); }, {"tolerance"});
}

TEST(Distortion, FromVectorAcceptsOpenCvLengths) {
  EXPECT_EQ(Distortion::FromVector({0.1, 0.2, 0.3, 0.4}).k3, 0.0);
  const Distortion d8 = Distortion::FromVector({1, 2, 3, 4, 5, 6, 7, 8});
  EXPECT_EQ(d8.k1, 1);
  EXPECT_EQ(d8.p1, 3);
  EXPECT_EQ(d8.k3, 5);
  EXPECT_EQ(d8.k6, 8);
  EXPECT_EQ(d8.ToVector().size(), 8u);
  EXPECT_EQ(Distortion::FromVector({1, 2, 3, 4, 5}).ToVector().size(), 5u);
  EXPECT_NO_THROW(Distortion::FromVector({1, 2, 3, 4, 5, 6, 7, 8, 0, 0, 0, 0, 0, 0}));
  ExpectErrorMentions(
      [] {
        Distortion::FromVector({1, 2, 3}, "c.yaml", "D");
      },
      {"c.yaml", "D", "got 3"});
  ExpectErrorMentions(
      [] {
        Distortion::FromVector({1, 2, 3, 4, 5, 6, 7, 8, 0.1, 0, 0, 0});
      },
      {"thin-prism"});
}

// ----- calibration files -----

TEST(CameraFile, ReadsOpenCvFileStorageYaml) {
  const std::string dir = testing::ScratchDir("camera_opencv_yaml");
  const std::string path = dir + "/calib.yaml";
  WriteText(path, R"(%YAML:1.0
---
calibration_time: "Sat 21 Nov 2026 10:00:00 CET"
image_width: 640
image_height: 480
flags: 0
# intrinsics from cv::calibrateCamera
camera_matrix: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 5.3591573396163199e+02, 0., 3.4228315473308373e+02, 0.,
       5.3591573396163199e+02, 2.3557082909788173e+02, 0., 0., 1. ]
distortion_coefficients: !!opencv-matrix
   rows: 5
   cols: 1
   dt: d
   data: [ -2.6637260909660682e-01, -3.8588898922304653e-02,
       1.7831947042852964e-03, -2.8122100441115472e-04,
       2.3839153080878486e-01 ]
avg_reprojection_error: 3.9245445977189417e-01
)");
  const PinholeCamera c = ReadCameraFile(path);
  EXPECT_EQ(c.width, 640);
  EXPECT_EQ(c.height, 480);
  EXPECT_DOUBLE_EQ(c.fx, 5.3591573396163199e+02);
  EXPECT_DOUBLE_EQ(c.fy, 5.3591573396163199e+02);
  EXPECT_DOUBLE_EQ(c.cx, 3.4228315473308373e+02);
  EXPECT_DOUBLE_EQ(c.cy, 2.3557082909788173e+02);
  EXPECT_DOUBLE_EQ(c.distortion.k1, -2.6637260909660682e-01);
  EXPECT_DOUBLE_EQ(c.distortion.p2, -2.8122100441115472e-04);
  EXPECT_DOUBLE_EQ(c.distortion.k3, 2.3839153080878486e-01);
  EXPECT_TRUE(c.camera_from_world.isApprox(Eigen::Isometry3d::Identity()));
}

TEST(CameraFile, ReadsRosStyleYaml) {
  const std::string dir = testing::ScratchDir("camera_ros_yaml");
  const std::string path = dir + "/ros.yml";
  WriteText(path, R"(image_width: 1280
image_height: 720
camera_name: laparoscope_left
camera_matrix:
  rows: 3
  cols: 3
  data: [1000.5, 0, 640.25, 0, 1001.5, 360.75, 0, 0, 1]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [-0.1, 0.01, 0.001, -0.002, 0]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
)");
  const PinholeCamera c = ReadCameraFile(path);
  EXPECT_EQ(c.width, 1280);
  EXPECT_DOUBLE_EQ(c.fy, 1001.5);
  EXPECT_DOUBLE_EQ(c.cy, 360.75);
  EXPECT_DOUBLE_EQ(c.distortion.p1, 0.001);

  // Short names K / D / width / height, flat K, block-sequence D.
  const std::string short_path = dir + "/short.yaml";
  WriteText(short_path, R"(width: 320
height: 240
K: [300, 0, 160,
    0, 301, 120,
    0, 0, 1]
D:
  - 0.05
  - -0.01
  - 0
  - 0
)");
  const PinholeCamera s = ReadCameraFile(short_path);
  EXPECT_EQ(s.height, 240);
  EXPECT_DOUBLE_EQ(s.fy, 301);
  EXPECT_DOUBLE_EQ(s.distortion.k2, -0.01);
}

TEST(CameraFile, YamlErrorsNameFileLineAndKey) {
  const std::string dir = testing::ScratchDir("camera_yaml_errors");
  const std::string path = dir + "/bad.yaml";
  // Wrong element count in data (line 6 holds the data).
  WriteText(path,
            "%YAML:1.0\nimage_width: 640\nimage_height: 480\ncamera_matrix: !!opencv-matrix\n"
            "   rows: 3\n   cols: 3\n   dt: d\n   data: [ 1, 0, 2, 0, 1 ]\n");
  ExpectErrorMentions([&] { ReadCameraFile(path); },
                      {"bad.yaml", "line 8", "camera_matrix.data", "9"});
  // Missing key.
  WriteText(path, "image_width: 640\ncamera_matrix: [1, 0, 2, 0, 1, 3, 0, 0, 1]\n");
  ExpectErrorMentions([&] { ReadCameraFile(path); }, {"bad.yaml", "image_height"});
  // Not a number.
  WriteText(path,
            "image_width: 640\nimage_height: abc\ncamera_matrix: [1, 0, 2, 0, 1, 3, 0, 0, 1]\n");
  ExpectErrorMentions([&] { ReadCameraFile(path); }, {"bad.yaml", "line 2", "image_height", "abc"});
  // Unterminated flow sequence.
  WriteText(path, "image_width: 640\nimage_height: 480\ncamera_matrix: [1, 0, 2,\n  0, 1, 3\n");
  ExpectErrorMentions([&] { ReadCameraFile(path); }, {"bad.yaml", "line 3", "unterminated"});
  // Bad indentation.
  WriteText(path, "image_width: 640\n   image_height: 480\n");
  ExpectErrorMentions([&] { ReadCameraFile(path); }, {"bad.yaml", "line 2"});
  // Fisheye model rejected.
  WriteText(path,
            "image_width: 640\nimage_height: 480\ncamera_matrix: [1, 0, 2, 0, 1, 3, 0, 0, 1]\n"
            "distortion_model: equidistant\nD: [0.1, 0.2, 0.3, 0.4]\n");
  ExpectErrorMentions([&] { ReadCameraFile(path); }, {"bad.yaml", "line 4", "equidistant"});
  // Invalid intrinsics.
  WriteText(path,
            "image_width: 640\nimage_height: 480\ncamera_matrix: [-1, 0, 2, 0, 1, 3, 0, 0, 1]\n");
  ExpectErrorMentions([&] { ReadCameraFile(path); }, {"bad.yaml", "fx"});
  // Skew.
  WriteText(
      path,
      "image_width: 640\nimage_height: 480\ncamera_matrix: [100, 2, 2, 0, 100, 3, 0, 0, 1]\n");
  ExpectErrorMentions([&] { ReadCameraFile(path); }, {"bad.yaml", "skew"});
  // Missing file.
  ExpectErrorMentions([&] { ReadCameraFile(dir + "/none.yaml"); }, {"none.yaml"});
}

TEST(CameraFile, JsonRoundTripKeepsEveryParameter) {
  const std::string dir = testing::ScratchDir("camera_json");
  PinholeCamera c = DistortedCamera();
  c.distortion.k3 = 0.01;
  c.distortion.k4 = 0.02;
  c.camera_from_world = SomePose();
  WriteCameraJson(dir + "/camera.json", c);
  const PinholeCamera r = ReadCameraFile(dir + "/camera.json");
  EXPECT_EQ(r.width, c.width);
  EXPECT_EQ(r.height, c.height);
  EXPECT_DOUBLE_EQ(r.fx, c.fx);
  EXPECT_DOUBLE_EQ(r.cy, c.cy);
  EXPECT_EQ(r.distortion.ToVector(), c.distortion.ToVector());
  EXPECT_LT((r.camera_from_world.matrix() - c.camera_from_world.matrix()).cwiseAbs().maxCoeff(),
            1e-12);
  const Eigen::Vector3d p(3, 4, 5);
  EXPECT_LT((r.Project(p) - c.Project(p)).norm(), 1e-9);
}

TEST(CameraFile, JsonQuaternionAndUnits) {
  const std::string dir = testing::ScratchDir("camera_json_quat");
  const std::string path = dir + "/cam.json";
  // 90 degrees about z: q = (cos 45, 0, 0, sin 45).
  WriteText(path, R"({"width": 100, "height": 80, "fx": 90, "fy": 90, "cx": 49.5, "cy": 39.5,
    "camera_from_world": {"rotation": [0.7071067811865476, 0, 0, 0.7071067811865476],
                          "translation_m": [0.01, 0, 0.2]}})");
  const PinholeCamera c = ReadCameraFile(path);
  EXPECT_TRUE(c.distortion.IsZero());
  const Eigen::Vector3d x_in_camera = c.camera_from_world.linear() * Eigen::Vector3d::UnitX();
  EXPECT_LT((x_in_camera - Eigen::Vector3d::UnitY()).norm(), 1e-12);
  EXPECT_LT((c.camera_from_world.translation() - Eigen::Vector3d(10, 0, 200)).norm(), 1e-12);
}

TEST(CameraFile, JsonErrorsNameFileAndKey) {
  const std::string dir = testing::ScratchDir("camera_json_errors");
  const std::string path = dir + "/cam.json";
  WriteText(path, R"({"width": 100, "height": 80, "fxx": 90, "fy": 90, "cx": 49.5, "cy": 39.5})");
  ExpectErrorMentions([&] { ReadCameraFile(path); }, {"cam.json", "fx", "required key is missing"});
  WriteText(
      path,
      R"({"width": 100, "height": 80, "fx": 90, "fy": 90, "cx": 49.5, "cy": 39.5, "k1": 0.1})");
  ExpectErrorMentions([&] { ReadCameraFile(path); },
                      {"cam.json", "k1", "unknown key", "distortion"});
  WriteText(path, R"({"width": "100", "height": 80, "fx": 90, "fy": 90, "cx": 49.5, "cy": 39.5})");
  ExpectErrorMentions([&] { ReadCameraFile(path); }, {"cam.json", "width", "integer"});
  WriteText(path, "{\"width\": 100,\n \"height\": 80,\n \"fx\": 90 \"fy\": 90}");
  ExpectErrorMentions([&] { ReadCameraFile(path); }, {"cam.json", "line 3", "syntax"});
  WriteText(path, R"({"width": 100, "height": 80, "fx": 90, "fy": 90, "cx": 49.5, "cy": 39.5,
    "camera_from_world": {"rotation": [1, 0, 0, 0, 1, 0, 0, 0, -1]}})");
  ExpectErrorMentions([&] { ReadCameraFile(path); },
                      {"cam.json", "camera_from_world.rotation", "determinant"});
  WriteText(path, R"({"width": 100, "height": 80, "fx": 90, "fy": -1, "cx": 49.5, "cy": 39.5})");
  ExpectErrorMentions([&] { ReadCameraFile(path); }, {"cam.json", "fy", "positive"});
}

}  // namespace
}  // namespace arreg
