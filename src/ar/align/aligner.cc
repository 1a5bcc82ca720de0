#include "ar/align/aligner.h"

#include <ceres/ceres.h>
#include <ceres/cubic_interpolation.h>
#include <ceres/rotation.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>
#include <numeric>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/json_reader.h"

namespace arreg::align {

std::vector<Landmark> ReadLandmarks(const std::string& path) {
  const nlohmann::json json = ParseJsonFile(path);
  JsonObjectReader root(json, path, "");
  std::vector<Landmark> landmarks;
  for (JsonObjectReader& r : root.ObjectArray("landmarks", /*required=*/true)) {
    Landmark l;
    r.Required("pixel", &l.pixel);
    r.Required("model_point_mm", &l.point_in_model);
    ARREG_CHECK_INPUT(l.pixel.allFinite() && l.point_in_model.allFinite(), path, r.path(),
                      "values must be finite");
    r.Finish();
    landmarks.push_back(l);
  }
  root.Finish();
  ARREG_CHECK_INPUT(!landmarks.empty(), path, "landmarks", "no landmarks given");
  return landmarks;
}

const char* RobustLossName(RobustLoss loss) { return NameOf(kRobustLossNames, loss); }

RobustLoss ParseRobustLoss(const std::string& name, const std::string& field) {
  return ParseName(kRobustLossNames, name, "", field);
}

void AlignOptions::Check() const {
  const std::string f = "";
  ARREG_CHECK_INPUT(loss_scale_px > 0, f, "align.loss_scale_px", "must be > 0");
  ARREG_CHECK_INPUT(contour_spacing_px >= 1, f, "align.contour_spacing_px", "must be >= 1");
  ARREG_CHECK_INPUT(silhouette_weight > 0 && landmark_weight > 0, f, "align.weights",
                    "must be > 0");
  ARREG_CHECK_INPUT(max_outer_iterations >= 1 && max_inner_iterations >= 1, f,
                    "align.max_iterations", "must be >= 1");
  ARREG_CHECK_INPUT(local_starts >= 0 && local_start_deg >= 0, f, "align.local_starts",
                    "must be >= 0");
  ARREG_CHECK_INPUT(search_viewpoints >= 1 && search_rolls >= 1 && search_refined >= 1, f,
                    "align.search", "counts must be >= 1");
  ARREG_CHECK_INPUT(search_scale_px > 0 && search_scale_px <= 1, f, "align.search_scale_px",
                    "must be in (0, 1]");
  ARREG_CHECK_INPUT(min_iou >= 0 && min_iou <= 1, f, "align.min_iou", "must be in [0, 1]");
  ARREG_CHECK_INPUT(max_mean_contour_px > 0 && max_landmark_rms_px > 0, f,
                    "align.max_mean_contour_px", "must be > 0");
}

namespace {

constexpr double kNearMm = 1.0;

// The camera as plain numbers for the templated residuals.
struct CameraModel {
  double r[9], t[3];  // camera_from_world, row-major rotation
  double fx, fy, cx, cy, k1, k2, k3, k4, k5, k6, p1, p2;
  explicit CameraModel(const PinholeCamera& c) {
    const Eigen::Matrix3d rot = c.camera_from_world.linear();
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) r[3 * i + j] = rot(i, j);
      t[i] = c.camera_from_world.translation()(i);
    }
    fx = c.fx, fy = c.fy, cx = c.cx, cy = c.cy;
    const Distortion& d = c.distortion;
    k1 = d.k1, k2 = d.k2, k3 = d.k3, k4 = d.k4, k5 = d.k5, k6 = d.k6, p1 = d.p1, p2 = d.p2;
  }
  // PinholeCamera::Project for any scalar type; false behind the near plane.
  template <typename T>
  bool Project(const T* w, T* px) const {
    T pc[3];
    for (std::ptrdiff_t i = 0; i < 3; ++i)
      pc[i] = r[3 * i] * w[0] + r[3 * i + 1] * w[1] + r[3 * i + 2] * w[2] + t[i];
    if (!(pc[2] > T(kNearMm))) return false;
    const T x = pc[0] / pc[2], y = pc[1] / pc[2];
    const T r2 = x * x + y * y;
    const T radial =
        (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1.0 + r2 * (k4 + r2 * (k5 + r2 * k6)));
    const T xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
    const T yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
    px[0] = fx * xd + cx;
    px[1] = fy * yd + cy;
    return true;
  }
};

