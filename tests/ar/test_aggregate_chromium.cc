// The aggregated report (`arreg report`) in headless Chromium: no console errors, the plots and
// the table are in the DOM, a #sort= link sorts the table by running the page's script, and the
// screenshot is not blank.
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "ar/eval/aggregate.h"
#include "ar/eval/evaluation.h"
#include "core/file_util.h"
#include "test_chromium.h"
#include "test_eval_fixtures.h"

namespace arreg::eval {
namespace {

namespace fs = std::filesystem;

using ::arreg::testing::ChromiumCommand;
using ::arreg::testing::ExpectNoConsoleErrors;
using ::arreg::testing::FindChromium;
using ::arreg::testing::RunShell;

// Three evaluated jobs a, b, c at 40, 20 and 30 frames/s, and a failed one.
fs::path MakeAggregate(const fixtures::Folders& f) {
  EvalOptions o;
  o.color_maps = false;
  o.hausdorff.sampling.min_random_samples = 500;
  const RunEvaluation ev = EvaluateRun(f.run.string(), f.gt.string(), o);
  std::vector<AggregateRow> rows;
  for (const auto& [scene, fps] :
       std::vector<std::pair<std::string, double>>{{"a", 40.0}, {"b", 20.0}, {"c", 30.0}}) {
    const fs::path job = f.root / "scenes" / scene / "topology";
    WriteEvalReport((job / "eval").string(), f.gt.string(), ev, nullptr, o);
    nlohmann::json run = {{"totals", {{"fps_end_to_end", fps}}}, {"seconds", 1.0}};
    fixtures::WriteText(job / "run" / "run.json", run.dump());
    rows.push_back(ReadAggregateRow(ParseAggregateEntry(job.string())));
  }
  fixtures::WriteText(f.root / "scenes" / "d" / "topology" / "logs" / "run.log",
                      "arreg run: error: d.json: line 1: expected a JSON object\n");
  rows.push_back(ReadAggregateRow(ParseAggregateEntry((f.root / "scenes/d/topology").string())));
  WriteAggregateReport((f.root / "agg").string(), rows);
  return f.root / "agg" / "report.html";
}

TEST(AggregateReportInBrowser, OpensSortsByTheLinkAndShowsThePlots) {
  const std::string chromium = FindChromium();
  if (chromium.empty()) GTEST_SKIP() << "chromium not installed (scripts/install-deps installs it)";
  const fixtures::Folders f = fixtures::MakeFolders("aggregate_chromium");
  const fs::path page = MakeAggregate(f);
  const std::string url = "file://" + fs::absolute(page).string() + "#sort=fps:desc";

  const fs::path dom = f.root / "dom.html", dom_log = f.root / "dom.log";
  ASSERT_EQ(RunShell(ChromiumCommand(chromium, f.root / "profile1") + "--dump-dom '" + url + "'",
                     dom, dom_log),
            0)
      << ReadFileToString(dom_log.string());
  ExpectNoConsoleErrors(ReadFileToString(dom_log.string()));
  const std::string text = ReadFileToString(dom.string());
  for (const char* id : {"plot-dice_final", "plot-fps", "plot-hd_surface_mean_gt_to_model", "worst",
                         "failed", "runs"})
    EXPECT_NE(text.find(std::string("id=\"") + id + "\""), std::string::npos) << id;
  // The script ran: the table says how it is sorted, and the rows are in that order (failed
  // row, without fps, last).
  EXPECT_NE(text.find("data-sorted=\"fps:desc\""), std::string::npos);
  const size_t body = text.find("<tbody>");
  ASSERT_NE(body, std::string::npos);
  std::vector<size_t> at;
  for (const char* cell : {">a</td>", ">c</td>", ">b</td>", ">d</td>"})
    at.push_back(text.find(cell, body));
  for (size_t i = 0; i < at.size(); ++i) ASSERT_NE(at[i], std::string::npos) << i;
  EXPECT_LT(at[0], at[1]);
  EXPECT_LT(at[1], at[2]);
  EXPECT_LT(at[2], at[3]);

  const fs::path png = f.root / "screenshot.png", shot_log = f.root / "shot.log";
  ASSERT_EQ(RunShell(ChromiumCommand(chromium, f.root / "profile2") +
                         "--hide-scrollbars --window-size=1200,1400 --screenshot='" + png.string() +
                         "' '" + url + "'",
                     f.root / "shot.out", shot_log),
            0)
      << ReadFileToString(shot_log.string());
  ExpectNoConsoleErrors(ReadFileToString(shot_log.string()));
  const cv::Mat colour = cv::imread(png.string(), cv::IMREAD_COLOR);
  ASSERT_FALSE(colour.empty()) << "no screenshot written";
  // The strip plots' points (#1f77b4 at 70 % opacity on white) are drawn.
  cv::Mat blue;
  cv::inRange(colour, cv::Scalar(170, 120, 10), cv::Scalar(235, 190, 130), blue);
  EXPECT_GT(cv::countNonZero(blue), 50);
}

}  // namespace
}  // namespace arreg::eval
