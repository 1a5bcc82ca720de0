// Drift correction: features realigned to their window at acquisition by an affine warp.
#include "tracking/tracker.h"

namespace arreg {

void FeatureTracker::Anchor(int id, cv::Point2f position_px) {
  if (!options_.drift.enabled) return;
  if (static_cast<int>(anchors_.size()) <= id) anchors_.resize(id + 1);
  DriftAnchor& anchor = anchors_[id];
  anchor.linear = cv::Matx22f::eye();
  MakeAffineAnchor(pyramid_.float_image(0), position_px, options_.drift,
                   options_.lk.min_eigen_threshold, roi_, &anchor.window);
}

void FeatureTracker::CorrectDrift() {
  for (FeatureState& f : current_) {
    DriftAnchor& anchor = anchors_[f.id];
    if (f.status != TrackStatus::kTracked || anchor.window.side == 0) continue;
    const AffineRefinement refined = RefineAffine(anchor.window, pyramid_.float_image(0),
                                                  {f.position_px, anchor.linear}, options_.drift);
    if (!refined.accepted) continue;
    f.displacement_px += refined.warp.centre - f.position_px;
    f.position_px = refined.warp.centre;
    anchor.linear = refined.warp.linear;
  }
}

}  // namespace arreg