// point_in_world = exp(log_scale) R(omega) (p - centroid) + tau: rotation and scale act about
// the model's centroid, which keeps the translation decoupled from them.
template <typename T>
void ToWorld(const T* omega, const T* tau, const T* log_scale, const Eigen::Vector3d& rel, T* w) {
  const T p[3] = {T(rel.x()), T(rel.y()), T(rel.z())};
  T q[3];
  ceres::AngleAxisRotatePoint(omega, p, q);
  const T s = exp(log_scale[0]);
  for (int i = 0; i < 3; ++i) w[i] = s * q[i] + tau[i];
}

using Interpolator = ceres::BiCubicInterpolator<ceres::Grid2D<double, 1>>;

// Signed distance of the outline at a contour point's image.
struct ContourResidual {
  const CameraModel* camera;
  const Interpolator* distance;
  Eigen::Vector3d rel;
  template <typename T>
  bool operator()(const T* omega, const T* tau, const T* log_scale, T* r) const {
    T w[3], px[2];
    ToWorld(omega, tau, log_scale, rel, w);
    if (!camera->Project(w, px)) return false;
    distance->Evaluate(px[1], px[0], r);
    return true;
  }
};

// Distance along the outline's normal from an outline point to the image of its nearest
// contour point (point-to-line, so the contour may slide along the outline).
struct MatchResidual {
  const CameraModel* camera;
  Eigen::Vector3d rel;
  Eigen::Vector2d target, normal;
  template <typename T>
  bool operator()(const T* omega, const T* tau, const T* log_scale, T* r) const {
    T w[3], px[2];
    ToWorld(omega, tau, log_scale, rel, w);
    if (!camera->Project(w, px)) return false;
    r[0] = normal.x() * (px[0] - target.x()) + normal.y() * (px[1] - target.y());
    return true;
  }
};

struct LandmarkResidual {
  const CameraModel* camera;
  Eigen::Vector3d rel;
  Eigen::Vector2d pixel;
  template <typename T>
  bool operator()(const T* omega, const T* tau, const T* log_scale, T* r) const {
    T w[3], px[2];
    ToWorld(omega, tau, log_scale, rel, w);
    if (!camera->Project(w, px)) return false;
    r[0] = px[0] - pixel.x();
    r[1] = px[1] - pixel.y();
    return true;
  }
};

// Keeps the centroid's depth (camera z) at the start's: one image cannot tell a larger organ
// from a nearer one, so with a free scale the distance must come from the initial pose.
struct DepthPrior {
  const CameraModel* camera;
  double depth_mm, weight_per_mm;
  template <typename T>
  bool operator()(const T* tau, T* r) const {
    const double* R = camera->r;
    const T z = R[6] * tau[0] + R[7] * tau[1] + R[8] * tau[2] + camera->t[2];
    r[0] = weight_per_mm * (z - depth_mm);
    return true;
  }
};

struct Parameters {
  double omega[3], tau[3], log_scale[1];
};

Parameters ToParameters(const ModelPose& pose, const Eigen::Vector3d& centroid) {
  Parameters p;
  Eigen::Matrix<double, 3, 3, Eigen::ColMajor> r = pose.rotation;
  ceres::RotationMatrixToAngleAxis(r.data(), p.omega);
  const Eigen::Vector3d tau = pose.Apply(centroid);
  for (int i = 0; i < 3; ++i) p.tau[i] = tau(i);
  p.log_scale[0] = std::log(pose.scale);
  return p;
}

ModelPose ToPose(const Parameters& p, const Eigen::Vector3d& centroid) {
  ModelPose pose;
  Eigen::Matrix<double, 3, 3, Eigen::ColMajor> r;
  ceres::AngleAxisToRotationMatrix(p.omega, r.data());
  pose.rotation = r;
  pose.scale = std::exp(p.log_scale[0]);
  pose.translation_mm = Eigen::Vector3d(p.tau[0], p.tau[1], p.tau[2]) - pose.scale * (r * centroid);
  return pose;
}

ceres::LossFunction* MakeLoss(const AlignOptions& o, double weight) {
  ceres::LossFunction* base = nullptr;
  switch (o.robust_loss) {
    case RobustLoss::kHuber:
      base = new ceres::HuberLoss(o.loss_scale_px);
      break;
    case RobustLoss::kCauchy:
      base = new ceres::CauchyLoss(o.loss_scale_px);
      break;
    case RobustLoss::kNone:
      break;
  }
  return new ceres::ScaledLoss(base, weight, ceres::TAKE_OWNERSHIP);
}

