// Replays every input the fuzzers found (tests/data/fuzz/<target>/<file>):
// each must now end in acceptance or in arreg::Error, never in a crash or
// another exception. Under scripts/test --sanitize, ASan and UBSan check the
// same inputs for memory errors and undefined behaviour.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <set>
#include <string>
#include <vector>

#include "core/log.h"
#include "fuzz/fuzz_entries.h"

namespace fs = std::filesystem;

namespace {

const fs::path kFindings = fs::path(ARREG_SOURCE_DIR) / "tests" / "data" / "fuzz";

std::vector<uint8_t> ReadBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

TEST(FuzzReplay, EveryFindingFolderNamesATarget) {
  if (!fs::exists(kFindings)) GTEST_SKIP() << "no findings saved";
  std::set<std::string> names;
  for (const auto& t : arreg::fuzz::Targets()) names.insert(t.name);
  for (const auto& entry : fs::directory_iterator(kFindings)) {
    if (!entry.is_directory()) continue;
    EXPECT_TRUE(names.count(entry.path().filename().string()))
        << entry.path() << " is not a fuzz target's folder";
  }
}

TEST(FuzzReplay, EverySavedFindingEndsInAResultOrAnError) {
  if (!fs::exists(kFindings)) GTEST_SKIP() << "no findings saved";
  const arreg::LogLevel level = arreg::GetLogLevel();
  arreg::SetLogLevel(arreg::LogLevel::kSilent);
  int replayed = 0;
  for (const auto& target : arreg::fuzz::Targets()) {
    const fs::path folder = kFindings / target.name;
    if (!fs::exists(folder)) continue;
    for (const auto& entry : fs::directory_iterator(folder)) {
      if (!entry.is_regular_file()) continue;
      const std::vector<uint8_t> bytes = ReadBytes(entry.path());
      SCOPED_TRACE(entry.path().string());
      int outcome = -1;
      EXPECT_NO_THROW(outcome = arreg::fuzz::RunOne(target, bytes.data(), bytes.size()));
      EXPECT_TRUE(outcome == 0 || outcome == 1);
      ++replayed;
    }
  }
  arreg::SetLogLevel(level);
  RecordProperty("replayed", replayed);
}

// The entries themselves: a well-formed file of each text format is accepted,
// a truncated one is refused with arreg::Error (not a crash).
TEST(FuzzReplay, TheEntriesAcceptAValidFileAndRefuseATruncatedOne) {
  const std::string off =
      "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n";
  const auto& target = arreg::fuzz::FindTarget("off");
  const auto* data = reinterpret_cast<const uint8_t*>(off.data());
  EXPECT_EQ(arreg::fuzz::RunOne(target, data, off.size()), 1);
  EXPECT_EQ(arreg::fuzz::RunOne(target, data, off.size() / 2), 0);
  EXPECT_THROW(arreg::fuzz::FindTarget("no-such-format"), std::invalid_argument);
}

}  // namespace
