// The CI's random-cut sweeps: `arreg bench cutting --random 1000` (the SOFA livers when
// ../shared/data has them, the kidney with its internal structure, the beam) and the same with
// `--degree 2` (the quadratic remesher; a fifth mesh with curved faces) end with no violation,
// and their JSON holds the counts per kind.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <string>

#include "core/file_util.h"
#include "test_util.h"

namespace {

void ExpectCleanSweep(int degree) {
  const std::string binary = std::string(ARREG_BINARY_DIR) + "/apps/arreg";
  if (!arreg::FileExists(binary)) GTEST_SKIP() << "arreg binary not built";
  const std::string dir = arreg::testing::ScratchDir("random_cut_sweep_p" + std::to_string(degree));
  const std::string command = binary + " bench cutting --random 1000 --seed 1 --degree " +
                              std::to_string(degree) + " --json " + dir +
                              "/sweep.json --save-failures " + dir + "/failures 2>&1";
  const arreg::testing::CommandResult run = arreg::testing::RunCommand(command);
  const std::string& output = run.output;
  ASSERT_TRUE(run.exited) << output;
  EXPECT_EQ(run.status, 0) << output;
  const nlohmann::json j = nlohmann::json::parse(arreg::ReadFileToString(dir + "/sweep.json"));
  // Sequences end early once a mesh has 10,000 elements (about half the cuts drawn are not made,
  // docs/cutting.md) and at a violation.
  EXPECT_LE(j.at("cuts").get<int>(), 1000);
  EXPECT_GE(j.at("cuts").get<int>(), 300);
  EXPECT_EQ(j.at("violations").get<int>(), 0) << j.at("violation_list").dump(2);
  EXPECT_TRUE(j.at("per_mesh").contains("kidney"));
  EXPECT_TRUE(j.at("per_mesh").contains("beam"));
  EXPECT_EQ(j.at("degree").get<int>(), degree);
  if (degree == 2) {
    EXPECT_TRUE(j.at("per_mesh").contains("beam-curved"));
  }
  int crossed = 0;
  for (const char* kind : {"plane", "sphere", "cylinder", "bent-sheet", "partial", "crack-front",
                           "graze-vertex", "graze-edge", "graze-face"}) {
    ASSERT_TRUE(j.at("per_kind").contains(kind)) << kind;
    EXPECT_GT(j["per_kind"][kind].at("crossed").get<int>(), 0) << kind;
    crossed += j["per_kind"][kind].at("crossed").get<int>();
  }
  EXPECT_GT(crossed, 0.7 * j.at("cuts").get<int>());
}

TEST(RandomCutSweep, ThousandCutsWithoutViolation) { ExpectCleanSweep(1); }

TEST(RandomCutSweep, ThousandQuadraticCutsWithoutViolation) { ExpectCleanSweep(2); }

}  // namespace