TermStats Stats(const std::vector<double>& abs_values) {
  TermStats s;
  s.count = static_cast<int>(abs_values.size());
  if (s.count == 0) return s;
  double sum = 0, sum2 = 0;
  for (double v : abs_values) {
    sum += v;
    sum2 += v * v;
    s.max_px = std::max(s.max_px, v);
  }
  s.mean_px = sum / s.count;
  s.rms_px = std::sqrt(sum2 / s.count);
  return s;
}

// The problem at one contour extraction: its residuals and the figures for the report.
class Context {
 public:
  Context(const AlignInput& input, const AlignOptions& options)
      : in_(input), o_(options), camera_(*input.camera) {
    if (in_.outline) {
      const cv::Mat& d = in_.outline->signed_distance_px;
      grid_ = std::make_unique<ceres::Grid2D<double, 1>>(d.ptr<double>(), 0, d.rows, 0, d.cols);
      distance_ = std::make_unique<Interpolator>(*grid_);
    }
  }

  const Eigen::Vector3d& centroid() const { return in_.surface->centroid(); }

  struct Built {
    bool valid = false;
    std::unique_ptr<ceres::Problem> problem;
    std::vector<double> contour_abs, match_abs, landmark_abs;
    cv::Mat mask;
  };

  // Extracts the contour at `params` and builds the residuals on it.
  Built Build(Parameters* params, double depth_mm) const {
    Built b;
    const ModelPose pose = ToPose(*params, centroid());
    ProjectedModel projected = ProjectModel(*in_.surface, *in_.camera, pose, o_.contour_spacing_px,
                                            1.0, true, o_.smooth_contour);
    if (!projected.valid) return b;
    const ContourSamples& c = projected.contour;
    const int n_contour = static_cast<int>(c.points_in_model.rows());
    if (in_.outline && n_contour < 6) return b;
    b.valid = true;
    b.mask = projected.mask;
    ceres::Problem::Options po;
    b.problem = std::make_unique<ceres::Problem>(po);
    ceres::Problem& problem = *b.problem;
    problem.AddParameterBlock(params->omega, 3);
    problem.AddParameterBlock(params->tau, 3);
    problem.AddParameterBlock(params->log_scale, 1);
    if (!o_.estimate_scale) {
      problem.SetParameterBlockConstant(params->log_scale);
    } else {
      // 0.01 mm of depth weighs as 1 px of the whole silhouette: the depth is held.
      problem.AddResidualBlock(new ceres::AutoDiffCostFunction<DepthPrior, 1, 3>(new DepthPrior{
                                   &camera_, depth_mm, 100.0 * std::sqrt(o_.silhouette_weight)}),
                               nullptr, params->tau);
    }
    if (in_.outline) {
      const Outline& outline = *in_.outline;
      ceres::LossFunction* contour_loss = MakeLoss(o_, 0.5 * o_.silhouette_weight / n_contour);
      for (int i = 0; i < n_contour; ++i) {
        const Eigen::Vector3d rel = c.points_in_model.row(i).transpose() - centroid();
        problem.AddResidualBlock(new ceres::AutoDiffCostFunction<ContourResidual, 1, 3, 3, 1>(
                                     new ContourResidual{&camera_, distance_.get(), rel}),
                                 contour_loss, params->omega, params->tau, params->log_scale);
        double d = 0;
        distance_->Evaluate(c.pixels(i, 1), c.pixels(i, 0), &d);
        b.contour_abs.push_back(std::fabs(d));
      }
      const int n_outline = static_cast<int>(outline.boundary_px.rows());
      ceres::LossFunction* match_loss = MakeLoss(o_, 0.5 * o_.silhouette_weight / n_outline);
      for (int i = 0; i < n_outline; ++i) {
        const Eigen::Vector2d q = outline.boundary_px.row(i).transpose();
        int best = 0;
        double best_d2 = std::numeric_limits<double>::infinity();
        for (int j = 0; j < n_contour; ++j) {
          const double d2 = (c.pixels.row(j).transpose() - q).squaredNorm();
          if (d2 < best_d2) best_d2 = d2, best = j;
        }
        const Eigen::Vector2d normal = outline.normals.row(i).transpose();
        const Eigen::Vector3d rel = c.points_in_model.row(best).transpose() - centroid();
        problem.AddResidualBlock(new ceres::AutoDiffCostFunction<MatchResidual, 1, 3, 3, 1>(
                                     new MatchResidual{&camera_, rel, q, normal}),
                                 match_loss, params->omega, params->tau, params->log_scale);
        b.match_abs.push_back(std::fabs(normal.dot(c.pixels.row(best).transpose() - q)));
      }
    }
    if (!in_.landmarks.empty()) {
      ceres::LossFunction* loss = MakeLoss(o_, o_.landmark_weight);
      for (const Landmark& l : in_.landmarks) {
        const Eigen::Vector3d rel = l.point_in_model - centroid();
        problem.AddResidualBlock(new ceres::AutoDiffCostFunction<LandmarkResidual, 2, 3, 3, 1>(
                                     new LandmarkResidual{&camera_, rel, l.pixel}),
                                 loss, params->omega, params->tau, params->log_scale);
        const Eigen::Vector3d w = pose.Apply(l.point_in_model);
        const Eigen::Vector3d pc = in_.camera->camera_from_world * w;
        b.landmark_abs.push_back(pc.z() > kNearMm
                                     ? (in_.camera->ProjectFromCamera(pc) - l.pixel).norm()
                                     : std::numeric_limits<double>::infinity());
      }
    }
    return b;
  }

