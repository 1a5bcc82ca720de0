// align acceptance (label slow): 100 seeded perturbations of up to 20 deg and 20 mm of the
// kidney-cut and band-stretch poses. Outline alone: >= 90 % within 2 deg / 2 mm at the
// centroid; with 4 landmarks (0.25 px noise): 100 % within 1 deg / 1 mm.
#include <gtest/gtest.h>

#include <random>

#include "ar/align/align_eval.h"
#include "test_align_fixture.h"

namespace arreg::align {
namespace {

void CheckHundred(const std::string& scenario) {
  const testing::AlignScene& s = testing::GetAlignScene(scenario);
  int outline_ok = 0, landmarks_ok = 0;
  constexpr int kRuns = 100;
  for (int k = 0; k < kRuns; ++k) {
    std::mt19937_64 rng(k + 1);
    const TrialPair t = RunTrialPair(s, AlignOptions(), 20, 20, 4, 0.25, &rng);
    const TrialResult &a = t.outline_only, &b = t.with_landmarks;
    outline_ok += a.fits && a.rotation_error_deg <= 2 && a.translation_error_mm <= 2;
    landmarks_ok += b.fits && b.rotation_error_deg <= 1 && b.translation_error_mm <= 1;
  }
  EXPECT_GE(outline_ok, 90) << scenario;
  EXPECT_EQ(landmarks_ok, kRuns) << scenario;
}

TEST(AlignAcceptance, Kidney100) { CheckHundred("kidney-cut"); }
TEST(AlignAcceptance, Band100) { CheckHundred("band-stretch"); }

}  // namespace
}  // namespace arreg::align
