// The accuracy benchmark's metrics against closed forms (cut-line error, latency), its
// aggregation over scenes, the acceptance lines and the manifest's errors.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <functional>
#include <set>
#include <string>
#include <vector>

#include "ar/eval/benchmark.h"
#include "core/error.h"
#include "core/json_reader.h"
#include "test_util.h"

namespace arreg::eval {
namespace {

// The square [-50, 50]^2 of the plane z = 0, two triangles: a planar true cut surface.
SurfaceMesh PlaneSquare() {
  SurfaceMesh s;
  s.vertices.resize(4, 3);
  s.vertices << -50, -50, 0, 50, -50, 0, 50, 50, 0, -50, 50, 0;
  s.faces.resize(2, 3);
  s.faces << 0, 1, 2, 0, 2, 3;
  return s;
}

std::string ErrorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

TEST(BenchMetrics, StraightPolylineAtAKnownOffsetFromAPlane) {
  const SurfaceMesh plane = PlaneSquare();
  const TriangleDistanceQuery q(plane.vertices, plane.faces);
  const std::vector<Eigen::Vector3d> line = {{-20, 0, 3}, {20, 5, 3}};
  EXPECT_NEAR(PolylineSurfaceError(line, q, 0.5), 3.0, 1e-12);
  // Leaving the cut surface's edge at x = 50: distance 0 over [40, 50], x - 50 over [50, 60];
  // the mean over the 20 mm is 100 / 2 / 20 = 2.5 (the midpoint rule is exact on each half).
  const std::vector<Eigen::Vector3d> past_edge = {{40, 0, 0}, {60, 0, 0}};
  EXPECT_NEAR(PolylineSurfaceError(past_edge, q, 0.5), 2.5, 1e-9);
  // One point: its distance.
  EXPECT_NEAR(PolylineSurfaceError({{0, 0, -7}}, q, 0.5), 7.0, 1e-12);
  EXPECT_THROW(PolylineSurfaceError({}, q, 0.5), Error);
}

TEST(BenchMetrics, SegmentsRepeatedByLaterEventsCountOnce) {
  const SurfaceMesh plane = PlaneSquare();
  const TriangleDistanceQuery q(plane.vertices, plane.faces);
  const Eigen::Vector3d a(-20, 0, 4), b(20, 0, 4), c(20, 40, 0);
  // AB at distance 4 (40 mm), BC from 4 to 0 (mean 2, length sqrt(40^2 + 4^2)).
  const double bc = std::sqrt(40.0 * 40 + 4 * 4);
  const double expected = (40 * 4.0 + bc * 2.0) / (40 + bc);
  EXPECT_NEAR(PolylinesSurfaceError({{a, b}, {a, b, c}}, q, 0.5), expected, 1e-9);
  // The same segment walked backwards is the same segment.
  EXPECT_NEAR(PolylinesSurfaceError({{b, a}, {a, b, c}}, q, 0.5), expected, 1e-9);
}

TEST(BenchMetrics, FirstFrameOfAnOpening) {
  EXPECT_EQ(FirstFrameAtLeast({0, 0.5, 1.99, 2.0, 5}, 2.0), 3);
  EXPECT_FALSE(FirstFrameAtLeast({0, 1, 1.5}, 2.0).has_value());
  EXPECT_FALSE(FirstFrameAtLeast({}, 2.0).has_value());
}

SceneResult Result(const std::string& name, const std::string& scenario, SceneClass scene_class) {
  BenchScene b;
  b.name = name;
  b.source = SceneSource::kSynth;
  b.scenario = scenario;
  b.split = BenchSplit::kDev;
  b.scene_class = scene_class;
  return SceneResult::For(b);
}

TEST(BenchMetrics, CutsAreFoundOrMisplacedAndTheLatencyCountsFromTheOpening) {
  TrueCut truth;
  truth.present = true;
  truth.surface = PlaneSquare();
  truth.opening_mm = std::vector<double>{0, 0, 1, 2.5, 3, 4, 5, 6};
  const std::vector<AppliedCut> applied = {
      {6, {{-20, 0, 20}, {20, 0, 20}}},  // 20 mm off: misplaced
      {7, {{-20, 0, 1}, {20, 0, 1}}},    // 1 mm off: found
  };
  SceneResult r = Result("a", "band-cut-v", SceneClass::kCut);
  ScoreCuts(applied, truth, BenchMetricsOptions(), &r);
  EXPECT_EQ(r.applied_cuts, 2);
  EXPECT_EQ(r.found_cuts, 1);
  EXPECT_EQ(r.misplaced_cuts, 1);
  EXPECT_TRUE(r.cut_found);
  EXPECT_EQ(r.opening_frame, 3);
  EXPECT_EQ(r.first_found_cut_frame, 7);
  EXPECT_EQ(r.latency_frames, 4);
  EXPECT_NEAR(*r.cut_line_error_mm, 10.5, 1e-9);  // both polylines, 40 mm each

  // Ground truth without the per-frame opening: no latency.
  truth.opening_mm.reset();
  SceneResult old = Result("b", "band-cut-v", SceneClass::kCut);
  ScoreCuts(applied, truth, BenchMetricsOptions(), &old);
  EXPECT_FALSE(old.latency_frames.has_value());
  EXPECT_TRUE(old.cut_found);

  // A cut scene whose ground truth has no cut, and the reverse, are errors.
  TrueCut none;
  SceneResult wrong = Result("c", "band-cut-v", SceneClass::kCut);
  EXPECT_NE(
      ErrorOf([&] { ScoreCuts(applied, none, BenchMetricsOptions(), &wrong); }).find("class cut"),
      std::string::npos);
  SceneResult stretch = Result("d", "band-stretch", SceneClass::kStretch);
  EXPECT_THROW(ScoreCuts(applied, truth, BenchMetricsOptions(), &stretch), Error);
  ScoreCuts(applied, none, BenchMetricsOptions(), &stretch);
  EXPECT_EQ(stretch.misplaced_cuts, 2);  // every cut on a no-cut scene is false
  EXPECT_FALSE(stretch.cut_line_error_mm.has_value());
}

TEST(BenchResult, StatusRoundTripsThroughJsonAndABadOneNamesTheFile) {
  SceneResult r;
  r.name = "s";
  r.status = SceneStatus::kSkipped;
  r.reason = "no blender";
  const nlohmann::json j = r.ToJson();
  EXPECT_EQ(j.at("status"), "skipped");
  EXPECT_EQ(SceneResult::FromJson(j, "result.json").status, SceneStatus::kSkipped);
  for (SceneStatus s : {SceneStatus::kOk, SceneStatus::kSkipped, SceneStatus::kFailed})
    EXPECT_EQ(ParseSceneStatus(SceneStatusName(s), "status"), s);
  nlohmann::json bad = j;
  bad["status"] = "done";
  try {
    SceneResult::FromJson(bad, "result.json");
    FAIL() << "status 'done' was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("result.json"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("status"), std::string::npos) << e.what();
  }
}

TEST(BenchResult, SourceSplitAndClassRoundTripThroughJson) {
  SceneResult r;
  r.name = "p";
  r.source = SceneSource::kPhantom;
  r.split = BenchSplit::kTest;
  r.scene_class = SceneClass::kNoCut;
  const nlohmann::json j = r.ToJson();
  EXPECT_EQ(j.at("source"), "phantom");
  EXPECT_EQ(j.at("split"), "test");
  EXPECT_EQ(j.at("class"), "no-cut");
  const SceneResult back = SceneResult::FromJson(j, "result.json");
  EXPECT_EQ(back.source, SceneSource::kPhantom);
  EXPECT_EQ(back.split, BenchSplit::kTest);
  EXPECT_EQ(back.scene_class, SceneClass::kNoCut);
  nlohmann::json bad = j;
  bad["split"] = "train";
  EXPECT_NE(ErrorOf([&] {
              SceneResult::FromJson(bad, "result.json");
            }).find("result.json: split: must be dev, test or quick, got 'train'"),
            std::string::npos);
  EXPECT_NE(ErrorOf([] {
              ParseSceneSource("blender", "m.json", "source");
            }).find("must be synth or phantom"),
            std::string::npos);
}

TEST(BenchAggregation, RatesMediansAndRatiosOverScenes) {
  std::vector<SceneResult> results;
  const double with[3] = {0.97, 0.95, 0.90}, without[3] = {0.91, 0.85, 0.90};
  const int latency[3] = {2, 6, 3};
  for (int k = 0; k < 3; ++k) {
    SceneResult r = Result("cut" + std::to_string(k), "band-cut-v", SceneClass::kCut);
    r.cut_found = k < 2;
    r.applied_cuts = 1;
    r.found_cuts = k < 2;
    r.misplaced_cuts = k == 2;
    r.cut_line_error_mm = 1.0 + k;
    if (k < 2) r.latency_frames = latency[k];
    r.dice_final = with[k];
    r.dice_final_no_topology = without[k];
    r.dice_min = with[k] - 0.01;
    r.surface_mean_mm = 1.0 + k;
    r.surface_worst_mm = 2.0 + k;
    results.push_back(r);
  }
  SceneResult failed = Result("cut3", "band-cut-v", SceneClass::kCut);
  failed.status = SceneStatus::kFailed;
  results.push_back(failed);
  for (int k = 0; k < 4; ++k) {
    SceneResult r = Result("stretch" + std::to_string(k), "band-stretch", SceneClass::kStretch);
    r.applied_cuts = r.misplaced_cuts = k == 0 ? 3 : 0;
    r.dice_final = r.dice_final_no_topology = 0.99;
    results.push_back(r);
  }
  const std::vector<GroupRow> rows = AggregateResults(results);
  ASSERT_EQ(rows.size(), 2u);
  const GroupRow& cut = rows[0];
  EXPECT_EQ(cut.scenes, 4);
  EXPECT_EQ(cut.ok, 3);
  EXPECT_EQ(cut.failed, 1);
  EXPECT_NEAR(*cut.recall, 2.0 / 3, 1e-12);
  EXPECT_NEAR(*cut.misplaced_per_scene, 1.0 / 3, 1e-12);
  EXPECT_NEAR(*cut.cut_line_error_mm, 2.0, 1e-12);
  EXPECT_NEAR(*cut.latency_median_frames, 4.0, 1e-12);  // median of 2 and 6
  EXPECT_NEAR(*cut.dice_final, (0.97 + 0.95 + 0.90) / 3, 1e-12);
  EXPECT_NEAR(*cut.error_ratio, (0.03 + 0.05 + 0.10) / (0.09 + 0.15 + 0.10), 1e-12);
  EXPECT_NEAR(*cut.dice_min, 0.89, 1e-12);
  EXPECT_NEAR(*cut.surface_mean_mm, 2.0, 1e-12);
  EXPECT_NEAR(*cut.surface_worst_mm, 4.0, 1e-12);
  EXPECT_FALSE(cut.false_cuts_per_scene.has_value());
  EXPECT_FALSE(cut.internal_mean_mm.has_value());
  const GroupRow& stretch = rows[1];
  EXPECT_NEAR(*stretch.false_cuts_per_scene, 0.75, 1e-12);
  EXPECT_NEAR(*stretch.false_cut_scenes, 0.25, 1e-12);
  EXPECT_FALSE(stretch.recall.has_value());
  EXPECT_NEAR(*stretch.error_ratio, 1.0, 1e-12);  // the same Dice with and without
  // Every row is printed under the header.
  const std::string table = FormatTable(rows);
  EXPECT_NE(table.find("band-cut-v"), std::string::npos);
  EXPECT_NE(table.find("band-stretch"), std::string::npos);

  // Acceptance: 2 of 3 cuts found fails the 95 % line; 1 of 4 no-cut scenes with a cut fails.
  const std::vector<Criterion> criteria = AcceptanceCriteria(results);
  ASSERT_FALSE(criteria.empty());
  EXPECT_EQ(criteria[0].pass, false);
  bool saw_false_cut_line = false;
  for (const Criterion& c : criteria)
    if (c.text.find("false cuts") != std::string::npos) {
      saw_false_cut_line = true;
      EXPECT_EQ(c.pass, false);
      EXPECT_NE(c.measured.find("1 of 4"), std::string::npos) << c.measured;
    }
  EXPECT_TRUE(saw_false_cut_line);
}

TEST(BenchAcceptance, PassesWhenEveryBoundHoldsAndSaysWhenNothingMeasuresALine) {
  std::vector<SceneResult> results;
  for (int k = 0; k < 20; ++k) {
    SceneResult r = Result("c" + std::to_string(k), "band-precut-side", SceneClass::kCut);
    r.cut_found = true;
    r.applied_cuts = r.found_cuts = 1;
    r.cut_line_error_mm = 2.0;
    r.latency_frames = 3;
    r.dice_final = 0.97;
    r.dice_final_no_topology = 0.90;
    results.push_back(r);
  }
  for (const Criterion& c : AcceptanceCriteria(results)) {
    if (c.text.find("cut scenes") == 0)
      EXPECT_EQ(c.pass, true) << c.text << ": " << c.measured;
    else
      EXPECT_FALSE(c.pass.has_value()) << c.text << ": " << c.measured;  // no such scene
  }
}

TEST(BenchManifest, ExpandsSeedsAndKeysTheCacheByEveryParameter) {
  const nlohmann::json j = ParseJsonText(R"({"version": 1, "scenes": [
    {"name": "s", "source": "synth", "scenario": "band-stretch", "seeds": [3, 4],
     "split": "dev", "class": "stretch", "params": {"frames": 50, "size": "320x256",
     "zoom": 1.5}},
    {"name": "p", "source": "phantom", "scenario": "precut", "seed": 9, "split": "test",
     "class": "cut", "params": {"frames": 30, "size": "320x256"}}]})",
                                         "m.json");
  const std::vector<BenchScene> scenes = ParseBenchManifest(j, "m.json");
  ASSERT_EQ(scenes.size(), 3u);
  EXPECT_EQ(scenes[0].name, "s-s3");
  EXPECT_EQ(scenes[1].name, "s-s4");
  EXPECT_EQ(scenes[1].seed, 4);
  EXPECT_EQ(scenes[0].params.width, 320);
  EXPECT_EQ(scenes[0].params.zoom, 1.5);
  EXPECT_EQ(scenes[0].params.amplitude, 1.0);  // the generator's default
  EXPECT_EQ(scenes[2].name, "p");
  EXPECT_TRUE(scenes[2].ExpectsCut());
  // The key changes with the seed and with any parameter.
  EXPECT_NE(scenes[0].CacheKey(), scenes[1].CacheKey());
  BenchScene other = scenes[0];
  other.params.amplitude = 0.9;
  EXPECT_NE(other.CacheKey(), scenes[0].CacheKey());
  EXPECT_EQ(BenchScene(scenes[0]).CacheKey(), scenes[0].CacheKey());
  EXPECT_EQ(scenes[0].CacheKey().rfind("synth-band-stretch-s3-", 0), 0u);
}