  // Camera z of the centroid (mm).
  double Depth(const Parameters& p) const {
    return (in_.camera->camera_from_world * Eigen::Vector3d(p.tau[0], p.tau[1], p.tau[2])).z();
  }

  static double Cost(ceres::Problem* problem) {
    double cost = 0;
    problem->Evaluate(ceres::Problem::EvaluateOptions(), &cost, nullptr, nullptr, nullptr);
    return cost;
  }

  StartResult Run(const ModelPose& initial, ceres::Solver::Summary* last) const {
    StartResult s;
    s.initial = initial;
    Parameters params = ToParameters(initial, centroid());
    const double depth = Depth(params);
    ceres::Solver::Options so;
    so.linear_solver_type = ceres::DENSE_QR;
    so.max_num_iterations = o_.max_inner_iterations;
    so.num_threads = 1;
    so.logging_type = ceres::SILENT;
    so.minimizer_progress_to_stdout = false;
    so.function_tolerance = 1e-10;
    so.parameter_tolerance = 1e-10;
    const double radius = in_.surface->radius_mm();
    for (int outer = 0; outer < o_.max_outer_iterations; ++outer) {
      Built b = Build(&params, depth);
      if (!b.valid) return s;
      const Parameters before = params;
      ceres::Solve(so, b.problem.get(), last);
      if (outer == 0) s.cost_before = last->initial_cost;
      ++s.outer_iterations;
      s.inner_iterations += last->num_successful_steps + last->num_unsuccessful_steps;
      const ModelPose a = ToPose(before, centroid()), c = ToPose(params, centroid());
      const double moved_deg = RotationErrorDeg(a, c);
      const double moved = (PointErrorMm(a, c, centroid()) +
                            radius * std::fabs(params.log_scale[0] - before.log_scale[0])) /
                           radius;
      if (moved_deg < o_.converged_rotation_deg && moved < o_.converged_translation) break;
    }
    Built b = Build(&params, depth);
    if (!b.valid) return s;
    s.valid = true;
    s.final = ToPose(params, centroid());
    s.cost_after = Cost(b.problem.get());
    return s;
  }

  // The final figures of a pose (contour re-extracted there).
  void Figures(const ModelPose& pose, AlignResult* r) const {
    Parameters params = ToParameters(pose, centroid());
    Built b = Build(&params, Depth(params));
    r->contour_to_outline = Stats(b.contour_abs);
    r->outline_to_contour = Stats(b.match_abs);
    r->landmarks = Stats(b.landmark_abs);
    if (in_.outline && b.valid) r->iou = MaskIou(b.mask, in_.outline->mask);
  }

 private:
  const AlignInput& in_;
  const AlignOptions& o_;
  CameraModel camera_;
  std::unique_ptr<ceres::Grid2D<double, 1>> grid_;
  std::unique_ptr<Interpolator> distance_;
};

