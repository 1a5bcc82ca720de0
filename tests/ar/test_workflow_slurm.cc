// The workflow on a real cluster: a single-node Slurm started here (scripts/slurm-local: munged,
// slurmctld, slurmd, generated slurm.conf) runs the smoke manifest through the slurm profile;
// every job goes through sbatch (Slurm's job completion log, its per-job logs), the aggregated
// figures equal the local profile's, and Slurm stops cleanly. Skips where Slurm cannot start.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "core/file_util.h"
#include "test_util.h"

namespace arreg {
namespace {

namespace fs = std::filesystem;

// Runs a shell command with stdout and stderr in files; returns the exit status.
int Shell(const std::string& command, const fs::path& out, const fs::path& err) {
  const int raw =
      std::system((command + " >'" + out.string() + "' 2>'" + err.string() + "'").c_str());
  return WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
}

int Batch(const std::string& profile, const fs::path& out, const fs::path& scratch) {
  // A bound on the wall time, so that a hung job still ends the test and Slurm is stopped.
  return Shell(std::string("timeout 900 '") + ARREG_SOURCE_DIR + "/scripts/batch' --profile " +
                   profile + " --out '" + out.string() + "' --arreg '" + ARREG_BINARY_DIR +
                   "/apps/arreg'",
               scratch / (profile + ".out"), scratch / (profile + ".err"));
}

std::string Script() { return std::string("'") + ARREG_SOURCE_DIR + "/scripts/slurm-local'"; }

// Stops the Slurm started in `dir` when the test ends, passed or not.
struct SlurmGuard {
  fs::path dir;
  bool running = false;
  ~SlurmGuard() {
    if (running) std::system((Script() + " stop '" + dir.string() + "' >/dev/null 2>&1").c_str());
  }
};

TEST(WorkflowSlurm, SmokeManifestThroughSbatchMatchesTheLocalProfile) {
  if (geteuid() != 0) GTEST_SKIP() << "not root: slurmd cannot start (run as root to include it)";
  if (std::system("command -v snakemake slurmctld slurmd munged >/dev/null 2>&1") != 0)
    GTEST_SKIP() << "snakemake, slurm-wlm or munge missing (scripts/install-deps installs them)";
  const fs::path scratch = ::arreg::testing::ScratchDir("workflow_slurm");
  SlurmGuard slurm{scratch / "slurm"};
  const int started = Shell(Script() + " start '" + slurm.dir.string() + "'", scratch / "start.out",
                            scratch / "start.err");
  if (started != 0) {
    // Stop what did start before skipping.
    std::system((Script() + " stop '" + slurm.dir.string() + "' >/dev/null 2>&1").c_str());
    GTEST_SKIP() << "Slurm could not start here: "
                 << ReadFileToString((scratch / "start.err").string());
  }
  slurm.running = true;
  ASSERT_EQ(setenv("SLURM_CONF", (slurm.dir / "slurm.conf").c_str(), 1), 0);

  ASSERT_EQ(Batch("slurm", scratch / "slurm-out", scratch), 0)
      << ReadFileToString((scratch / "slurm.err").string());
  ASSERT_EQ(Batch("local", scratch / "local-out", scratch), 0)
      << ReadFileToString((scratch / "local.err").string());

  // Every job but `all` went through sbatch: 3 synth, 6 run, 6 eval, 1 report, all completed,
  // each with Slurm's own log.
  std::map<std::string, int> completed;
  std::istringstream jobs(ReadFileToString((slurm.dir / "jobcomp.log").string()));
  int entries = 0;
  for (std::string line; std::getline(jobs, line);) {
    std::smatch m;
    if (!std::regex_search(line, m, std::regex(R"( Name=arreg-(\w+) )"))) continue;
    ++entries;
    std::smatch s;
    ASSERT_TRUE(std::regex_search(line, s, std::regex(R"(JobState=(\S+))"))) << line;
    EXPECT_EQ(s[1], "COMPLETED") << line;
    ++completed[m[1]];
  }
  EXPECT_EQ(entries, 16);
  EXPECT_EQ(completed,
            (std::map<std::string, int>{{"eval", 6}, {"report", 1}, {"run", 6}, {"synth", 3}}));
  int slurm_logs = 0;
  for (const auto& e : fs::directory_iterator(scratch / "slurm-out" / "slurm-logs"))
    slurm_logs += e.path().extension() == ".out";
  EXPECT_EQ(slurm_logs, 16);

  // The same figures as the local profile (speed aside).
  const nlohmann::json a = nlohmann::json::parse(
      ReadFileToString((scratch / "slurm-out" / "report" / "report.json").string()));
  const nlohmann::json b = nlohmann::json::parse(
      ReadFileToString((scratch / "local-out" / "report" / "report.json").string()));
  ASSERT_EQ(a["rows"].size(), 6u);
  ASSERT_EQ(b["rows"].size(), 6u);
  for (size_t i = 0; i < 6; ++i) {
    nlohmann::json x = a["rows"][i], y = b["rows"][i];
    EXPECT_EQ(x["status"], "ok") << x["error"];
    for (nlohmann::json* row : {&x, &y}) {
      row->erase("fps");
      row->erase("seconds");
    }
    EXPECT_EQ(x, y) << i;
  }

  // Slurm stops cleanly: the script waits for the daemons to end.
  std::vector<pid_t> daemons;
  for (const char* file : {"slurmd.pid", "slurmctld.pid", "munge/munged.pid"})
    daemons.push_back(std::stoi(ReadFileToString((slurm.dir / file).string())));
  slurm.running = false;
  EXPECT_EQ(Shell(Script() + " stop '" + slurm.dir.string() + "'", scratch / "stop.out",
                  scratch / "stop.err"),
            0)
      << ReadFileToString((scratch / "stop.err").string());
  for (const pid_t pid : daemons) EXPECT_NE(kill(pid, 0), 0) << "daemon " << pid << " still runs";
}

}  // namespace
}  // namespace arreg
