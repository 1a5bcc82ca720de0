// `arreg bench accuracy --quick` end to end (label slow): the short CI subset of the manifest
// runs, the JSON holds every metric, the synth no-cut scene has no false cut and the synth cut
// scene's cut is found; the phantom scene runs or is skipped with its reason.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <string>

#include "core/file_util.h"
#include "core/json_reader.h"
#include "test_util.h"

namespace {

TEST(BenchAccuracy, QuickSubsetFindsTheCutAndMakesNoFalseOne) {
  const std::string binary = std::string(ARREG_BINARY_DIR) + "/apps/arreg";
  if (!arreg::FileExists(binary)) GTEST_SKIP() << "arreg binary not built";
  const std::string dir = arreg::testing::ScratchDir("bench_accuracy_quick");
  const std::string json = dir + "/bench.json";
  // From the source tree: the default manifest and phantom tool paths are relative to it.
  const std::string command = "cd " + std::string(ARREG_SOURCE_DIR) + " && " + binary +
                              " bench accuracy --quick --jobs 2 --cache " + dir + "/cache --json " +
                              json + " 2>&1";
  const arreg::testing::CommandResult run = arreg::testing::RunCommand(command);
  const std::string& output = run.output;
  ASSERT_TRUE(run.exited) << output;
  EXPECT_EQ(run.status, 0) << output;
  ASSERT_TRUE(arreg::FileExists(json)) << output;
  const nlohmann::json j = arreg::ParseJsonFile(json);

  const char* scene_keys[] = {"applied_cuts",     "found_cuts",        "misplaced_cuts",
                              "cut_found",        "cut_line_error_mm", "opening_frame",
                              "latency_frames",   "dice_final",        "dice_final_no_topology",
                              "dice_min",         "surface_mean_mm",   "surface_worst_mm",
                              "internal_mean_mm", "internal_worst_mm"};
  bool saw_stretch = false, saw_cut = false;
  for (const nlohmann::json& s : j.at("scenes")) {
    for (const char* key : scene_keys) EXPECT_TRUE(s.contains(key)) << s.dump() << " " << key;
    if (s.at("source") == "phantom") {
      // Without blender the phantom scene is listed as skipped with the reason.
      if (s.at("status") == "skipped")
        EXPECT_FALSE(s.at("reason").get<std::string>().empty());
      else
        EXPECT_EQ(s.at("status"), "ok") << s.dump();
      continue;
    }
    ASSERT_EQ(s.at("status"), "ok") << s.dump() << "\n" << output;
    EXPECT_GT(s.at("dice_final").get<double>(), 0.9) << s.dump();
    EXPECT_FALSE(s.at("surface_mean_mm").is_null()) << s.dump();
    if (s.at("class") == "stretch") {
      saw_stretch = true;
      EXPECT_EQ(s.at("applied_cuts"), 0) << s.dump();
    } else if (s.at("class") == "cut") {
      saw_cut = true;
      EXPECT_TRUE(s.at("cut_found").get<bool>()) << s.dump();
      EXPECT_EQ(s.at("misplaced_cuts"), 0) << s.dump();
      EXPECT_FALSE(s.at("cut_line_error_mm").is_null()) << s.dump();
      EXPECT_FALSE(s.at("latency_frames").is_null()) << s.dump();
    }
  }
  EXPECT_TRUE(saw_stretch);
  EXPECT_TRUE(saw_cut);
  const char* row_keys[] = {"recall",
                            "false_cuts_per_scene",
                            "false_cut_scenes",
                            "misplaced_per_scene",
                            "cut_line_error_mm",
                            "latency_median_frames",
                            "dice_final",
                            "dice_final_no_topology",
                            "error_ratio",
                            "dice_min",
                            "surface_mean_mm",
                            "surface_worst_mm",
                            "internal_mean_mm",
                            "internal_worst_mm"};
  ASSERT_FALSE(j.at("table").empty());
  for (const nlohmann::json& row : j.at("table"))
    for (const char* key : row_keys) EXPECT_TRUE(row.contains(key)) << row.dump() << " " << key;
  EXPECT_FALSE(j.at("acceptance").at("quick").empty());
  // The printed table and acceptance lines.
  EXPECT_NE(output.find("recall"), std::string::npos) << output;
  EXPECT_NE(output.find("acceptance (issue 33)"), std::string::npos) << output;
}

}  // namespace
