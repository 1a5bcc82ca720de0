// FeatureTracker: frame preparation and the per-frame order of the steps (track, filter,
// correct, check, re-identify, re-detect); each step lives in its own tracker_*.cc.
#include "tracking/tracker.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include <opencv2/imgproc.hpp>

#include "core/error.h"

namespace arreg {

namespace {
SurfOptions DetectorOptions(SurfOptions surf) {
  surf.max_keypoints = 0;  // the tracker chooses among all points (distance, highlights)
  surf.upright = true;     // orientations are computed for the chosen points only
  return surf;
}
}  // namespace

FeatureTracker::FeatureTracker(const FeatureTrackerOptions& options)
    : options_(options),
      surf_((options.Check(), DetectorOptions(options.surf))),
      round_surf_(DetectorOptions(options.surf)),
      weak_surf_([&] {
        SurfOptions weak = DetectorOptions(options.surf);
        weak.hessian_threshold = options.min_hessian_threshold;
        return weak;
      }()) {}

int FeatureTracker::num_active() const {
  return static_cast<int>(std::count_if(current_.begin(), current_.end(), [](const auto& f) {
    return f.status == TrackStatus::kTracked;
  }));
}

void FeatureTracker::PrepareFrame(const cv::Mat& image, const cv::Mat& roi_mask) {
  roi_ = roi_mask;
  const std::string where = "frame " + std::to_string(frame_);
  ARREG_CHECK_INPUT(image.type() == CV_8UC1 || image.type() == CV_8UC3, "", where,
                    "tracker input must be an 8-bit grey or BGR image");
  if (frame_ > 0)
    ARREG_CHECK_INPUT(image.size() == gray_.size(), "", where, "image size changed from ",
                      gray_.cols, "x", gray_.rows, " to ", image.cols, "x", image.rows);
  ARREG_CHECK_INPUT(
      roi_mask.empty() || (roi_mask.type() == CV_8UC1 && roi_mask.size() == image.size()), "",
      where, "ROI mask must be empty or CV_8UC1 of the image size");
  if (image.channels() == 3) {
    bgr_ = image;
    cv::cvtColor(image, gray_, cv::COLOR_BGR2GRAY);
  } else {
    bgr_.release();
    gray_ = image;
  }
  instrument_mask_.release();
  instrument_in_frame_ = false;
  free_roi_ = roi_mask;
  if (options_.instruments.enabled && !bgr_.empty()) {
    instrument_mask_ = InstrumentMask(bgr_, options_.instruments.mask);
    instrument_in_frame_ = cv::countNonZero(instrument_mask_) > 0;
    if (instrument_in_frame_) {
      // A new buffer: free_roi_ shares the caller's ROI until here.
      cv::Mat free;
      cv::bitwise_not(instrument_mask_, free);
      if (!roi_mask.empty()) cv::bitwise_and(free, roi_mask, free);
      free_roi_ = free;
    }
  }
  // The previous frame's pyramid is kept, not rebuilt; the buffers of the one
  // before are reused for the new one.
  std::swap(previous_pyramid_, pyramid_);
  pyramid_.Build(gray_, options_.lk.pyramid_levels, options_.lk.window_px);
}

namespace {

// Median over the features of the distance to the nearest other one, pixels; 0 for fewer than
// two. Quadratic: called once, on frame 0's features (at most max_features).
double MedianNearestNeighbourDistance(const std::vector<FeatureState>& features) {
  if (features.size() < 2) return 0.0;
  std::vector<double> nearest(features.size(), std::numeric_limits<double>::infinity());
  for (size_t i = 0; i < features.size(); ++i)
    for (size_t j = i + 1; j < features.size(); ++j) {
      const double d = cv::norm(features[i].position_px - features[j].position_px);
      nearest[i] = std::min(nearest[i], d);
      nearest[j] = std::min(nearest[j], d);
    }
  std::nth_element(nearest.begin(), nearest.begin() + nearest.size() / 2, nearest.end());
  return nearest[nearest.size() / 2];
}

}  // namespace

TrackFrameSummary FeatureTracker::Initialize(const cv::Mat& image, const cv::Mat& roi_mask) {
  frame_ = 0;
  store_ = TrackStore();
  current_.clear();
  previous_position_.clear();
  lost_.clear();
  instrument_seen_.clear();
  previous_small_mask_.release();
  rode_.clear();
  acquired_look_.clear();
  acquired_surroundings_.clear();
  acquired_clean_.clear();
  anchors_.clear();
  reference_descriptors_.release();
  round_frame_ = -1;
  PrepareFrame(image, roi_mask);
  TrackFrameSummary summary;
  summary.frame = 0;
  summary.num_new = Detect(free_roi_);
  summary.num_active = summary.num_new;
  initial_spacing_px_ = MedianNearestNeighbourDistance(current_);
  summary.count[static_cast<int>(TrackStatus::kTracked)] = summary.num_new;
  return summary;
}

TrackFrameSummary FeatureTracker::Track(const cv::Mat& image, const cv::Mat& roi_mask) {
  ARREG_CHECK_INPUT(frame_ >= 0, "", "FeatureTracker", "Track() before Initialize()");
  ++frame_;
  PrepareFrame(image, roi_mask);

  // Only the features still followed go on; the lost ones were reported last frame.
  std::vector<FeatureState> active;
  active.reserve(current_.size());
  for (const FeatureState& f : current_)
    if (f.status == TrackStatus::kTracked) active.push_back(f);
  current_.swap(active);
  previous_position_.resize(current_.size());
  for (size_t i = 0; i < current_.size(); ++i) previous_position_[i] = current_[i].position_px;

  TrackFrameSummary summary;
  summary.frame = frame_;
  const int n = static_cast<int>(current_.size());
  if (n > 0) {
    points_from_.resize(n);
    points_to_.resize(n);
    const LucasKanadeOptions& lk = options_.lk;
    for (int i = 0; i < n; ++i) {
      points_from_[i] = current_[i].position_px;
      points_to_[i] =
          points_from_[i] + (lk.predict_motion ? current_[i].displacement_px : cv::Point2f(0, 0));
    }
    TrackLucasKanade(previous_pyramid_, pyramid_, points_from_, lk, true, &points_to_, &lk_status_);
    const bool fb = lk.forward_backward_max_px > 0;
    if (fb) {
      // Back from where each point landed, starting at where it came from.
      LucasKanadeOptions back = lk;
      back.pyramid_levels =
          lk.backward_pyramid_levels < 0 ? lk.pyramid_levels : lk.backward_pyramid_levels;
      back.epsilon_px = lk.backward_epsilon_px;
      points_back_ = points_from_;
      TrackLucasKanade(pyramid_, previous_pyramid_, points_to_, back, true, &points_back_,
                       &lk_status_back_);
    }
    const float border = static_cast<float>(options_.border_px);
    const float fb_max2 =
        static_cast<float>(lk.forward_backward_max_px * lk.forward_backward_max_px);
    candidates_.clear();
    for (int i = 0; i < n; ++i) {
      FeatureState& f = current_[i];
      const cv::Point2f from = f.position_px, to = points_to_[i];
      // A highlight that appears over a feature hides it: LK then fails or
      // flees the bright spot, and the highlight is the reason reported.
      if (!lk_status_[i]) {
        f.status = IsSpecular(from) ? TrackStatus::kSpecular : TrackStatus::kLostFlow;
        continue;
      }
      f.displacement_px = to - f.position_px;
      f.position_px = to;
      const cv::Point2f miss = fb ? points_back_[i] - points_from_[i] : cv::Point2f(0, 0);
      if (to.x < border || to.y < border || to.x > gray_.cols - 1 - border ||
          to.y > gray_.rows - 1 - border) {
        f.status = TrackStatus::kLostBorder;
      } else if (OnInstrument(to)) {
        f.status = TrackStatus::kInstrument;
      } else if (IsSpecular(to) || IsSpecular(from)) {
        f.status = TrackStatus::kSpecular;
      } else if (fb && (!lk_status_back_[i] || miss.dot(miss) > fb_max2)) {
        f.status = TrackStatus::kLostForwardBackward;
      } else if (!InsideRoi(to, roi_mask)) {
        f.status = TrackStatus::kLostRoi;
      } else {
        candidates_.push_back(i);
      }
    }
    if (options_.instruments.enabled && options_.instruments.motion.enabled) {
      RejectRigidInstrumentMotion();
      candidates_.erase(
          std::remove_if(candidates_.begin(), candidates_.end(),
                         [&](int i) { return current_[i].status != TrackStatus::kTracked; }),
          candidates_.end());
    }
    if (options_.outliers.enabled) {
      candidate_positions_.clear();
      candidate_displacements_.clear();
      for (int i : candidates_) {
        candidate_positions_.push_back(current_[i].position_px);
        candidate_displacements_.push_back(current_[i].displacement_px);
      }
      outlier_flags_ =
          SpatioTemporalOutliers(candidate_positions_, candidate_displacements_, options_.outliers);
      for (size_t j = 0; j < candidates_.size(); ++j)
        if (outlier_flags_[j])
          current_[candidates_[j]].status = TrackStatus::kOutlierSpatioTemporal;
    }
    if (options_.drift.enabled && frame_ % options_.drift.every_frames == 0) CorrectDrift();
    if (options_.appearance.enabled && frame_ % options_.appearance.every_frames == 0)
      CheckAppearance();
    for (const FeatureState& f : current_) {
      store_.Record(f.id, {frame_, f.position_px, f.status});
      // A lost feature's anchor is never used again (one found again is anchored anew where it
      // is found): free it, so that a long video does not keep one per feature ever seen.
      if (f.status != TrackStatus::kTracked && f.id < static_cast<int>(anchors_.size()))
        anchors_[f.id] = DriftAnchor();
    }
  }
  if (options_.reidentify.enabled) {
    RememberLost();
    if (frame_ % options_.reidentify.every_frames == 0) {
      round_surf_.SetImage(gray_);
      round_frame_ = frame_;
      summary.num_reidentified = Reidentify(free_roi_);
      if (options_.reidentify.reacquire_by_lk) summary.num_reidentified += Reacquire(free_roi_);
    }
  }
  if (options_.redetect_every_frames > 0 && frame_ % options_.redetect_every_frames == 0)
    summary.num_new = Detect(free_roi_);
  for (const FeatureState& f : current_) ++summary.count[static_cast<int>(f.status)];
  summary.num_active = summary.count[static_cast<int>(TrackStatus::kTracked)];
  return summary;
}

}  // namespace arreg
