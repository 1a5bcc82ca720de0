// End-to-end generation of every scenario at its default size (640 x 512,
// 100 frames): the truth converges, keeps its volume, cuts really open, and
// the outputs read back (video frame count, scene file). Labelled slow.
#include <gtest/gtest.h>

#include <cstdio>

#include "ar/synth/generator.h"
#include "ar/synth/scenarios.h"
#include "core/scene.h"
#include "test_util.h"
#include "tracking/video_io.h"

namespace arreg::synth {
namespace {

class ScenarioAtDefaultSize : public ::testing::TestWithParam<std::string> {};

TEST_P(ScenarioAtDefaultSize, GeneratesAConsistentScene) {
  const std::string name = GetParam();
  SynthOptions o;
  o.scenario = name;
  o.out_dir = testing::ScratchDir("synth_slow_" + name);
  o.frames = 100;
  const SynthSummary s = GenerateSyntheticScene(o);
  std::printf(
      "%s: %.1f s, truth %d tets (model %d), %d Newton iterations, max volume change "
      "%.3f %%, cut open fraction %.2f, max opening %.1f mm\n",
      name.c_str(), s.seconds, s.truth_tetrahedra, s.model_tetrahedra, s.newton_iterations,
      100 * s.max_volume_change, s.cut_open_fraction, s.max_cut_opening_mm);
  RecordProperty("seconds", std::to_string(s.seconds));
  EXPECT_EQ(s.unconverged_frames, 0);
  EXPECT_GE(s.truth_tetrahedra, 4 * s.model_tetrahedra);
  EXPECT_LT(s.max_volume_change, 0.02);
  if (name == "band-stretch") {
    EXPECT_EQ(s.cut_first_frame, -1);
    EXPECT_EQ(s.final_truth_vertices, s.truth_vertices);
  } else {
    EXPECT_GE(s.cut_first_frame, 0);
    EXPECT_GE(s.cut_open_fraction, 0.5);
    EXPECT_GT(s.max_cut_opening_mm, 2.0);
  }
  const Scene scene = ReadScene(o.out_dir + "/scene.json");
  EXPECT_EQ(scene.camera.width, 640);
  EXPECT_EQ(scene.camera.height, 512);
  EXPECT_EQ(scene.internal_structures.size(), name == "kidney-cut" ? 1u : 0u);
  // Membranes: a shell and no tet model; vessel-cut: the organ and its vessel.
  const bool membrane = name.rfind("membrane-", 0) == 0;
  EXPECT_EQ(scene.thin_structures.size(), membrane || name == "vessel-cut" ? 1u : 0u);
  EXPECT_EQ(scene.model_mesh_path.empty(), membrane);
  VideoReader video;
  video.Open(scene.video_path);
  int frames = 0;
  cv::Mat image;
  while (video.Read(&image)) ++frames;
  EXPECT_EQ(frames, 100);
}

INSTANTIATE_TEST_SUITE_P(AllScenarios, ScenarioAtDefaultSize,
                         ::testing::Values("band-stretch", "band-precut-side", "band-precut-middle",
                                           "band-cut-v", "band-cut-s", "kidney-cut", "membrane-cut",
                                           "membrane-tear", "vessel-cut"),
                         [](const auto& info) {
                           std::string n = info.param;
                           for (char& c : n)
                             if (c == '-') c = '_';
                           return n;
                         });

}  // namespace
}  // namespace arreg::synth
