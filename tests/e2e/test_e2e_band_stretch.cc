// Issue 6 acceptance on the synthetic band-stretch scene (default size: 120 frames at
// 640 x 512): `arreg synth` -> `arreg run` -> `arreg eval` through the library calls.
#include <gtest/gtest.h>

#include <algorithm>
#include <string>

#include "ar/eval/evaluation.h"
#include "ar/pipeline/record_writer.h"
#include "ar/pipeline/registration_pipeline.h"
#include "ar/synth/generator.h"
#include "core/scene.h"
#include "test_util.h"

namespace arreg {
namespace {

TEST(EndToEnd, BandStretchRegistersWithoutCuts) {
  const std::string dir = testing::ScratchDir("e2e_band_stretch");
  synth::SynthOptions so;
  so.scenario = "band-stretch";
  so.out_dir = dir + "/scene";  // default size, frames and seed
  synth::GenerateSyntheticScene(so);

  const Scene scene = ReadScene(dir + "/scene/scene.json");
  const pipeline::PipelineOptions options = pipeline::ReadPipelineOptions(scene);
  pipeline::RegistrationPipeline pipe(scene, options);
  pipeline::RecordWriter records(dir + "/run", false);
  pipe.AddObserver(&records);
  pipeline::RunOptions run;
  run.overlay_video_path = dir + "/run/overlay.mp4";
  const pipeline::RunSummary summary = pipe.Run(run);
  EXPECT_EQ(summary.frames, so.frames);
  // The band is stretched without any cut: the detector must stay silent.
  EXPECT_EQ(summary.cut_events, 0);
  EXPECT_EQ(summary.cuts_applied, 0);

  eval::EvalOptions eo;
  eo.color_maps = false;
  const eval::RunEvaluation ev = eval::EvaluateRun(dir + "/run", dir + "/scene/gt", eo);
  std::printf("band-stretch: Dice final %.4f mean %.4f; surface Hausdorff mean %.3f / %.3f mm\n",
              ev.dice_final, ev.dice_mean, ev.surface->mean_model_to_gt,
              ev.surface->mean_gt_to_model);
  EXPECT_GE(ev.dice_final, 0.95);
  ASSERT_TRUE(ev.surface.has_value());
  EXPECT_LE(std::max(ev.surface->mean_model_to_gt, ev.surface->mean_gt_to_model), 2.0);

  // Twice the features (the detector's radii shrink with their spacing): still no cut. Before
  // the detector's opening balance, stem features the model could not follow made 1-2 cuts here.
  pipeline::PipelineOptions dense = options;
  dense.tracking.surf.hessian_threshold = 0.5;
  dense.tracking.min_distance_px = 2;
  struct Attached : pipeline::FrameObserver {
    int features = 0;
    void OnStart(const pipeline::RunStart& s) override { features = s.features_attached; }
    void OnFrame(const pipeline::FrameState&) override {}
  } attached;
  pipeline::RegistrationPipeline dense_pipe(scene, dense);
  dense_pipe.AddObserver(&attached);
  const pipeline::RunSummary dense_summary = dense_pipe.Run(pipeline::RunOptions());
  std::printf("band-stretch, %d features attached: %d cut events\n", attached.features,
              dense_summary.cut_events);
  EXPECT_GE(attached.features, 400);
  EXPECT_EQ(dense_summary.cut_events, 0);
}

// The band-stretch scene of `seed`, generated under a scratch directory of its own (`tag` tells
// apart two tests of one seed, which ctest may run at once).
Scene BandStretchScene(int seed, const std::string& tag = "") {
  const std::string dir = testing::ScratchDir("e2e_band_stretch_seed" + std::to_string(seed) + tag);
  synth::SynthOptions so;
  so.scenario = "band-stretch";
  so.seed = seed;
  so.out_dir = dir + "/scene";
  synth::GenerateSyntheticScene(so);
  return ReadScene(dir + "/scene/scene.json");
}

pipeline::RunSummary RunScene(const Scene& scene, const pipeline::PipelineOptions& options) {
  return pipeline::RegistrationPipeline(scene, options).Run(pipeline::RunOptions());
}

// Seed 24 (of 41 band-stretch seeds, 15 made events before session 18, 13 of them only
// rejected ones like these): the strain concentrations at the stem's two re-entrant corners,
// which the coarse model cannot follow, pass the detector's tests at one corner (frame 29) and
// then at the other (frame 36); joined, they make a polyline across the stem whose cut
// keep_connected rejects at every depth. The detector now asks before adding such a segment
// (cutting.refuse_splitting_segments): no event. Without the rule the same run makes rejected
// events, so the seed still exercises it. These corners were found on the tracks of
// frame-to-frame LK: the drift-corrected tracks (the default since session 21) start nothing
// here, so the rule is exercised without the correction.
TEST(EndToEnd, BandStretchStemCornersAreNotJoinedIntoACut) {
  const Scene scene = BandStretchScene(24);
  pipeline::PipelineOptions options = pipeline::ReadPipelineOptions(scene);
  ASSERT_TRUE(options.cutting.refuse_splitting_segments);
  EXPECT_EQ(RunScene(scene, options).cut_events, 0);
  options.tracking.drift.enabled = false;
  const pipeline::RunSummary summary = RunScene(scene, options);
  EXPECT_EQ(summary.cut_events, 0);
  EXPECT_EQ(summary.cuts_applied, 0);
  options.cutting.refuse_splitting_segments = false;
  const pipeline::RunSummary without = RunScene(scene, options);
  std::printf("band-stretch seed 24: %d cut events, %d without refuse_splitting_segments\n",
              summary.cut_events, without.cut_events);
  EXPECT_GT(without.cut_events, 0);
  EXPECT_EQ(without.cuts_applied, 0);
}

// Seed 38 (of 41 band-stretch seeds, the one that still made an event after session 18): at
// frame 27 one band feature above the stem's left corner opens from five stem features below it,
// all as far from their model points as it is (a strain concentration the coarse model cannot
// follow), so neither the lone-feature test nor the balance test rejects the cluster; the point
// starts a polyline that grows at frame 39 from another band feature's star, and the event cuts
// into the junction. A star no longer starts a polyline (cutting.reject_star_starts): no event.
// As for seed 24, on the tracks of frame-to-frame LK (the drift-corrected ones start nothing).
TEST(EndToEnd, BandStretchStarAtTheStemCornerStartsNoCut) {
  const Scene scene = BandStretchScene(38);
  pipeline::PipelineOptions options = pipeline::ReadPipelineOptions(scene);
  ASSERT_TRUE(options.cutting.detector.reject_star_starts);
  EXPECT_EQ(RunScene(scene, options).cut_events, 0);
  options.tracking.drift.enabled = false;
  const pipeline::RunSummary summary = RunScene(scene, options);
  EXPECT_EQ(summary.cut_events, 0);
  options.cutting.detector.reject_star_starts = false;
  const pipeline::RunSummary without = RunScene(scene, options);
  std::printf("band-stretch seed 38: %d cut events, %d without reject_star_starts\n",
              summary.cut_events, without.cut_events);
  EXPECT_GT(without.cut_events, 0);
}

// Seed 62 (one of the three of the fresh seeds 61-80 that made an event after session 19): at
// frame 36 four pairs across the stem's junction, two features on each side, pass every test of
// the image-only measure, and the polyline grows at frame 38 into an event along the junction.
// The model-regularised measure has no start there, so with conservative starts
// (cutting.confirm_starts_with_model_measure, opt-in) the start is not confirmed: no event.
// As for seed 24, on the tracks of frame-to-frame LK: the drift-corrected ones start nothing.
// Per frame, the starts one of the detector's tests refused (`counter`, e.g. unconfirmed_starts):
// each is a cluster of at least one outlier, and the clusters of a frame are disjoint, so a frame
// never counts more than its outliers.
class RejectedStartsWatcher : public pipeline::FrameObserver {
 public:
  explicit RejectedStartsWatcher(int cutting::DetectionResult::*counter) : counter_(counter) {}
  void OnFrame(const pipeline::FrameState& frame) override {
    if (frame.detection == nullptr) return;
    const int count = frame.detection->*counter_;
    total += count;
    if (count > static_cast<int>(frame.detection->outliers.size())) ++frames_over_outliers;
  }
  int total = 0;
  int frames_over_outliers = 0;

