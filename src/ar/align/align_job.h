// The `arreg align` controller: reads a scene and the frame's outline, landmarks and
// initial pose, runs the aligner, and writes the aligned scene, an overlay and a summary.
#pragma once

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <string>

#include "ar/align/aligner.h"
#include "core/scene.h"

namespace arreg::align {

struct AlignJob {
  std::string scene_path;      // input scene (left untouched), required
  int frame = 0;               // video frame the outline and landmarks belong to, default 0
  std::string outline_path;    // mask image or polygon JSON, "" for none
  std::string landmarks_path;  // landmarks JSON, "" for none
  // Rigid-transform JSON of the initial world_from_model, "scene" for the scene's own
  // model.world_from_model, "" for none (search over viewpoints, or PnP on the landmarks).
  std::string init_pose;
  std::string out_path;      // aligned scene (JSON), required
  std::string overlay_path;  // PNG; "" -> out_path with .overlay.png for .json
  std::string summary_path;  // JSON; "" -> out_path with .summary.json for .json
  AlignOptions options;
  void Check() const;
};

// The model surface (boundary of the scene's tetrahedral model, mm) of a scene.
ModelSurface LoadModelSurface(const Scene& scene);

// Scene with the model placed at `pose`. A pose with scale != 1 cannot be expressed by
// world_from_model: the model mesh and the internal structures are then written scaled
// (mm) next to `out_path` (<stem>.model.vtk, <stem>.structure<i>.obj) and the scene
// points to them.
void WriteAlignedScene(const Scene& scene, const ModelPose& pose, const std::string& out_path);

// The fit drawn over `background` (BGR, camera size): outline (green), the model's
// silhouette at the pose (yellow), landmarks (red: clicked pixel, blue: projected model point).
cv::Mat DrawAlignOverlay(const cv::Mat& background, const PinholeCamera& camera,
                         const ModelSurface& surface, const ModelPose& pose, const Outline* outline,
                         const std::vector<Landmark>& landmarks, const AlignResult& result);

// The summary written by `arreg align` (docs/align.md lists the keys).
nlohmann::json AlignSummaryJson(const AlignResult& result,
                                const Eigen::Vector3d& centroid_in_model);

struct AlignJobResult {
  AlignResult result;
  std::string overlay_path, summary_path;
  bool video_frame_used = false;  // false: the overlay is drawn on a grey background
};

// Runs the job. Throws arreg::Error on bad input and when the fit is refused (the model
// does not fit the outline or the landmarks), before writing anything.
AlignJobResult RunAlignJob(const AlignJob& job);

}  // namespace arreg::align
