#include "tracking/surf.h"
#include "test_images.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <random>

#include <opencv2/imgproc.hpp>

#include "core/error.h"

namespace arreg {
namespace {

constexpr double kPi = 3.14159265358979323846;

cv::Mat GaussianBlob(int size, cv::Point2d centre, double sigma, double amplitude) {
  cv::Mat image(size, size, CV_8UC1);
  for (int y = 0; y < size; ++y)
    for (int x = 0; x < size; ++x) {
      const double d2 = (x - centre.x) * (x - centre.x) + (y - centre.y) * (y - centre.y);
      image.at<uint8_t>(y, x) =
          cv::saturate_cast<uint8_t>(30 + amplitude * std::exp(-d2 / (2 * sigma * sigma)));
    }
  return image;
}

// Band-limited random texture (blurred noise at three scales), mean 128, std ~40.
cv::Mat Texture(int rows, int cols, unsigned seed) {
  return testing::BandLimitedTexture(rows, cols, seed, 128.0, 40.0);
}

std::vector<SurfKeypoint> Detect(const cv::Mat& gray, cv::Mat* descriptors = nullptr,
                                 const SurfOptions& options = {}) {
  SurfDetector surf(options);
  std::vector<SurfKeypoint> keypoints;
  cv::Mat d;
  surf.DetectAndDescribe(gray, cv::Mat(), &keypoints, &d);
  if (descriptors) *descriptors = d;
  return keypoints;
}

double WrapAngle(double a) {
  while (a > kPi) a -= 2 * kPi;
  while (a <= -kPi) a += 2 * kPi;
  return a;
}

struct Correspondence {
  int a, b;
};

// Repeatability (Mikolajczyk & Schmid style): keypoints of A mapped into B by
// the known transform `a_to_b` (positions) with scale factor `scale_ab`. A
// pair corresponds when the positions agree within max(1.5 px, 0.4 s) and the
// scales within a factor 1.4. Only points whose image lies at least `margin`
// inside the other image and whose scale is detectable in both are counted.
struct Repeatability {
  double value = 0;
  int common_a = 0, common_b = 0;
  std::vector<Correspondence> pairs;
};

Repeatability Measure(const std::vector<SurfKeypoint>& a, const std::vector<SurfKeypoint>& b,
                      const cv::Size& size_a, const cv::Size& size_b,
                      const std::function<cv::Point2d(cv::Point2d)>& a_to_b,
                      const std::function<cv::Point2d(cv::Point2d)>& b_to_a, double scale_ab,
                      double min_scale_a, double margin) {
  auto inside = [margin](cv::Point2d p, cv::Size s) {
    return p.x >= margin && p.y >= margin && p.x < s.width - margin && p.y < s.height - margin;
  };
  std::vector<int> ia, ib;
  for (int i = 0; i < static_cast<int>(a.size()); ++i)
    if (a[i].scale_px >= min_scale_a && inside(a_to_b(a[i].position_px), size_b) &&
        inside(a[i].position_px, size_a))
      ia.push_back(i);
  for (int j = 0; j < static_cast<int>(b.size()); ++j)
    if (b[j].scale_px / scale_ab >= min_scale_a && inside(b_to_a(b[j].position_px), size_a) &&
        inside(b[j].position_px, size_b))
      ib.push_back(j);
  Repeatability r;
  r.common_a = static_cast<int>(ia.size());
  r.common_b = static_cast<int>(ib.size());
  std::vector<bool> used(b.size(), false);
  for (int i : ia) {
    const cv::Point2d pa = a[i].position_px;
    int best = -1;
    double best_d = 1e9;
    for (int j : ib) {
      if (used[j]) continue;
      const double d = cv::norm(b_to_a(b[j].position_px) - pa);
      const double ratio = b[j].scale_px / scale_ab / a[i].scale_px;
      if (d <= std::max(1.5, 0.4 * a[i].scale_px) && ratio < 1.4 && ratio > 1 / 1.4 && d < best_d) {
        best = j;
        best_d = d;
      }
    }
    if (best >= 0) {
      used[best] = true;
      r.pairs.push_back({i, best});
    }
  }
  r.value = static_cast<double>(r.pairs.size()) / std::max(1, std::min(r.common_a, r.common_b));
  return r;
}

TEST(Surf, GaussianBlobIsFoundAtItsCentreWithScaleProportionalToSigma) {
  const cv::Point2d centre(130.3, 120.7);
  std::vector<double> ratios;
  for (double sigma : {3.0, 4.0, 6.0, 8.0, 12.0, 16.0}) {
    const auto keypoints = Detect(GaussianBlob(260, centre, sigma, 200));
    ASSERT_FALSE(keypoints.empty()) << "sigma " << sigma;
    const SurfKeypoint& strongest = keypoints[0];
    EXPECT_LT(cv::norm(cv::Point2d(strongest.position_px) - centre), 0.15) << "sigma " << sigma;
    EXPECT_EQ(strongest.laplacian_sign, -1) << "bright blob";
    ratios.push_back(strongest.scale_px / sigma);
  }
  const auto [lo, hi] = std::minmax_element(ratios.begin(), ratios.end());
  // Proportional: one factor for all sigmas within +-10 %. The factor itself
  // (~0.71, i.e. 1/sqrt(2)) is where the area-normalised box determinant of a
  // Gaussian blob peaks.
  EXPECT_LT(*hi / *lo, 1.2);
  EXPECT_GT(*lo, 0.6);
  EXPECT_LT(*hi, 0.85);
}

TEST(Surf, RepeatableUnderNinetyDegreeRotationAndOrientationFollows) {
  const cv::Mat a = Texture(320, 320, 1);
  cv::Mat b;
  cv::rotate(a, b, cv::ROTATE_90_CLOCKWISE);  // (x, y) -> (rows - 1 - y, x)
  const auto ka = Detect(a), kb = Detect(b);
  const double n = a.rows - 1;
  const auto r = Measure(
      ka, kb, a.size(), b.size(), [n](cv::Point2d p) { return cv::Point2d(n - p.y, p.x); },
      [n](cv::Point2d p) { return cv::Point2d(p.y, n - p.x); }, 1.0, 0.0, 15.0);
  std::printf("rot90: %zu pairs of %d/%d, repeatability %.3f\n", r.pairs.size(), r.common_a,
              r.common_b, r.value);
  ASSERT_GT(r.common_a, 100);
  EXPECT_GE(r.value, 0.8);
  // Directions turn by +90 degrees (y down).
  std::vector<double> errors;
  for (const auto& p : r.pairs)
    errors.push_back(
        std::abs(WrapAngle(kb[p.b].orientation_rad - ka[p.a].orientation_rad - kPi / 2)));
  std::sort(errors.begin(), errors.end());
  std::printf("rot90 orientation median err %.2f deg, 80%% %.2f\n",
              errors[errors.size() / 2] * 180 / kPi, errors[errors.size() * 8 / 10] * 180 / kPi);
  EXPECT_LT(errors[errors.size() / 2], 5 * kPi / 180);
}

TEST(Surf, OrientationAndDescriptorsFollowAnArbitraryRotation) {
  const cv::Mat a = Texture(360, 360, 2);
  const double angle_deg = 30;
  const cv::Matx23d m = cv::getRotationMatrix2D(cv::Point2f(179.5f, 179.5f), angle_deg, 1.0);
  cv::Mat b;
  cv::warpAffine(a, b, m, a.size(), cv::INTER_CUBIC, cv::BORDER_REFLECT);
  cv::Matx23d inv;
  cv::invertAffineTransform(m, inv);
  auto apply = [](const cv::Matx23d& t, cv::Point2d p) {
    return cv::Point2d(t(0, 0) * p.x + t(0, 1) * p.y + t(0, 2),
                       t(1, 0) * p.x + t(1, 1) * p.y + t(1, 2));
  };
  cv::Mat da, db;
  const auto ka = Detect(a, &da), kb = Detect(b, &db);
  const auto r = Measure(
      ka, kb, a.size(), b.size(), [&](cv::Point2d p) { return apply(m, p); },
      [&](cv::Point2d p) { return apply(inv, p); }, 1.0, 0.0, 40.0);
  std::printf("rot30: %zu pairs of %d/%d, repeatability %.3f\n", r.pairs.size(), r.common_a,
              r.common_b, r.value);
  ASSERT_GT(r.pairs.size(), 50u);
  std::vector<double> errors;
  int nearest_is_correct = 0;
  for (const auto& p : r.pairs) {
    const double t = ka[p.a].orientation_rad;
    const double expected = std::atan2(m(1, 0) * std::cos(t) + m(1, 1) * std::sin(t),
                                       m(0, 0) * std::cos(t) + m(0, 1) * std::sin(t));
    errors.push_back(std::abs(WrapAngle(kb[p.b].orientation_rad - expected)));
    // Re-identification: the nearest descriptor in B is the corresponding point.
    int best = -1;
    double best_d = 1e9;
    for (int j = 0; j < db.rows; ++j) {
      const double d = cv::norm(da.row(p.a), db.row(j), cv::NORM_L2SQR);
      if (d < best_d) {
        best_d = d;
        best = j;
      }
    }
    nearest_is_correct += best == p.b;
  }
  std::sort(errors.begin(), errors.end());
  std::printf("rot30 orientation median err %.2f deg; nn correct %d/%zu\n",
              errors[errors.size() / 2] * 180 / kPi, nearest_is_correct, r.pairs.size());
  EXPECT_LT(errors[errors.size() / 2], 8 * kPi / 180);
  EXPECT_GE(nearest_is_correct, 0.7 * r.pairs.size());
}

TEST(Surf, RepeatableUnderScalingByTwo) {
  const cv::Mat a = Texture(512, 512, 3);
  cv::Mat b;
  cv::resize(a, b, cv::Size(256, 256), 0, 0, cv::INTER_AREA);
  // Pixel centres: x_b = (x_a + 0.5) / 2 - 0.5.
  const auto ka = Detect(a), kb = Detect(b);
  // Scales below 2 x the smallest one SURF finds (about 2 px) cannot reappear in B.
  const auto r = Measure(
      ka, kb, a.size(), b.size(),
      [](cv::Point2d p) { return cv::Point2d((p.x + 0.5) / 2 - 0.5, (p.y + 0.5) / 2 - 0.5); },
      [](cv::Point2d p) { return cv::Point2d(2 * p.x + 0.5, 2 * p.y + 0.5); }, 0.5, 4.4, 20.0);
  std::printf("scale2: %zu pairs of %d/%d, repeatability %.3f\n", r.pairs.size(), r.common_a,
              r.common_b, r.value);
  ASSERT_GT(r.common_b, 50);
  EXPECT_GE(r.value, 0.6);
}

TEST(Surf, RepeatableUnderBrightnessAndContrastChange) {
  const cv::Mat a = Texture(320, 320, 4);
  cv::Mat b;
  a.convertTo(b, CV_8U, 0.8, 45);  // darker contrast, brighter mean
  const auto ka = Detect(a), kb = Detect(b);
  auto same = [](cv::Point2d p) { return p; };
  const auto r = Measure(ka, kb, a.size(), b.size(), same, same, 1.0, 0.0, 15.0);
  std::printf("brightness: %zu pairs of %d/%d, repeatability %.3f\n", r.pairs.size(), r.common_a,
              r.common_b, r.value);
  ASSERT_GT(r.common_b, 100);
  EXPECT_GE(r.value, 0.6);
}

TEST(Surf, MaskAndOptions) {
  const cv::Mat a = Texture(200, 200, 5);
  cv::Mat mask = cv::Mat::zeros(a.size(), CV_8UC1);
  mask(cv::Rect(0, 0, 100, 200)).setTo(255);
  SurfDetector surf;
  std::vector<SurfKeypoint> keypoints;
  surf.SetImage(a);
  surf.Detect(mask, &keypoints);
  ASSERT_FALSE(keypoints.empty());
  for (const auto& kp : keypoints) EXPECT_LT(kp.position_px.x, 100.5f);
  for (size_t i = 1; i < keypoints.size(); ++i)
    EXPECT_GE(keypoints[i - 1].response, keypoints[i].response) << "strongest first";
  SurfOptions options;
  options.max_keypoints = 10;
  options.upright = true;
  const auto top = Detect(a, nullptr, options);
  ASSERT_EQ(top.size(), 10u);
  for (const auto& kp : top) EXPECT_EQ(kp.orientation_rad, 0.f);
  options.octaves = 0;
  EXPECT_THROW(options.Check(), Error);
}

// Responses computed only around the centres, on the whole image's integral
// image, give exactly the points of whole-image detection near the centres:
// same positions, scales, responses, signs, orientations and order. Centres
// at corners and edges, overlapping, alone, outside the image; with and
// without a mask; reusing the detector's buffers after a whole-image call.
TEST(Surf, DetectNearEqualsTheWholeImagesPointsNearTheCentres) {
  const cv::Mat image = Texture(512, 640, 31);
  cv::Mat roi(image.size(), CV_8UC1, cv::Scalar(0));
  cv::circle(roi, cv::Point(330, 250), 230, cv::Scalar(255), -1);
  const std::vector<cv::Point2f> centres = {{6, 5},     {634, 507}, {320, 3},   {320, 256},
                                            {150, 400}, {170, 395}, {500, 120}, {-40, 300}};
  for (const bool upright : {true, false}) {
    SurfOptions options;
    options.hessian_threshold = 8;
    options.upright = upright;
    for (const float radius : {3.f, 24.f, 80.f}) {
      for (const cv::Mat& mask : {cv::Mat(), roi}) {
        SurfDetector surf(options);
        surf.SetImage(image);
        std::vector<SurfKeypoint> all, expected, actual;
        surf.Detect(mask, &all);
        for (const SurfKeypoint& kp : all)
          for (const cv::Point2f& c : centres)
            if ((kp.position_px - c).dot(kp.position_px - c) <= radius * radius) {
              expected.push_back(kp);
              break;
            }
        surf.DetectNear(mask, centres, radius, &actual);
        if (radius > 20) {
          ASSERT_GT(expected.size(), 20u);
        }
        ASSERT_EQ(actual.size(), expected.size()) << "radius " << radius;
        for (size_t i = 0; i < expected.size(); ++i) {
          EXPECT_EQ(actual[i].position_px, expected[i].position_px) << i;
          EXPECT_EQ(actual[i].scale_px, expected[i].scale_px) << i;
          EXPECT_EQ(actual[i].response, expected[i].response) << i;
          EXPECT_EQ(actual[i].laplacian_sign, expected[i].laplacian_sign) << i;
          EXPECT_EQ(actual[i].octave, expected[i].octave) << i;
          EXPECT_EQ(actual[i].orientation_rad, expected[i].orientation_rad) << i;
        }
      }
    }
  }
  SurfDetector surf;
  surf.SetImage(image);
  std::vector<SurfKeypoint> none{SurfKeypoint()};
  surf.DetectNear(cv::Mat(), {}, 10.f, &none);
  EXPECT_TRUE(none.empty());
  EXPECT_THROW(surf.DetectNear(cv::Mat(), centres, -1.f, &none), Error);
}

}  // namespace
}  // namespace arreg
