// Issue 7 end-to-end acceptance on cut scenes: a synthetic scenario is generated, registered with
// and without topology updates and evaluated against its ground truth; and the real clip.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <functional>
#include <limits>
#include <string>

#include "ar/eval/evaluation.h"
#include "ar/pipeline/record_writer.h"
#include "ar/pipeline/registration_pipeline.h"
#include "ar/synth/generator.h"
#include "core/mesh_generators.h"
#include "core/mesh_io.h"
#include "core/scene.h"
#include "test_util.h"

namespace arreg {
namespace {

struct RegisteredRun {
  pipeline::RunSummary summary;
  eval::RunEvaluation evaluation;
};

// Generates `scenario` (seed, frames) into dir/scene, its ground truth saved every 10th frame
// and the last (the frames evaluated); returns that folder.
std::string GenerateScene(const std::string& dir, const char* scenario, int frames, int seed) {
  synth::SynthOptions so;
  so.scenario = scenario;
  so.out_dir = dir + "/scene";
  so.frames = frames;
  so.surface_every_k = 10;
  so.seed = seed;
  synth::GenerateSyntheticScene(so);
  return so.out_dir;
}

// Registers the scene of `scene_dir` with the scene's options, changed by `adjust`, and
// evaluates it against scene_dir/gt; `watcher`, if any, observes the run.
RegisteredRun RegisterAndEvaluate(
    const std::string& scene_dir, const std::string& run_dir,
    const std::function<void(pipeline::PipelineOptions*)>& adjust = {},
    pipeline::FrameObserver* watcher = nullptr) {
  const Scene scene = ReadScene(scene_dir + "/scene.json");
  pipeline::PipelineOptions options = pipeline::ReadPipelineOptions(scene);
  options.render.enabled = false;  // Dice and Hausdorff use the saved meshes, not the overlay
  if (adjust) adjust(&options);
  pipeline::RegistrationPipeline pipe(scene, options);
  pipeline::RecordWriter records(run_dir, false);
  pipe.AddObserver(&records);
  if (watcher) pipe.AddObserver(watcher);
  RegisteredRun out;
  out.summary = pipe.Run(pipeline::RunOptions());
  eval::EvalOptions eo;
  eo.color_maps = false;
  out.evaluation = eval::EvaluateRun(run_dir, scene_dir + "/gt", eo);
  return out;
}

// One acceptance case: the figures that hold on it (issue 7 asks for Dice >= 0.95 everywhere and
// the thesis margins: +0.06 for precut bands, +0.15 for cuts made while filmed).
struct CutCase {
  const char* scenario;
  int frames;
  int min_cuts_applied;           // cut events applied with topology updates
  double min_dice_with_topology;  // final Dice with topology updates
  double min_dice_gain;           // final Dice with minus without topology
  bool hausdorff_lower;           // kidney: surface and internal Hausdorff means lower with cuts
};

void PrintTo(const CutCase& c, std::ostream* os) { *os << c.scenario; }

class EndToEndCut : public ::testing::TestWithParam<CutCase> {};

TEST_P(EndToEndCut, RegistrationWithAndWithoutTopology) {
  const CutCase& c = GetParam();
  const std::string dir = testing::ScratchDir(std::string("e2e_cuts_") + c.scenario);
  const std::string scene = GenerateScene(dir, c.scenario, c.frames, 1);
  const RegisteredRun with = RegisterAndEvaluate(scene, dir + "/with");
  const RegisteredRun without = RegisterAndEvaluate(
      scene, dir + "/without", [](pipeline::PipelineOptions* o) { o->cutting.enabled = false; });
  const eval::RunEvaluation& a = with.evaluation;
  const eval::RunEvaluation& b = without.evaluation;
  ASSERT_TRUE(a.surface.has_value() && b.surface.has_value());
  std::printf(
      "%s (%d frames): cut events %d (applied %d); Dice final %.4f vs %.4f without; "
      "surface Hausdorff mean %.3f/%.3f vs %.3f/%.3f mm\n",
      c.scenario, c.frames, with.summary.cut_events, with.summary.cuts_applied, a.dice_final,
      b.dice_final, a.surface->mean_model_to_gt, a.surface->mean_gt_to_model,
      b.surface->mean_model_to_gt, b.surface->mean_gt_to_model);
  if (a.internal && b.internal)
    std::printf("  internal Hausdorff mean %.3f/%.3f vs %.3f/%.3f mm\n",
                a.internal->mean_model_to_gt, a.internal->mean_gt_to_model,
                b.internal->mean_model_to_gt, b.internal->mean_gt_to_model);

  EXPECT_GE(with.summary.cuts_applied, c.min_cuts_applied);
  EXPECT_EQ(without.summary.cut_events, 0);
  EXPECT_GE(a.dice_final, c.min_dice_with_topology);
  EXPECT_GE(a.dice_final - b.dice_final, c.min_dice_gain);
  if (c.hausdorff_lower) {
    ASSERT_TRUE(a.internal.has_value() && b.internal.has_value());
    // Each direction on its own: since the cut structure is capped (session 9), the truth's
    // cut faces find the model's caps, not the rim of a hole.
    EXPECT_LT(a.internal->mean_model_to_gt, b.internal->mean_model_to_gt);
    EXPECT_LT(a.internal->mean_gt_to_model, b.internal->mean_gt_to_model);
    EXPECT_LT(a.surface->mean_model_to_gt, b.surface->mean_model_to_gt);
    EXPECT_LT(a.surface->mean_gt_to_model, b.surface->mean_gt_to_model);
  }
}

// Thresholds: what holds here (72 frames, seed 1) and at 120 frames on seeds 1 and 2, with the
// default detector and spring parameters on every scene (docs/cutting.md, "Session 6"), set
// before the output fit (docs/pipeline.md, "Output fit"), which raised every figure. Measured
// here with it (session 11): kidney-cut 2 cuts, 0.962 vs 0.913 without, surface and internal
// Hausdorff means lower; band-cut-v 4 cuts, 0.971 vs 0.859; band-cut-s 6 cuts, 0.971 vs 0.903;
// band-precut-side 1 cut, 0.955 vs 0.936; band-precut-middle 1 cut, 0.977 vs 0.969. With the
// integrator's line search (session 13) band-cut-v has 3 cuts, 0.956 vs 0.853 (docs/cutting.md
// "Session 13"), the others as above to 0.001. Since `tracking.min_features` (session 17) the
// kidney carries 200 features instead of 124: 2 cuts, 0.968 vs 0.940 without, so it is held to
// issue 7's 0.95. Issue 7 asks for Dice >= 0.95 (at 120 frames not met on kidney-cut seed 23,
// docs/cutting.md "Session 17") and gains of +0.15 / +0.06 (not met).
INSTANTIATE_TEST_SUITE_P(Scenarios, EndToEndCut,
                         ::testing::Values(CutCase{"kidney-cut", 72, 1, 0.95, 0.005, true},
                                           CutCase{"band-cut-v", 72, 2, 0.93, 0.08, false},
                                           CutCase{"band-cut-s", 72, 1, 0.90, 0.02, false},
                                           CutCase{"band-precut-side", 72, 1, 0.92, 0.01, false},
                                           CutCase{"band-precut-middle", 72, 1, 0.94, -0.005,
                                                   false}),
                         [](const ::testing::TestParamInfo<CutCase>& info) {
                           std::string name = info.param.scenario;
                           for (char& ch : name)
                             if (ch == '-') ch = '_';
                           return name;
                         });

// The lowest frame-0 y of the cut points the detector inserts, and the frame of the first.
class CutPointWatcher : public pipeline::FrameObserver {
 public:
  void OnFrame(const pipeline::FrameState& frame) override {
    if (frame.detection == nullptr) return;
    for (const cutting::CutPoint& p : frame.detection->new_cut_points) {
      lowest_y_mm = std::min(lowest_y_mm, p.initial_position_mm.y());
      if (first_frame < 0) first_frame = frame.frame;
    }
  }
  double lowest_y_mm = std::numeric_limits<double>::infinity();
  int first_frame = -1;  // -1: none
};

// band-cut-v seed 4, 120 frames: the tear runs down x = 50 mm from the top edge (y = 110 mm) to
// y = 35 mm, and the band meets its stem at y = 0, a junction stretched as the band opens into
// a V. The growth probe's outliers there lie 28-50 mm ahead of the polyline's end; without the
// lead limit (cutting.probe_max_lead_factor) the probe put a point there (y = 12.6 mm at frame
// 105) and the model was cut towards the junction. With it, no cut point lies below 20 mm and
// the final Dice holds issue 7's 0.95 (docs/detection.md "A tear grows from its tip").
TEST(EndToEnd, BandCutVTearIsNotGrownIntoTheJunction) {
  const std::string dir = testing::ScratchDir("e2e_cuts_band_cut_v_seed4");
  const std::string scene = GenerateScene(dir, "band-cut-v", 120, 4);
  const auto lead = [](double factor) {
    return [factor](pipeline::PipelineOptions* o) {
      o->cutting.detector.probe_max_lead_factor = factor;
    };
  };
  CutPointWatcher limited, unlimited;
  const RegisteredRun with = RegisterAndEvaluate(scene, dir + "/limited", lead(1.0), &limited);
  RegisterAndEvaluate(scene, dir + "/unlimited", lead(100.0), &unlimited);
  std::printf(
      "band-cut-v seed 4: %d cuts applied, final Dice %.4f, lowest cut point y = %.1f mm "
      "(%.1f mm without the lead limit)\n",
      with.summary.cuts_applied, with.evaluation.dice_final, limited.lowest_y_mm,
      unlimited.lowest_y_mm);
  EXPECT_GE(with.summary.cuts_applied, 3);
  EXPECT_GT(limited.lowest_y_mm, 20.0);
  EXPECT_LT(unlimited.lowest_y_mm, 20.0);
  EXPECT_GE(with.evaluation.dice_final, 0.95);
}

// band-cut-v seed 22, 120 frames: the tracker loses the tear's lip features as it opens, so the
// clusters across it are of bridges whose endpoints lie at unequal distances from the seam, and
// their balance (0.36-0.50) fell below cutting.min_opening_balance in every frame: nothing was
// cut (final Dice 0.866). Held to min_opening_balance_bridges (1/3), the cut starts at frame 53
// and the final Dice holds issue 7's 0.95 (docs/detection.md "Clusters of bridges").
TEST(EndToEnd, BandCutVTearWhoseLipsAreLostStartsFromBridges) {
  const std::string dir = testing::ScratchDir("e2e_cuts_band_cut_v_seed22");
  const std::string scene = GenerateScene(dir, "band-cut-v", 120, 22);
  const auto bound = [](double balance) {
    return [balance](pipeline::PipelineOptions* o) {
      o->cutting.detector.min_opening_balance_bridges = balance;
    };
  };
  CutPointWatcher bridges, strict;
  const RegisteredRun with =
      RegisterAndEvaluate(scene, dir + "/bridges", bound(1.0 / 3.0), &bridges);
  const RegisteredRun without = RegisterAndEvaluate(scene, dir + "/strict", bound(0.5), &strict);
  std::printf(
      "band-cut-v seed 22: first cut point at frame %d, %d cuts applied, final Dice %.4f "
      "(held to 0.5: first point at frame %d, %d cuts, %.4f)\n",
      bridges.first_frame, with.summary.cuts_applied, with.evaluation.dice_final,
      strict.first_frame, without.summary.cuts_applied, without.evaluation.dice_final);
  EXPECT_GE(bridges.first_frame, 37);  // not before the cut opens (its first faces at 37)
  EXPECT_LE(bridges.first_frame, 70);
  EXPECT_GE(with.summary.cuts_applied, 3);
  EXPECT_GE(with.evaluation.dice_final, 0.95);
  EXPECT_EQ(without.summary.cuts_applied, 0);
}

// Counts what the detector had to look at: attached features, and per frame the pairs it
// evaluated and the largest mu relative to the outlier threshold.
class DetectionWatcher : public pipeline::FrameObserver {
 public:
  void OnStart(const pipeline::RunStart& start) override { attached = start.features_attached; }
  void OnFrame(const pipeline::FrameState& frame) override {
    if (frame.detection == nullptr || frame.detection->pairs.size() < 100) return;
    ++frames_with_pairs;
    outliers += static_cast<int>(frame.detection->outliers.size());
  }
  int attached = 0;
  int frames_with_pairs = 0;  // frames with at least 100 pairs evaluated
  int outliers = 0;           // outlier pairs over all frames
};

// The real clip (a grasper pulls soft tissue up and to the right; no cut) registered with a flat
// box model in front of a nominal camera (f = 600 px, no calibration is known). As an initial
// registration would, the model covers tissue only: the region above the grasper and the blue
// instrument at frame 0 (pixels x 200..640, y 0..250). The tissue there is stretched and then
// covered by the grasper, so its features are lost one after the other; the detector must stay
// silent throughout.
TEST(EndToEndRealClip, PullingTissueGivesNoCut) {
  ARREG_REQUIRE_SHARED(video, "real/pulling_tissue.mp4");
  const std::string dir = testing::ScratchDir("e2e_cuts_real_clip");
  // 76 x 42 x 10 mm, front face 100 mm from the camera: x -20..56 mm, y -44..-2 mm.
  TetMesh box = MakeBoxTetMesh(Eigen::Vector3d(76, 42, 10), Eigen::Vector3i(8, 4, 1));
  for (int i = 0; i < box.vertices.rows(); ++i)
    box.vertices.row(i) += Eigen::RowVector3d(-20, -44, 100);
  WriteTetMesh(dir + "/box.vtk", box);
  {
    std::ofstream scene(dir + "/scene.json");
    scene << "{\"model\": \"box.vtk\", \"video\": \"" << video
          << "\", \"camera\": {\"width\": 640, \"height\": 512, \"fx\": 600, \"fy\": 600, "
             "\"cx\": 319.5, \"cy\": 255.5}}\n";
  }
  const Scene scene = ReadScene(dir + "/scene.json");
  pipeline::PipelineOptions options = pipeline::ReadPipelineOptions(scene);
  options.render.enabled = false;
  pipeline::RegistrationPipeline pipe(scene, options);
  DetectionWatcher watcher;
  pipe.AddObserver(&watcher);
  const pipeline::RunSummary summary = pipe.Run(pipeline::RunOptions());
  std::printf(
      "real clip: %d frames, %d features attached, %d frames with >= 100 pairs, %d outlier "
      "pairs in all, %d cut events\n",
      summary.frames, watcher.attached, watcher.frames_with_pairs, watcher.outliers,
      summary.cut_events);
  // The detector had something to look at: the tissue carries features and pairs for the first
  // part of the clip, while the grasper stretches it.
  EXPECT_GE(watcher.attached, 40);
  EXPECT_GE(watcher.frames_with_pairs, 20);
  EXPECT_EQ(summary.frames, 63);
  EXPECT_EQ(summary.cut_events, 0);
}

}  // namespace
}  // namespace arreg
