// Instrument rejection in the tracker: features on the instrument mask, riding an instrument
// (the motion test) or near one.
#include "tracking/tracker.h"

#include <algorithm>
#include <cmath>

#include <opencv2/imgproc.hpp>

#include "tracking/tracker_internal.h"

namespace arreg {

using tracker_internal::MaskHas;

bool FeatureTracker::OnInstrument(cv::Point2f p) const {
  return !instrument_mask_.empty() && MaskHas(instrument_mask_, p);
}

void FeatureTracker::RejectRigidInstrumentMotion() {
  const InstrumentMotionOptions& o = options_.instruments.motion;
  // Where instruments were seen lately: the mask, and the features dropped as on an
  // instrument in the last kInstrumentMemoryFrames frames (parts the colour misses).
  const bool mask = !instrument_mask_.empty() && cv::countNonZero(instrument_mask_) > 0;
  instrument_seen_.erase(
      std::remove_if(instrument_seen_.begin(), instrument_seen_.end(),
                     [&](const auto& s) { return frame_ - s.first > kInstrumentMemoryFrames; }),
      instrument_seen_.end());
  if (!mask && instrument_seen_.empty()) return;
  // Distance to the mask, on the mask shrunk like the segmentation (a pixel more or less does
  // not matter against band_px, and it costs a quarter): features within band_px are
  // candidates.
  const int ds = options_.instruments.mask.downscale;
  cv::Mat distance;
  bool moving_mask = false;
  if (mask) {
    cv::Mat small;
    cv::resize(
        instrument_mask_, small,
        cv::Size((instrument_mask_.cols + ds - 1) / ds, (instrument_mask_.rows + ds - 1) / ds), 0,
        0, cv::INTER_NEAREST);
    cv::Mat moving = small.clone();
    // A region that has not moved since the previous frame (a caption bar, the black corners
    // of the endoscope's image, an instrument held still) drags nothing along: no candidates
    // beside it, or tissue moving past it would be taken for riding it.
    if (previous_small_mask_.size() == small.size()) {
      cv::Mat labels, stats, centroids, kept;
      const int n = cv::connectedComponentsWithStats(small, labels, stats, centroids, 8, CV_32S);
      cv::bitwise_and(small, previous_small_mask_, kept);
      std::vector<int> area(n, 0), still(n, 0), before(n, 0);
      for (int r = 0; r < small.rows; ++r) {
        const int* l = labels.ptr<int>(r);
        const uint8_t* k = kept.ptr<uint8_t>(r);
        for (int c = 0; c < small.cols; ++c) ++area[l[c]], still[l[c]] += k[c] != 0;
      }
      std::vector<uint8_t> is_static(n, 0);
      bool any = false;
      for (int k = 1; k < n; ++k) {
        const cv::Rect box(stats.at<int>(k, cv::CC_STAT_LEFT), stats.at<int>(k, cv::CC_STAT_TOP),
                           stats.at<int>(k, cv::CC_STAT_WIDTH),
                           stats.at<int>(k, cv::CC_STAT_HEIGHT));
        before[k] = cv::countNonZero(previous_small_mask_(box));
        is_static[k] = still[k] >= 0.97 * area[k] && before[k] <= 1.03 * area[k];
        any = any || is_static[k];
      }
      for (int r = 0; any && r < small.rows; ++r) {
        const int* l = labels.ptr<int>(r);
        uint8_t* m = moving.ptr<uint8_t>(r);
        for (int c = 0; c < small.cols; ++c)
          if (is_static[l[c]]) m[c] = 0;
      }
    }
    previous_small_mask_ = small;
    moving_mask = cv::countNonZero(moving) > 0;
    cv::bitwise_not(moving, moving);
    cv::distanceTransform(moving, distance, cv::DIST_L2, 3);
  } else {
    previous_small_mask_.release();
  }
  if (!moving_mask && instrument_seen_.empty()) return;
  const float band2 = static_cast<float>(o.band_px * o.band_px);
  std::vector<int> index;
  std::vector<cv::Point2f> from, to;
  std::vector<uint8_t> near;
  for (int i = 0; i < static_cast<int>(current_.size()); ++i) {
    const FeatureState& f = current_[i];
    // Features followed into this frame: still tracked, or just found on the instrument.
    if (f.status != TrackStatus::kTracked && f.status != TrackStatus::kInstrument) continue;
    bool close = false;
    if (moving_mask) {
      const int x = std::clamp(static_cast<int>(f.position_px.x / ds), 0, distance.cols - 1);
      const int y = std::clamp(static_cast<int>(f.position_px.y / ds), 0, distance.rows - 1);
      close = distance.at<float>(y, x) * ds <= o.band_px;
    }
    for (size_t k = 0; k < instrument_seen_.size() && !close; ++k) {
      const cv::Point2f d = instrument_seen_[k].second - f.position_px;
      close = d.dot(d) <= band2;
    }
    index.push_back(i);
    from.push_back(previous_position_[i]);
    to.push_back(f.position_px);
    near.push_back(close ? 1 : 0);
  }
  const std::vector<bool> flagged = RigidInstrumentMotion(from, to, near, o);
  for (size_t j = 0; j < index.size(); ++j) {
    FeatureState& f = current_[index[j]];
    if (flagged[j]) {
      f.status = TrackStatus::kInstrument;
      if (static_cast<int>(rode_.size()) <= f.id) rode_.resize(f.id + 1, 0);
      rode_[f.id] = 1;
    }
    if (f.status == TrackStatus::kInstrument) instrument_seen_.emplace_back(frame_, f.position_px);
  }
}

bool FeatureTracker::WindowOnInstrument(cv::Point2f p) const {
  if (!instrument_in_frame_) return false;
  const int half = options_.lk.window_px / 2;
  const int cx = static_cast<int>(std::lround(p.x)), cy = static_cast<int>(std::lround(p.y));
  const cv::Rect window = cv::Rect(cx - half, cy - half, 2 * half + 1, 2 * half + 1) &
                          cv::Rect(0, 0, instrument_mask_.cols, instrument_mask_.rows);
  return !window.empty() && cv::countNonZero(instrument_mask_(window)) > 0;
}

bool FeatureTracker::ReidentifyAfterInstrument() const {
  return options_.reidentify.enabled && options_.reidentify.after_instrument &&
         options_.instruments.enabled;
}

bool FeatureTracker::NearInstrument(cv::Point2f p) const {
  const double band = options_.instruments.motion.band_px;
  for (const auto& [frame, q] : instrument_seen_)
    if ((q - p).dot(q - p) <= band * band) return true;
  if (instrument_mask_.empty()) return false;
  const int r = static_cast<int>(std::ceil(band));
  const int cx = static_cast<int>(std::lround(p.x)), cy = static_cast<int>(std::lround(p.y));
  const int y0 = std::max(0, cy - r), y1 = std::min(instrument_mask_.rows - 1, cy + r);
  const int x0 = std::max(0, cx - r), x1 = std::min(instrument_mask_.cols - 1, cx + r);
  for (int y = y0; y <= y1; ++y) {
    const uint8_t* m = instrument_mask_.ptr<uint8_t>(y);
    for (int x = x0; x <= x1; ++x)
      if (m[x] && (x - p.x) * (x - p.x) + (y - p.y) * (y - p.y) <= band * band) return true;
  }
  return false;
}

}  // namespace arreg
