// Drift correction of tracked features: the window a feature showed when it was
// acquired is aligned to the current frame with an affine warp and a gain and
// bias (inverse-compositional Lucas-Kanade, Baker & Matthews 2004; the affine
// consistency of Shi & Tomasi 1994), starting where frame-to-frame tracking put
// it. Frame-to-frame translation tracking of stretching texture drifts: each
// step aligns a window that has changed shape a little, off the feature's
// centre, and the errors add up (band-stretch at 186 %: 1.9 px median, 16 px
// worst after 60 frames; 0.3 px median with it, docs/tracking.md "Drift correction").
#pragma once

#include <vector>

#include <opencv2/core.hpp>

namespace arreg {

struct DriftCorrectionOptions {
  bool enabled = true;  // default true
  // Side of the anchored window, pixels (odd, 9..63). Larger windows hold the six parameters
  // better, smaller ones are more local; 31 leaves the fewest features more than 3 px off on
  // stretched synthetic bands (docs/tracking.md, "Drift correction"). Default 31.
  int window_px = 31;
  // Refinements every this many frames (1: every frame); between them the drift of a few
  // frames is small. Default 3.
  int every_frames = 3;
  // Gauss-Newton iterations per refinement. Default 10.
  int max_iterations = 10;
  // Stop when the update moves the window's centre and corners by less than this, pixels.
  // Default 0.05.
  double epsilon_px = 0.05;
  // A refinement is kept only when the warped window then correlates with the anchor by at
  // least this (normalised cross-correlation). Default 0.9.
  double min_correlation = 0.9;
  // ... and moves the feature by at most this from where tracking put it, pixels (drift
  // grows by a fraction of a pixel per frame; a larger jump is another match). Default 2.
  double max_correction_px = 2.0;
  // ... and the warp's linear part has singular values within [1 / max_scale, max_scale].
  // Default 3.
  double max_scale = 3.0;

  void Check() const;  // throws arreg::Error naming the bad field
};

// A feature's window at acquisition with what the inverse-compositional
// iteration needs of it: the pixels used, their zero-mean, unit-norm grey levels,
// the steepest-descent images of the six affine parameters (built from the
// normalised grey levels' gradient) and the inverse of their Gauss-Newton matrix.
struct AffineAnchor {
  int side = 0;                  // of the window; 0: no anchor
  std::vector<float> ox, oy;     // offsets of the pixels used from the window's centre
  std::vector<float> t;          // their normalised grey levels (sum 0, sum of squares 1)
  std::vector<float> sd;         // 6 x n steepest-descent values, parameter-major
  cv::Vec<double, 6> sd_sum;     // sum over the pixels of each steepest-descent image
  cv::Vec<double, 6> sd_t;       // ... and of each times t
  cv::Matx<double, 6, 6> h_inv;  // inverse Gauss-Newton matrix
};

// Builds the anchor of the side x side window centred at p in `image` (CV_32F;
// read into the padding of the buffer a view views, as LucasKanadePyramid levels
// are). With a `mask` (CV_8UC1 of the image's size; empty: all), only the
// window's pixels on nonzero mask pixels are used: the object's, not the
// background that a window at its silhouette also shows and that does not
// move with it. False when the window does not fit, when less than half of it
// is on the mask, and when the window is too flat or
// degenerate for an affine fit (smallest eigenvalue of the gradient matrix per
// pixel below min_eigen_threshold, in LucasKanadeOptions units).
bool MakeAffineAnchor(const cv::Mat& image, cv::Point2f p, const DriftCorrectionOptions& options,
                      double min_eigen_threshold, const cv::Mat& mask, AffineAnchor* anchor);

// The state of the warp: current centre and linear part (x_image = centre + linear * x,
// x relative to the anchor window's centre).
struct AffineWarp {
  cv::Point2f centre;
  cv::Matx22f linear = cv::Matx22f::eye();
};

struct AffineRefinement {
  bool accepted = false;  // converged and passed the checks of the options
  AffineWarp warp;        // the refined warp (whether accepted or not)
  double correlation = 0;
  int iterations = 0;
};

// Aligns the anchor to `image` (CV_32F; a view may be read into the padding of
// the buffer it views, as LucasKanadePyramid levels are) from `start`. Not
// accepted when the warped window leaves the readable area.
AffineRefinement RefineAffine(const AffineAnchor& anchor, const cv::Mat& image,
                              const AffineWarp& start, const DriftCorrectionOptions& options);

}  // namespace arreg
