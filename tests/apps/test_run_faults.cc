// Runs that survive faults (docs/reliability.md): `arreg run` killed with SIGKILL at random
// moments leaves only complete files, SIGTERM stops it with complete records, and two runs of the
// same scene give the same records and byte-identical meshes.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <fcntl.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "core/file_util.h"
#include "core/mesh_io.h"

namespace fs = std::filesystem;

namespace {

const std::string kBinary = std::string(ARREG_BINARY_DIR) + "/apps/arreg";
const std::string kDir = std::string(ARREG_BINARY_DIR) + "/tests-out/run_faults";

// Runs arreg with `args` (stdout and stderr to `log`); returns the pid without waiting.
pid_t Spawn(const std::vector<std::string>& args, const std::string& log) {
  const pid_t pid = fork();
  if (pid == 0) {
    const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd >= 0) {
      dup2(fd, 1);
      dup2(fd, 2);
    }
    std::vector<char*> argv;
    argv.push_back(const_cast<char*>(kBinary.c_str()));
    for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    execv(kBinary.c_str(), argv.data());
    _exit(127);
  }
  return pid;
}

int Wait(pid_t pid) {
  int status = 0;
  waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

int RunArreg(const std::vector<std::string>& args, const std::string& log) {
  return Wait(Spawn(args, log));
}

class RunFaults : public ::testing::Test {
 protected:
  // A short cut scene (a V-cut opens in it, so the remesher runs) generated once.
  static void SetUpTestSuite() {
    if (!fs::exists(kBinary)) return;
    scene_ = kDir + "/scene";
    if (fs::exists(scene_ + "/scene.json")) return;
    fs::remove_all(scene_);
    fs::create_directories(kDir);
    // Exit 1 only says that a frame of the truth stopped at Newton's iteration limit (a last-digit
    // change of the arithmetic can tip one); the scene is complete and fine for these tests.
    const int rc = RunArreg({"synth", "--scenario", "band-cut-v", "--seed", "4001", "--frames",
                             "50", "--size", "320x256", "--gt-every", "10", "--out", scene_},
                            kDir + "/synth.log");
    ASSERT_TRUE(rc == 0 || rc == 1) << arreg::ReadFileToString(kDir + "/synth.log");
    ASSERT_TRUE(fs::exists(scene_ + "/scene.json"));
  }
  void SetUp() override {
    if (!fs::exists(kBinary)) GTEST_SKIP() << kBinary << " is not built";
  }
  static std::vector<std::string> RunArgs(const std::string& out) {
    return {"run", "--scene", scene_ + "/scene.json", "--out", out, "--no-video", "--quiet"};
  }
  static std::string scene_;
};
std::string RunFaults::scene_;

// frames.jsonl without the timings (the only fields that may differ between two runs).
std::vector<nlohmann::json> RecordsWithoutTimings(const std::string& path) {
  std::vector<nlohmann::json> records;
  std::ifstream in(path);
  for (std::string line; std::getline(in, line);) {
    nlohmann::json j = nlohmann::json::parse(line);
    j.erase("ms");
    records.push_back(j);
  }
  return records;
}

TEST_F(RunFaults, TwoRunsGiveTheSameRecordsAndByteIdenticalMeshes) {
  const std::string a = kDir + "/same-a", b = kDir + "/same-b";
  for (const std::string& out : {a, b}) {
    fs::remove_all(out);
    ASSERT_EQ(RunArreg(RunArgs(out), out + ".log"), 0) << arreg::ReadFileToString(out + ".log");
  }
  const auto ra = RecordsWithoutTimings(a + "/frames.jsonl");
  ASSERT_EQ(ra.size(), 50u);
  EXPECT_TRUE(ra == RecordsWithoutTimings(b + "/frames.jsonl"));
  int cuts = 0;
  for (const auto& r : ra) cuts += static_cast<int>(r["cut_events"].size());
  EXPECT_GT(cuts, 0) << "the scene should exercise the remesher";
  int compared = 0;
  for (const char* sub : {"mesh", "surface", "internal"}) {
    if (!fs::exists(a + "/" + sub)) continue;
    for (const auto& e : fs::directory_iterator(a + "/" + sub)) {
      const fs::path other = fs::path(b) / sub / e.path().filename();
      ASSERT_TRUE(fs::exists(other)) << other;
      EXPECT_EQ(arreg::ReadFileToString(e.path().string()), arreg::ReadFileToString(other.string()))
          << e.path();
      ++compared;
    }
  }
  EXPECT_GT(compared, 10);
}

// Every visible file of `dir` is whole: JSON parses, every line of frames.jsonl parses, meshes
// read. Writers put unfinished output under hidden temporary names (.NAME.tmp-PID-N.EXT, core/
// file_util.h) and rename it when complete, so only those may be partial.
void ExpectOnlyCompleteFiles(const std::string& dir) {
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    if (!e.is_regular_file()) continue;
    const std::string name = e.path().filename().string();
    if (name.rfind('.', 0) == 0) {
      EXPECT_NE(name.find(".tmp-"), std::string::npos) << "unexpected hidden file " << e.path();
      continue;
    }
    const std::string ext = e.path().extension().string(), path = e.path().string();
    SCOPED_TRACE(path);
    if (ext == ".json") {
      EXPECT_NO_THROW(nlohmann::json::parse(arreg::ReadFileToString(path)));
    } else if (ext == ".jsonl") {
      const std::string text = arreg::ReadFileToString(path);
      EXPECT_TRUE(text.empty() || text.back() == '\n') << "a partial last line";
      std::istringstream in(text);
      for (std::string line; std::getline(in, line);) EXPECT_NO_THROW(nlohmann::json::parse(line));
    } else if (ext == ".obj" || ext == ".vtk") {
      EXPECT_NO_THROW(arreg::ReadMeshFile(path));
    }
  }
}

