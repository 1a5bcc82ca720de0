// Pinhole camera with OpenCV's lens distortion model (radial k1..k6, tangential
// p1 p2): projection, unprojection at a depth, rays, and calibration file I/O.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace arreg {

class JsonObjectReader;

// A half-line in world coordinates: origin + t * direction, t >= 0.
struct Ray {
  Eigen::Vector3d origin_in_world = Eigen::Vector3d::Zero();
  Eigen::Vector3d direction_in_world = Eigen::Vector3d::UnitZ();  // unit length
  Eigen::Vector3d PointAt(double t) const { return origin_in_world + t * direction_in_world; }
};

// OpenCV's "rational" distortion model acting on normalized coordinates
// (x, y) = (X/Z, Y/Z), r^2 = x^2 + y^2:
//   radial = (1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 + k5 r^4 + k6 r^6)
//   x_d = x radial + 2 p1 x y + p2 (r^2 + 2 x^2)
//   y_d = y radial + p1 (r^2 + 2 y^2) + 2 p2 x y
// All zero means no distortion. Coefficient vectors follow OpenCV's order
// (k1, k2, p1, p2[, k3[, k4, k5, k6]]).
struct Distortion {
  double k1 = 0.0, k2 = 0.0, p1 = 0.0, p2 = 0.0, k3 = 0.0;  // dimensionless
  double k4 = 0.0, k5 = 0.0, k6 = 0.0;                      // rational denominator

  bool IsZero() const;
  // Accepts 4, 5, 8 coefficients, or OpenCV's 12/14 when the thin-prism and tilt
  // terms beyond the 8th are zero. Throws arreg::Error(file, where) otherwise.
  static Distortion FromVector(const std::vector<double>& coefficients,
                               const std::string& file = "", const std::string& where = "");
  // 5 coefficients when k4..k6 are zero (what most tools write), else 8.
  std::vector<double> ToVector() const;
};

// Undistortion runs OpenCV's fixed-point iteration (cv::undistortPoints) and, if
// that has not met the tolerance, Newton steps with the analytic Jacobian.
struct UndistortOptions {
  int max_fixed_point_iterations = 20;  // count; OpenCV's default is 5
  int max_newton_iterations = 10;       // count
  // Stop when |Distort(x) - x_d| (normalized units) falls below this. 1e-12
  // normalized units is about 1e-9 px for focal lengths up to 1000 px.
  double tolerance = 1e-12;
  void Check() const;
};

struct UndistortSummary {
  bool converged = false;
  int iterations = 0;     // fixed-point + Newton iterations done
  double residual = 0.0;  // final |Distort(x) - x_d|, normalized units
};

// Camera frame convention (OpenCV): x to the right in the image, y down, z
// forward along the optical axis; points in front of the camera have z > 0.
// Pixel convention (OpenCV): the centre of the top-left pixel is (0, 0), so the
// image covers [-0.5, width - 0.5] x [-0.5, height - 0.5].
// Lengths (translations, depths) are in millimetres, arreg's internal unit.
class PinholeCamera {
 public:
  int width = 0;              // image width, px
  int height = 0;             // image height, px
  double fx = 0.0, fy = 0.0;  // focal lengths, px
  double cx = 0.0, cy = 0.0;  // principal point, px
  Distortion distortion;
  // Rigid transform taking world points to camera coordinates:
  // point_in_camera = camera_from_world * point_in_world.
  Eigen::Isometry3d camera_from_world = Eigen::Isometry3d::Identity();
  UndistortOptions undistort_options;

  // Throws arreg::Error(file, "<prefix>.<field>") naming the first invalid field
  // (width/height >= 1, fx/fy > 0 and finite, finite cx/cy/distortion, rotation
  // orthonormal with determinant +1).
  void Check(const std::string& file = "", const std::string& prefix = "camera") const;

  // Intrinsic matrix [fx 0 cx; 0 fy cy; 0 0 1] (3 x 3).
  Eigen::Matrix3d K() const;
  Eigen::Isometry3d world_from_camera() const { return camera_from_world.inverse(); }
  // Optical centre in world coordinates.
  Eigen::Vector3d CenterInWorld() const;

