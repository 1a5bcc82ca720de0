#include "core/camera.h"

#include <Eigen/LU>
#include <Eigen/SVD>
#include <cmath>
#include <sstream>

#include "core/error.h"
#include "core/file_util.h"
#include "core/json_reader.h"
#include "core/opencv_yaml.h"

namespace arreg {
namespace {

std::string Field(const std::string& prefix, const std::string& name) {
  return prefix.empty() ? name : prefix + "." + name;
}

std::string Num(double v) {
  std::ostringstream os;
  os.precision(12);
  os << v;
  return os.str();
}

// Rotation matrices read from files carry rounding; accept them within this
// tolerance of orthonormality and snap them onto SO(3).
constexpr double kRotationTolerance = 1e-4;

// Nearest rotation (SVD projection); throws when `r` is not close to one.
Eigen::Matrix3d CheckedRotation(const Eigen::Matrix3d& r, const std::string& file,
                                const std::string& where) {
  if (!r.allFinite()) throw Error(file, where, "rotation has non-finite entries");
  const double error = (r.transpose() * r - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (error > kRotationTolerance)
    throw Error(file, where,
                "rotation is not orthonormal (max |R^T R - I| = " + Num(error) + ", tolerance " +
                    Num(kRotationTolerance) + ")");
  if (r.determinant() < 0.0)
    throw Error(file, where, "rotation has determinant -1 (a reflection, not a rotation)");
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(r, Eigen::ComputeFullU | Eigen::ComputeFullV);
  return svd.matrixU() * svd.matrixV().transpose();
}

}  // namespace

bool Distortion::IsZero() const {
  return k1 == 0.0 && k2 == 0.0 && p1 == 0.0 && p2 == 0.0 && k3 == 0.0 && k4 == 0.0 && k5 == 0.0 &&
         k6 == 0.0;
}

Distortion Distortion::FromVector(const std::vector<double>& c, const std::string& file,
                                  const std::string& where) {
  const std::size_t n = c.size();
  if (n != 0 && n != 4 && n != 5 && n != 8 && n != 12 && n != 14)
    throw Error(file, where,
                "expected 4, 5, 8, 12 or 14 distortion coefficients (OpenCV order k1 k2 p1 p2 k3 "
                "k4 k5 k6 ...), got " +
                    std::to_string(n));
  for (std::size_t i = 8; i < n; ++i) {
    if (c[i] != 0.0)
      throw Error(file, where,
                  "coefficient " + std::to_string(i + 1) +
                      " is non-zero: OpenCV's thin-prism (s1..s4) and tilt (tauX, tauY) terms "
                      "are not supported");
  }
  for (std::size_t i = 0; i < n; ++i)
    if (!std::isfinite(c[i])) throw Error(file, where, "distortion coefficients must be finite");
  Distortion d;
  double* fields[8] = {&d.k1, &d.k2, &d.p1, &d.p2, &d.k3, &d.k4, &d.k5, &d.k6};
  for (std::size_t i = 0; i < std::min<std::size_t>(n, 8); ++i) *fields[i] = c[i];
  return d;
}

std::vector<double> Distortion::ToVector() const {
  if (k4 == 0.0 && k5 == 0.0 && k6 == 0.0) return {k1, k2, p1, p2, k3};
  return {k1, k2, p1, p2, k3, k4, k5, k6};
}

void UndistortOptions::Check() const {
  ARREG_CHECK_INPUT(max_fixed_point_iterations >= 0, "", "undistort.max_fixed_point_iterations",
                    "must be >= 0, got ", max_fixed_point_iterations);
  ARREG_CHECK_INPUT(max_newton_iterations >= 0, "", "undistort.max_newton_iterations",
                    "must be >= 0, got ", max_newton_iterations);
  ARREG_CHECK_INPUT(max_fixed_point_iterations + max_newton_iterations > 0, "",
                    "undistort.max_newton_iterations", "at least one iteration is needed");
  ARREG_CHECK_INPUT(tolerance > 0.0 && std::isfinite(tolerance), "", "undistort.tolerance",
                    "must be positive, got ", tolerance);
}

void PinholeCamera::Check(const std::string& file, const std::string& prefix) const {
  ARREG_CHECK_INPUT(width >= 1, file, Field(prefix, "width"), "must be >= 1 px, got ", width);
  ARREG_CHECK_INPUT(height >= 1, file, Field(prefix, "height"), "must be >= 1 px, got ", height);
  ARREG_CHECK_INPUT(fx > 0.0 && std::isfinite(fx), file, Field(prefix, "fx"),
                    "focal length must be positive, got ", Num(fx));
  ARREG_CHECK_INPUT(fy > 0.0 && std::isfinite(fy), file, Field(prefix, "fy"),
                    "focal length must be positive, got ", Num(fy));
  ARREG_CHECK_INPUT(std::isfinite(cx), file, Field(prefix, "cx"), "must be finite");
  ARREG_CHECK_INPUT(std::isfinite(cy), file, Field(prefix, "cy"), "must be finite");
  for (double c : distortion.ToVector())
    ARREG_CHECK_INPUT(std::isfinite(c), file, Field(prefix, "distortion"), "must be finite");
  const Eigen::Matrix3d r = camera_from_world.linear();
  const double error = (r.transpose() * r - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  ARREG_CHECK_INPUT(error < 1e-6 && r.determinant() > 0.0, file,
                    Field(prefix, "camera_from_world.rotation"),
                    "must be a rotation (orthonormal, determinant +1)");
  ARREG_CHECK_INPUT(camera_from_world.translation().allFinite(), file,
                    Field(prefix, "camera_from_world.translation_mm"), "must be finite");
  undistort_options.Check();
}

Eigen::Matrix3d PinholeCamera::K() const {
  Eigen::Matrix3d k;
  k << fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0;
  return k;
}

Eigen::Vector3d PinholeCamera::CenterInWorld() const {
  // c = -R^T t for camera_from_world = [R | t].
  return -(camera_from_world.linear().transpose() * camera_from_world.translation());
}

Eigen::Vector2d PinholeCamera::Distort(const Eigen::Vector2d& n) const {
  const Distortion& d = distortion;
  const double x = n.x(), y = n.y();
  const double r2 = x * x + y * y;
  const double num = 1.0 + r2 * (d.k1 + r2 * (d.k2 + r2 * d.k3));
  const double den = 1.0 + r2 * (d.k4 + r2 * (d.k5 + r2 * d.k6));
  const double radial = num / den;
  return {x * radial + 2.0 * d.p1 * x * y + d.p2 * (r2 + 2.0 * x * x),
          y * radial + d.p1 * (r2 + 2.0 * y * y) + 2.0 * d.p2 * x * y};
}

Eigen::Matrix2d PinholeCamera::DistortJacobian(const Eigen::Vector2d& n) const {
  const Distortion& d = distortion;
  const double x = n.x(), y = n.y();
  const double r2 = x * x + y * y;
  const double num = 1.0 + r2 * (d.k1 + r2 * (d.k2 + r2 * d.k3));
  const double den = 1.0 + r2 * (d.k4 + r2 * (d.k5 + r2 * d.k6));
  const double dnum_dr2 = d.k1 + r2 * (2.0 * d.k2 + 3.0 * r2 * d.k3);
  const double dden_dr2 = d.k4 + r2 * (2.0 * d.k5 + 3.0 * r2 * d.k6);
  const double radial = num / den;
  const double dradial_dr2 = (dnum_dr2 * den - num * dden_dr2) / (den * den);
  const double dr_dx = dradial_dr2 * 2.0 * x;
  const double dr_dy = dradial_dr2 * 2.0 * y;
  Eigen::Matrix2d j;
  j(0, 0) = radial + x * dr_dx + 2.0 * d.p1 * y + 6.0 * d.p2 * x;
  j(0, 1) = x * dr_dy + 2.0 * d.p1 * x + 2.0 * d.p2 * y;
  j(1, 0) = y * dr_dx + 2.0 * d.p1 * x + 2.0 * d.p2 * y;
  j(1, 1) = radial + y * dr_dy + 6.0 * d.p1 * y + 2.0 * d.p2 * x;
  return j;
}

Eigen::Vector2d PinholeCamera::Undistort(const Eigen::Vector2d& distorted,
                                         UndistortSummary* summary) const {
  UndistortSummary local;
  UndistortSummary& s = summary ? *summary : local;
  s = UndistortSummary();
  if (distortion.IsZero()) {
    s.converged = true;
    return distorted;
  }
  const UndistortOptions& o = undistort_options;
  const Distortion& d = distortion;
  Eigen::Vector2d x = distorted;
  double residual = (Distort(x) - distorted).norm();
  Eigen::Vector2d best = x;
  double best_residual = residual;
  // OpenCV's fixed point: x = (x_d - tangential(x)) / radial(x).
  for (int it = 0; it < o.max_fixed_point_iterations && residual > o.tolerance; ++it) {
    const double r2 = x.squaredNorm();
    const double inverse_radial = (1.0 + r2 * (d.k4 + r2 * (d.k5 + r2 * d.k6))) /
                                  (1.0 + r2 * (d.k1 + r2 * (d.k2 + r2 * d.k3)));
    if (!(inverse_radial > 0.0) || !std::isfinite(inverse_radial)) break;  // left the valid domain
    const double dx = 2.0 * d.p1 * x.x() * x.y() + d.p2 * (r2 + 2.0 * x.x() * x.x());
    const double dy = d.p1 * (r2 + 2.0 * x.y() * x.y()) + 2.0 * d.p2 * x.x() * x.y();
    x = Eigen::Vector2d((distorted.x() - dx) * inverse_radial,
                        (distorted.y() - dy) * inverse_radial);
    residual = (Distort(x) - distorted).norm();
    ++s.iterations;
    if (!std::isfinite(residual)) break;
    if (residual < best_residual) {
      best = x;
      best_residual = residual;
    }
  }
  // Newton polishing: quadratic convergence where the fixed point is slow
  // (strong distortion near the image corners).
  x = best;
  residual = best_residual;
  for (int it = 0; it < o.max_newton_iterations && residual > o.tolerance; ++it) {
    const Eigen::Matrix2d j = DistortJacobian(x);
    const double det = j.determinant();
    if (!(std::fabs(det) > 1e-12)) break;
    x -= j.inverse() * (Distort(x) - distorted);
    residual = (Distort(x) - distorted).norm();
    ++s.iterations;
    if (!std::isfinite(residual)) break;
    if (residual < best_residual) {
      best = x;
      best_residual = residual;
    }
  }
  s.residual = best_residual;
  s.converged = best_residual <= o.tolerance;
  return best;
}

Eigen::Vector2d PinholeCamera::PixelToNormalized(const Eigen::Vector2d& pixel,
                                                 UndistortSummary* summary) const {
  return Undistort(Eigen::Vector2d((pixel.x() - cx) / fx, (pixel.y() - cy) / fy), summary);
}

Eigen::Vector2d PinholeCamera::NormalizedToPixel(const Eigen::Vector2d& normalized) const {
  const Eigen::Vector2d d = Distort(normalized);
  return {fx * d.x() + cx, fy * d.y() + cy};
}

Eigen::Vector2d PinholeCamera::ProjectFromCamera(const Eigen::Vector3d& p) const {
  return NormalizedToPixel(Eigen::Vector2d(p.x() / p.z(), p.y() / p.z()));
}

Eigen::Vector2d PinholeCamera::Project(const Eigen::Vector3d& point_in_world) const {
  return ProjectFromCamera(camera_from_world * point_in_world);
}

Eigen::Vector3d PinholeCamera::ProjectWithDepth(const Eigen::Vector3d& point_in_world) const {
  const Eigen::Vector3d p = camera_from_world * point_in_world;
  const Eigen::Vector2d uv = ProjectFromCamera(p);
  return {uv.x(), uv.y(), p.z()};
}

Eigen::Vector3d PinholeCamera::Unproject(const Eigen::Vector2d& pixel, double depth,
                                         UndistortSummary* summary) const {
  const Eigen::Vector2d n = PixelToNormalized(pixel, summary);
  return camera_from_world.inverse() * Eigen::Vector3d(n.x() * depth, n.y() * depth, depth);
}

Ray PinholeCamera::RayThroughPixel(const Eigen::Vector2d& pixel, UndistortSummary* summary) const {
  const Eigen::Vector2d n = PixelToNormalized(pixel, summary);
  Ray ray;
  ray.origin_in_world = CenterInWorld();
  ray.direction_in_world =
      (camera_from_world.linear().transpose() * Eigen::Vector3d(n.x(), n.y(), 1.0)).normalized();
  return ray;
}

bool PinholeCamera::IsInImage(const Eigen::Vector2d& pixel, double margin_px) const {
  return pixel.x() >= -0.5 + margin_px && pixel.x() <= width - 0.5 - margin_px &&
         pixel.y() >= -0.5 + margin_px && pixel.y() <= height - 0.5 - margin_px;
}

PinholeCamera PinholeCamera::Scaled(double factor) const {
  ARREG_CHECK_INPUT(factor > 0.0 && std::isfinite(factor), "", "scale factor",
                    "must be positive, got ", factor);
  PinholeCamera c = *this;
  c.width = std::max(1, static_cast<int>(std::lround(width * factor)));
  c.height = std::max(1, static_cast<int>(std::lround(height * factor)));
  c.fx = fx * factor;
  c.fy = fy * factor;
  c.cx = (cx + 0.5) * factor - 0.5;
  c.cy = (cy + 0.5) * factor - 0.5;
  return c;
}

PinholeCamera PinholeCamera::FromFieldOfView(int width, int height, double fov_x_deg) {
  ARREG_CHECK_INPUT(fov_x_deg > 0.0 && fov_x_deg < 180.0, "", "fov_x_deg",
                    "must be in (0, 180) degrees, got ", fov_x_deg);
  PinholeCamera c;
  c.width = width;
  c.height = height;
  c.fx = c.fy = 0.5 * width / std::tan(0.5 * fov_x_deg * M_PI / 180.0);
  c.cx = 0.5 * (width - 1);
  c.cy = 0.5 * (height - 1);
  c.Check("", "camera");
  return c;
}

Eigen::Isometry3d CameraFromWorldLookAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
                                        const Eigen::Vector3d& up) {
  const Eigen::Vector3d forward = target - eye;
  ARREG_CHECK_INPUT(forward.norm() > 0.0, "", "look_at", "eye and target coincide");
  const Eigen::Vector3d z = forward.normalized();
  // Image y points down, so x = z x up gives a right-handed frame with -y near `up`.
  const Eigen::Vector3d x_raw = z.cross(up);
  ARREG_CHECK_INPUT(up.norm() > 0.0 && x_raw.norm() > 1e-9 * up.norm(), "", "look_at.up",
                    "up vector is zero or parallel to the viewing direction");
  const Eigen::Vector3d x = x_raw.normalized();
  const Eigen::Vector3d y = z.cross(x);
  Eigen::Matrix3d world_from_camera_rotation;
  world_from_camera_rotation.col(0) = x;
  world_from_camera_rotation.col(1) = y;
  world_from_camera_rotation.col(2) = z;
  Eigen::Isometry3d camera_from_world = Eigen::Isometry3d::Identity();
  camera_from_world.linear() = world_from_camera_rotation.transpose();
  camera_from_world.translation() = -(world_from_camera_rotation.transpose() * eye);
  return camera_from_world;
}

void PinholeCamera::LookAt(const Eigen::Vector3d& eye_in_world,
                           const Eigen::Vector3d& target_in_world,
                           const Eigen::Vector3d& up_in_world) {
  camera_from_world = CameraFromWorldLookAt(eye_in_world, target_in_world, up_in_world);
}

// ---------------------------------------------------------------------------
// JSON

Eigen::Isometry3d ReadRigidTransformJson(JsonObjectReader& reader) {
  Eigen::Isometry3d transform = Eigen::Isometry3d::Identity();
  nlohmann::json rotation;
  if (reader.Optional("rotation", &rotation)) {
    const std::string where = reader.KeyPath("rotation");
    if (rotation.is_array() && rotation.size() == 4 && !rotation[0].is_array()) {
      Eigen::Vector4d q;
      ReadJsonValue(rotation, reader.file(), where, &q);
      ARREG_CHECK_INPUT(q.norm() > 1e-12, reader.file(), where, "quaternion [w, x, y, z] is zero");
      ARREG_CHECK_INPUT(std::fabs(q.norm() - 1.0) < kRotationTolerance, reader.file(), where,
                        "quaternion [w, x, y, z] must have unit norm, got norm ", Num(q.norm()));
      transform.linear() =
          Eigen::Quaterniond(q(0), q(1), q(2), q(3)).normalized().toRotationMatrix();
    } else {
      Eigen::Matrix3d r;
      ReadJsonValue(rotation, reader.file(), where, &r);
      transform.linear() = CheckedRotation(r, reader.file(), where);
    }
  }
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
  const bool has_mm = reader.Optional("translation_mm", &translation);
  Eigen::Vector3d translation_m;
  if (reader.Optional("translation_m", &translation_m)) {
    if (has_mm)
      reader.Fail("translation_m", "give either translation_mm or translation_m, not both");
    translation = 1000.0 * translation_m;
  }
  transform.translation() = translation;
  reader.Finish();
  return transform;
}

nlohmann::json RigidTransformToJson(const Eigen::Isometry3d& transform) {
  nlohmann::json rotation = nlohmann::json::array();
  for (int r = 0; r < 3; ++r)
    rotation.push_back(
        {transform.linear()(r, 0), transform.linear()(r, 1), transform.linear()(r, 2)});
  const Eigen::Vector3d t = transform.translation();
  return {{"rotation", rotation}, {"translation_mm", {t.x(), t.y(), t.z()}}};
}

PinholeCamera ReadCameraJson(JsonObjectReader& reader) {
  PinholeCamera camera;
  reader.Required("width", &camera.width);
  reader.Required("height", &camera.height);
  reader.Required("fx", &camera.fx);
  reader.Required("fy", &camera.fy);
  reader.Required("cx", &camera.cx);
  reader.Required("cy", &camera.cy);
  std::vector<double> coefficients;
  if (reader.Optional("distortion", &coefficients))
    camera.distortion =
        Distortion::FromVector(coefficients, reader.file(), reader.KeyPath("distortion"));
  if (auto extrinsics = reader.OptionalObject("camera_from_world"))
    camera.camera_from_world = ReadRigidTransformJson(*extrinsics);
  reader.Finish();
  camera.Check(reader.file(), reader.path());
  return camera;
}

nlohmann::json CameraToJson(const PinholeCamera& camera) {
  nlohmann::json j;
  j["width"] = camera.width;
  j["height"] = camera.height;
  j["fx"] = camera.fx;
  j["fy"] = camera.fy;
  j["cx"] = camera.cx;
  j["cy"] = camera.cy;
  j["distortion"] = camera.distortion.ToVector();
  j["camera_from_world"] = RigidTransformToJson(camera.camera_from_world);
  return j;
}

void WriteCameraJson(const std::string& path, const PinholeCamera& camera) {
  camera.Check(path, "camera");
  const std::string text = CameraToJson(camera).dump(2) + "\n";
  WriteFileAtomic(path, [&](std::ostream& os) { os << text; });
}

// ---------------------------------------------------------------------------
// OpenCV / ROS YAML

namespace {

// The one present key among `names` (aliases); errors when several are.
const YamlNode* FindAlias(const YamlNode& root, const std::vector<std::string>& names,
                          const std::string& file, std::string* found_name) {
  const YamlNode* found = nullptr;
  for (const std::string& name : names) {
    const YamlNode* node = root.Find(name);
    if (node == nullptr) continue;
    if (found != nullptr)
      throw Error(file, "line " + std::to_string(node->line),
                  "both '" + *found_name + "' and '" + name + "' are given; keep one");
    found = node;
    *found_name = name;
  }
  return found;
}

std::string AliasList(const std::vector<std::string>& names) {
  std::string s;
  for (std::size_t i = 0; i < names.size(); ++i) s += (i ? "' or '" : "'") + names[i];
  return s + "'";
}

const YamlNode& RequireAlias(const YamlNode& root, const std::vector<std::string>& names,
                             const std::string& file, std::string* found_name) {
  const YamlNode* node = FindAlias(root, names, file, found_name);
  if (node == nullptr)
    throw Error(file, names[0], "required key is missing (" + AliasList(names) + ")");
  return *node;
}

}  // namespace

PinholeCamera ReadCameraOpenCvYaml(const std::string& text, const std::string& file) {
  const YamlNode root = ParseOpenCvYaml(text, file);
  if (root.kind != YamlNode::Kind::kMapping)
    throw Error(file, "line " + std::to_string(std::max(root.line, 1)),
                "expected a mapping of calibration keys (camera_matrix, distortion_coefficients, "
                "image_width, image_height)");
  PinholeCamera camera;
  std::string name;
  {
    const YamlNode& node = RequireAlias(root, {"image_width", "width"}, file, &name);
    camera.width = YamlToInt(node, file, name);
  }
  {
    const YamlNode& node = RequireAlias(root, {"image_height", "height"}, file, &name);
    camera.height = YamlToInt(node, file, name);
  }
  {
    const YamlNode& node = RequireAlias(root, {"camera_matrix", "K", "cameraMatrix"}, file, &name);
    Eigen::MatrixXd k = YamlToMatrix(node, file, name);
    if (k.size() == 9 && k.cols() == 1) {
      const Eigen::VectorXd flat = k.col(0);
      k.resize(3, 3);
      for (int i = 0; i < 9; ++i) k(i / 3, i % 3) = flat(i);
    }
    const std::string where = "line " + std::to_string(node.line);
    ARREG_CHECK_INPUT(k.rows() == 3 && k.cols() == 3, file, where, name,
                      ": expected a 3x3 camera matrix, got ", k.rows(), "x", k.cols());
    ARREG_CHECK_INPUT(k(1, 0) == 0.0 && k(2, 0) == 0.0 && k(2, 1) == 0.0 && k(2, 2) == 1.0, file,
                      where, name, ": expected the form [fx 0 cx; 0 fy cy; 0 0 1]");
    ARREG_CHECK_INPUT(std::fabs(k(0, 1)) <= 1e-9 * std::fabs(k(0, 0)), file, where, name,
                      ": skew (K[0][1] = ", Num(k(0, 1)), ") is not supported");
    camera.fx = k(0, 0);
    camera.fy = k(1, 1);
    camera.cx = k(0, 2);
    camera.cy = k(1, 2);
  }
  if (const YamlNode* model = root.Find("distortion_model")) {
    const std::string m = YamlToString(*model, file, "distortion_model");
    ARREG_CHECK_INPUT(m == "plumb_bob" || m == "rational_polynomial" || m == "radtan", file,
                      "line " + std::to_string(model->line), "distortion_model: '", m,
                      "' is not supported (OpenCV's pinhole model: plumb_bob, rational_polynomial, "
                      "radtan; fisheye/equidistant is a different model)");
  }
  if (const YamlNode* node = FindAlias(
          root, {"distortion_coefficients", "D", "dist_coeffs", "distCoeffs"}, file, &name)) {
    if (node->kind != YamlNode::Kind::kNull) {
      const Eigen::MatrixXd d = YamlToMatrix(*node, file, name);
      ARREG_CHECK_INPUT(d.rows() == 1 || d.cols() == 1 || d.size() == 0, file,
                        "line " + std::to_string(node->line), name,
                        ": expected a row or column of coefficients, got ", d.rows(), "x",
                        d.cols());
      std::vector<double> c(d.data(), d.data() + d.size());
      camera.distortion =
          Distortion::FromVector(c, file, "line " + std::to_string(node->line) + ", " + name);
    }
  }
  if (const YamlNode* node = root.Find("camera_from_world")) {
    const Eigen::MatrixXd t = YamlToMatrix(*node, file, "camera_from_world");
    const std::string where = "line " + std::to_string(node->line);
    ARREG_CHECK_INPUT(t.rows() == 4 && t.cols() == 4, file, where,
                      "camera_from_world: expected a 4x4 matrix (translation in mm), got ",
                      t.rows(), "x", t.cols());
    ARREG_CHECK_INPUT(t.row(3).isApprox(Eigen::RowVector4d(0, 0, 0, 1)), file, where,
                      "camera_from_world: last row must be [0 0 0 1]");
    camera.camera_from_world.linear() =
        CheckedRotation(t.topLeftCorner<3, 3>(), file, where + ", camera_from_world");
    camera.camera_from_world.translation() = t.topRightCorner<3, 1>();
  }
  camera.Check(file, "");
  return camera;
}

PinholeCamera ReadCameraFile(const std::string& path) {
  const std::string text = ReadFileToString(path);
  const std::size_t start = text.rfind("\xEF\xBB\xBF", 0) == 0 ? 3 : 0;  // UTF-8 byte-order mark
  const std::size_t first = text.find_first_not_of(" \t\r\n", start);
  if (first != std::string::npos && text[first] == '{') {
    const nlohmann::json j = ParseJsonText(text, path);
    JsonObjectReader reader(j, path, "");
    return ReadCameraJson(reader);
  }
  if (first != std::string::npos && text[first] == '<')
    throw Error(path, "",
                "OpenCV XML calibration files are not supported; save it as YAML or JSON");
  return ReadCameraOpenCvYaml(text, path);
}

}  // namespace arreg
