// Helpers shared by the tracker's source files (tracker*.cc): patch sampling, correlation and
// mask lookup. Not part of the tracking module's interface.
#pragma once

#include <cmath>
#include <cstdint>
#include <vector>

#include <opencv2/core.hpp>

namespace arreg::tracker_internal {

// Whether the pixel nearest to p is set in a non-empty CV_8UC1 mask (false outside it).
inline bool MaskHas(const cv::Mat& mask, cv::Point2f p) {
  const int x = static_cast<int>(std::lround(p.x)), y = static_cast<int>(std::lround(p.y));
  if (x < 0 || y < 0 || x >= mask.cols || y >= mask.rows) return false;
  return mask.at<uint8_t>(y, x) != 0;
}

// The side x side patch of a CV_32F image (padded by at least side / 2 + 1
// around its rows/cols, as LucasKanadePyramid levels are) centred at p,
// sampled bilinearly, row by row.
void SamplePatch(const cv::Mat& image, cv::Point2f p, int side, std::vector<float>* patch);

// Normalised cross-correlation of two patches of the same size (0 when flat).
double Correlation(const std::vector<float>& a, const std::vector<float>& b);

}  // namespace arreg::tracker_internal
