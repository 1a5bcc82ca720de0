// `arreg bench tracking`: decode, SURF detection and LK tracking speed on one
// video, single-threaded, medians over repeated runs.
#include <algorithm>
#include <cstdio>
#include <ostream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "bench_util.h"
#include "commands.h"
#include "core/error.h"
#include "core/file_util.h"
#include "option_parser.h"
#include "tracking/surf.h"
#include "tracking/tracker.h"
#include "tracking/video_io.h"

namespace arreg::cli {

namespace {

// Wall time, or the CPU time of this thread: on a shared machine the latter
// is the time the work takes on one core, whatever else runs.
bool g_use_cpu_clock = true;

struct Clock {
  using time_point = double;  // milliseconds
  static double now() { return g_use_cpu_clock ? ThreadCpuMs() : WallMs(); }
};

double MillisecondsSince(double start_ms) { return Clock::now() - start_ms; }

}  // namespace

int RunBenchTracking(int argc, char** argv) {
  std::string video, json_path, tracks_csv, clock = "cpu";
  int repeats = 5;
  bool skip_lk_500 = false;
  double hessian_threshold = FeatureTrackerOptions().surf.hessian_threshold;
  OptionParser parser("arreg bench tracking --video V [--json OUT] [options]",
                      "Times video decoding (luma), SURF detection on the first frame and "
                      "Lucas-Kanade tracking through the clip, on one thread; prints medians "
                      "over --repeats runs.");
  parser.AddString("video", &video, "V", "video file or image folder", true);
  parser.AddString("json", &json_path, "OUT", "also write the figures to this JSON file");
  parser.AddInt("repeats", &repeats, "N", "runs per measurement (median taken)");
  parser.AddFlag(
      "skip-lk-500", &skip_lk_500,
      "skip lk_500_ms (for videos where SURF at threshold 1 finds fewer than 500 points)");
  parser.AddString("tracks-csv", &tracks_csv, "OUT",
                   "also write the tracks of the clip (with re-identification) as CSV "
                   "(id,frame,x_px,y_px,status)");
  parser.AddString("clock", &clock, "cpu|wall",
                   "cpu: CPU time of the benchmark thread (robust on a busy machine); wall: "
                   "elapsed time");
  parser.AddDouble("hessian-threshold", &hessian_threshold, "T",
                   "SURF Hessian threshold used by the tracker");
  parser.SetEpilog(
      "Figures: decode_ms_per_frame (ReadGray), detect_ms (Fast-Hessian + orientation on\n"
      "frame 0), describe_ms (64-D descriptors of those points), track_ms_per_frame\n"
      "(FeatureTracker::Track incl. pyramid, forward-backward check, filters and\n"
      "re-identification; track_no_reid_ms_per_frame without the latter,\n"
      "track_whole_frame_reid_ms_per_frame with SURF on the whole frame for it,\n"
      "track_drift_ms_per_frame with the drift correction of tracking.drift_correction),\n"
      "lk_500_ms (Track() of 500 features detected in frame f-1 into frame f, f = 1..10),\n"
      "lk_500_opencv_ms (the same with OpenCV's calcOpticalFlowPyrLK as the LK backend),\n"
      "features_initial,\n"
      "features_final (still tracked at the last frame).");
  if (!parser.Parse(argc, argv)) return 0;
  ARREG_CHECK_INPUT(repeats >= 1, "", "--repeats", "must be >= 1, got ", repeats);
  ARREG_CHECK_INPUT(clock == "cpu" || clock == "wall", "", "--clock", "must be cpu or wall, got '",
                    clock, "'");
  g_use_cpu_clock = clock == "cpu";
  cv::setNumThreads(1);

  // Decoding: the whole clip per run, luma taken straight from the stream.
  std::vector<cv::Mat> frames;
  std::vector<double> decode_runs;
  int width = 0, height = 0;
  for (int run = 0; run < repeats; ++run) {
    VideoReader reader;
    reader.Open(video);  // decoder on one thread (the default)
    width = reader.width();
    height = reader.height();
    std::vector<cv::Mat> decoded;
    cv::Mat gray;
    const auto start = Clock::now();
    while (reader.ReadGray(&gray)) decoded.push_back(gray.clone());
    const double ms = MillisecondsSince(start);
    ARREG_CHECK_INPUT(decoded.size() >= 2, video, "", "need at least two frames to benchmark");
    decode_runs.push_back(ms / decoded.size());
    frames = std::move(decoded);
  }

  FeatureTrackerOptions options;
  options.surf.hessian_threshold = hessian_threshold;
  options.Check();

  // Detection on the first frame.
  std::vector<double> detect_runs, describe_runs;
  size_t detected = 0;
  for (int run = 0; run < repeats; ++run) {
    SurfDetector surf(options.surf);
    std::vector<SurfKeypoint> keypoints;
    cv::Mat descriptors;
    auto start = Clock::now();
    surf.SetImage(frames[0]);
    surf.Detect(cv::Mat(), &keypoints);
    detect_runs.push_back(MillisecondsSince(start));
    start = Clock::now();
    surf.Describe(keypoints, &descriptors);
    describe_runs.push_back(MillisecondsSince(start));
    detected = keypoints.size();
  }

  // Tracking through the clip, with the default re-identification (SURF every
  // few frames) and without it, to show what it costs.
  struct ClipRun {
    double ms_per_frame = 0, mean_active = 0;
    int initial = 0, final = 0, reidentified = 0;
  };
  auto track_clip = [&](const FeatureTrackerOptions& clip_options, const std::string& csv_path) {
    std::vector<double> runs;
    ClipRun result;
    for (int run = 0; run < repeats; ++run) {
      FeatureTracker tracker(clip_options);
      result.initial = tracker.Initialize(frames[0]).num_active;
      double total_ms = 0, active_sum = 0;
      result.reidentified = 0;
      for (size_t f = 1; f < frames.size(); ++f) {
        active_sum += tracker.num_active();
        const auto start = Clock::now();
        result.reidentified += tracker.Track(frames[f]).num_reidentified;
        total_ms += MillisecondsSince(start);
      }
      result.final = tracker.num_active();
      if (run == 0 && !csv_path.empty()) tracker.store().WriteCsv(csv_path);
      result.mean_active = active_sum / (frames.size() - 1);
      runs.push_back(total_ms / (frames.size() - 1));
    }
    result.ms_per_frame = Median(runs);
    return result;
  };
  FeatureTrackerOptions no_reid_options = options;
  no_reid_options.reidentify.enabled = false;
  const ClipRun clip_no_reid = track_clip(no_reid_options, "");
  // Re-identification with SURF on the whole frame (the reference the windows
  // around the predictions reproduce): what the windows save.
  FeatureTrackerOptions whole_frame_options = options;
  whole_frame_options.reidentify.search_near_predictions = false;
  const ClipRun clip_whole_frame = track_clip(whole_frame_options, "");
  // With the drift correction, whatever the default: what it costs.
  FeatureTrackerOptions drift_options = options;
  drift_options.drift.enabled = true;
  const ClipRun clip_drift = track_clip(drift_options, "");
  // The default last: the first clip measured in a process read up to 1.5 ms
  // per frame higher (fresh buffers), which hid the difference to the above.
  const ClipRun clip = track_clip(options, tracks_csv);
  const int features_initial = clip.initial, features_final = clip.final;

  // One tracking step with exactly 500 features: for each frame pair (f-1, f),
  // f = 1..10, 500 points are detected in frame f-1 (not timed) and Track()
  // follows all of them into frame f (timed: the pyramid of frame f, the
  // forward pass, the backward check, the masks and the outlier filter). Fresh
  // features carry no motion prediction, so this is the steady state's worst case.
  // One tracker serves all pairs, so that, as in a running video, the pyramid
  // buffers of the frame before are reused rather than allocated.
  FeatureTrackerOptions options_500 = options;
  options_500.max_features = 500;
  options_500.surf.hessian_threshold = 1.0;
  int lk_500_features = 0;
  const size_t lk_500_frames = std::min<size_t>(10, frames.size() - 1);
  auto lk_500 = [&](LucasKanadeBackend backend) {
    FeatureTrackerOptions backend_options = options_500;
    backend_options.lk.backend = backend;
    std::vector<double> runs;
    for (int run = 0; run < repeats; ++run) {
      double total_ms = 0;
      FeatureTracker tracker(backend_options);
      for (size_t f = 1; f <= lk_500_frames; ++f) {
        lk_500_features = tracker.Initialize(frames[f - 1]).num_active;
        ARREG_CHECK_INPUT(lk_500_features == 500, video, "frame " + std::to_string(f - 1), "only ",
                          lk_500_features,
                          " SURF points at threshold 1 (need 500; --skip-lk-500 skips this)");
        const auto start = Clock::now();
        tracker.Track(frames[f]);
        total_ms += MillisecondsSince(start);
      }
      runs.push_back(total_ms / lk_500_frames);
    }
    return Median(runs);
  };
  // Ours (the default) and OpenCV's calcOpticalFlowPyrLK on the same pyramids,
  // window, levels and termination: why ours is the default.
  const double lk_500_ms = skip_lk_500 ? 0.0 : lk_500(LucasKanadeBackend::kArreg);
  const double lk_500_opencv_ms = skip_lk_500 ? 0.0 : lk_500(LucasKanadeBackend::kOpenCv);

  nlohmann::json out;
  out["video"] = video;
  out["width"] = width;
  out["height"] = height;
  out["frames"] = frames.size();
  out["repeats"] = repeats;
  out["threads"] = 1;
  out["clock"] = clock;
  out["hessian_threshold"] = hessian_threshold;
  out["decode_ms_per_frame"] = Median(decode_runs);
  out["detect_ms"] = Median(detect_runs);
  out["describe_ms"] = Median(describe_runs);
  out["surf_points_frame0"] = detected;
  out["track_ms_per_frame"] = clip.ms_per_frame;
  out["mean_active_features"] = clip.mean_active;
  out["reidentified"] = clip.reidentified;
  out["track_no_reid_ms_per_frame"] = clip_no_reid.ms_per_frame;
  out["features_final_no_reid"] = clip_no_reid.final;
  out["track_whole_frame_reid_ms_per_frame"] = clip_whole_frame.ms_per_frame;
  out["features_final_whole_frame_reid"] = clip_whole_frame.final;
  out["track_drift_ms_per_frame"] = clip_drift.ms_per_frame;
  out["features_final_drift"] = clip_drift.final;
  if (!skip_lk_500) {
    out["lk_500_ms"] = lk_500_ms;
    out["lk_500_opencv_ms"] = lk_500_opencv_ms;
  }
  out["lk_500_features"] = lk_500_features;
  out["features_initial"] = features_initial;
  out["features_final"] = features_final;

  std::printf("tracking benchmark: %s (%dx%d, %zu frames, 1 thread, %s time, median of %d runs)\n",
              video.c_str(), width, height, frames.size(), clock.c_str(), repeats);
  std::printf("  decode_ms_per_frame  %8.3f\n", Median(decode_runs));
  std::printf("  detect_ms            %8.3f  (%zu SURF points, threshold %g)\n",
              Median(detect_runs), detected, hessian_threshold);
  std::printf("  describe_ms          %8.3f\n", Median(describe_runs));
  std::printf(
      "  track_ms_per_frame   %8.3f  (%.0f active features on average, %d re-identifications)\n",
      clip.ms_per_frame, clip.mean_active, clip.reidentified);
  std::printf(
      "  track_no_reid_ms_per_frame %8.3f  (re-identification off: %d features at the end)\n",
      clip_no_reid.ms_per_frame, clip_no_reid.final);
  std::printf(
      "  track_whole_frame_reid_ms_per_frame %8.3f  (SURF on the whole frame: %d "
      "re-identifications, "
      "%d features at the end)\n",
      clip_whole_frame.ms_per_frame, clip_whole_frame.reidentified, clip_whole_frame.final);
  std::printf(
      "  track_drift_ms_per_frame %8.3f  (drift correction on, every %d frames: %d features at "
      "the end)\n",
      clip_drift.ms_per_frame, drift_options.drift.every_frames, clip_drift.final);
  if (!skip_lk_500) {
    std::printf(
        "  lk_500_ms            %8.3f  (Track() of %d features, frame pairs 0-1 .. %zu-%zu)\n",
        lk_500_ms, lk_500_features, lk_500_frames - 1, lk_500_frames);
    std::printf("  lk_500_opencv_ms     %8.3f  (the same with cv::calcOpticalFlowPyrLK)\n",
                lk_500_opencv_ms);
  }
  std::printf("  features_initial     %8d\n", features_initial);
  std::printf("  features_final       %8d\n", features_final);
  if (!json_path.empty()) {
    WriteFileAtomic(json_path, [&out](std::ostream& os) { os << out.dump(2) << '\n'; });
  }
  return 0;
}

}  // namespace arreg::cli
