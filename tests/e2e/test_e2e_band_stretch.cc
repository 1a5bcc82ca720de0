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
}

}  // namespace
}  // namespace arreg
