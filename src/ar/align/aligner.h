// `arreg align`'s solver: places the model in the world from one frame's organ outline
// and/or 2D-3D landmarks with Ceres (silhouette and reprojection terms, robust loss,
// multi-start), and judges whether the result fits.
#pragma once

#include <Eigen/Core>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "ar/align/silhouette.h"
#include "core/camera.h"
#include "core/enum_names.h"

namespace arreg::align {

// An image pixel known to show a given point of the model.
struct Landmark {
  Eigen::Vector2d pixel = Eigen::Vector2d::Zero();           // px (distorted image)
  Eigen::Vector3d point_in_model = Eigen::Vector3d::Zero();  // mm, model frame
};

// Reads {"landmarks": [{"pixel": [u, v], "model_point_mm": [x, y, z]}, ...]}; errors name
// the file and the entry.
std::vector<Landmark> ReadLandmarks(const std::string& path);

// Robust loss on the residuals (px): Huber, Cauchy, or none (least squares).
enum class RobustLoss { kHuber, kCauchy, kNone };
inline constexpr EnumName<RobustLoss> kRobustLossNames[] = {
    {RobustLoss::kHuber, "huber"}, {RobustLoss::kCauchy, "cauchy"}, {RobustLoss::kNone, "none"}};
// The spelling on the command line and in summaries: "huber", "cauchy", "none".
const char* RobustLossName(RobustLoss loss);
// Inverse of RobustLossName; throws arreg::Error naming `field` for any other name.
RobustLoss ParseRobustLoss(const std::string& name, const std::string& field);

struct AlignOptions {
  // Also estimate a uniform scale (default off: rigid). One image cannot tell a larger organ
  // from a nearer one, so the centroid's distance from the camera is then held at the start's.
  bool estimate_scale = false;
  RobustLoss robust_loss = RobustLoss::kHuber;  // default Huber
  double loss_scale_px = 2.0;       // px where the robust loss leaves the quadratic, default 2
  double contour_spacing_px = 3.0;  // distance between silhouette samples (px), default 3
  // Contour samples on the smooth surface through the mesh's vertices instead of its chords
  // (ModelSurface::EdgePoint): a coarse model's faces sag inside the organ, which makes its
  // silhouette too small. On the kidney scene it takes the outline-only error from 1.7-2.1 deg /
  // 1.2-2 mm to 1.3 deg / 0.5 mm; creases (the band's box edges) are unaffected. Default on.
  bool smooth_contour = true;
  // Weight of the whole silhouette (both directions together) relative to one landmark:
  // each direction's residuals are averaged, so the weight does not grow with the image size.
  // The contour's samples are strongly correlated (one model error moves a whole stretch), so
  // the outline counts as a few independent points, not hundreds. Default 8: with 4 landmarks
  // at 0.5 px noise, 4 lets them tilt the band beyond 1 deg, 8 and 16 keep both synthetic
  // scenes within 1 deg / 1 mm (docs/align.md).
  double silhouette_weight = 8.0;  // default 8
  double landmark_weight = 1.0;    // per landmark, default 1
  int max_outer_iterations = 30;   // contour re-extractions per start, default 30
  int max_inner_iterations = 10;   // Levenberg-Marquardt iterations per contour, default 10
  // Outer iterations stop when the pose moves less than these (deg, fraction of model radius).
  double converged_rotation_deg = 0.005;  // default 0.005
  double converged_translation = 2e-5;    // default 2e-5 of the model's radius

  // Starts around a given initial pose, besides the pose itself (seeded, rotations up to
  // local_start_deg about the model's centroid), so that a local minimum near the start can
  // be recognised and the number of starts agreeing can be reported. Default 2.
  int local_starts = 2;
  double local_start_deg = 10.0;  // default 10
  // Search without an initial pose: viewpoints over the sphere x in-plane rotations, each at
  // the depth where the model's mean projected area matches the outline's, scored by the
  // overlap of the silhouettes; the best `search_refined` distinct candidates are refined.
  int search_viewpoints = 60;     // default 60
  int search_rolls = 12;          // in-plane rotations, default 12 (30 degrees apart)
  int search_refined = 8;         // default 8
  double search_scale_px = 0.25;  // resolution of the candidate silhouettes, default 1/4

  // Starts ending within these of the best count as reaching the same optimum.
  double same_optimum_deg = 1.0;  // default 1
  double same_optimum_mm = 1.0;   // default 1 (at the model's centroid)
  // A different optimum whose cost is within this factor of the best makes the problem
  // ambiguous (warning).
  double ambiguity_cost_ratio = 1.5;  // default 1.5
  // The fit is refused below this overlap of the model's silhouette with the outline, or
  // above this mean distance between the two contours (px, both directions averaged). The
  // mean is taken over ~1 px-accurate binary boundaries: a correct pose gives well under 1 px.
  double min_iou = 0.9;              // default 0.9
  double max_mean_contour_px = 2.5;  // default 2.5
  double max_landmark_rms_px = 5.0;  // default 5 (refusal with landmarks)
  uint64_t seed = 1;                 // local starts, default 1
  void Check() const;
};

// What a start of the solver did.
struct StartResult {
  ModelPose initial, final;
  double cost_before = 0, cost_after = 0;  // Ceres cost (0.5 sum of squared, weighted, robustified)
  int outer_iterations = 0, inner_iterations = 0;
  bool valid = false;  // false when the model left the front of the camera
};

struct TermStats {
  int count = 0;
  double rms_px = 0, mean_px = 0, max_px = 0;
};

struct AlignResult {
  ModelPose pose;       // the best start's final pose
  bool fits = false;    // passed the fit checks
  std::string failure;  // why not, when !fits
  std::vector<StartResult> starts;
  int best_start = -1;
  int starts_at_optimum = 0;  // starts ending within same_optimum_* of the best
  bool ambiguous = false;
  std::string warning;  // set when ambiguous
  // Final figures of the best start.
  double iou = 0;
  TermStats contour_to_outline, outline_to_contour, landmarks;
  // Ceres' summary of the best start's last solve.
  std::string ceres_termination, ceres_message, ceres_minimizer;
  int ceres_iterations = 0, ceres_residuals = 0, ceres_parameters = 0;
  double ceres_initial_cost = 0, ceres_final_cost = 0, ceres_time_s = 0;
  double seconds = 0;  // wall time of Align
};

struct AlignInput {
  const PinholeCamera* camera = nullptr;
  const ModelSurface* surface = nullptr;
  const Outline* outline = nullptr;       // may be null when landmarks are given
  std::vector<Landmark> landmarks;        // may be empty when an outline is given
  std::optional<ModelPose> initial_pose;  // none: search
};

AlignResult Align(const AlignInput& input, const AlignOptions& options);

// A seeded random rigid perturbation of `pose` about the world point where it puts
// `center_in_model`: a uniformly random axis and direction, rotation angle uniform in
// [0, max_deg], translation length uniform in [0, max_mm]. For tests and benchmarks that
// start `align` from a known error.
ModelPose PerturbPose(const ModelPose& pose, const Eigen::Vector3d& center_in_model, double max_deg,
                      double max_mm, std::mt19937_64* rng);

}  // namespace arreg::align
