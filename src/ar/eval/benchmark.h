// The accuracy benchmark's definitions (`arreg bench accuracy`, docs/benchmark.md): the scene
// manifest, the per-scene cut and registration scores, their aggregation and the acceptance lines.
#pragma once

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "ar/eval/evaluation.h"
#include "ar/eval/hausdorff.h"
#include "core/mesh.h"

namespace arreg::eval {

// Where a scene comes from: `arreg synth` or tools/phantoms/make-scene. Spelled "synth",
// "phantom" in the manifest and the JSON.
enum class SceneSource { kSynth, kPhantom };
// "dev" (to work on), "test" (to report only) or "quick" (the CI subset, run by --quick only).
enum class BenchSplit { kDev, kTest, kQuick };
// "cut" (precut or cut while filmed), "no-cut", or "stretch" (a no-cut scene under large
// stretch).
enum class SceneClass { kCut, kNoCut, kStretch };
const char* SceneSourceName(SceneSource source);
const char* BenchSplitName(BenchSplit split);
const char* SceneClassName(SceneClass scene_class);
// Inverses of the names; throw arreg::Error naming `file` and `field` for any other name.
SceneSource ParseSceneSource(const std::string& name, const std::string& file,
                             const std::string& field);
BenchSplit ParseBenchSplit(const std::string& name, const std::string& file,
                           const std::string& field);
SceneClass ParseSceneClass(const std::string& name, const std::string& file,
                           const std::string& field);

// Generator parameters of one scene. `frames` and the size are required in the manifest; the
// others exist for the synth source only and default to `arreg synth`'s defaults.
struct BenchSceneParams {
  int frames = 0;                                   // video frames, >= 2
  int width = 0, height = 0;                        // image size in px (even)
  double zoom = 1.0;                                // synth --zoom, in [0.5, 4]
  double amplitude = 1.0;                           // synth --amplitude, in (0, 1.5]
  double noise = 2.0;                               // synth --noise, 8-bit grey levels, >= 0
  double blur = 0.0;                                // synth --blur, px, >= 0
  bool occluder = false;                            // synth --occluder
  nlohmann::json ToJson(SceneSource source) const;  // the keys the source takes
};

// One scene of the manifest.
struct BenchScene {
  std::string name;  // unique in the manifest
  SceneSource source = SceneSource::kSynth;
  std::string scenario;  // the source's scenario name
  int seed = 0;          // >= 0
  BenchSplit split = BenchSplit::kDev;
  SceneClass scene_class = SceneClass::kCut;
  BenchSceneParams params;
  // A cut is expected in the ground truth; stretch scenes are no-cut scenes too.
  bool ExpectsCut() const { return scene_class == SceneClass::kCut; }
  // Folder name in the scene cache: source, scenario, seed and a hash of every generator
  // parameter, so that a change of any of them makes a new scene.
  std::string CacheKey() const;
};

// Reads the manifest (docs/benchmark.md "Manifest"). An entry with `seeds` (a list) stands for
// one scene per seed, named `<name>-s<seed>`. Throws arreg::Error naming the file and the key
// path of a missing, mistyped, unknown or out-of-range field, and duplicate names.
std::vector<BenchScene> ReadBenchManifest(const std::string& path);
std::vector<BenchScene> ParseBenchManifest(const nlohmann::json& json, const std::string& file);

struct BenchMetricsOptions {
  // An applied cut whose polyline lies within this mean distance of the true cut surface is
  // a found cut, farther a misplaced one (mm); default 10.
  double found_within_mm = 10.0;
  // The true cut counts as open from the first frame its opening reaches this (mm); default 2.
  double opening_mm = 2.0;
  // Spacing of the samples along a polyline for the cut-line error (mm); default 0.5.
  double sample_step_mm = 0.5;
  void Check() const;
};

// Length-weighted mean distance of a polyline (rest frame, mm) to a surface: each segment is cut
// into ceil(length / step_mm) equal pieces and the distance is taken at their midpoints. A
// polyline of one point (or of zero length) gives that point's distance. Throws for an empty one.
double PolylineSurfaceError(const std::vector<Eigen::Vector3d>& polyline,
                            const TriangleDistanceQuery& surface, double step_mm);
// The same over several polylines together, a segment repeated in a later polyline (the same
// two end points) counted once: later cut events repeat the segments applied before.
double PolylinesSurfaceError(const std::vector<std::vector<Eigen::Vector3d>>& polylines,
                             const TriangleDistanceQuery& surface, double step_mm);

// First index whose value is >= threshold; none when no value reaches it.
std::optional<int> FirstFrameAtLeast(const std::vector<double>& values, double threshold);

// An applied cut event of a run (frames.jsonl, status "cut").
struct AppliedCut {
  int frame = 0;
  std::vector<Eigen::Vector3d> polyline_rest_mm;
};
// Throws arreg::Error naming the file and line for an applied event without a usable
// `polyline_rest_mm`.
std::vector<AppliedCut> ReadAppliedCuts(const std::string& frames_jsonl);

// The true cut of a ground-truth folder (gt/cut.json).
struct TrueCut {
  bool present = false;
  SurfaceMesh surface;                            // gt/cut_surface.obj, rest frame (mm)
  std::optional<std::vector<double>> opening_mm;  // per frame; absent in older ground truth
};
TrueCut ReadTrueCut(const std::string& gt_dir);

// How a scene of the benchmark ended: measured, skipped (its source is unavailable) or failed.
enum class SceneStatus { kOk, kSkipped, kFailed };
// The spelling in the JSON: "ok", "skipped", "failed".
const char* SceneStatusName(SceneStatus status);
// Inverse of SceneStatusName; throws arreg::Error naming `field` for any other name.
SceneStatus ParseSceneStatus(const std::string& name, const std::string& field);

// Everything the benchmark reports for one scene (docs/benchmark.md "Metrics").
struct SceneResult {
  std::string name, scenario;
  SceneSource source = SceneSource::kSynth;
  BenchSplit split = BenchSplit::kDev;
  SceneClass scene_class = SceneClass::kCut;
  SceneStatus status = SceneStatus::kOk;
  std::string reason;      // why skipped or failed
  int applied_cuts = 0;    // applied cut events of the run with topology
  int found_cuts = 0;      // of those within found_within_mm of the true cut surface
  int misplaced_cuts = 0;  // the others (on a no-cut scene: every applied event)
  bool cut_found = false;
  std::optional<double> cut_line_error_mm;  // every applied polyline together (cut scenes)
  std::optional<int> opening_frame;         // first frame with opening >= opening_mm
  std::optional<int> first_found_cut_frame;
  std::optional<int> latency_frames;  // first_found_cut_frame - opening_frame
  std::optional<double> dice_final, dice_final_no_topology, dice_min;
  // Per frame the mean of the two directed mean distances; mean over frames and worst frame.
  std::optional<double> surface_mean_mm, surface_worst_mm;
  std::optional<double> internal_mean_mm, internal_worst_mm;
  double seconds = 0;  // wall time of the scene (generation, runs, evaluation)

