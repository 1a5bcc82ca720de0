// Masks: specular highlights, the region of interest and mask images read from files.
#include "tracking/tracker.h"

#include <algorithm>
#include <cmath>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "tracking/tracker_internal.h"

namespace arreg {

using tracker_internal::MaskHas;

cv::Mat SpecularMask(const cv::Mat& image, const SpecularOptions& options) {
  ARREG_CHECK_INPUT(image.type() == CV_8UC1 || image.type() == CV_8UC3, "", "SpecularMask image",
                    "expected CV_8UC1 or CV_8UC3");
  cv::Mat mask(image.size(), CV_8UC1, cv::Scalar(0));
  for (int r = 0; r < image.rows; ++r) {
    uint8_t* out = mask.ptr<uint8_t>(r);
    if (image.channels() == 1) {
      const uint8_t* in = image.ptr<uint8_t>(r);
      for (int c = 0; c < image.cols; ++c) out[c] = in[c] >= options.min_value ? 255 : 0;
    } else {
      const cv::Vec3b* in = image.ptr<cv::Vec3b>(r);
      for (int c = 0; c < image.cols; ++c) {
        const int v = std::max({in[c][0], in[c][1], in[c][2]});
        const int m = std::min({in[c][0], in[c][1], in[c][2]});
        out[c] = v >= options.min_value && 255 * (v - m) <= options.max_saturation * v ? 255 : 0;
      }
    }
  }
  return mask;
}

cv::Mat ReadMask(const std::string& path, int width, int height) {
  const cv::Mat image = cv::imread(path, cv::IMREAD_GRAYSCALE);
  ARREG_CHECK_INPUT(!image.empty(), path, "", "cannot read the mask image");
  ARREG_CHECK_INPUT(image.cols == width && image.rows == height, path, "", "mask is ", image.cols,
                    "x", image.rows, " but the video is ", width, "x", height);
  cv::Mat mask;
  cv::threshold(image, mask, 0, 255, cv::THRESH_BINARY);
  return mask;
}

bool FeatureTracker::IsSpecular(cv::Point2f p) const {
  const SpecularOptions& o = options_.specular;
  if (!o.enabled) return false;
  const int cx = static_cast<int>(std::lround(p.x)), cy = static_cast<int>(std::lround(p.y));
  const int r0 = std::max(0, cy - o.radius_px), r1 = std::min(gray_.rows - 1, cy + o.radius_px);
  const int c0 = std::max(0, cx - o.radius_px), c1 = std::min(gray_.cols - 1, cx + o.radius_px);
  for (int r = r0; r <= r1; ++r)
    for (int c = c0; c <= c1; ++c) {
      if (bgr_.empty()) {
        if (gray_.at<uint8_t>(r, c) >= o.min_value) return true;
      } else {
        const cv::Vec3b px = bgr_.at<cv::Vec3b>(r, c);
        const int v = std::max({px[0], px[1], px[2]});
        const int m = std::min({px[0], px[1], px[2]});
        if (v >= o.min_value && 255 * (v - m) <= o.max_saturation * v) return true;
      }
    }
  return false;
}

bool FeatureTracker::InsideRoi(cv::Point2f p, const cv::Mat& roi_mask) const {
  return roi_mask.empty() || MaskHas(roi_mask, p);
}

}  // namespace arreg