TEST(BenchManifest, ErrorsNameTheField) {
  auto error = [](const std::string& scene) {
    const std::string text = R"({"version": 1, "scenes": [)" + scene + "]}";
    return ErrorOf([&] { ParseBenchManifest(ParseJsonText(text, "m.json"), "m.json"); });
  };
  const std::string params = R"("params": {"frames": 30, "size": "320x256"})";
  const std::string head = R"({"name": "a", "source": "synth", "scenario": "band-stretch", )";
  EXPECT_NE(error(head + R"("seed": 1, "class": "stretch", )" + params + "}")
                .find("m.json: scenes[0].split"),
            std::string::npos);
  EXPECT_NE(error(head + R"("seed": 1, "split": "dev", "class": "cuts", )" + params + "}")
                .find(R"(scenes[0].class: "cuts" is not one of "cut", "no-cut", "stretch")"),
            std::string::npos);
  EXPECT_NE(error(head + R"("seed": 1, "split": "dev", "class": "stretch", "params":
                  {"frames": 30, "size": "321x256"}})")
                .find("scenes[0].params.size"),
            std::string::npos);
  EXPECT_NE(error(head + R"("seed": 1, "split": "dev", "class": "stretch", "params":
                  {"size": "320x256"}})")
                .find("scenes[0].params.frames"),
            std::string::npos);
  EXPECT_NE(
      error(head + R"("split": "dev", "class": "stretch", )" + params + "}").find("scenes[0].seed"),
      std::string::npos);
  // Synth-only parameters are unknown keys for a phantom scene.
  EXPECT_NE(error(R"({"name": "p", "source": "phantom", "scenario": "precut", "seed": 1,
                  "split": "dev", "class": "cut", "params": {"frames": 30, "size": "320x256",
                  "zoom": 2}})")
                .find("zoom"),
            std::string::npos);
  const std::string one =
      head + R"("seed": 1, "split": "dev", "class": "stretch", )" + params + "}";
  EXPECT_NE(error(one + "," + one).find("duplicate scene name 'a'"), std::string::npos);
  EXPECT_NE(ErrorOf([] {
              ParseBenchManifest(ParseJsonText(R"({"version": 2, "scenes": []})", "m.json"),
                                 "m.json");
            }).find("version"),
            std::string::npos);
}