// Points evenly spread over the unit sphere (Fibonacci lattice).
std::vector<Eigen::Vector3d> SphereDirections(int n) {
  std::vector<Eigen::Vector3d> d;
  const double golden = M_PI * (3.0 - std::sqrt(5.0));
  for (int i = 0; i < n; ++i) {
    const double z = 1.0 - 2.0 * (i + 0.5) / n, r = std::sqrt(1.0 - z * z);
    d.emplace_back(r * std::cos(golden * i), r * std::sin(golden * i), z);
  }
  return d;
}

// Coarse search without an initial pose: candidate rotations, each placed so that its
// silhouette's area and centroid match the outline's, ranked by overlap.
std::vector<ModelPose> SearchStarts(const AlignInput& in, const AlignOptions& o) {
  const PinholeCamera& camera = *in.camera;
  const Outline& outline = *in.outline;
  const ModelSurface& surface = *in.surface;
  const double f = 0.5 * (camera.fx + camera.fy);
  // Cauchy: a convex body's projected area averaged over directions is a quarter of its surface.
  const double r_mm = std::sqrt(surface.area_mm2() / (4 * M_PI));
  const double r_px = std::sqrt(outline.area_px / M_PI);
  const double depth0 = f * r_mm / r_px;
  const double s = o.search_scale_px;
  cv::Mat small;
  cv::resize(outline.mask, small, cv::Size(), s, s, cv::INTER_AREA);
  cv::threshold(small, small, 127, 255, cv::THRESH_BINARY);
  const Eigen::Matrix3d world_from_camera = camera.camera_from_world.linear().transpose();
  const Eigen::Vector2d target = camera.PixelToNormalized(outline.centroid_px);

  auto place = [&](const Eigen::Matrix3d& camera_from_model, const Eigen::Vector2d& normalized,
                   double depth) {
    ModelPose p;
    p.rotation = world_from_camera * camera_from_model;
    const Eigen::Vector3d centre_in_camera(normalized.x() * depth, normalized.y() * depth, depth);
    p.translation_mm =
        camera.camera_from_world.inverse() * centre_in_camera - p.rotation * surface.centroid();
    return p;
  };
  struct Candidate {
    ModelPose pose;
    double iou;
  };
  std::vector<Candidate> candidates;
  for (const Eigen::Vector3d& d : SphereDirections(o.search_viewpoints)) {
    // The model's direction d points at the camera (camera -z).
    const Eigen::Matrix3d towards =
        Eigen::Quaterniond::FromTwoVectors(d, -Eigen::Vector3d::UnitZ()).toRotationMatrix();
    for (int k = 0; k < o.search_rolls; ++k) {
      const Eigen::Matrix3d rotation =
          Eigen::AngleAxisd(2 * M_PI * k / o.search_rolls, Eigen::Vector3d::UnitZ()) * towards;
      ModelPose p = place(rotation, target, depth0);
      ProjectedModel pm = ProjectModel(surface, camera, p, 1.0, s, false);
      if (!pm.valid) continue;
      const cv::Moments m = cv::moments(pm.mask, true);
      if (m.m00 <= 0) continue;
      // Match the outline's area (depth) and centroid (shift at the new depth).
      const double depth = depth0 * std::sqrt(m.m00 / (s * s) / outline.area_px);
      const Eigen::Vector2d centroid_px((m.m10 / m.m00 + 0.5) / s - 0.5,
                                        (m.m01 / m.m00 + 0.5) / s - 0.5);
      const Eigen::Vector2d offset = camera.PixelToNormalized(centroid_px) - target;
      p = place(rotation, target - offset * (depth0 / depth), depth);
      pm = ProjectModel(surface, camera, p, 1.0, s, false);
      if (!pm.valid) continue;
      candidates.push_back({p, MaskIou(pm.mask, small)});
    }
  }
  std::sort(candidates.begin(), candidates.end(),
            [](const Candidate& a, const Candidate& b) { return a.iou > b.iou; });
  // Distinct candidates only: refining near-copies of one pose says nothing new.
  constexpr double kDistinctDeg = 25.0;
  std::vector<ModelPose> starts;
  for (const Candidate& c : candidates) {
    if (static_cast<int>(starts.size()) >= o.search_refined) break;
    bool distinct = true;
    for (const ModelPose& s2 : starts)
      if (RotationErrorDeg(s2, c.pose) < kDistinctDeg) distinct = false;
    if (distinct) starts.push_back(c.pose);
  }
  return starts;
}