  static SceneResult For(const BenchScene& scene);
  nlohmann::json ToJson() const;
  static SceneResult FromJson(const nlohmann::json& json, const std::string& file);
};

// Scores the applied cuts against the true cut. Throws arreg::Error when the ground truth's
// cut does not match the scene class (a cut scene without a cut or the reverse).
void ScoreCuts(const std::vector<AppliedCut>& applied, const TrueCut& truth,
               const BenchMetricsOptions& options, SceneResult* result);
// Dice and Hausdorff figures of the run with topology and the final Dice of the one without.
void ScoreRegistration(const RunEvaluation& with_topology, const RunEvaluation& without_topology,
                       SceneResult* result);

// One line of the table: the scenes of one source, scenario and split.
struct GroupRow {
  std::string scenario;
  SceneSource source = SceneSource::kSynth;
  BenchSplit split = BenchSplit::kDev;
  SceneClass scene_class = SceneClass::kCut;
  int scenes = 0, ok = 0, skipped = 0, failed = 0;
  std::optional<double> recall;                 // cut: scenes with a found cut / ok scenes
  std::optional<double> false_cuts_per_scene;   // no-cut, stretch: applied events / ok scenes
  std::optional<double> false_cut_scenes;       // no-cut, stretch: share of ok scenes with one
  std::optional<double> misplaced_per_scene;    // cut: misplaced events / ok scenes
  std::optional<double> cut_line_error_mm;      // cut: mean over scenes with an applied cut
  std::optional<double> latency_median_frames;  // cut: median over scenes with a latency
  std::optional<double> dice_final, dice_final_no_topology;  // means over ok scenes
  std::optional<double> error_ratio;  // sum(1 - Dice with) / sum(1 - Dice without)
  std::optional<double> dice_min;     // smallest per-frame Dice of any scene
  std::optional<double> surface_mean_mm, surface_worst_mm;    // mean of means, worst frame
  std::optional<double> internal_mean_mm, internal_worst_mm;  // same, scenes with structures
  nlohmann::json ToJson() const;
};
// Groups by (source, scenario, split), in order of first appearance.
std::vector<GroupRow> AggregateResults(const std::vector<SceneResult>& results);
std::string FormatTable(const std::vector<GroupRow>& rows);

// One acceptance line of issue 33 with its measured value; `pass` is absent when no scene
// measures it.
struct Criterion {
  std::string text;
  std::string measured;
  std::optional<bool> pass;
  nlohmann::json ToJson() const;
};
// The acceptance criteria of issue 33 over the given results (one split, both sources).
std::vector<Criterion> AcceptanceCriteria(const std::vector<SceneResult>& results);

}  // namespace arreg::eval
