// The evaluation report opens in headless Chromium without console errors and
// shows its plots (DOM holds the SVGs, the screenshot is not blank).
#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <ostream>
#include <string>

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

TEST(EvalReportInBrowser, OpensWithoutConsoleErrorsAndShowsThePlots) {
  const std::string chromium = FindChromium();
  if (chromium.empty()) GTEST_SKIP() << "chromium not installed (scripts/install-deps installs it)";
  const fixtures::Folders f = fixtures::MakeFolders("eval_report_chromium");
  EvalOptions o;
  o.hausdorff.sampling.min_random_samples = 2000;
  const RunEvaluation run = EvaluateRun(f.run.string(), f.gt.string(), o);
  const RunEvaluation base = EvaluateRun(f.baseline.string(), f.gt.string(), o);
  WriteEvalReport(f.out.string(), f.gt.string(), run, &base, o);
  const std::string url = "file://" + fs::absolute(f.out / "report.html").string();

  const fs::path dom = f.root / "dom.html", dom_log = f.root / "dom.log";
  ASSERT_EQ(RunShell(ChromiumCommand(chromium, f.root / "profile1") + "--dump-dom '" + url + "'",
                     dom, dom_log),
            0)
      << ReadFileToString(dom_log.string());
  const std::string dom_text = ReadFileToString(dom.string());
  ExpectNoConsoleErrors(ReadFileToString(dom_log.string()));
  for (const char* id :
       {"plot-dice", "plot-hausdorff-surface", "plot-hausdorff-internal", "plot-feature-error"})
    EXPECT_NE(dom_text.find(std::string("id=\"") + id + "\""), std::string::npos) << id;
  EXPECT_NE(dom_text.find("<polyline"), std::string::npos);
  EXPECT_NE(dom_text.find("key-numbers"), std::string::npos);

  const fs::path png = f.root / "screenshot.png", shot_log = f.root / "shot.log";
  ASSERT_EQ(RunShell(ChromiumCommand(chromium, f.root / "profile2") +
                         "--hide-scrollbars "
                         "--window-size=1200,1600 --screenshot='" +
                         png.string() + "' '" + url + "'",
                     f.root / "shot.out", shot_log),
            0)
      << ReadFileToString(shot_log.string());
  ExpectNoConsoleErrors(ReadFileToString(shot_log.string()));
  const cv::Mat shot = cv::imread(png.string(), cv::IMREAD_GRAYSCALE);
  ASSERT_FALSE(shot.empty()) << "no screenshot written";
  cv::Scalar mean, stddev;
  cv::meanStdDev(shot, mean, stddev);
  EXPECT_GT(stddev[0], 10.0) << "screenshot looks blank";
  // Plot strokes (blue run curve, #1f77b4) are present in the rendered page.
  const cv::Mat colour = cv::imread(png.string(), cv::IMREAD_COLOR);
  cv::Mat blue;
  cv::inRange(colour, cv::Scalar(150, 90, 0), cv::Scalar(210, 150, 60), blue);
  EXPECT_GT(cv::countNonZero(blue), 200);
}

// Control: the log check above would see a console error if the page had one.
TEST(EvalReportInBrowser, ConsoleErrorsOfAPageReachTheLog) {
  const std::string chromium = FindChromium();
  if (chromium.empty()) GTEST_SKIP() << "chromium not installed (scripts/install-deps installs it)";
  const fs::path root = ::arreg::testing::ScratchDir("eval_chromium_control");
  WriteFileAtomic((root / "bad.html").string(), [](std::ostream& os) {
    os << "<html><body><script>console.error('deliberate-eval-error')</script></body></html>";
  });
  const fs::path log = root / "log.txt";
  ASSERT_EQ(RunShell(ChromiumCommand(chromium, root / "profile") + "--dump-dom 'file://" +
                         (root / "bad.html").string() + "'",
                     root / "dom.html", log),
            0);
  const std::string text = ReadFileToString(log.string());
  EXPECT_NE(text.find("CONSOLE"), std::string::npos) << text;
  EXPECT_NE(text.find("deliberate-eval-error"), std::string::npos);
}

}  // namespace
}  // namespace arreg::eval
