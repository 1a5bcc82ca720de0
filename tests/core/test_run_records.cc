// Reading back run.json, frames.jsonl and a ground truth's meta.json (core/run_records.h).
#include "core/run_records.h"

#include <gtest/gtest.h>

#include <fstream>

#include "core/error.h"
#include "test_util.h"

namespace arreg {
namespace {

std::string Write(const std::string& dir, const std::string& name, const std::string& text) {
  const std::string path = dir + "/" + name;
  std::ofstream(path) << text;
  return path;
}

// The message of the arreg::Error that `f` throws ("" when it does not throw).
template <typename F>
std::string ErrorOf(F f) {
  try {
    f();
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

TEST(RunRecords, ReadsASummaryAndItsFrames) {
  const std::string dir = testing::ScratchDir("run_records");
  const RunSummaryRecord run = ReadRunSummary(Write(dir, "run.json", R"({"camera": {"width": 64,
    "height": 48, "fx": 50, "fy": 50, "cx": 32, "cy": 24}, "frames": 2, "interrupted": true,
    "topology": false, "thin_structures": ["sheet"]})"));
  EXPECT_EQ(run.camera.width, 64);
  EXPECT_EQ(run.frames, 2);
  EXPECT_TRUE(run.interrupted);
  EXPECT_FALSE(run.topology);
  EXPECT_EQ(run.thin_structures, std::vector<std::string>{"sheet"});
  const auto frames =
      ReadFrameRecords(Write(dir, "frames.jsonl",
                             "{\"frame\": 0, \"feature_error_mean_mm\": 0.5}\n\n{\"frame\": 1, "
                             "\"feature_error_mean_mm\": null, \"feature_error_max_mm\": 2}\n"),
                       2);
  ASSERT_EQ(frames.size(), 2u);
  EXPECT_EQ(frames[0].feature_error_mean_mm, 0.5);
  EXPECT_FALSE(frames[0].feature_error_max_mm);
  EXPECT_FALSE(frames[1].feature_error_mean_mm);
  EXPECT_EQ(frames[1].feature_error_max_mm, 2.0);
}

TEST(RunRecords, ErrorsNameTheFileAndThePlace) {
  const std::string dir = testing::ScratchDir("run_records_bad");
  const std::string skipped = Write(dir, "skip.jsonl", "{\"frame\": 0}\n{\"frame\": 2}\n");
  const std::string msg = ErrorOf([&] { ReadFrameRecords(skipped, 3); });
  EXPECT_NE(msg.find("skip.jsonl"), std::string::npos) << msg;
  EXPECT_NE(msg.find("line 2"), std::string::npos) << msg;
  EXPECT_NE(msg.find("expected frame 1, got 2"), std::string::npos) << msg;
  const std::string short_log = Write(dir, "short.jsonl", "{\"frame\": 0}\n");
  EXPECT_NE(ErrorOf([&] { ReadFrameRecords(short_log, 2); }).find("1 frame records"),
            std::string::npos);
  const std::string dup = Write(dir, "dup.json", R"({"camera": {"width": 64, "height": 48,
    "fx": 50, "fy": 50, "cx": 32, "cy": 24}, "frames": 1, "thin_structures": ["a", "a"]})");
  EXPECT_NE(ErrorOf([&] { ReadRunSummary(dup); }).find("thin_structures[1]"), std::string::npos);
  const std::string meta = Write(dir, "meta.json", R"({"frames": "ten"})");
  EXPECT_NE(ErrorOf([&] { ReadGroundTruthMeta(meta); }).find("frames"), std::string::npos);
  const GroundTruthMeta ok =
      ReadGroundTruthMeta(Write(dir, "ok.json", R"({"frames": 4, "width": 8})"));
  EXPECT_EQ(ok.frames, 4);
  EXPECT_EQ(ok.width, 8);
  EXPECT_FALSE(ok.height);
}

}  // namespace
}  // namespace arreg
