// Sparse pyramidal Lucas-Kanade (translation) of our own, on OpenCV's optical-flow pyramids:
// templates on the integer pixel grid, an initial guess per point, buffers kept between calls.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include <opencv2/core.hpp>

#include "core/enum_names.h"

namespace arreg {

// Which implementation follows the points.
enum class LucasKanadeBackend : uint8_t {
  // Ours (this file): templates on the integer grid, a smaller window at the
  // coarse levels, AVX kernels; 3.8-4.2 ms for the 500-feature step on the
  // build machine (arreg bench tracking: lk_500_ms).
  kArreg = 0,
  // OpenCV's cv::calcOpticalFlowPyrLK on the same 8-bit pyramids, window,
  // levels and termination (window_px at every level: coarse_window_px and
  // the coarse-level tolerance are ours only); about three times the time
  // (lk_500_opencv_ms 12-20 ms), positions within 0.02 px of ours (median).
  kOpenCv = 1,
};
// The spelling in scene files and records: "arreg", "opencv".
inline constexpr EnumName<LucasKanadeBackend> kLucasKanadeBackendNames[] = {
    {LucasKanadeBackend::kArreg, "arreg"}, {LucasKanadeBackend::kOpenCv, "opencv"}};
const char* LucasKanadeBackendName(LucasKanadeBackend backend);

struct LucasKanadeOptions {
  // Implementation. Default kArreg (the one that meets the 4 ms target).
  LucasKanadeBackend backend = LucasKanadeBackend::kArreg;
  // Side of the square integration window at level 0, pixels (odd, 5..63). Default 21.
  int window_px = 21;
  // Window side at the coarser levels (odd, >= 5; at most window_px is used).
  // They only start the next level: 15 px there still covers 30..120 px of the
  // image, follows the 20 px pan of RoiBorderAndIdsBehave (11 does not) and
  // costs half the 21 px window per iteration. Default 15.
  int coarse_window_px = 15;
  // Coarsest pyramid level (0 = no pyramid); each level halves the image.
  // Level 2 already loses a 20 px pan of a smooth texture that level 3 follows
  // (tests/tracking: RoiBorderAndIdsBehave). Default 3.
  int pyramid_levels = 3;
  // Gauss-Newton iterations per pyramid level. Most points converge in 2-4,
  // but a window reaching into the reflected margin at a coarse level can need
  // 20 (10 loses a point of a 20 px pan in RoiBorderAndIdsBehave). Default 20.
  int max_iterations = 20;
  // Stop a level when the update is below this, pixels of that level. Default 0.03.
  double epsilon_px = 0.03;
  // Minimum eigenvalue of the window's gradient matrix divided by the window's
  // pixel count, (grey levels / pixel)^2 (OpenCV's `minEigThreshold` units);
  // flatter windows are lost (kLostFlow). Default 1e-4.
  double min_eigen_threshold = 1e-4;
  // Forward-backward consistency: lost when tracking back lands farther than
  // this from the start, pixels; <= 0 disables the check. Default 1.0.
  double forward_backward_max_px = 1.0;
  // The backward pass starts at the forward pass's start point (where a
  // consistent track returns) at this coarsest level, and stops at updates
  // below backward_epsilon_px: its result is only compared with
  // forward_backward_max_px. From level 1 it still finds the true return point
  // of a track that drifted by up to ~2 windows; larger jumps are the outlier
  // filter's. -1 = pyramid_levels. Default 1.
  int backward_pyramid_levels = 1;
  // Stop the backward pass at updates below this, pixels. Default 0.1.
  double backward_epsilon_px = 0.1;
  // Start the forward search at the feature's previous frame-to-frame
  // displacement (constant velocity) instead of zero. Default true.
  bool predict_motion = true;

  void Check() const;  // throws arreg::Error naming the bad field
};

// How far a view may be read outside its rows/cols (the padding of the buffer it views).
struct Margins {
  int left, top, right, bottom;
};
Margins MarginsOf(const cv::Mat& view);

// One frame's pyramid: levels (cv::buildOpticalFlowPyramid's, padded by one
// window) as floats with their Scharr gradients. Built once per frame, it
// is the target of the forward pass into this frame, the template of the
// backward pass and the template of the next frame's forward pass.
class LucasKanadePyramid {
 public:
  // `gray` CV_8UC1. Reuses the buffers of the previous build when sizes agree.
  void Build(const cv::Mat& gray, int pyramid_levels, int window_px);
  bool empty() const { return levels_.empty(); }
  // cv::buildOpticalFlowPyramid's 8-bit levels (views padded by one window,
  // reflected), as cv::calcOpticalFlowPyrLK takes them.
  const std::vector<cv::Mat>& opencv_levels() const { return levels_; }
  int num_levels() const { return static_cast<int>(float_.size()); }
  // Level l (0 = full size) as CV_32F grey levels and its gradient (grey levels
  // per pixel), views into buffers padded by one window: every iteration reads
  // them, so the conversion is done once per frame rather than once per point.
  const cv::Mat& float_image(int level) const { return float_[level][0]; }
  const cv::Mat& gradient_x(int level) const { return float_[level][1]; }
  const cv::Mat& gradient_y(int level) const { return float_[level][2]; }

 private:
  std::vector<cv::Mat> levels_;
  // Per level: image, d/dx, d/dy views; and the padded buffers they view.
  std::vector<std::array<cv::Mat, 3>> float_, buffers_;
};

// Counters of one TrackLucasKanade call.
struct LucasKanadeSummary {
  int points = 0;
  int found = 0;
  long iterations = 0;  // Gauss-Newton iterations summed over points and levels
  std::array<long, 9> iterations_at_level{};  // the same per pyramid level
};

// Follows `start_px` (positions in `from`) into `to`. With `use_initial_guess`,
// (*end_px)[i] holds on entry a guess of where point i lands (e.g. the start
// plus its previous motion); otherwise the search starts at the start position.
// On return (*end_px)[i] is the position in `to` and (*found)[i] is 1 when
// Lucas-Kanade converged on a textured window that stays inside the image
// margin, 0 otherwise. Both pyramids must come from images of the same size
// built with the same window and at least options.pyramid_levels levels.
LucasKanadeSummary TrackLucasKanade(const LucasKanadePyramid& from, const LucasKanadePyramid& to,
                                    const std::vector<cv::Point2f>& start_px,
                                    const LucasKanadeOptions& options, bool use_initial_guess,
                                    std::vector<cv::Point2f>* end_px, std::vector<uint8_t>* found);

}  // namespace arreg