 private:
  int cutting::DetectionResult::*counter_;
};

TEST(EndToEnd, BandStretchJunctionStartUnconfirmedByTheModelMeasure) {
  const Scene scene = BandStretchScene(62);
  pipeline::PipelineOptions options = pipeline::ReadPipelineOptions(scene);
  ASSERT_FALSE(options.cutting.detector.confirm_starts_with_model_measure);
  EXPECT_EQ(RunScene(scene, options).cut_events, 0);
  options.tracking.drift.enabled = false;
  const pipeline::RunSummary by_default = RunScene(scene, options);
  options.cutting.detector.confirm_starts_with_model_measure = true;
  pipeline::RegistrationPipeline pipe(scene, options);
  RejectedStartsWatcher watcher(&cutting::DetectionResult::unconfirmed_starts);
  pipe.AddObserver(&watcher);
  const pipeline::RunSummary conservative = pipe.Run(pipeline::RunOptions());
  std::printf(
      "band-stretch seed 62: %d cut events, %d with confirm_starts_with_model_measure (%d starts "
      "unconfirmed)\n",
      by_default.cut_events, conservative.cut_events, watcher.total);
  EXPECT_GT(by_default.cut_events, 0);
  EXPECT_EQ(conservative.cut_events, 0);
  EXPECT_GT(watcher.total, 0);
  EXPECT_EQ(watcher.frames_over_outliers, 0);
}

// Seed 30 (one of the ten of 81 seeds that made an event with the drift-corrected tracks
// before session 21): while the band is released, the coarse model lags at the stem behind
// targets that are right, and at frame 101 a cluster of pairs across the lag opens on both
// sides; but its pairs are shrinking, as the tissue relaxes, and a cut opens its pairs. A
// cluster whose pairs close starts no cut (cutting.closing_window_frames): no event; without the
// rule the start grows into an event.
TEST(EndToEnd, BandStretchReleaseClosesTheStemsPairsAndStartsNoCut) {
  const Scene scene = BandStretchScene(30);
  pipeline::PipelineOptions options = pipeline::ReadPipelineOptions(scene);
  ASSERT_TRUE(options.tracking.drift.enabled);
  ASSERT_GT(options.cutting.detector.closing_window_frames, 0);
  pipeline::RegistrationPipeline pipe(scene, options);
  RejectedStartsWatcher watcher(&cutting::DetectionResult::closing_starts);
  pipe.AddObserver(&watcher);
  const pipeline::RunSummary summary = pipe.Run(pipeline::RunOptions());
  options.cutting.detector.closing_window_frames = 0;
  const pipeline::RunSummary without = RunScene(scene, options);
  std::printf("band-stretch seed 30: %d cut events (%d closing starts), %d without the rule\n",
              summary.cut_events, watcher.total, without.cut_events);
  EXPECT_EQ(summary.cut_events, 0);
  EXPECT_GT(watcher.total, 0);
  EXPECT_GT(without.cut_events, 0);
}

// Seed 30 again, with twice the features (Hessian threshold 0.5, 2 px apart; ~440 features and
// a shorter r_F), where 16 of 81 band-stretch seeds made cuts before session 23: a lone point at
// a stem corner was grown the next frames by a cluster across the stem whose lower side's
// targets lag their model points as the upper side's lead them (opening balance -0.23 to -0.06
// on 13 of the 16). Across a cut the uncut model spans the gap and no lip's targets lie inward,
// so such a growth is rejected and the lone point dropped (cutting.min_lone_growth_balance): no
// event here (4 of the 81 seeds still make one); without the rule 3 events.
TEST(EndToEnd, BandStretchWithTwiceTheFeaturesGrowsNoLonePointIntoACut) {
  const Scene scene = BandStretchScene(30, "_dense");
  pipeline::PipelineOptions options = pipeline::ReadPipelineOptions(scene);
  options.tracking.surf.hessian_threshold = 0.5;
  options.tracking.min_distance_px = 2;
  ASSERT_EQ(options.cutting.detector.min_lone_growth_balance, 0.0);
  const pipeline::RunSummary summary = RunScene(scene, options);
  options.cutting.detector.min_lone_growth_balance = -1.0;
  const pipeline::RunSummary without = RunScene(scene, options);
  std::printf("band-stretch seed 30, twice the features: %d cut events, %d without the rule\n",
              summary.cut_events, without.cut_events);
  EXPECT_EQ(summary.cut_events, 0);
  EXPECT_GT(without.cut_events, 0);
}

}  // namespace
}  // namespace arreg
