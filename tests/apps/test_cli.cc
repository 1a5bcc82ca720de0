// The command-line contract: exit 0 for help and version, 2 for wrong usage,
// 1 for bad input, and a single error line that names what is wrong.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <string>

#include "core/file_util.h"
#include "test_util.h"

namespace {

struct Result {
  int exit_code = -1;
  std::string output;  // stdout and stderr together
};

Result RunArreg(const std::string& args) {
  const std::string binary = std::string(ARREG_BINARY_DIR) + "/apps/arreg";
  Result r;
  FILE* pipe = popen((binary + " " + args + " 2>&1").c_str(), "r");
  if (!pipe) return r;
  std::array<char, 4096> buffer{};
  while (fgets(buffer.data(), buffer.size(), pipe)) r.output += buffer.data();
  const int status = pclose(pipe);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

int CountLines(const std::string& text) {
  int lines = 0;
  for (char c : text) lines += c == '\n';
  return lines;
}

class Cli : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!arreg::FileExists(std::string(ARREG_BINARY_DIR) + "/apps/arreg"))
      GTEST_SKIP() << "arreg binary not built";
  }
};

TEST_F(Cli, HelpListsEveryCommandAndExitsZero) {
  const Result r = RunArreg("--help");
  EXPECT_EQ(r.exit_code, 0);
  for (const char* command : {"info", "synth", "run", "eval", "debug", "bench"})
    EXPECT_NE(r.output.find(std::string("  ") + command + " "), std::string::npos) << command;
}

TEST_F(Cli, EverySubcommandHasHelp) {
  for (const char* command : {"info", "synth", "run", "eval", "debug", "bench"}) {
    const Result r = RunArreg(std::string(command) + " --help");
    EXPECT_EQ(r.exit_code, 0) << command;
    EXPECT_NE(r.output.find("usage: arreg " + std::string(command)), std::string::npos)
        << command << ": " << r.output;
  }
}

TEST_F(Cli, VersionPrintsTheProjectVersion) {
  const Result r = RunArreg("--version");
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_EQ(r.output.rfind("arreg ", 0), 0u) << r.output;
}

// The binary's BLAS symbols bind to the system's libblas.so.3 (OpenBLAS after
// install-deps), not to a library on Ceres' link line that exports the same names.
TEST_F(Cli, VersionNamesTheBlasAndItIsLibblas) {
  const Result r = RunArreg("--version");
  EXPECT_EQ(r.exit_code, 0);
  const size_t at = r.output.find("\nblas: ");
  ASSERT_NE(at, std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("shadows"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("none loaded"), std::string::npos) << r.output;
}

TEST_F(Cli, WrongUsageExitsTwoWithOneLineNamingTheOption) {
  Result r = RunArreg("run --no-such-option");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(CountLines(r.output), 1) << r.output;
  EXPECT_NE(r.output.find("--no-such-option"), std::string::npos) << r.output;

  r = RunArreg("no-such-command");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("no-such-command"), std::string::npos) << r.output;

  r = RunArreg("bench no-such-benchmark");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("no-such-benchmark"), std::string::npos) << r.output;

  r = RunArreg("info");
  EXPECT_EQ(r.exit_code, 2) << "missing positional argument";
}

TEST_F(Cli, BadInputExitsOneWithOneLineNamingTheFile) {
  const std::string missing = std::string(ARREG_BINARY_DIR) + "/no/such/mesh.msh";
  Result r = RunArreg("info " + missing);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_EQ(CountLines(r.output), 1) << r.output;
  EXPECT_NE(r.output.find(missing), std::string::npos) << r.output;

  r = RunArreg("run --scene " + std::string(ARREG_BINARY_DIR) + "/no/scene.json --out " +
               std::string(ARREG_BINARY_DIR) + "/test_scratch/cli_run");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("scene.json"), std::string::npos) << r.output;
}

TEST_F(Cli, BadSceneOverrideExitsOneNamingTheOption) {
  for (const char* set : {"--set nosection.key=1", "--set tracking.no_such_key=1",
                          "--set tracking.redetect_every_frames=x"}) {
    const Result r = RunArreg(std::string("bench accuracy ") + set);
    EXPECT_EQ(r.exit_code, 1) << set;
    EXPECT_EQ(CountLines(r.output), 1) << r.output;
    EXPECT_TRUE(r.output.find("--set") != std::string::npos ||
                r.output.find("tracking.") != std::string::npos)
        << r.output;
  }
}

// `arreg bench cutting` on a small sphere: the split's figures reach the JSON (a sphere of
// 6 rings has 4 x 36 - 24 = 120 triangles; a plane through its centre needs caps on both
// sides), and a sphere too coarse to exist is refused with a one-line error naming the option.
TEST_F(Cli, BenchCuttingReportsTheStructureSplit) {
  const std::string json = arreg::testing::ScratchDir("cli_bench_cutting") + "/cutting.json";
  Result r = RunArreg("bench cutting --steps 1 --repeats 1 --structure-rings 6 --json " + json);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const nlohmann::json j = nlohmann::json::parse(arreg::ReadFileToString(json));
  EXPECT_EQ(j.at("structure_split").at("triangles").get<int>(), 120);
  const int caps = j.at("structure_split").at("cap_triangles").get<int>();
  EXPECT_GT(caps, 0);
  EXPECT_EQ(caps % 2, 0) << "one cap per side";
  EXPECT_GT(j.at("speed").at("median_ms").get<double>(), 0.0);

  r = RunArreg("bench cutting --structure-rings 1");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_EQ(CountLines(r.output), 1) << r.output;
  EXPECT_NE(r.output.find("--structure-rings"), std::string::npos) << r.output;
}

// Progress written to a pipe or log file (not a terminal) is whole lines, never a bar
// redrawn with carriage returns, for synth, run and eval alike; and eval sums up the frames
// where the truth has a surface and the run saved none in one warning line. A 6-frame scene
// at 160x128 keeps this to seconds.
TEST_F(Cli, ProgressInALogIsWholeLinesAndEvalSummarisesMissingSurfaces) {
  const std::string dir = arreg::testing::ScratchDir("cli_progress");
  Result r =
      RunArreg("synth --scenario band-stretch --frames 6 --size 160x128 --gt-every 1 --out " + dir +
               "/scene");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(r.output.find('\r'), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("arreg synth: frame 6/6 (100 %)\n"), std::string::npos) << r.output;

  // Surfaces saved at frames 0, 3 and 5 (the last); the truth has one at every frame.
  r = RunArreg("run --scene " + dir + "/scene/scene.json --out " + dir +
               "/run --no-video --save-every 3");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(r.output.find('\r'), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("arreg run: frame 6/6 (100 %)"), std::string::npos) << r.output;

  r = RunArreg("eval --run " + dir + "/run --gt " + dir + "/scene/gt --out " + dir +
               "/report --no-colormaps --min-samples 1000 --max-samples 2000");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(r.output.find('\r'), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("arreg eval: run frame 3/3 (100 %)"), std::string::npos) << r.output;
  size_t warnings = 0;
  for (size_t at = r.output.find("no surface at"); at != std::string::npos;
       at = r.output.find("no surface at", at + 1))
    ++warnings;
  EXPECT_EQ(warnings, 1u) << r.output;
  EXPECT_NE(
      r.output.find("no surface at 3 frames where the ground truth has one (first 1, last 4)"),
      std::string::npos)
      << r.output;
}

}  // namespace