TEST(BenchManifest, TheCommittedManifestReadsAndHasBothSplitsAndTheQuickSubset) {
  const std::vector<BenchScene> scenes =
      ReadBenchManifest(std::string(ARREG_SOURCE_DIR) + "/data/benchmark/accuracy.json");
  int dev = 0, test = 0, quick = 0;
  std::set<int> dev_seeds, test_seeds;
  for (const BenchScene& s : scenes) {
    dev += s.split == BenchSplit::kDev;
    test += s.split == BenchSplit::kTest;
    quick += s.split == BenchSplit::kQuick;
    (s.split == BenchSplit::kDev ? dev_seeds : test_seeds).insert(s.seed);
  }
  EXPECT_GE(dev, 25);
  EXPECT_GE(test, 25);
  EXPECT_GE(quick, 2);
  for (int seed : dev_seeds) EXPECT_EQ(test_seeds.count(seed), 0u) << seed;
}

TEST(BenchRecords, AppliedCutsComeWithTheirRestPolyline) {
  const std::string dir = testing::ScratchDir("bench_records");
  const std::string path = dir + "/frames.jsonl";
  {
    std::ofstream out(path);
    out << R"({"frame": 0, "cut_events": []})"
        << "\n";
    out << R"({"frame": 1, "cut_events": [{"frame": 1, "status": "rejected", "polyline_rest_mm": []},)"
        << R"( {"frame": 1, "status": "cut", "polyline_rest_mm": [[0, 0, 1], [10, 0, 1]]}]})"
        << "\n";
  }
  const std::vector<AppliedCut> cuts = ReadAppliedCuts(path);
  ASSERT_EQ(cuts.size(), 1u);
  EXPECT_EQ(cuts[0].frame, 1);
  ASSERT_EQ(cuts[0].polyline_rest_mm.size(), 2u);
  EXPECT_EQ(cuts[0].polyline_rest_mm[1], Eigen::Vector3d(10, 0, 1));
  {
    std::ofstream out(path);
    out << R"({"frame": 0, "cut_events": [{"frame": 0, "status": "cut"}]})"
        << "\n";
  }
  EXPECT_NE(ErrorOf([&] { ReadAppliedCuts(path); }).find("line 1: cut_events.polyline_rest_mm"),
            std::string::npos);
}

}  // namespace
}  // namespace arreg::eval
