// Accuracy trials of `align` on scenes with a known pose: seeded perturbations of the true
// pose as starts, synthetic landmarks, and the errors of the result (tests, `arreg bench align`).
#pragma once

#include <memory>
#include <random>
#include <string>
#include <vector>

#include "ar/align/aligner.h"
#include "core/scene.h"

namespace arreg::align {

// `count` landmarks on model vertices that face the camera at `truth` and project inside
// `mask` (so they are visible), spread over the image by farthest-point sampling, with their
// pixels at the true projection plus Gaussian noise of `noise_px` (seeded by `rng`).
std::vector<Landmark> SyntheticLandmarks(const ModelSurface& surface, const PinholeCamera& camera,
                                         const ModelPose& truth, const cv::Mat& mask, int count,
                                         double noise_px, std::mt19937_64* rng);

struct TrialResult {
  double rotation_error_deg = 0;    // angle of R_est R_true^T
  double translation_error_mm = 0;  // distance between where the two poses put the centroid
  bool fits = false;
  double seconds = 0;      // wall time of Align
  double cpu_seconds = 0;  // processor time of Align (one thread)
};

// Align from PerturbPose(truth, centroid, max_deg, max_mm, rng) with the outline and landmarks
// of `input` (input.initial_pose is replaced).
TrialResult RunPerturbedTrial(AlignInput input, const AlignOptions& options, const ModelPose& truth,
                              double max_deg, double max_mm, std::mt19937_64* rng);

// A synthetic scene folder (`arreg synth`): its scene, model surface, frame-0 outline
// (gt/masks/000000.png) and true pose (the scene's world_from_model).
struct SceneCase {
  std::string dir;
  Scene scene;
  std::unique_ptr<ModelSurface> surface;
  std::unique_ptr<Outline> outline;
  ModelPose truth;
  AlignInput Input() const;  // camera, surface and outline; no landmarks, no initial pose
};
SceneCase LoadSceneCase(const std::string& dir, double spacing_px);

// One trial as `arreg bench align` and the tests run it: from a start drawn by `rng`, the
// outline alone; then `landmarks` SyntheticLandmarks (noise `noise_px`) as well, from a second
// start drawn by the same rng.
struct TrialPair {
  TrialResult outline_only, with_landmarks;
};
TrialPair RunTrialPair(const SceneCase& c, const AlignOptions& options, double max_deg,
                       double max_mm, int landmarks, double noise_px, std::mt19937_64* rng);

}  // namespace arreg::align