// A start from the landmarks alone (PnP), when there is no initial pose and 4 or more.
std::optional<ModelPose> PnpStart(const AlignInput& in) {
  if (in.landmarks.size() < 4) return std::nullopt;
  const PinholeCamera& c = *in.camera;
  std::vector<cv::Point3d> object;
  std::vector<cv::Point2d> image;
  for (const Landmark& l : in.landmarks) {
    object.emplace_back(l.point_in_model.x(), l.point_in_model.y(), l.point_in_model.z());
    image.emplace_back(l.pixel.x(), l.pixel.y());
  }
  const cv::Mat k = (cv::Mat_<double>(3, 3) << c.fx, 0, c.cx, 0, c.fy, c.cy, 0, 0, 1);
  const std::vector<double> d = c.distortion.ToVector();
  cv::Mat rvec, tvec;
  if (!cv::solvePnP(object, image, k, d, rvec, tvec, false,
                    in.landmarks.size() >= 6 ? cv::SOLVEPNP_ITERATIVE : cv::SOLVEPNP_SQPNP))
    return std::nullopt;
  cv::Mat r;
  cv::Rodrigues(rvec, r);
  Eigen::Isometry3d camera_from_model = Eigen::Isometry3d::Identity();
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) camera_from_model.linear()(i, j) = r.at<double>(i, j);
    camera_from_model.translation()(i) = tvec.at<double>(i);
  }
  return ModelPose::FromRigid(c.camera_from_world.inverse() * camera_from_model);
}

}  // namespace

ModelPose PerturbPose(const ModelPose& pose, const Eigen::Vector3d& center_in_model, double max_deg,
                      double max_mm, std::mt19937_64* rng) {
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  auto direction = [&] {
    Eigen::Vector3d v;
    do v = Eigen::Vector3d(normal(*rng), normal(*rng), normal(*rng));
    while (v.norm() < 1e-9);
    return Eigen::Vector3d(v.normalized());
  };
  const Eigen::Vector3d axis = direction();
  const double angle = unit(*rng) * max_deg * M_PI / 180.0;
  const Eigen::Vector3d shift = direction() * (unit(*rng) * max_mm);
  const Eigen::Matrix3d delta = Eigen::AngleAxisd(angle, axis).toRotationMatrix();
  const Eigen::Vector3d center = pose.Apply(center_in_model);
  ModelPose out = pose;
  out.rotation = delta * pose.rotation;
  out.translation_mm = delta * (pose.translation_mm - center) + center + shift;
  return out;
}

