// Appearance: each feature's look at acquisition, and the check that drops features
// dragged off by an occluder edge.
#include "tracking/tracker.h"

#include "tracking/tracker_internal.h"

namespace arreg {

using tracker_internal::Correlation;
using tracker_internal::SamplePatch;

void FeatureTracker::RememberLook(int id, cv::Point2f position_px) {
  const bool after_instrument = ReidentifyAfterInstrument();
  if (!options_.appearance.enabled && !after_instrument) return;
  if (static_cast<int>(acquired_look_.size()) <= id) acquired_look_.resize(id + 1);
  SamplePatch(pyramid_.float_image(0), position_px, options_.lk.window_px, &acquired_look_[id]);
  if (!after_instrument) return;
  if (static_cast<int>(acquired_surroundings_.size()) <= id) {
    acquired_surroundings_.resize(id + 1);
    acquired_clean_.resize(id + 1, 0);
  }
  acquired_clean_[id] = NearInstrument(position_px) ? 0 : 1;
  if (acquired_clean_[id] && options_.reidentify.reacquire_by_lk)
    SamplePatch(pyramid_.float_image(0), position_px,
                options_.lk.window_px + 2 * kReacquireMarginPx, &acquired_surroundings_[id]);
  else
    acquired_surroundings_[id].clear();
}

void FeatureTracker::CheckAppearance() {
  std::vector<float> window;
  for (FeatureState& f : current_) {
    if (f.status != TrackStatus::kTracked) continue;
    SamplePatch(pyramid_.float_image(0), f.position_px, options_.lk.window_px, &window);
    if (Correlation(window, acquired_look_[f.id]) < options_.appearance.min_correlation)
      f.status = TrackStatus::kLostAppearance;
  }
}

}  // namespace arreg
