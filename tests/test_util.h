// Helpers shared by the tests: locating ../shared/data (tests that need it
// skip cleanly when it is absent), scratch directories, and surface parts.
#pragma once

#include <sys/wait.h>

#include <gtest/gtest.h>
#include <Eigen/Core>
#include <array>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "core/mesh.h"

namespace arreg::testing {

// Absolute path of `relative` under the shared data folder (../shared/data
// beside the checkout, or $ARREG_SHARED_DATA), or "" when it does not exist.
inline std::string SharedDataPath(const std::string& relative) {
  namespace fs = std::filesystem;
  std::string root;
  if (const char* env = std::getenv("ARREG_SHARED_DATA"))
    root = env;
  else
    root = std::string(ARREG_SOURCE_DIR) + "/../shared/data";
  const fs::path p = fs::path(root) / relative;
  std::error_code ec;
  return fs::exists(p, ec) ? fs::weakly_canonical(p).string() : std::string();
}

// A fresh, empty scratch directory under the build tree, inside a folder named after the
// running test: ctest runs tests as parallel processes, and two tests that build the same
// fixture (the same `name`) must not remove each other's files.
inline std::string ScratchDir(const std::string& name) {
  namespace fs = std::filesystem;
  fs::path p = fs::path(ARREG_BINARY_DIR) / "test_scratch";
  if (const ::testing::TestInfo* test = ::testing::UnitTest::GetInstance()->current_test_info()) {
    std::string folder = std::string(test->test_suite_name()) + "." + test->name();
    for (char& c : folder)
      if (c == '/') c = '_';
    p /= folder;
  }
  p /= name;
  fs::remove_all(p);
  fs::create_directories(p);
  return p.string();
}

// What a shell command printed on stdout and how it ended.
struct CommandResult {
  bool exited = false;  // ended normally (not by a signal)
  int status = -1;      // its exit status when it exited
  std::string output;
};
// Runs `command` through the shell (append " 2>&1" to capture stderr too).
inline CommandResult RunCommand(const std::string& command) {
  CommandResult r;
  FILE* pipe = popen(command.c_str(), "r");
  if (pipe == nullptr) return r;
  std::array<char, 4096> buffer{};
  while (fgets(buffer.data(), buffer.size(), pipe)) r.output += buffer.data();
  const int status = pclose(pipe);
  r.exited = WIFEXITED(status);
  if (r.exited) r.status = WEXITSTATUS(status);
  return r;
}

// The faces of `s` whose label (one per face) is `label`, on the same vertices.
inline SurfaceMesh FacesWithLabel(const SurfaceMesh& s, const Eigen::VectorXi& labels, int label) {
  SurfaceMesh out;
  out.vertices = s.vertices;
  std::vector<int> kept;
  for (int f = 0; f < s.num_faces(); ++f)
    if (labels(f) == label) kept.push_back(f);
  out.faces.resize(static_cast<int>(kept.size()), 3);
  for (size_t k = 0; k < kept.size(); ++k)
    out.faces.row(static_cast<int>(k)) = s.faces.row(kept[k]);
  return out;
}

}  // namespace arreg::testing

// Skips the current test with a message when shared data is missing.
#define ARREG_REQUIRE_SHARED(var, relative)                           \
  const std::string var = ::arreg::testing::SharedDataPath(relative); \
  if (var.empty()) GTEST_SKIP() << "../shared/data/" << (relative) << " not present; skipped"