  // Distorted pixel of a world point. The result is meaningless for points with
  // camera z <= 0; use ProjectWithDepth when that can happen.
  Eigen::Vector2d Project(const Eigen::Vector3d& point_in_world) const;
  // (u, v, z_camera): the pixel and the depth along the optical axis.
  Eigen::Vector3d ProjectWithDepth(const Eigen::Vector3d& point_in_world) const;
  // Distorted pixel of a point given in camera coordinates.
  Eigen::Vector2d ProjectFromCamera(const Eigen::Vector3d& point_in_camera) const;

  // World point seen at `pixel` whose camera z equals `depth` (scene units).
  Eigen::Vector3d Unproject(const Eigen::Vector2d& pixel, double depth,
                            UndistortSummary* summary = nullptr) const;
  // Ray from the optical centre through `pixel` (distortion removed), world frame.
  Ray RayThroughPixel(const Eigen::Vector2d& pixel, UndistortSummary* summary = nullptr) const;

  // True when the pixel lies inside the image shrunk by `margin_px` on each side.
  bool IsInImage(const Eigen::Vector2d& pixel, double margin_px = 0.0) const;

  // Normalized <-> distorted normalized coordinates (see Distortion).
  Eigen::Vector2d Distort(const Eigen::Vector2d& normalized) const;
  // d Distort / d normalized (2 x 2).
  Eigen::Matrix2d DistortJacobian(const Eigen::Vector2d& normalized) const;
  Eigen::Vector2d Undistort(const Eigen::Vector2d& distorted_normalized,
                            UndistortSummary* summary = nullptr) const;
  // Pixel <-> undistorted normalized coordinates.
  Eigen::Vector2d PixelToNormalized(const Eigen::Vector2d& pixel,
                                    UndistortSummary* summary = nullptr) const;
  Eigen::Vector2d NormalizedToPixel(const Eigen::Vector2d& normalized) const;

  // The same camera for an image resized by `factor` (e.g. 0.5 halves the
  // resolution): focal lengths and principal point follow OpenCV's pixel-centre
  // convention, cx' = (cx + 0.5) * factor - 0.5.
  PinholeCamera Scaled(double factor) const;

  // A distortion-free camera with horizontal field of view `fov_x_deg`, square
  // pixels and the principal point at the image centre (synthetic scenes).
  static PinholeCamera FromFieldOfView(int width, int height, double fov_x_deg);
  // Places the camera at `eye_in_world` looking at `target_in_world`, with the
  // image's "up" (-y) as close as possible to `up_in_world`. Throws arreg::Error
  // when eye == target or `up` is parallel to the viewing direction.
  void LookAt(const Eigen::Vector3d& eye_in_world, const Eigen::Vector3d& target_in_world,
              const Eigen::Vector3d& up_in_world);
};

// camera_from_world for a camera at `eye` looking at `target` (see PinholeCamera::LookAt).
Eigen::Isometry3d CameraFromWorldLookAt(const Eigen::Vector3d& eye_in_world,
                                        const Eigen::Vector3d& target_in_world,
                                        const Eigen::Vector3d& up_in_world);

// Reads a calibration file: OpenCV FileStorage YAML (camera_matrix,
// distortion_coefficients, image_width, image_height; ROS-style K, D, width,
// height) or JSON (see docs/scene-format.md). The format is chosen by content
// (a leading '{' means JSON). Errors name the file and the line or key.
PinholeCamera ReadCameraFile(const std::string& path);
// Parses the JSON camera object (inline in a scene or a whole camera file).
// Finishes the reader (unknown keys are errors) and checks the camera.
PinholeCamera ReadCameraJson(JsonObjectReader& reader);
// Parses an OpenCV YAML calibration held in memory; `file` is used in messages.
PinholeCamera ReadCameraOpenCvYaml(const std::string& text, const std::string& file);

// JSON object that ReadCameraJson reads back exactly.
nlohmann::json CameraToJson(const PinholeCamera& camera);
// Writes CameraToJson atomically.
void WriteCameraJson(const std::string& path, const PinholeCamera& camera);

// Rigid transform from JSON: {"rotation": 3x3 (nested or 9 row-major) or
// [w, x, y, z] quaternion, "translation_mm": [x, y, z] (or "translation_m" in
// metres, converted)}, both optional (identity). Finishes the reader.
Eigen::Isometry3d ReadRigidTransformJson(JsonObjectReader& reader);
nlohmann::json RigidTransformToJson(const Eigen::Isometry3d& transform);

}  // namespace arreg
