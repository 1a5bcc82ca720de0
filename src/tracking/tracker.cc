#include "tracking/tracker.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <map>
#include <ostream>
#include <set>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

#include "core/error.h"
#include "core/file_util.h"

namespace arreg {

const char* TrackStatusName(TrackStatus status) {
  switch (status) {
    case TrackStatus::kTracked:
      return "tracked";
    case TrackStatus::kLostBorder:
      return "lost-border";
    case TrackStatus::kLostRoi:
      return "lost-roi";
    case TrackStatus::kLostFlow:
      return "lost-flow";
    case TrackStatus::kLostForwardBackward:
      return "lost-fb";
    case TrackStatus::kOutlierSpatioTemporal:
      return "outlier-spatiotemporal";
    case TrackStatus::kSpecular:
      return "specular";
    case TrackStatus::kLostAppearance:
      return "lost-appearance";
    case TrackStatus::kInstrument:
      return "instrument";
  }
  return "unknown";
}

void OutlierFilterOptions::Check() const {
  ARREG_CHECK_INPUT(neighbours >= 0, "", "OutlierFilterOptions.neighbours", "must be >= 0, got ",
                    neighbours);
  ARREG_CHECK_INPUT(ratio >= 1, "", "OutlierFilterOptions.ratio", "must be >= 1, got ", ratio);
  ARREG_CHECK_INPUT(slack_px >= 0, "", "OutlierFilterOptions.slack_px", "must be >= 0, got ",
                    slack_px);
}

void SpecularOptions::Check() const {
  ARREG_CHECK_INPUT(min_value >= 0 && min_value <= 255, "", "SpecularOptions.min_value",
                    "must be in 0..255, got ", min_value);
  ARREG_CHECK_INPUT(max_saturation >= 0 && max_saturation <= 255, "",
                    "SpecularOptions.max_saturation", "must be in 0..255, got ", max_saturation);
  ARREG_CHECK_INPUT(radius_px >= 0 && radius_px <= 32, "", "SpecularOptions.radius_px",
                    "must be in 0..32, got ", radius_px);
}

void ReidentifyOptions::Check() const {
  ARREG_CHECK_INPUT(every_frames >= 1, "", "ReidentifyOptions.every_frames", "must be >= 1, got ",
                    every_frames);
  ARREG_CHECK_INPUT(max_lost_frames >= 1, "", "ReidentifyOptions.max_lost_frames",
                    "must be >= 1, got ", max_lost_frames);
  ARREG_CHECK_INPUT(neighbours >= 1, "", "ReidentifyOptions.neighbours", "must be >= 1, got ",
                    neighbours);
  ARREG_CHECK_INPUT(min_neighbours >= 1 && min_neighbours <= neighbours, "",
                    "ReidentifyOptions.min_neighbours", "must be in 1..neighbours, got ",
                    min_neighbours);
  ARREG_CHECK_INPUT(gate_px > 0, "", "ReidentifyOptions.gate_px", "must be > 0, got ", gate_px);
  ARREG_CHECK_INPUT(max_descriptor_distance > 0 && max_descriptor_distance <= 2, "",
                    "ReidentifyOptions.max_descriptor_distance", "must be in (0, 2], got ",
                    max_descriptor_distance);
  ARREG_CHECK_INPUT(ratio > 0 && ratio <= 1, "", "ReidentifyOptions.ratio",
                    "must be in (0, 1], got ", ratio);
  ARREG_CHECK_INPUT(max_scale_factor >= 1, "", "ReidentifyOptions.max_scale_factor",
                    "must be >= 1, got ", max_scale_factor);
  ARREG_CHECK_INPUT(min_patch_correlation >= -1 && min_patch_correlation <= 1, "",
                    "ReidentifyOptions.min_patch_correlation", "must be in [-1, 1], got ",
                    min_patch_correlation);
  ARREG_CHECK_INPUT(min_lk_correlation >= -1 && min_lk_correlation <= 1, "",
                    "ReidentifyOptions.min_lk_correlation", "must be in [-1, 1], got ",
                    min_lk_correlation);
}

void AppearanceCheckOptions::Check() const {
  ARREG_CHECK_INPUT(every_frames >= 1, "", "AppearanceCheckOptions.every_frames",
                    "must be >= 1, got ", every_frames);
  ARREG_CHECK_INPUT(min_correlation >= -1 && min_correlation <= 1, "",
                    "AppearanceCheckOptions.min_correlation", "must be in [-1, 1], got ",
                    min_correlation);
}

void FeatureTrackerOptions::Check() const {
  surf.Check();
  reidentify.Check();
  appearance.Check();
  drift.Check();
  instruments.Check();
  lk.Check();
  outliers.Check();
  specular.Check();
  ARREG_CHECK_INPUT(max_features >= 1, "", "FeatureTrackerOptions.max_features",
                    "must be >= 1, got ", max_features);
  ARREG_CHECK_INPUT(min_features >= 0, "", "FeatureTrackerOptions.min_features",
                    "must be >= 0, got ", min_features);
  ARREG_CHECK_INPUT(std::isfinite(min_hessian_threshold) && min_hessian_threshold >= 0, "",
                    "FeatureTrackerOptions.min_hessian_threshold", "must be >= 0, got ",
                    min_hessian_threshold);
  ARREG_CHECK_INPUT(min_distance_px >= 0, "", "FeatureTrackerOptions.min_distance_px",
                    "must be >= 0, got ", min_distance_px);
  ARREG_CHECK_INPUT(border_px >= 0, "", "FeatureTrackerOptions.border_px", "must be >= 0, got ",
                    border_px);
  ARREG_CHECK_INPUT(redetect_every_frames >= 0, "", "FeatureTrackerOptions.redetect_every_frames",
                    "must be >= 0, got ", redetect_every_frames);
  ARREG_CHECK_INPUT(redetect_hole_factor >= 0 && std::isfinite(redetect_hole_factor), "",
                    "FeatureTrackerOptions.redetect_hole_factor", "must be >= 0, got ",
                    redetect_hole_factor);
}

// ---------------------------------------------------------------------------
// TrackStore

int TrackStore::Add(const SurfKeypoint& keypoint, const cv::Mat& descriptor_row) {
  ARREG_ASSERT(descriptor_row.rows == 1 && descriptor_row.cols == kSurfDescriptorSize &&
                   descriptor_row.type() == CV_32F,
               "");
  const int id = num_features();
  histories_.emplace_back();
  keypoints_.push_back(keypoint);
  descriptors_.push_back(descriptor_row);
  return id;
}

void TrackStore::Record(int id, const TrackObservation& observation) {
  ARREG_ASSERT(id >= 0 && id < num_features(), "feature id ", id);
  histories_[id].push_back(observation);
}

const std::vector<TrackObservation>& TrackStore::history(int id) const {
  ARREG_ASSERT(id >= 0 && id < num_features(), "feature id ", id);
  return histories_[id];
}

const SurfKeypoint& TrackStore::keypoint(int id) const {
  ARREG_ASSERT(id >= 0 && id < num_features(), "feature id ", id);
  return keypoints_[id];
}

cv::Mat TrackStore::descriptor(int id) const {
  ARREG_ASSERT(id >= 0 && id < num_features(), "feature id ", id);
  return descriptors_.row(id);
}

void TrackStore::WriteCsv(const std::string& path) const {
  WriteFileAtomic(path, [this](std::ostream& out) {
    out << "id,frame,x_px,y_px,status\n";
    for (int id = 0; id < num_features(); ++id)
      for (const TrackObservation& o : histories_[id])
        out << id << ',' << o.frame << ',' << o.position_px.x << ',' << o.position_px.y << ','
            << TrackStatusName(o.status) << '\n';
  });
}

// ---------------------------------------------------------------------------
// Masks

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

namespace {

// The k nearest other points of every point, from a uniform grid of about k
// points per cell searched ring by ring: O(n k) instead of O(n^2) for the
// ~500 features of a frame. neighbours[i * k + j] is the j-th of point i (unordered).
void NearestNeighbours(const std::vector<cv::Point2f>& points, int k,
                       std::vector<int>* neighbours) {
  const int n = static_cast<int>(points.size());
  neighbours->assign(static_cast<size_t>(n) * k, -1);
  cv::Point2f lo = points[0], hi = points[0];
  for (const cv::Point2f& p : points) {
    lo.x = std::min(lo.x, p.x), lo.y = std::min(lo.y, p.y);
    hi.x = std::max(hi.x, p.x), hi.y = std::max(hi.y, p.y);
  }
  const float area = std::max(1.f, (hi.x - lo.x) * (hi.y - lo.y));
  const float cell = std::max(1.f, std::sqrt(area * k / n));
  const int cols = static_cast<int>((hi.x - lo.x) / cell) + 1;
  const int rows = static_cast<int>((hi.y - lo.y) / cell) + 1;
  // Points sorted by cell (counting sort): cell c holds order[start[c] .. start[c+1]).
  std::vector<int> start(static_cast<size_t>(cols) * rows + 1, 0), order(n), cell_of(n);
  for (int i = 0; i < n; ++i) {
    const int cx = static_cast<int>((points[i].x - lo.x) / cell);
    const int cy = static_cast<int>((points[i].y - lo.y) / cell);
    cell_of[i] = cy * cols + cx;
    ++start[cell_of[i] + 1];
  }
  for (size_t c = 1; c < start.size(); ++c) start[c] += start[c - 1];
  std::vector<int> fill(start.begin(), start.end() - 1);
  for (int i = 0; i < n; ++i) order[fill[cell_of[i]]++] = i;

  std::vector<std::pair<float, int>> best;  // max-heap of the k nearest so far
  for (int i = 0; i < n; ++i) {
    best.clear();
    const int cx = cell_of[i] % cols, cy = cell_of[i] / cols;
    for (int ring = 0;; ++ring) {
      for (int y = cy - ring; y <= cy + ring; ++y) {
        if (y < 0 || y >= rows) continue;
        const bool edge_row = y == cy - ring || y == cy + ring;
        for (int x = cx - ring; x <= cx + ring; x += edge_row ? 1 : 2 * ring) {
          if (x >= 0 && x < cols) {
            for (int m = start[y * cols + x]; m < start[y * cols + x + 1]; ++m) {
              const int j = order[m];
              if (j == i) continue;
              const cv::Point2f d = points[j] - points[i];
              const float d2 = d.dot(d);
              if (static_cast<int>(best.size()) < k) {
                best.emplace_back(d2, j);
                std::push_heap(best.begin(), best.end());
              } else if (d2 < best.front().first) {
                std::pop_heap(best.begin(), best.end());
                best.back() = {d2, j};
                std::push_heap(best.begin(), best.end());
              }
            }
          }
          if (ring == 0) break;
        }
      }
      // Points outside the rings searched are at least as far as the block's
      // nearest side that still has cells beyond it (at least ring * cell,
      // often nearly a cell more: ring 1 then suffices where ring * cell would
      // search ring 2 too, with twice the points). The margin covers a point
      // that float rounding put in the cell beside.
      const float inf = std::numeric_limits<float>::infinity();
      const cv::Point2f p = points[i] - lo;
      float reach = inf;
      if (cx - ring > 0) reach = std::min(reach, p.x - (cx - ring) * cell);
      if (cx + ring + 1 < cols) reach = std::min(reach, (cx + ring + 1) * cell - p.x);
      if (cy - ring > 0) reach = std::min(reach, p.y - (cy - ring) * cell);
      if (cy + ring + 1 < rows) reach = std::min(reach, (cy + ring + 1) * cell - p.y);
      if (reach == inf) break;  // every cell searched
      reach -= 1e-3f * cell;
      if (static_cast<int>(best.size()) == k && reach > 0 && best.front().first <= reach * reach)
        break;
    }
    for (int j = 0; j < k; ++j) (*neighbours)[static_cast<size_t>(i) * k + j] = best[j].second;
  }
}

}  // namespace

std::vector<bool> SpatioTemporalOutliers(const std::vector<cv::Point2f>& positions_px,
                                         const std::vector<cv::Point2f>& displacements_px,
                                         const OutlierFilterOptions& options) {
  ARREG_ASSERT(positions_px.size() == displacements_px.size(), "");
  const int n = static_cast<int>(positions_px.size());
  std::vector<bool> outlier(n, false);
  if (n < 2) return outlier;
  std::vector<double> magnitude(n);
  double total = 0;
  for (int i = 0; i < n; ++i) {
    magnitude[i] = std::hypot(displacements_px[i].x, displacements_px[i].y);
    total += magnitude[i];
  }
  const int k = std::min(options.neighbours, n - 1);
  std::vector<int> neighbours;
  if (k > 0) NearestNeighbours(positions_px, k, &neighbours);
  for (int i = 0; i < n; ++i) {
    double reference;
    if (k == 0) {
      reference = (total - magnitude[i]) / (n - 1);
    } else {
      double sum = 0;
      for (int j = 0; j < k; ++j) sum += magnitude[neighbours[static_cast<size_t>(i) * k + j]];
      reference = sum / k;
    }
    outlier[i] = magnitude[i] > options.ratio * reference + options.slack_px;
  }
  return outlier;
}

// ---------------------------------------------------------------------------
// FeatureTracker

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
  free_roi_ = roi_mask;
  if (options_.instruments.enabled && !bgr_.empty()) {
    instrument_mask_ = InstrumentMask(bgr_, options_.instruments.mask);
    if (cv::countNonZero(instrument_mask_) > 0) {
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

namespace {
// Whether the pixel nearest to p is set in a non-empty CV_8UC1 mask (false outside it).
bool MaskHas(const cv::Mat& mask, cv::Point2f p) {
  const int x = static_cast<int>(std::lround(p.x)), y = static_cast<int>(std::lround(p.y));
  if (x < 0 || y < 0 || x >= mask.cols || y >= mask.rows) return false;
  return mask.at<uint8_t>(y, x) != 0;
}
}  // namespace

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

bool FeatureTracker::InsideRoi(cv::Point2f p, const cv::Mat& roi_mask) const {
  return roi_mask.empty() || MaskHas(roi_mask, p);
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

namespace {

// The side x side patch of a CV_32F image (padded by at least side / 2 + 1
// around its rows/cols, as LucasKanadePyramid levels are) centred at p,
// sampled bilinearly, row by row.
void SamplePatch(const cv::Mat& image, cv::Point2f p, int side, std::vector<float>* patch) {
  patch->resize(static_cast<size_t>(side) * side);
  const float x0 = p.x - side / 2, y0 = p.y - side / 2;
  const int ix = static_cast<int>(std::floor(x0)), iy = static_cast<int>(std::floor(y0));
  const float fx = x0 - ix, fy = y0 - iy;
  const ptrdiff_t step = static_cast<ptrdiff_t>(image.step[0] / sizeof(float));
  for (int r = 0; r < side; ++r) {
    const float* a = image.ptr<float>() + (iy + r) * step + ix;
    const float* b = a + step;
    for (int c = 0; c < side; ++c)
      (*patch)[r * side + c] =
          (1 - fy) * ((1 - fx) * a[c] + fx * a[c + 1]) + fy * ((1 - fx) * b[c] + fx * b[c + 1]);
  }
}

// Normalised cross-correlation of two patches of the same size (0 when flat).
double Correlation(const std::vector<float>& a, const std::vector<float>& b) {
  const size_t n = a.size();
  double ma = 0, mb = 0;
  for (size_t i = 0; i < n; ++i) ma += a[i], mb += b[i];
  ma /= n, mb /= n;
  double ab = 0, aa = 0, bb = 0;
  for (size_t i = 0; i < n; ++i) {
    ab += (a[i] - ma) * (b[i] - mb);
    aa += (a[i] - ma) * (a[i] - ma);
    bb += (b[i] - mb) * (b[i] - mb);
  }
  return aa > 0 && bb > 0 ? ab / std::sqrt(aa * bb) : 0.0;
}

}  // namespace

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

void FeatureTracker::CheckAppearance() {
  std::vector<float> window;
  for (FeatureState& f : current_) {
    if (f.status != TrackStatus::kTracked) continue;
    SamplePatch(pyramid_.float_image(0), f.position_px, options_.lk.window_px, &window);
    if (Correlation(window, acquired_look_[f.id]) < options_.appearance.min_correlation)
      f.status = TrackStatus::kLostAppearance;
  }
}

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

namespace {

// Bilinear samples of the side x side window with top-left corner (x0, y0) of
// a row-major float image (`step` floats per row, rows x cols), into `window`:
// one set of weights for the whole window. False when it does not fit.
bool SampleWindow(const float* image, ptrdiff_t step, int rows, int cols, int side, float x0,
                  float y0, float* window) {
  const int ix = static_cast<int>(std::floor(x0)), iy = static_cast<int>(std::floor(y0));
  if (ix < 0 || iy < 0 || ix + side >= cols || iy + side >= rows) return false;
  const float fx = x0 - ix, fy = y0 - iy;
  const float w00 = (1 - fx) * (1 - fy), w01 = fx * (1 - fy), w10 = (1 - fx) * fy, w11 = fx * fy;
  for (int r = 0; r < side; ++r) {
    const float* a = image + (iy + r) * step + ix;
    const float* b = a + step;
    for (int c = 0; c < side; ++c)
      window[r * side + c] = w00 * a[c] + w01 * a[c + 1] + w10 * b[c] + w11 * b[c + 1];
  }
  return true;
}

// Translation-only Lucas-Kanade of the side x side template in the middle of
// `surroundings` ((side + 2 margin)^2, row by row; the margin gives the
// template's central-difference gradient) against `sample(x0, y0, window)`
// (SampleWindow on the target), started with the template's centre at
// `start`. Stops after 30 iterations (one level only: from a prediction a few
// pixels off, 20 keep 48 instead of 53 survivors on the real clip), at updates
// below 0.03 px, or when the centre leaves `start` by more than max_shift_px.
template <class Sample>
bool TrackPatch(const std::vector<float>& surroundings, int side, int margin, cv::Point2f start,
                float max_shift_px, double min_eigen_threshold, const Sample& sample,
                cv::Point2f* end) {
  const int cs = side + 2 * margin, n = side * side;
  thread_local std::vector<float> t, gx, gy, window;
  t.resize(n), gx.resize(n), gy.resize(n), window.resize(n);
  double sxx = 0, sxy = 0, syy = 0;
  for (int r = 0; r < side; ++r)
    for (int c = 0; c < side; ++c) {
      const int k = r * side + c, q = (r + margin) * cs + (c + margin);
      t[k] = surroundings[q];
      gx[k] = 0.5f * (surroundings[q + 1] - surroundings[q - 1]);
      gy[k] = 0.5f * (surroundings[q + cs] - surroundings[q - cs]);
      sxx += gx[k] * gx[k], sxy += gx[k] * gy[k], syy += gy[k] * gy[k];
    }
  const double det = sxx * syy - sxy * sxy;
  const double min_eig =
      (sxx + syy - std::sqrt((sxx - syy) * (sxx - syy) + 4 * sxy * sxy)) / (2.0 * n);
  if (det < 1e-6 || min_eig < min_eigen_threshold) return false;
  cv::Point2f p = start;
  for (int it = 0; it < 30; ++it) {
    if (!sample(p.x - side / 2, p.y - side / 2, window.data())) return false;
    float bx = 0, by = 0;
    for (int k = 0; k < n; ++k) {
      const float d = window[k] - t[k];
      bx += d * gx[k], by += d * gy[k];
    }
    const cv::Point2f step(static_cast<float>((sxy * by - syy * bx) / det),
                           static_cast<float>((sxy * bx - sxx * by) / det));
    p += step;
    if (!std::isfinite(p.x) || !std::isfinite(p.y) ||
        (p - start).dot(p - start) > max_shift_px * max_shift_px)
      return false;
    if (step.dot(step) < 0.03f * 0.03f) {
      *end = p;
      return true;
    }
  }
  return false;
}

}  // namespace

int FeatureTracker::Reacquire(const cv::Mat& roi_mask) {
  if (predictions_.empty() || lost_.empty()) return 0;
  const ReidentifyOptions& o = options_.reidentify;
  const int side = options_.lk.window_px, margin = kReacquireMarginPx, cs = side + 2 * margin;
  const cv::Mat& image = pyramid_.float_image(0);
  const ptrdiff_t step = static_cast<ptrdiff_t>(image.step[0] / sizeof(float));
  auto sample_image = [&](float x0, float y0, float* window) {
    return SampleWindow(image.ptr<float>(), step, image.rows, image.cols, side, x0, y0, window);
  };

  // The current window and its surroundings are sampled from the padded
  // pyramid level: the feature must stay a window away from the edge.
  const float border = static_cast<float>(std::max(options_.border_px, side));
  const float min_distance = static_cast<float>(options_.min_distance_px);
  const float fb_max = static_cast<float>(
      options_.lk.forward_backward_max_px > 0 ? options_.lk.forward_backward_max_px : 1.0);
  std::vector<int> index_of(store_.num_features(), -1);
  for (int l = 0; l < static_cast<int>(lost_.size()); ++l) index_of[lost_[l].id] = l;
  std::vector<uint8_t> found(lost_.size(), 0);
  std::vector<float> patch, surroundings;
  int count = 0;
  for (const auto& [id, q] : predictions_) {
    const int l = index_of[id];
    if (l < 0 || lost_[l].surroundings.empty()) continue;  // found by SURF this round
    const LostFeature& f = lost_[l];
    cv::Point2f p;
    if (!TrackPatch(f.surroundings, side, margin, q, static_cast<float>(o.gate_px),
                    options_.lk.min_eigen_threshold, sample_image, &p))
      continue;
    if (p.x < border || p.y < border || p.x > gray_.cols - 1 - border ||
        p.y > gray_.rows - 1 - border || !InsideRoi(p, roi_mask) || IsSpecular(p) ||
        (f.after_instrument && NearInstrument(p)))
      continue;
    SamplePatch(image, p, side, &patch);
    if (Correlation(patch, f.patch) < o.min_lk_correlation) continue;
    // Back from the current window into the old surroundings, from their centre.
    SamplePatch(image, p, cs, &surroundings);
    const float centre = static_cast<float>(cs / 2);
    cv::Point2f back;
    if (!TrackPatch(
            surroundings, side, margin, cv::Point2f(centre, centre), static_cast<float>(margin),
            options_.lk.min_eigen_threshold,
            [&](float x0, float y0, float* window) {
              return SampleWindow(f.surroundings.data(), cs, cs, cs, side, x0, y0, window);
            },
            &back))
      continue;
    const cv::Point2f miss = back - cv::Point2f(centre, centre);
    if (miss.dot(miss) > fb_max * fb_max) continue;
    bool crowded = false;
    for (const FeatureState& g : current_)
      if (g.status == TrackStatus::kTracked &&
          (g.position_px - p).dot(g.position_px - p) < min_distance * min_distance)
        crowded = true;
    if (crowded) continue;
    Restore(id, p);
    found[l] = 1;
    ++count;
  }
  ForgetFound(found);
  return count;
}

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
