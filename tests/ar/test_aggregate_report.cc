// `arreg report`'s aggregation: rows read from real evaluation folders (the hand-built runs of
// test_eval_fixtures.h, metrics known in closed form), failed rows from logs, and the three
// output files.
#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "ar/eval/aggregate.h"
#include "ar/eval/evaluation.h"
#include "core/error.h"
#include "core/file_util.h"
#include "test_eval_fixtures.h"

namespace arreg::eval {
namespace {

namespace fs = std::filesystem;

// A job folder DIR/{run,eval} evaluated against the fixture's ground truth; the run's
// run.json gets `fps_end_to_end` = fps, `seconds` and `cuts_applied`.
void MakeEvaluatedJob(const fixtures::Folders& f, const fs::path& job, double fps) {
  fs::create_directories(job);
  fs::copy(f.run, job / "run", fs::copy_options::recursive);
  nlohmann::json run = nlohmann::json::parse(ReadFileToString((job / "run" / "run.json").string()));
  run["totals"]["fps_end_to_end"] = fps;
  run["seconds"] = 3.0 / fps;
  run["cuts_applied"] = 1;
  fixtures::WriteText(job / "run" / "run.json", run.dump(2));
  EvalOptions o;
  o.color_maps = false;
  o.hausdorff.sampling.min_random_samples = 500;
  const RunEvaluation ev = EvaluateRun((job / "run").string(), f.gt.string(), o);
  WriteEvalReport((job / "eval").string(), f.gt.string(), ev, nullptr, o);
}

TEST(AggregateEntry, LabelFromTheArgumentOrTheFolders) {
  const AggregateEntry a = ParseAggregateEntry("kidney-s3/no-topology=out/x");
  EXPECT_EQ(a.scene, "kidney-s3");
  EXPECT_EQ(a.variant, "no-topology");
  EXPECT_EQ(a.dir, "out/x");
  const AggregateEntry b = ParseAggregateEntry("out/scenes/band-s1/topology/");
  EXPECT_EQ(b.scene, "band-s1");
  EXPECT_EQ(b.variant, "topology");
  EXPECT_THROW(ParseAggregateEntry("nolabel=out/x"), Error);
  EXPECT_THROW(ParseAggregateEntry("a/=out/x"), Error);
  EXPECT_THROW(ParseAggregateEntry("topology"), Error);  // no parent folder: no scene
}

TEST(Aggregate, RowsCarryTheEvaluationsFiguresAndTheRunsSpeed) {
  const fixtures::Folders f = fixtures::MakeFolders("aggregate_rows");
  const fs::path jobs = f.root / "scenes";
  MakeEvaluatedJob(f, jobs / "sq" / "topology", 40.0);
  const AggregateRow row =
      ReadAggregateRow(ParseAggregateEntry((jobs / "sq" / "topology").string()));
  ASSERT_TRUE(row.ok) << row.error;
  EXPECT_EQ(row.scene, "sq");
  EXPECT_EQ(row.variant, "topology");
  // Closed form (test_eval_fixtures.h): Dice 1, 0.75, 6/7; surface 3 mm apart at frame 2 only,
  // internal 0.5 mm apart at frame 2 and coincident at frame 0.
  EXPECT_NEAR(*row.dice_final, 6.0 / 7.0, 1e-9);
  EXPECT_NEAR(*row.dice_mean, (1.0 + 0.75 + 6.0 / 7.0) / 3.0, 1e-9);
  EXPECT_NEAR(*row.surface_max, 3.0, 1e-9);
  EXPECT_NEAR(*row.internal_max, 0.5, 1e-9);
  EXPECT_NEAR(*row.feature_error_mean_mm, 1.5, 1e-12);
  EXPECT_DOUBLE_EQ(*row.fps, 40.0);
  EXPECT_EQ(*row.frames, 3);
  EXPECT_EQ(*row.cuts_applied, 1);
  EXPECT_TRUE(fs::exists(row.report));
}

TEST(Aggregate, AFolderWithoutEvaluationIsAFailedRowWithItsLogsErrorLine) {
  const fs::path root = ::arreg::testing::ScratchDir("aggregate_failed");
  const fs::path job = root / "scenes" / "bad" / "topology";
  // The scene-level log is older and has no error; the job's run log has one, among progress.
  fixtures::WriteText(root / "scenes" / "bad" / "logs" / "synth.log", "synth done\n");
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  fixtures::WriteText(job / "logs" / "run.log",
                      "arreg run: frame 3/12\rarreg run: frame 4/12\n"
                      "arreg run: error: in/bad.json:line 2: expected a JSON object\n"
                      "[Sun Nov 29] Error in rule run:\n");
  AggregateRow row = ReadAggregateRow(ParseAggregateEntry(job.string()));
  EXPECT_FALSE(row.ok);
  EXPECT_EQ(row.error, "arreg run: error: in/bad.json:line 2: expected a JSON object");
  EXPECT_EQ(fs::path(row.log).filename(), "run.log");

  // Without an error line anywhere: the most recent log's last line.
  fs::remove(job / "logs" / "run.log");
  row = ReadAggregateRow(ParseAggregateEntry(job.string()));
  EXPECT_FALSE(row.ok);
  EXPECT_EQ(row.error, "synth done");

  // Without logs: what is missing; a folder that does not exist at all.
  fs::remove_all(root / "scenes" / "bad" / "logs");
  row = ReadAggregateRow(ParseAggregateEntry(job.string()));
  EXPECT_NE(row.error.find("eval/report.json: missing"), std::string::npos) << row.error;
  row = ReadAggregateRow(ParseAggregateEntry((root / "scenes" / "none" / "v").string()));
  EXPECT_FALSE(row.ok);
  EXPECT_NE(row.error.find("no such folder"), std::string::npos) << row.error;

  // A damaged report.json names the file.
  fixtures::WriteText(job / "eval" / "report.json", "{\"dice_final\": 0.9");
  row = ReadAggregateRow(ParseAggregateEntry(job.string()));
  EXPECT_FALSE(row.ok);
  EXPECT_NE(row.error.find("report.json: not valid JSON"), std::string::npos) << row.error;
}

TEST(Aggregate, WritesTheSameRowsAsHtmlCsvAndJson) {
  const fixtures::Folders f = fixtures::MakeFolders("aggregate_write");
  const fs::path jobs = f.root / "scenes";
  MakeEvaluatedJob(f, jobs / "a" / "topology", 40.0);
  MakeEvaluatedJob(f, jobs / "b" / "topology", 20.0);
  fixtures::WriteText(jobs / "b" / "no-topology" / "logs" / "run.log",
                      "arreg run: error: b/scene.json: model: missing\n");
  std::vector<AggregateRow> rows;
  for (const char* dir : {"a/topology", "b/topology", "b/no-topology"})
    rows.push_back(ReadAggregateRow(ParseAggregateEntry((jobs / dir).string())));
  const fs::path out = f.root / "agg";
  WriteAggregateReport(out.string(), rows);

  const nlohmann::json j = nlohmann::json::parse(ReadFileToString((out / "report.json").string()));
  ASSERT_EQ(j["rows"].size(), 3u);
  EXPECT_EQ(j["rows"][2]["status"], "failed");
  EXPECT_EQ(j["rows"][2]["error"], "arreg run: error: b/scene.json: model: missing");
  EXPECT_TRUE(j["rows"][2]["dice_final"].is_null());
  EXPECT_NEAR(j["rows"][0]["dice_final"].get<double>(), 6.0 / 7.0, 1e-9);
  EXPECT_EQ(j["summary"]["ok"], 2);
  EXPECT_EQ(j["summary"]["failed"], 1);
  EXPECT_DOUBLE_EQ(j["summary"]["fps"]["median"].get<double>(), 30.0);
  EXPECT_DOUBLE_EQ(j["summary"]["fps"]["min"].get<double>(), 20.0);

  std::ifstream csv(out / "report.csv");
  std::vector<std::string> lines;
  for (std::string line; std::getline(csv, line);) lines.push_back(line);
  ASSERT_EQ(lines.size(), 4u);
  EXPECT_EQ(lines[0].rfind("scene,variant,status,dice_final,", 0), 0u) << lines[0];
  EXPECT_EQ(lines[1].rfind("a,topology,ok,0.857142857,", 0), 0u) << lines[1];
  EXPECT_EQ(lines[3].rfind("b,no-topology,failed,", 0), 0u) << lines[3];

  const std::string html = ReadFileToString((out / "report.html").string());
  for (const char* id : {"id=\"runs\"", "id=\"plot-dice_final\"", "id=\"plot-fps\"",
                         "id=\"plot-hd_surface_mean_gt_to_model\"", "id=\"worst\"", "id=\"failed\"",
                         "b/scene.json: model: missing"})
    EXPECT_NE(html.find(id), std::string::npos) << id;
  // Links to the scenes' own reports are relative to the page and lead to real files.
  const std::string link = "href=\"../scenes/a/topology/eval/report.html\"";
  EXPECT_NE(html.find(link), std::string::npos);
  EXPECT_TRUE(fs::exists(out / "../scenes/a/topology/eval/report.html"));
  // No external resources: the page stands alone.
  EXPECT_EQ(html.find("src=\"http"), std::string::npos);
}

}  // namespace
}  // namespace arreg::eval
