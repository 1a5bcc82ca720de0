// scripts/batch end to end: the smoke manifest through the Snakemake workflow (local profile)
// gives one aggregated report whose rows are the scenes' own evaluations; a rerun after deleting
// one run folder redoes exactly that run, its evaluation and the aggregation; a corrupt scene is
// a failed row with arreg's one-line error while the other scenes complete.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "core/file_util.h"
#include "test_util.h"

namespace arreg {
namespace {

namespace fs = std::filesystem;

struct Result {
  int status = -1;
  std::string out, err;
};

// scripts/batch with its stdout and stderr captured; --cores 2, the test's arreg binary.
Result Batch(const fs::path& scratch, const std::string& args) {
  const fs::path out = scratch / "batch.out", err = scratch / "batch.err";
  const std::string command = std::string("'") + ARREG_SOURCE_DIR + "/scripts/batch' " + args +
                              " --cores 2 --arreg '" + ARREG_BINARY_DIR + "/apps/arreg' >'" +
                              out.string() + "' 2>'" + err.string() + "'";
  Result r;
  const int raw = std::system(command.c_str());
  r.status = WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
  r.out = ReadFileToString(out.string());
  r.err = ReadFileToString(err.string());
  return r;
}

std::string LastLine(const std::string& text) {
  std::istringstream in(text);
  std::string line, last;
  while (std::getline(in, line))
    if (!line.empty()) last = line;
  return last;
}

nlohmann::json ReadJson(const fs::path& path) {
  return nlohmann::json::parse(ReadFileToString(path.string()));
}

// Snakemake's "Job stats" table: rule -> count.
std::map<std::string, int> JobStats(const std::string& log) {
  std::map<std::string, int> counts;
  const size_t at = log.find("Job stats:");
  if (at == std::string::npos) return counts;
  std::istringstream in(log.substr(at));
  std::string line;
  const std::regex row(R"(^(\w+)\s+(\d+)\s+\d+\s+\d+\s*$)");
  while (std::getline(in, line)) {
    std::smatch m;
    if (std::regex_match(line, m, row) && m[1] != "total") counts[m[1]] = std::stoi(m[2]);
    if (line.rfind("total", 0) == 0) break;
  }
  return counts;
}

bool HaveSnakemake() { return std::system("command -v snakemake >/dev/null 2>&1") == 0; }

TEST(Workflow, SmokeManifestAggregatesEveryScenesEvaluationAndResumes) {
  if (!HaveSnakemake())
    GTEST_SKIP() << "snakemake not installed (scripts/install-deps installs it)";
  const fs::path scratch = ::arreg::testing::ScratchDir("workflow_smoke");
  const fs::path out = scratch / "out";
  const Result first =
      Batch(scratch, std::string(ARREG_SOURCE_DIR) + "/data/manifests/smoke.yaml --out '" +
                         out.string() + "'");
  ASSERT_EQ(first.status, 0) << first.err;
  EXPECT_EQ(LastLine(first.out), (out / "report").string());
  const std::map<std::string, int> stats = JobStats(first.err);
  EXPECT_EQ(stats.at("synth"), 3);
  EXPECT_EQ(stats.at("run"), 6);
  EXPECT_EQ(stats.at("eval"), 6);
  EXPECT_EQ(stats.at("report"), 1);

  const nlohmann::json report = ReadJson(out / "report" / "report.json");
  ASSERT_EQ(report["rows"].size(), 6u);
  EXPECT_EQ(report["summary"]["ok"], 6);
  std::set<std::string> scenes, variants;
  for (const nlohmann::json& row : report["rows"]) {
    const std::string scene = row["scene"], variant = row["variant"];
    scenes.insert(scene);
    variants.insert(variant);
    ASSERT_EQ(row["status"], "ok") << scene << " / " << variant << ": " << row["error"];
    // The aggregated figures are the scene's own evaluation's, exactly.
    const fs::path job = out / "scenes" / scene / variant;
    const nlohmann::json eval = ReadJson(job / "eval" / "report.json");
    EXPECT_EQ(row["dice_final"].get<double>(), eval["dice_final"].get<double>());
    EXPECT_EQ(row["hd_surface_mean_gt_to_model"].get<double>(),
              eval["hausdorff_surface"]["mean_gt_to_model"].get<double>());
    EXPECT_GT(row["dice_final"].get<double>(), 0.8) << scene << " / " << variant;
    EXPECT_LE(row["dice_final"].get<double>(), 1.0);
    EXPECT_EQ(row["frames"], 12);
    EXPECT_GT(row["fps"].get<double>(), 0.0);
    EXPECT_TRUE(fs::exists(out / row["report"].get<std::string>()));
    // The topology variant is evaluated beside its no-topology baseline.
    EXPECT_EQ(eval.contains("baseline"), variant == "topology") << scene << " / " << variant;
    if (variant == "topology")
      EXPECT_EQ(
          eval["baseline"]["dice_final"].get<double>(),
          ReadJson(out / "scenes" / scene / "no-topology" / "eval" / "report.json")["dice_final"]
              .get<double>());
  }
  EXPECT_EQ(scenes, (std::set<std::string>{"band-stretch-s1", "band-cut-s-s1", "kidney-cut-s1"}));
  EXPECT_EQ(variants, (std::set<std::string>{"topology", "no-topology"}));

  // Rerun after deleting one run folder: that run, its evaluation and the aggregation only.
  std::map<std::string, fs::file_time_type> before;
  for (const auto& e : fs::recursive_directory_iterator(out / "scenes"))
    if (e.path().filename() == "run.json" || e.path().filename() == "report.json")
      before[e.path().string()] = fs::last_write_time(e.path());
  const fs::path deleted = out / "scenes" / "band-stretch-s1" / "topology";
  fs::remove_all(deleted / "run");
  const fs::file_time_type report_time = fs::last_write_time(out / "report" / "report.json");
  const Result second =
      Batch(scratch, std::string(ARREG_SOURCE_DIR) + "/data/manifests/smoke.yaml --out '" +
                         out.string() + "'");
  ASSERT_EQ(second.status, 0) << second.err;
  EXPECT_EQ(JobStats(second.err),
            (std::map<std::string, int>{{"all", 1}, {"eval", 1}, {"report", 1}, {"run", 1}}))
      << second.err;
  for (const auto& [path, time] : before) {
    ASSERT_TRUE(fs::exists(path)) << path;
    const bool redone = fs::path(path).parent_path().parent_path() == deleted;
    if (redone)
      EXPECT_GT(fs::last_write_time(path), time) << path;
    else
      EXPECT_EQ(fs::last_write_time(path), time) << path;
  }
  EXPECT_TRUE(fs::exists(deleted / "run" / "run.json"));
  EXPECT_GT(fs::last_write_time(out / "report" / "report.json"), report_time);
  // Same registration, same figures.
  const nlohmann::json again = ReadJson(out / "report" / "report.json");
  for (size_t i = 0; i < 6; ++i)
    EXPECT_EQ(again["rows"][i]["dice_final"], report["rows"][i]["dice_final"]) << i;
}

TEST(Workflow, ACorruptSceneIsAFailedRowAndTheOthersComplete) {
  if (!HaveSnakemake())
    GTEST_SKIP() << "snakemake not installed (scripts/install-deps installs it)";
  const fs::path scratch = ::arreg::testing::ScratchDir("workflow_corrupt");
  WriteFileAtomic((scratch / "broken.json").string(),
                  [](std::ostream& os) { os << "{\"camera\": "; });
  WriteFileAtomic((scratch / "manifest.yaml").string(), [](std::ostream& os) {
    os << "defaults: {frames: 6, size: 160x128}\n"
          "variants:\n  topology: {args: []}\n"
          "scenes:\n"
          "  - {scenario: band-stretch, seeds: [1, 2]}\n"
          "  - {name: broken, scene: broken.json, gt: no-gt}\n";
  });
  const fs::path out = scratch / "out";
  const Result r =
      Batch(scratch, "'" + (scratch / "manifest.yaml").string() + "' --out '" + out.string() + "'");
  EXPECT_EQ(r.status, 1) << r.err;
  ASSERT_EQ(LastLine(r.out), (out / "report").string()) << r.err;
  const nlohmann::json report = ReadJson(out / "report" / "report.json");
  ASSERT_EQ(report["rows"].size(), 3u);
  EXPECT_EQ(report["summary"]["failed"], 1);
  for (const nlohmann::json& row : report["rows"]) {
    if (row["scene"] == "broken") {
      EXPECT_EQ(row["status"], "failed");
      const std::string error = row["error"];
      EXPECT_EQ(error.rfind("arreg run: error: ", 0), 0u) << error;
      EXPECT_NE(error.find("broken.json: line 1"), std::string::npos) << error;
      EXPECT_TRUE(fs::exists(out / row["log"].get<std::string>()));
    } else {
      EXPECT_EQ(row["status"], "ok") << row["error"];
      EXPECT_GT(row["dice_final"].get<double>(), 0.8);
    }
  }
  const std::string html = ReadFileToString((out / "report" / "report.html").string());
  EXPECT_NE(html.find("broken.json: line 1"), std::string::npos);
}

TEST(Workflow, AManifestErrorIsOneLineNamingTheKey) {
  if (!HaveSnakemake())
    GTEST_SKIP() << "snakemake not installed (scripts/install-deps installs it)";
  const fs::path scratch = ::arreg::testing::ScratchDir("workflow_manifest_error");
  WriteFileAtomic((scratch / "manifest.yaml").string(), [](std::ostream& os) {
    os << "variants:\n  topology: {args: []}\nscenes:\n  - {scenario: band-stretch, sed: 1}\n";
  });
  const Result r = Batch(scratch, "'" + (scratch / "manifest.yaml").string() + "' --out '" +
                                      (scratch / "out").string() + "'");
  EXPECT_EQ(r.status, 1);
  const std::string line =
      "workflow: " + (scratch / "manifest.yaml").string() + ": scenes[0].sed: unknown key\n";
  EXPECT_EQ(r.err.rfind(line, 0), 0u) << r.err;
  EXPECT_EQ(r.err.find("Traceback"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(scratch / "out" / "scenes"));
}

}  // namespace
}  // namespace arreg
