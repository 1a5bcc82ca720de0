// `arreg eval`: compares a run directory (docs/run-format.md) with a ground-truth
// directory (Dice per frame, Hausdorff of surfaces and internal structures, feature error).
#pragma once

#include <Eigen/Core>
#include <functional>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "ar/eval/hausdorff.h"
#include "core/camera.h"
#include "core/mesh.h"

namespace arreg::eval {

struct EvalOptions {
  HausdorffOptions hausdorff;  // surface sampling for both directed parts (see hausdorff.h)
  bool color_maps = true;      // write per-vertex colour maps (OBJ + PNG); default true
  // Top of the colour scale in mm; 0 (default) uses the symmetric Hausdorff
  // distance of the structure at the colour-map frame, so both directions share a scale.
  double color_map_max_mm = 0.0;
  int color_map_supersampling = 2;  // anti-aliasing of the colour-map images, 1..8; default 2
  // Keep, per frame with a Dice, an image of the true mask against the model's silhouette
  // (OverlapImage) for REPORT/overlap/; default false.
  bool overlap_images = false;
  // Called after each evaluated frame with (done, total) frames; may be empty (default).
  std::function<void(int done, int total)> progress;
  void Check() const;
};

// The five Hausdorff figures of one pair of surfaces (mm).
struct HausdorffFigures {
  double mean_model_to_gt = 0.0;
  double mean_gt_to_model = 0.0;
  double max_model_to_gt = 0.0;
  double max_gt_to_model = 0.0;
  double max = 0.0;  // symmetric: max of the two directed maxima
};

// Figures of one thin structure (run.json `thin_structures`) at one frame: the Dice of its own
// silhouette (run's thin/<name> against gt/thin/<name>, both rasterised with the run camera)
// and the Hausdorff figures of its surface; absent where the ground truth has no thin/ file.
struct ThinFrameFigures {
  std::optional<double> dice;
  std::optional<HausdorffFigures> hausdorff;
};

// Over the evaluated frames of one thin structure: Dice at the last frame with one and mean,
// Hausdorff aggregated like the surface's.
struct ThinSummary {
  std::string name;
  std::optional<double> dice_final, dice_mean;
  std::optional<HausdorffFigures> hausdorff;
};

struct FrameEvaluation {
  int frame = 0;
  // Present at the frames where the run saved its surface (surface/NNNNNN.obj) or, with thin
  // structures, thin/NNNNNN.obj: then the Dice of the union silhouette (organ and thin structures).
  std::optional<double> dice;
  // Present where both the run and the ground truth have the surface / internal structures.
  std::optional<HausdorffFigures> surface;
  std::optional<HausdorffFigures> internal;
  // From frames.jsonl; absent when the run logged null (no alive springs).
  std::optional<double> feature_error_mean_mm;
  std::optional<double> feature_error_max_mm;
  // One entry per thin structure of the run (same order as RunEvaluation::thin), at frames with a
  // Dice; empty without thin structures.
  std::vector<ThinFrameFigures> thin;
};

// A mesh with per-vertex distances to the other surface, for the colour maps.
struct DistanceField {
  std::string name;  // "surface_model_to_gt", "surface_gt_to_model", "internal_model_to_gt", ...
  int frame = 0;
  SurfaceMesh mesh;           // the registered model or the ground truth at `frame`
  Eigen::VectorXd distances;  // (#V) mm
  double scale_max_mm = 1.0;  // top of the colour scale
};

struct RunEvaluation {
  std::string run_dir;
  std::string label;  // "with topology" / "without topology" (run.json `topology`)
  bool topology = true;
  bool interrupted = false;
  int num_frames = 0;  // frames the run processed
  PinholeCamera camera;

  double dice_final = 0.0;  // at the last frame with a saved surface
  double dice_mean = 0.0;   // over the frames with a saved surface
  // Over the frames where both have the structure: means are averaged over
  // frames, maxima are the largest over frames. Absent when no frame has it.
  std::optional<HausdorffFigures> surface;
  std::optional<HausdorffFigures> internal;
  // Mean of the per-frame means and largest per-frame maximum (frames.jsonl).
  std::optional<double> feature_error_mean_mm;
  std::optional<double> feature_error_max_mm;

  // One per name in run.json `thin_structures` (empty without): per-structure Dice and Hausdorff.
  std::vector<ThinSummary> thin;

  std::vector<FrameEvaluation> frames;         // one per processed frame, in order
  std::vector<DistanceField> distance_fields;  // colour maps at the last frame with a GT surface
  // With EvalOptions::overlap_images: (frame, PNG bytes of OverlapImage) per frame with a Dice.
  std::vector<std::pair<int, std::vector<unsigned char>>> overlap_pngs;
};

// The objects of an OBJ file (`o name` groups; vertices before the first `o` belong to an object
// named ""), each with its own compact vertex list, in file order. Throws arreg::Error naming the
// file and line on malformed lines or out-of-range indices.
std::vector<std::pair<std::string, SurfaceMesh>> ReadObjObjects(const std::string& path);

// Reads everything, checks consistency and computes the metrics. Throws
// arreg::Error naming the file for a missing run.json / frames.jsonl /
// meta.json / mask, unreadable meshes or PNGs, mask sizes that differ from
// the camera and frame counts that do not match.
RunEvaluation EvaluateRun(const std::string& run_dir, const std::string& gt_dir,
                          const EvalOptions& options = {});

// The report.json object of one run: dice_final, dice_mean, hausdorff_surface,
// hausdorff_internal, feature_error_mm, frames (nulls where unavailable).
nlohmann::json EvaluationToJson(const RunEvaluation& evaluation);

// Writes REPORT/report.json, report.csv, report.html and (when enabled) the
// colour maps under REPORT/colormaps/ and the overlap images under REPORT/overlap/
// (NNNNNN.png, the baseline's baseline_NNNNNN.png), all atomically. `baseline` (may be
// null) is a second run of the same ground truth, shown beside the first.
void WriteEvalReport(const std::string& out_dir, const std::string& gt_dir,
                     const RunEvaluation& run, const RunEvaluation* baseline,
                     const EvalOptions& options = {});

}  // namespace arreg::eval
