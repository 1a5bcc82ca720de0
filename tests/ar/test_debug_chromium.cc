// The debug viewer in headless Chromium, driven through ChromeDriver by
// test_debug_viewer_driver.py: it loads from file://, steps three frames with the arrow key,
// toggles two layers, selects a feature, and shows a non-blank page without console errors.
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <ostream>
#include <string>

#include "ar/debug/recorder.h"
#include "ar/debug/viewer.h"
#include "core/file_util.h"
#include "test_debug_fixture.h"
#include "test_util.h"

namespace arreg::debug {
namespace {

namespace fs = std::filesystem;

std::string FindExecutable(std::initializer_list<const char*> candidates) {
  for (const char* c : candidates)
    if (fs::exists(c)) return c;
  return "";
}

struct Browser {
  std::string chromium, chromedriver;
};

// Empty names when something is missing (the test skips).
Browser FindBrowser() {
  Browser b;
  b.chromium = FindExecutable({"/usr/bin/chromium", "/usr/bin/chromium-browser",
                               "/usr/bin/google-chrome", "/usr/bin/google-chrome-stable"});
  b.chromedriver = FindExecutable({"/usr/bin/chromedriver", "/usr/lib/chromium/chromedriver"});
  return b;
}

bool HavePython() { return std::system("python3 -c 'import urllib.request' >/dev/null 2>&1") == 0; }

// Runs the driver; returns its exit status. stderr goes to `log`.
int Drive(const Browser& b, const std::string& url, const fs::path& root, const std::string& extra,
          const fs::path& log) {
  const std::string script =
      std::string(ARREG_SOURCE_DIR) + "/tests/ar/test_debug_viewer_driver.py";
  const std::string cmd =
      "timeout 120 python3 '" + script + "' --chromium '" + b.chromium + "' --chromedriver '" +
      b.chromedriver + "' --url '" + url + "' --profile '" + (root / "profile").string() +
      "' --screenshot '" + (root / "shot.png").string() + "' --result '" +
      (root / "result.json").string() + "' " + extra + " >'" + log.string() + "' 2>&1";
  return std::system(cmd.c_str());
}

std::vector<std::string> SevereMessages(const nlohmann::json& log) {
  std::vector<std::string> severe;
  for (const auto& entry : log)
    if (entry.value("level", "") == "SEVERE") severe.push_back(entry.value("message", ""));
  return severe;
}

TEST(DebugViewerInBrowser, StepsFramesTogglesLayersAndShowsAFeatureHistory) {
  const Browser b = FindBrowser();
  if (b.chromium.empty() || b.chromedriver.empty() || !HavePython())
    GTEST_SKIP() << "chromium, chromium-driver or python3 missing (scripts/install-deps)";
  const fs::path root = ::arreg::testing::ScratchDir("debug_chromium");
  const std::string run = (root / "run").string();
  fixture::RecordRun(run);
  const std::string viewer = (root / "viewer").string();
  WriteDebugViewer(run, viewer);

  // A feature alive at frame 3, clicked at its recorded pixel.
  const nlohmann::json rec = nlohmann::json::parse(ReadFileToString(FrameRecordPath(run, 3)));
  nlohmann::json feature;
  for (const auto& f : rec["features"])
    if (f["alive"].get<bool>()) {
      feature = f;
      break;
    }
  ASSERT_TRUE(feature.is_object());
  const std::string click = "--click " + std::to_string(feature["id"].get<int>()) + "," +
                            std::to_string(feature["px"][0].get<double>()) + "," +
                            std::to_string(feature["px"][1].get<double>());

  const fs::path log = root / "driver.log";
  ASSERT_EQ(Drive(b, "file://" + viewer + "/index.html", root, click, log), 0)
      << ReadFileToString(log.string());
  const nlohmann::json r = nlohmann::json::parse(ReadFileToString((root / "result.json").string()));
  ASSERT_EQ(r["frames"].size(), size_t(fixture::kFrames));
  EXPECT_EQ(r["shown_before"], 0);
  EXPECT_EQ(r["label_before"], "0");
  EXPECT_EQ(r["shown_after"], 3);
  EXPECT_EQ(r["label_after"], "3");
  // Frame 3's rejected clusters as the record counts them.
  const nlohmann::json& det = rec["detection"];
  std::string rejected;
  for (const char* key :
       {"lone_features", "one_sided_clusters", "star_starts", "unconfirmed_starts",
        "closing_starts", "refused_points", "refused_segments"})
    rejected += (rejected.empty() ? "" : " / ") + std::to_string(det[key].get<int>());
  EXPECT_EQ(r["rejected_row"], rejected);
  for (const char* layer : {"pairs", "mesh"}) {
    ASSERT_TRUE(r["toggles"].contains(layer)) << layer;
    EXPECT_NE(r["toggles"][layer][0], r["toggles"][layer][1]) << layer;
  }
  EXPECT_EQ(r["selected"], std::to_string(feature["id"].get<int>()));
  EXPECT_EQ(r["mu_plot_paths"], 2);  // mu of its pairs and tau * mean mu
  EXPECT_TRUE(SevereMessages(r["log"]).empty()) << r["log"].dump(1);

  const cv::Mat shot = cv::imread((root / "shot.png").string(), cv::IMREAD_COLOR);
  ASSERT_FALSE(shot.empty());
  cv::Mat grey;
  cv::cvtColor(shot, grey, cv::COLOR_BGR2GRAY);
  cv::Scalar mean, stddev;
  cv::meanStdDev(grey, mean, stddev);
  EXPECT_GT(stddev[0], 10.0) << "screenshot looks blank";
  // The features layer is drawn: pixels of its green (#00dc00) are on screen.
  cv::Mat green;
  cv::inRange(shot, cv::Scalar(0, 190, 0), cv::Scalar(60, 255, 60), green);
  EXPECT_GT(cv::countNonZero(green), 50);
}

// Control: the log the test reads does report a console error of a page.
TEST(DebugViewerInBrowser, ConsoleErrorsReachTheLog) {
  const Browser b = FindBrowser();
  if (b.chromium.empty() || b.chromedriver.empty() || !HavePython())
    GTEST_SKIP() << "chromium, chromium-driver or python3 missing (scripts/install-deps)";
  const fs::path root = ::arreg::testing::ScratchDir("debug_chromium_control");
  WriteFileAtomic((root / "bad.html").string(), [](std::ostream& os) {
    os << "<html><body><script>console.error('deliberate-debug-error')</script>"
          "<script src='missing.js'></script></body></html>";
  });
  const fs::path log = root / "driver.log";
  ASSERT_EQ(Drive(b, "file://" + (root / "bad.html").string(), root, "--page-only", log), 0)
      << ReadFileToString(log.string());
  const nlohmann::json r = nlohmann::json::parse(ReadFileToString((root / "result.json").string()));
  const std::vector<std::string> severe = SevereMessages(r["log"]);
  ASSERT_EQ(severe.size(), 2u) << r["log"].dump(1);
  EXPECT_NE((severe[0] + severe[1]).find("deliberate-debug-error"), std::string::npos);
  EXPECT_NE((severe[0] + severe[1]).find("missing.js"), std::string::npos);
}

}  // namespace
}  // namespace arreg::debug