AlignResult Align(const AlignInput& in, const AlignOptions& o) {
  const auto t0 = std::chrono::steady_clock::now();
  o.Check();
  ARREG_ASSERT(in.camera && in.surface, "camera and surface are required");
  ARREG_CHECK_INPUT(in.outline || in.landmarks.size() >= 3, "", "align",
                    "needs an outline, or 3 or more landmarks (4 for a unique pose)");
  Context context(in, o);
  std::vector<ModelPose> starts;
  if (in.initial_pose) {
    starts.push_back(*in.initial_pose);
    std::mt19937_64 rng(o.seed);
    for (int k = 0; k < o.local_starts; ++k) {
      // Rotations of exactly local_start_deg about random axes through the centroid.
      ModelPose p = *in.initial_pose;
      std::normal_distribution<double> normal(0.0, 1.0);
      const Eigen::Vector3d axis =
          Eigen::Vector3d(normal(rng), normal(rng), normal(rng)).normalized();
      const Eigen::Matrix3d delta =
          Eigen::AngleAxisd(o.local_start_deg * M_PI / 180.0, axis).toRotationMatrix();
      const Eigen::Vector3d center = p.Apply(in.surface->centroid());
      p.rotation = delta * p.rotation;
      p.translation_mm = delta * (p.translation_mm - center) + center;
      starts.push_back(p);
    }
  } else if (auto pnp = PnpStart(in)) {
    starts.push_back(*pnp);
  } else {
    ARREG_CHECK_INPUT(in.outline, "", "align",
                      "without an initial pose, an outline or 4 or more landmarks are needed");
    starts = SearchStarts(in, o);
    ARREG_CHECK_INPUT(!starts.empty(), "", "align",
                      "no viewpoint of the search puts the model in front of the camera");
  }

  AlignResult r;
  std::vector<ceres::Solver::Summary> summaries;
  auto run = [&](const ModelPose& start) {
    summaries.emplace_back();
    r.starts.push_back(context.Run(start, &summaries.back()));
    const StartResult& s = r.starts.back();
    // Ties (starts reaching the same optimum) go to the earlier start: the given pose.
    if (s.valid &&
        (r.best_start < 0 || s.cost_after < (1 - 1e-9) * r.starts[r.best_start].cost_after))
      r.best_start = static_cast<int>(r.starts.size()) - 1;
  };
  for (const ModelPose& start : starts) run(start);
  if (!in.initial_pose && r.best_start >= 0 && in.landmarks.size() < 4) {
    // A silhouette hardly changes when a near-symmetric organ turns half a turn about the
    // viewing direction or an image axis; the search's grid may miss these poses, so they are
    // refined from the best one and take part in the ambiguity check below.
    const ModelPose best = r.starts[r.best_start].final;
    const Eigen::Vector3d center = best.Apply(in.surface->centroid());
    const Eigen::Matrix3d world_from_camera = in.camera->camera_from_world.linear().transpose();
    for (int axis = 0; axis < 3; ++axis) {
      const Eigen::Matrix3d turn = world_from_camera *
                                   Eigen::AngleAxisd(M_PI, Eigen::Vector3d::Unit(axis)) *
                                   world_from_camera.transpose();
      ModelPose p = best;
      p.rotation = turn * best.rotation;
      p.translation_mm = turn * (best.translation_mm - center) + center;
      run(p);
    }
  }
  if (r.best_start < 0) {
    r.failure = "no start converged with the model in front of the camera";
    r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return r;
  }
  const StartResult& best = r.starts[r.best_start];
  r.pose = best.final;
  const ceres::Solver::Summary& summary = summaries[r.best_start];
  r.ceres_termination = ceres::TerminationTypeToString(summary.termination_type);
  r.ceres_message = summary.message;
  r.ceres_minimizer = ceres::MinimizerTypeToString(summary.minimizer_type);
  r.ceres_iterations = static_cast<int>(summary.iterations.size()) - 1;
  r.ceres_residuals = summary.num_residuals;
  r.ceres_parameters = summary.num_effective_parameters_reduced;
  r.ceres_initial_cost = summary.initial_cost;
  r.ceres_final_cost = summary.final_cost;
  r.ceres_time_s = summary.total_time_in_seconds;

  // Agreement between starts, and other optima that fit about as well.
  constexpr double kDistinctFactor = 5.0;  // "another optimum": 5x the same-optimum tolerance
  const Eigen::Vector3d c = in.surface->centroid();
  for (const StartResult& s : r.starts) {
    if (!s.valid) continue;
    const double deg = RotationErrorDeg(s.final, best.final);
    const double mm = PointErrorMm(s.final, best.final, c);
    if (deg <= o.same_optimum_deg && mm <= o.same_optimum_mm) ++r.starts_at_optimum;
    if ((deg > kDistinctFactor * o.same_optimum_deg || mm > kDistinctFactor * o.same_optimum_mm) &&
        s.cost_after <= o.ambiguity_cost_ratio * best.cost_after && !r.ambiguous) {
      r.ambiguous = true;
      char text[256];
      std::snprintf(text, sizeof text,
                    "ambiguous: another pose %.1f deg / %.1f mm away fits almost as well (cost "
                    "%.4g vs %.4g)",
                    deg, mm, s.cost_after, best.cost_after);
      r.warning = text;
    }
  }

  context.Figures(r.pose, &r);
  char text[256];
  r.fits = true;
  if (in.outline) {
    const double mean_px = 0.5 * (r.contour_to_outline.mean_px + r.outline_to_contour.mean_px);
    if (r.iou < o.min_iou || mean_px > o.max_mean_contour_px) {
      r.fits = false;
      std::snprintf(text, sizeof text,
                    "the model does not fit the outline: silhouette overlap (IoU) %.3f (needs "
                    ">= %.2f), mean contour distance %.2f px (needs <= %.2f)",
                    r.iou, o.min_iou, mean_px, o.max_mean_contour_px);
      r.failure = text;
    }
  }
  if (r.fits && !in.landmarks.empty() && r.landmarks.rms_px > o.max_landmark_rms_px) {
    r.fits = false;
    std::snprintf(text, sizeof text,
                  "the landmarks do not fit: RMS reprojection error %.2f px (needs <= %.2f)",
                  r.landmarks.rms_px, o.max_landmark_rms_px);
    r.failure = text;
  }
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return r;
}

}  // namespace arreg::align
