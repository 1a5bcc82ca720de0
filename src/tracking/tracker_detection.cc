// Detection: SURF points kept by strength, away from followed features, highlights and
// the border; re-detection fills holes only.
#include "tracking/tracker.h"

#include <algorithm>
#include <set>
#include <utility>

namespace arreg {

int FeatureTracker::Detect(const cv::Mat& roi_mask) {
  const int room = options_.max_features - num_active();
  if (room <= 0) return 0;
  surf_.SetImage(gray_);
  std::vector<SurfKeypoint> candidates;
  surf_.Detect(roi_mask, &candidates);

  // Greedy by strength: keep points off highlights, inside the border and at
  // least min_distance_px from every kept or followed feature (grid lookup). A re-detection
  // that fills holes (redetect_hole_factor) keeps the new points farther from the followed
  // features and from each other.
  const float min_distance = static_cast<float>(options_.min_distance_px);
  const bool fill_holes =
      frame_ > 0 && options_.redetect_hole_factor > 0.0 && initial_spacing_px_ > 0.0;
  const float from_new =
      fill_holes ? std::max(min_distance, static_cast<float>(initial_spacing_px_)) : min_distance;
  const float from_followed =
      fill_holes ? std::max(min_distance,
                            static_cast<float>(options_.redetect_hole_factor * initial_spacing_px_))
                 : min_distance;
  const float cell = std::max({1.f, from_new, from_followed});
  const int grid_cols = static_cast<int>(gray_.cols / cell) + 1;
  const int grid_rows = static_cast<int>(gray_.rows / cell) + 1;
  // (point, whether it is a followed feature) per cell.
  std::vector<std::vector<std::pair<cv::Point2f, bool>>> grid(static_cast<size_t>(grid_cols) *
                                                              grid_rows);
  auto cell_of = [&](cv::Point2f p) {
    return cv::Point(std::clamp(static_cast<int>(p.x / cell), 0, grid_cols - 1),
                     std::clamp(static_cast<int>(p.y / cell), 0, grid_rows - 1));
  };
  auto crowded = [&](cv::Point2f p) {
    const cv::Point g = cell_of(p);
    for (int gy = std::max(0, g.y - 1); gy <= std::min(grid_rows - 1, g.y + 1); ++gy)
      for (int gx = std::max(0, g.x - 1); gx <= std::min(grid_cols - 1, g.x + 1); ++gx)
        for (const auto& [q, followed] : grid[gy * grid_cols + gx]) {
          const float d = followed ? from_followed : from_new;
          if ((p.x - q.x) * (p.x - q.x) + (p.y - q.y) * (p.y - q.y) < d * d) return true;
        }
    return false;
  };
  auto occupy = [&](cv::Point2f p, bool followed) {
    const cv::Point g = cell_of(p);
    grid[g.y * grid_cols + g.x].emplace_back(p, followed);
  };
  for (const FeatureState& f : current_)
    if (f.status == TrackStatus::kTracked) occupy(f.position_px, true);

  const float border = static_cast<float>(options_.border_px);
  std::vector<SurfKeypoint> accepted;
  auto accept = [&](const std::vector<SurfKeypoint>& points, int limit) {
    for (const SurfKeypoint& kp : points) {
      if (static_cast<int>(accepted.size()) >= limit) break;
      const cv::Point2f p = kp.position_px;
      if (p.x < border || p.y < border || p.x > gray_.cols - 1 - border ||
          p.y > gray_.rows - 1 - border)
        continue;
      if (IsSpecular(p) || crowded(p)) continue;
      occupy(p, false);
      accepted.push_back(kp);
    }
  };
  accept(candidates, room);
  // Too few: weaker points, strongest first, up to min_features. The lower threshold finds the
  // points above the threshold again, at the same positions: they were taken or refused above.
  const int wanted = std::min(room, options_.min_features - num_active());
  if (static_cast<int>(accepted.size()) < wanted &&
      options_.min_hessian_threshold < options_.surf.hessian_threshold) {
    std::set<std::pair<float, float>> seen;
    for (const SurfKeypoint& kp : candidates) seen.emplace(kp.position_px.x, kp.position_px.y);
    weak_surf_.SetImage(gray_);
    weak_surf_.Detect(roi_mask, &candidates);
    candidates.erase(std::remove_if(candidates.begin(), candidates.end(),
                                    [&](const SurfKeypoint& kp) {
                                      return seen.count({kp.position_px.x, kp.position_px.y}) > 0;
                                    }),
                     candidates.end());
    accept(candidates, wanted);
  }
  if (!options_.surf.upright) surf_.ComputeOrientations(&accepted);
  cv::Mat descriptors;
  surf_.Describe(accepted, &descriptors);
  for (size_t i = 0; i < accepted.size(); ++i) {
    const int id = store_.Add(accepted[i], descriptors.row(static_cast<int>(i)));
    RememberLook(id, accepted[i].position_px);
    Anchor(id, accepted[i].position_px);
    store_.Record(id, {frame_, accepted[i].position_px, TrackStatus::kTracked});
    current_.push_back({id, accepted[i].position_px, cv::Point2f(0, 0), TrackStatus::kTracked});
    previous_position_.push_back(accepted[i].position_px);
  }
  return static_cast<int>(accepted.size());
}

}  // namespace arreg