TEST_F(RunFaults, KilledAtRandomMomentsLeavesOnlyCompleteFiles) {
  // The length of a whole run on this machine sets the range of the kill moments.
  const std::string full = kDir + "/kill-full";
  fs::remove_all(full);
  const auto t0 = std::chrono::steady_clock::now();
  ASSERT_EQ(RunArreg(RunArgs(full), full + ".log"), 0);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::mt19937 rng(40);
  std::uniform_real_distribution<double> moment(0.02, 1.0);
  int killed_running = 0;
  for (int trial = 0; trial < 10; ++trial) {
    const std::string out = kDir + "/kill-" + std::to_string(trial);
    fs::remove_all(out);
    const pid_t pid = Spawn(RunArgs(out), out + ".log");
    std::this_thread::sleep_for(std::chrono::duration<double>(moment(rng) * seconds));
    killed_running += kill(pid, SIGKILL) == 0;
    Wait(pid);
    if (!fs::exists(out)) continue;  // killed before it made its folder
    ExpectOnlyCompleteFiles(out);
    // `arreg eval` on the remains works or names what is missing, in one line, exit 1.
    const std::string log = out + "-eval.log";
    const int rc = RunArreg({"eval", "--run", out, "--gt", scene_ + "/gt", "--out", out + "-eval",
                             "--no-colormaps", "--quiet"},
                            log);
    const std::string text = arreg::ReadFileToString(log);
    if (rc != 0) {
      EXPECT_EQ(rc, 1) << text;
      EXPECT_NE(text.find("missing"), std::string::npos) << text;
    }
  }
  EXPECT_GE(killed_running, 5) << "most kills should land while the run is working";
}

// SIGTERM (kill's default, a batch scheduler's time limit) stops the run after the current frame
// with complete records that `arreg eval` evaluates as an interrupted run.
TEST_F(RunFaults, TerminatedRunKeepsCompleteRecordsThatEvalReads) {
  const std::string out = kDir + "/term";
  fs::remove_all(out);
  const pid_t pid = Spawn(RunArgs(out), out + ".log");
  // Once a few frames are recorded (the first surfaces saved), ask it to stop.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
  while (!fs::exists(out + "/surface/000010.obj") && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  ASSERT_EQ(kill(pid, SIGTERM), 0);
  const int rc = Wait(pid);
  const nlohmann::json run = nlohmann::json::parse(arreg::ReadFileToString(out + "/run.json"));
  const int frames = run.at("frames").get<int>();
  if (run.at("interrupted").get<bool>()) {
    EXPECT_EQ(rc, 130);
    EXPECT_LT(frames, 50);
  } else {
    EXPECT_EQ(rc, 0);  // the signal came after the last frame
  }
  EXPECT_EQ(RecordsWithoutTimings(out + "/frames.jsonl").size(), static_cast<size_t>(frames));
  ExpectOnlyCompleteFiles(out);
  EXPECT_EQ(RunArreg({"eval", "--run", out, "--gt", scene_ + "/gt", "--out", out + "-eval",
                      "--no-colormaps", "--quiet"},
                     out + "-eval.log"),
            0)
      << arreg::ReadFileToString(out + "-eval.log");
}

}  // namespace
