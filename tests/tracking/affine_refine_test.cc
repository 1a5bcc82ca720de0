#include "tracking/affine_refine.h"
#include "test_images.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "tracking/tracker.h"

namespace arreg {
namespace {

// The image whose pixel at centre + L (x - centre) + shift is texture(x), times gain plus bias.
cv::Mat Warped(const cv::Mat& texture, cv::Point2f centre, const cv::Matx22d& l, cv::Point2f shift,
               double gain, double bias) {
  cv::Matx23d m(l(0, 0), l(0, 1), 0, l(1, 0), l(1, 1), 0);
  const cv::Vec2d c(centre.x, centre.y);
  const cv::Vec2d t = c - l * c + cv::Vec2d(shift.x, shift.y);
  m(0, 2) = t[0], m(1, 2) = t[1];
  cv::Mat out;
  cv::warpAffine(texture, out, m, texture.size(), cv::INTER_CUBIC, cv::BORDER_REFLECT);
  out.convertTo(out, CV_8U, gain, bias);
  return out;
}

TEST(AffineRefine, RecoversAWarpWithGainAndBiasFromATranslatedStart) {
  const cv::Mat texture = testing::BandLimitedTexture(240, 240, 3, 110, 30);
  const cv::Point2f centre(120.3f, 118.6f), shift(2.4f, -1.3f);
  const cv::Matx22d l(1.15, 0.10, -0.08, 0.88);
  const cv::Mat target = testing::PaddedFloatView(Warped(texture, centre, l, shift, 1.2, -12), 32);
  DriftCorrectionOptions options;
  AffineAnchor anchor;
  ASSERT_TRUE(MakeAffineAnchor(testing::PaddedFloatView(texture, 32), centre, options, 1e-4,
                               cv::Mat(), &anchor));
  // Tracking put the feature 1.1 px off, with no idea of the shape change.
  const cv::Point2f truth = centre + shift;
  const AffineRefinement r = RefineAffine(
      anchor, target, {truth + cv::Point2f(0.8f, -0.75f), cv::Matx22f::eye()}, options);
  EXPECT_TRUE(r.accepted);
  EXPECT_GT(r.correlation, 0.99);
  EXPECT_LT(cv::norm(r.warp.centre - truth), 0.05) << r.warp.centre;
  for (int i = 0; i < 2; ++i)
    for (int j = 0; j < 2; ++j) EXPECT_NEAR(r.warp.linear(i, j), l(i, j), 0.01) << i << j;
}

TEST(AffineRefine, ChecksRejectFarMovesFlatWindowsAndOtherTexture) {
  const cv::Mat texture = testing::BandLimitedTexture(240, 240, 4, 110, 30);
  const cv::Mat image = testing::PaddedFloatView(texture, 32);
  DriftCorrectionOptions options;
  AffineAnchor anchor;
  const cv::Point2f p(100, 110);
  ASSERT_TRUE(MakeAffineAnchor(image, p, options, 1e-4, cv::Mat(), &anchor));
  // Found, but farther from the start than max_correction_px: not accepted.
  options.max_correction_px = 1.0;
  const AffineRefinement far = RefineAffine(anchor, image, {p + cv::Point2f(1.5f, 0.5f)}, options);
  EXPECT_LT(cv::norm(far.warp.centre - p), 0.05);
  EXPECT_FALSE(far.accepted);
  // A flat window cannot anchor.
  const cv::Mat flat = testing::PaddedFloatView(cv::Mat(240, 240, CV_8U, cv::Scalar(90)), 32);
  AffineAnchor flat_anchor;
  EXPECT_FALSE(MakeAffineAnchor(flat, p, options, 1e-4, cv::Mat(), &flat_anchor));
  // Other texture does not correlate.
  const cv::Mat other =
      testing::PaddedFloatView(testing::BandLimitedTexture(240, 240, 5, 110, 30), 32);
  EXPECT_FALSE(RefineAffine(anchor, other, {p}, DriftCorrectionOptions{}).accepted);
  // Windows leaving the readable area are refused, not read out of bounds.
  AffineAnchor outside;
  EXPECT_FALSE(MakeAffineAnchor(image, cv::Point2f(-30, 10), options, 1e-4, cv::Mat(), &outside));
  EXPECT_FALSE(RefineAffine(anchor, image, {cv::Point2f(265, 265)}, options).accepted);
}

TEST(AffineRefine, OptionsAreChecked) {
  DriftCorrectionOptions o;
  o.window_px = 24;
  EXPECT_THROW(o.Check(), Error);
  o = {};
  o.max_scale = 1;
  EXPECT_THROW(o.Check(), Error);
  o = {};
  o.max_correction_px = 0;
  EXPECT_THROW(o.Check(), Error);
  EXPECT_NO_THROW(DriftCorrectionOptions{}.Check());
}

// Median and largest distance of the tracked features from where the stretch
// carried them, after `frames` frames of a texture stretched to 1.8 times
// its height (and sheared) about its top row, with and without drift correction.
std::pair<double, double> StretchErrors(bool drift_correction, int frames) {
  const cv::Mat texture = testing::BandLimitedTexture(400, 320, 8, 110, 30);
  auto warp = [&](int t) {
    const double s = 0.8 * t / frames;
    return cv::Matx23d(1, 0.25 * s, 0, 0, 1 + s, 0);
  };
  FeatureTrackerOptions options;
  options.drift.enabled = drift_correction;
  FeatureTracker tracker(options);
  tracker.Initialize(texture);
  for (int t = 1; t <= frames; ++t) {
    cv::Mat frame;
    cv::warpAffine(texture, frame, warp(t), texture.size(), cv::INTER_CUBIC, cv::BORDER_REFLECT);
    tracker.Track(frame);
  }
  std::vector<double> errors;
  for (const FeatureState& f : tracker.current()) {
    if (f.status != TrackStatus::kTracked) continue;
    const cv::Point2f p0 = tracker.store().history(f.id).front().position_px;
    if (!cv::Rect2f(40, 20, 200, 180).contains(p0)) continue;  // stays in the image
    const cv::Matx23d m = warp(frames);
    const cv::Point2f truth(static_cast<float>(m(0, 0) * p0.x + m(0, 1) * p0.y + m(0, 2)),
                            static_cast<float>(m(1, 0) * p0.x + m(1, 1) * p0.y + m(1, 2)));
    errors.push_back(cv::norm(f.position_px - truth));
  }
  EXPECT_GT(errors.size(), 30u);
  std::sort(errors.begin(), errors.end());
  return {errors[errors.size() / 2], errors.back()};
}

TEST(FeatureTracker, DriftCorrectionKeepsStretchingTextureOnTrack) {
  const auto [median_off, max_off] = StretchErrors(false, 60);
  const auto [median_on, max_on] = StretchErrors(true, 60);
  std::printf("stretch to 1.8: median / largest error %.3f / %.3f px without, %.3f / %.3f with\n",
              median_off, max_off, median_on, max_on);
  EXPECT_LT(median_on, 0.1) << "without: " << median_off;
  EXPECT_LT(max_on, 0.5) << "without: " << max_off;
  EXPECT_LT(3 * median_on, median_off) << "the drift this corrects";
}

}  // namespace
}  // namespace arreg
