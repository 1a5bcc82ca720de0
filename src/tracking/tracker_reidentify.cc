// Re-identification by SURF: lost features wait, are predicted from their neighbours' motion
// and matched by descriptor, scale and appearance.
#include "tracking/tracker.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <utility>

#include "tracking/tracker_internal.h"

namespace arreg {

using tracker_internal::Correlation;
using tracker_internal::SamplePatch;

void FeatureTracker::RememberLost() {
  std::vector<int> lost_ids;
  for (int i = 0; i < static_cast<int>(current_.size()); ++i) {
    const TrackStatus status = current_[i].status;
    // Outliers moved implausibly: they are dropped for good (thesis 7.4.1). So are features
    // that rode an instrument (the motion test): they would be found again on it, on parts the
    // colour mask misses. One that landed on the mask is tissue the instrument covers or drags:
    // it may be found again off the mask once uncovered. With after_instrument, every feature
    // the instrument took (landed on its mask, rode it, or jumped beside it) waits when its look
    // at acquisition was tissue, away from instruments: it was occluded or dragged tissue.
    const int id = current_[i].id;
    if (status == TrackStatus::kTracked) continue;
    const bool rode =
        status == TrackStatus::kInstrument && id < static_cast<int>(rode_.size()) && rode_[id];
    const bool taken_by_instrument =
        ReidentifyAfterInstrument() && id < static_cast<int>(acquired_clean_.size()) &&
        acquired_clean_[id] &&
        (status == TrackStatus::kInstrument ||
         (status == TrackStatus::kOutlierSpatioTemporal &&
          (NearInstrument(previous_position_[i]) || NearInstrument(current_[i].position_px))));
    if ((status == TrackStatus::kOutlierSpatioTemporal || rode) && !taken_by_instrument) continue;
    // Where it was last followed (the frame before): LK's position in this
    // frame is what failed. Its look there verifies a re-identification.
    LostFeature lost{id, frame_, previous_position_[i], {}, {}};
    if (taken_by_instrument) {
      // Its last look may be the instrument's edge that dragged or covered it: matched against
      // its look at acquisition, by SURF and by LK from that look.
      lost.patch = acquired_look_[id];
      lost.surroundings = acquired_surroundings_[id];
      lost.after_instrument = true;
    } else if (status == TrackStatus::kLostAppearance) {
      // Its last look may be the occluder edge that dragged it: a match must
      // look like the feature at its acquisition, and is found by SURF only
      // (re-acquisition by LK would follow the last look).
      lost.patch = acquired_look_[lost.id];
    } else {
      SamplePatch(previous_pyramid_.float_image(0), lost.position_px, options_.lk.window_px,
                  &lost.patch);
      // Not by LK after an instrument covered it: its last look may be the instrument's edge.
      if (options_.reidentify.reacquire_by_lk && status != TrackStatus::kInstrument)
        SamplePatch(previous_pyramid_.float_image(0), lost.position_px,
                    options_.lk.window_px + 2 * kReacquireMarginPx, &lost.surroundings);
    }
    lost_.push_back(std::move(lost));
    lost_ids.push_back(current_[i].id);
  }
  ReferenceDescriptorsOfLost(lost_ids);
}

void FeatureTracker::SyncReferenceDescriptors() {
  // Features detected since: their reference is the descriptor at detection.
  const int known = reference_descriptors_.rows;
  if (known < store_.num_features())
    reference_descriptors_.push_back(store_.descriptors().rowRange(known, store_.num_features()));
}

void FeatureTracker::ReferenceDescriptorsOfLost(const std::vector<int>& lost_ids) {
  SyncReferenceDescriptors();
  if (round_frame_ < 0) return;
  std::vector<SurfKeypoint> keypoints;
  std::vector<int> ids;
  for (int id : lost_ids) {
    // Its last observation in the round frame (a feature lost and found again
    // there has two): tracked there means it was refreshed there.
    const std::vector<TrackObservation>& h = store_.history(id);
    const auto after =
        std::upper_bound(h.begin(), h.end(), round_frame_,
                         [](int frame, const TrackObservation& o) { return frame < o.frame; });
    if (after == h.begin()) continue;
    const TrackObservation& at = *(after - 1);
    if (at.frame != round_frame_ || at.status != TrackStatus::kTracked) continue;
    SurfKeypoint kp = store_.keypoint(id);
    kp.position_px = at.position_px;
    keypoints.push_back(kp);
    ids.push_back(id);
  }
  if (keypoints.empty()) return;
  if (!options_.surf.upright) round_surf_.ComputeOrientations(&keypoints);
  cv::Mat descriptors;
  round_surf_.Describe(keypoints, &descriptors);
  for (size_t k = 0; k < ids.size(); ++k)
    descriptors.row(static_cast<int>(k)).copyTo(reference_descriptors_.row(ids[k]));
}

int FeatureTracker::Reidentify(const cv::Mat& roi_mask) {
  const ReidentifyOptions& o = options_.reidentify;
  lost_.erase(std::remove_if(
                  lost_.begin(), lost_.end(),
                  [&](const LostFeature& f) { return frame_ - f.lost_frame > o.max_lost_frames; }),
              lost_.end());
  predictions_.clear();
  if (lost_.empty()) return 0;
  SyncReferenceDescriptors();

  // Where each waiting feature should be now: moved like the features that
  // were nearest to it at the loss and are tracked both then and now.
  std::vector<int> tracked;
  for (int i = 0; i < static_cast<int>(current_.size()); ++i)
    if (current_[i].status == TrackStatus::kTracked) tracked.push_back(i);
  // Per loss frame: (position in the frame before the loss, position now).
  std::map<int, std::vector<std::pair<cv::Point2f, cv::Point2f>>> then_and_now;
  auto anchors_for =
      [&](int lost_frame) -> const std::vector<std::pair<cv::Point2f, cv::Point2f>>& {
    auto [it, inserted] = then_and_now.try_emplace(lost_frame);
    if (inserted) {
      for (int i : tracked) {
        const std::vector<TrackObservation>& h = store_.history(current_[i].id);
        const auto at =
            std::lower_bound(h.begin(), h.end(), lost_frame - 1,
                             [](const TrackObservation& o, int frame) { return o.frame < frame; });
        if (at != h.end() && at->frame == lost_frame - 1 && at->status == TrackStatus::kTracked)
          it->second.emplace_back(at->position_px, current_[i].position_px);
      }
    }
    return it->second;
  };
  const float border = static_cast<float>(options_.border_px);
  std::vector<cv::Point2f> predicted(lost_.size());
  std::vector<int> waiting;  // indices into lost_ with a usable prediction
  std::vector<std::pair<float, int>> by_distance;
  for (int l = 0; l < static_cast<int>(lost_.size()); ++l) {
    const LostFeature& f = lost_[l];
    const auto& anchors = anchors_for(f.lost_frame);
    if (static_cast<int>(anchors.size()) < o.min_neighbours) continue;
    by_distance.clear();
    for (int a = 0; a < static_cast<int>(anchors.size()); ++a) {
      const cv::Point2f d = anchors[a].first - f.position_px;
      by_distance.emplace_back(d.dot(d), a);
    }
    const int k = std::min<int>(o.neighbours, static_cast<int>(by_distance.size()));
    std::partial_sort(by_distance.begin(), by_distance.begin() + k, by_distance.end());
    cv::Point2f shift(0, 0);
    for (int m = 0; m < k; ++m) {
      const auto& [then, now] = anchors[by_distance[m].second];
      shift += now - then;
    }
    const cv::Point2f q = f.position_px + shift * (1.f / k);
    if (q.x < border || q.y < border || q.x > gray_.cols - 1 - border ||
        q.y > gray_.rows - 1 - border || !InsideRoi(q, roi_mask))
      continue;
    predicted[l] = q;
    waiting.push_back(l);
    predictions_.emplace_back(f.id, q);
  }
  if (waiting.empty()) return 0;

  // Fresh SURF points near a prediction and away from the followed features;
  // the responses are computed only around the predictions (DetectNear), not on the whole frame.
  const float gate = static_cast<float>(o.gate_px), wide = 2 * gate;
  std::vector<cv::Point2f> centres;
  for (int l : waiting) centres.push_back(predicted[l]);
  std::vector<SurfKeypoint> detected, near;
  if (o.search_near_predictions)
    round_surf_.DetectNear(roi_mask, centres, wide, &detected);
  else
    round_surf_.Detect(roi_mask, &detected);
  const float min_distance = static_cast<float>(options_.min_distance_px);
  for (const SurfKeypoint& kp : detected) {
    bool close = false;
    for (int l : waiting) {
      const cv::Point2f d = kp.position_px - predicted[l];
      if (d.dot(d) <= wide * wide) {
        close = true;
        break;
      }
    }
    if (!close) continue;
    bool taken = false;
    for (const FeatureState& f : current_) {
      const cv::Point2f d = kp.position_px - f.position_px;
      if (f.status == TrackStatus::kTracked && d.dot(d) < min_distance * min_distance) {
        taken = true;
        break;
      }
    }
    if (!taken) near.push_back(kp);
  }
  if (near.empty()) return 0;

  // Only features with an eligible candidate (inside the gate, same Laplacian
  // sign, scale within the factor) can match; the points within twice the gate
  // of those are all that need an orientation and a descriptor (the others
  // could neither match nor take part in a ratio test).
  const float max_log_scale = static_cast<float>(std::log(o.max_scale_factor));
  auto eligible = [&](const SurfKeypoint& kp, int l) {
    const cv::Point2f d = kp.position_px - predicted[l];
    const int id = lost_[l].id;
    return d.dot(d) <= gate * gate && kp.laplacian_sign == store_.keypoint(id).laplacian_sign &&
           std::abs(std::log(kp.scale_px / store_.keypoint(id).scale_px)) <= max_log_scale;
  };
  std::vector<int> searched;
  for (int l : waiting)
    if (std::any_of(near.begin(), near.end(),
                    [&](const SurfKeypoint& kp) { return eligible(kp, l); }))
      searched.push_back(l);
  if (searched.empty()) return 0;
  waiting.swap(searched);
  near.erase(std::remove_if(near.begin(), near.end(),
                            [&](const SurfKeypoint& kp) {
                              for (int l : waiting) {
                                const cv::Point2f d = kp.position_px - predicted[l];
                                if (d.dot(d) <= wide * wide) return false;
                              }
                              return true;
                            }),
             near.end());
  if (!options_.surf.upright) round_surf_.ComputeOrientations(&near);
  cv::Mat descriptors;
  round_surf_.Describe(near, &descriptors);

  // Best candidate inside the gate (descriptor distance, scale), checked by the
  // ratio test against every point within twice the gate.
  struct Match {
    float distance;
    int lost_index, keypoint;
  };
  std::vector<Match> matches;
  std::vector<float> patch;
  for (int l : waiting) {
    const int id = lost_[l].id;
    const cv::Mat reference = reference_descriptors_.row(id);
    float best = std::numeric_limits<float>::max(), second = best;
    int best_k = -1;
    for (int k = 0; k < static_cast<int>(near.size()); ++k) {
      const cv::Point2f d = near[k].position_px - predicted[l];
      const float d2 = d.dot(d);
      if (d2 > wide * wide) continue;
      const float distance = static_cast<float>(cv::norm(reference, descriptors.row(k)));
      if (eligible(near[k], l) && distance < best) {
        second = std::min(second, best);
        best = distance;
        best_k = k;
      } else {
        second = std::min(second, distance);
      }
    }
    if (best_k < 0 || best > o.max_descriptor_distance) continue;
    if (second < std::numeric_limits<float>::max() && best >= o.ratio * second) continue;
    // Tissue an instrument took is found again once the instrument has left it: a match beside
    // one may be the instrument itself.
    if (lost_[l].after_instrument && NearInstrument(near[best_k].position_px)) continue;
    SamplePatch(pyramid_.float_image(0), near[best_k].position_px, options_.lk.window_px, &patch);
    if (Correlation(patch, lost_[l].patch) < o.min_patch_correlation) continue;
    matches.push_back({best, l, best_k});
  }
  // One point per feature, the closest descriptors first; found features keep
  // min_distance_px from each other like detected ones.
  std::sort(matches.begin(), matches.end(),
            [](const Match& a, const Match& b) { return a.distance < b.distance; });
  std::vector<uint8_t> used_keypoint(near.size(), 0), found(lost_.size(), 0);
  std::vector<cv::Point2f> placed;
  int count = 0;
  for (const Match& m : matches) {
    if (used_keypoint[m.keypoint]) continue;
    const cv::Point2f p = near[m.keypoint].position_px;
    bool crowded = false;
    for (const cv::Point2f& q : placed)
      if ((p - q).dot(p - q) < min_distance * min_distance) crowded = true;
    if (crowded) continue;
    used_keypoint[m.keypoint] = 1;
    found[m.lost_index] = 1;
    placed.push_back(p);
    Restore(lost_[m.lost_index].id, p);
    ++count;
  }
  ForgetFound(found);
  return count;
}

void FeatureTracker::Restore(int id, const cv::Point2f& position_px) {
  RememberLook(id, position_px);
  Anchor(id, position_px);
  current_.push_back({id, position_px, cv::Point2f(0, 0), TrackStatus::kTracked});
  previous_position_.push_back(position_px);
  store_.Record(id, {frame_, position_px, TrackStatus::kTracked, true});
}

void FeatureTracker::ForgetFound(const std::vector<uint8_t>& found) {
  int kept = 0;
  for (int l = 0; l < static_cast<int>(lost_.size()); ++l) {
    if (found[l]) continue;
    if (kept != l) lost_[kept] = std::move(lost_[l]);  // never self-move: it empties the patch
    ++kept;
  }
  lost_.resize(kept);
}

}  // namespace arreg
