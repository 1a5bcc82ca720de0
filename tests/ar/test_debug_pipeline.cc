// `arreg run --debug` end to end: a synthetic band cut (arreg synth) registered by the real
// pipeline with the DebugRecorder attached; the records agree with the pipeline's own state.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <vector>

#include "ar/debug/recorder.h"
#include "ar/debug/viewer.h"
#include "ar/pipeline/pipeline_options.h"
#include "ar/pipeline/registration_pipeline.h"
#include "ar/synth/generator.h"
#include "core/file_util.h"
#include "core/scene.h"
#include "test_util.h"

namespace arreg::debug {
namespace {

nlohmann::json ReadJson(const std::string& path) {
  return nlohmann::json::parse(ReadFileToString(path));
}

TEST(DebugPipeline, RecordsOfARealRunAreConsistent) {
  const std::string dir = ::arreg::testing::ScratchDir("debug_pipeline");
  synth::SynthOptions so;
  so.scenario = "band-cut-v";
  so.out_dir = dir + "/synth";
  so.frames = 8;
  so.width = 320;
  so.height = 256;
  synth::GenerateSyntheticScene(so);
  const Scene scene = ReadScene(so.out_dir + "/scene.json");
  const pipeline::PipelineOptions options = pipeline::ReadPipelineOptions(scene);
  const std::string run = dir + "/run";
  DebugRecorderOptions ro;
  ro.run_dir = run;
  DebugRecorder recorder(ro);
  pipeline::RegistrationPipeline pipe(scene, options);
  pipe.AddObserver(&recorder);
  const pipeline::RunSummary s = pipe.Run();
  ASSERT_EQ(s.frames, 8);
  EXPECT_EQ(recorder.frames_recorded(), 8);

  const nlohmann::json meta = ReadJson(DebugDir(run) + "/meta.json");
  EXPECT_TRUE(meta["finished"].get<bool>());
  EXPECT_EQ(meta["summary"]["frames"], 8);
  const double r_f = meta["detector"]["neighbour_radius_mm"].get<double>();
  {
    // The outlier floor is 1 px (cutting.min_outlier_measure_px) at the attached features'
    // median frame-0 depth, or the millimetre floor where that is larger.
    const nlohmann::json rec0 = ReadJson(FrameRecordPath(run, 0));
    const auto& cam = meta["camera"];
    std::vector<double> depth;
    for (const auto& f : rec0["features"]) {
      if (!f["alive"].get<bool>() || f["lift"] == "not-attached") continue;
      const auto& z = cam["camera_from_world"][2];
      depth.push_back(z[0].get<double>() * f["model_mm"][0].get<double>() +
                      z[1].get<double>() * f["model_mm"][1].get<double>() +
                      z[2].get<double>() * f["model_mm"][2].get<double>() + z[3].get<double>());
    }
    ASSERT_FALSE(depth.empty());
    std::nth_element(depth.begin(), depth.begin() + depth.size() / 2, depth.end());
    const double px_mm =
        depth[depth.size() / 2] / (0.5 * (cam["fx"].get<double>() + cam["fy"].get<double>()));
    ASSERT_EQ(options.cutting.min_outlier_measure_px, 1.0);
    EXPECT_GT(px_mm, options.cutting.detector.min_outlier_measure_mm);
    EXPECT_NEAR(meta["detector"]["min_outlier_measure_mm"].get<double>(), px_mm, 1e-3 * px_mm);
  }
  int pairs_seen = 0, targets_seen = 0;
  for (int t = 0; t < s.frames; ++t) {
    const nlohmann::json rec = ReadJson(FrameRecordPath(run, t));
    EXPECT_EQ(rec["features"].size(), meta["start"]["features_detected"].get<size_t>());
    std::map<int, nlohmann::json> by_id;
    for (const auto& f : rec["features"]) {
      by_id[f["id"].get<int>()] = f;
      // A target lifted from the tracked pixel this frame projects back onto it.
      const std::string lift = f["lift"];
      if (f["alive"].get<bool>() && (lift == "surface-hit" || lift == "intercept")) {
        ++targets_seen;
        EXPECT_NEAR(f["target_px"][0].get<double>(), f["px"][0].get<double>(), 0.05);
        EXPECT_NEAR(f["target_px"][1].get<double>(), f["px"][1].get<double>(), 0.05);
      }
    }
    const auto& det = rec["detection"];
    ASSERT_TRUE(det.is_object());
    for (const auto& p : det["pairs"]) {
      ASSERT_TRUE(by_id.count(p[0].get<int>()) && by_id.count(p[1].get<int>()));
      const auto& a = by_id[p[0].get<int>()];
      const auto& b = by_id[p[1].get<int>()];
      EXPECT_NE(a["lift"], "not-attached");
      EXPECT_NE(b["lift"], "not-attached");
      EXPECT_EQ(p[3].get<int>() != 0, p[2].get<double>() > det["threshold"].get<double>());
      if (t == 0) {
        // C_F holds features closer than r_F at frame 0, where p^t is still close to p^0.
        const Eigen::Vector3d pa(a["model_mm"][0], a["model_mm"][1], a["model_mm"][2]);
        const Eigen::Vector3d pb(b["model_mm"][0], b["model_mm"][1], b["model_mm"][2]);
        EXPECT_LT((pa - pb).norm(), r_f + 0.5);
        ++pairs_seen;
      }
    }
  }
  EXPECT_GT(pairs_seen, 20);
  EXPECT_GT(targets_seen, 100);

  const ViewerSummary v = WriteDebugViewer(run, dir + "/viewer");
  EXPECT_EQ(v.frames, 8);
  EXPECT_EQ(v.features, meta["start"]["features_detected"].get<int>());
}

}  // namespace
}  // namespace arreg::debug
