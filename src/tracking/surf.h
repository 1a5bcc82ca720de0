// SURF (Bay, Ess, Tuytelaars, Van Gool 2008) implemented in the project, since
// Debian's OpenCV ships no xfeatures2d: Fast-Hessian detector, orientation, 64-D descriptor.
#pragma once

#include <cstdint>
#include <vector>

#include <opencv2/core.hpp>

namespace arreg {

struct SurfOptions {
  // Threshold on the determinant of the box-filter Hessian, in OpenCV's units
  // (area-normalised box responses on 0..255 images); lower gives more points. Default 100.
  double hessian_threshold = 100.0;
  // Number of octaves; each doubles the filter size step and the sampling step. Default 4.
  int octaves = 4;
  // Scale intervals per octave in which maxima are searched; an octave
  // evaluates intervals + 2 filter sizes. Default 2 (filters 9, 15, 21, 27 in octave 0).
  int intervals = 2;
  // Sampling step of the responses in the first octave, in pixels (doubles per octave). Default 1.
  int initial_sample_step = 1;
  // Skip the orientation (angle 0): faster, for cameras that do not roll. Default false.
  bool upright = false;
  // Keep only the strongest this many points (0 = all). Default 0.
  int max_keypoints = 0;

  void Check() const;  // throws arreg::Error naming the bad field
};

struct SurfKeypoint {
  cv::Point2f position_px;    // sub-pixel position, pixel centres at integers
  float scale_px = 0;         // s = 1.2 * filter_size / 9 (Gaussian sigma equivalent)
  float orientation_rad = 0;  // dominant orientation in (-pi, pi], image axes (x right, y down)
  float response = 0;         // interpolated determinant of the Hessian
  int8_t laplacian_sign = 0;  // sign of Dxx + Dyy: +1 dark blob on bright ground, -1 bright blob
  int octave = 0;
};

constexpr int kSurfDescriptorSize = 64;

// Computes SURF points and descriptors on one image at a time. Buffers
// (integral image, response layers) are kept between images of equal size.
class SurfDetector {
 public:
  explicit SurfDetector(const SurfOptions& options = {});

  const SurfOptions& options() const { return options_; }

  // Builds the integral image of `gray` (CV_8UC1); the calls below use it.
  void SetImage(const cv::Mat& gray);
  // Fast-Hessian points of the current image, strongest first; `mask`
  // (CV_8UC1, image size, nonzero = allowed) may be empty. Orientations are
  // assigned unless options.upright.
  void Detect(const cv::Mat& mask, std::vector<SurfKeypoint>* keypoints);
  // The points Detect() finds within `radius_px` of one of `centres` (same
  // positions, responses and order), with the responses computed only on the
  // samples that can give or neighbour such a point: the box sums come from
  // the whole image's integral image, so nothing depends on where the
  // computation stops. Re-identification looks near a few predictions, where
  // the whole frame cost 60 million instructions. options.max_keypoints is ignored.
  void DetectNear(const cv::Mat& mask, const std::vector<cv::Point2f>& centres, float radius_px,
                  std::vector<SurfKeypoint>* keypoints);
  // Dominant orientation from Haar responses within 6s.
  void ComputeOrientations(std::vector<SurfKeypoint>* keypoints) const;
  // Unit-length 64-D descriptors, one row (CV_32F) per keypoint.
  void Describe(const std::vector<SurfKeypoint>& keypoints, cv::Mat* descriptors) const;

  // SetImage + Detect + Describe.
  void DetectAndDescribe(const cv::Mat& gray, const cv::Mat& mask,
                         std::vector<SurfKeypoint>* keypoints, cv::Mat* descriptors);

 private:
  struct Layer {
    int filter_size = 0, step = 0;
    int rows = 0, cols = 0;
    std::vector<float> response;  // (rows x cols) det of Hessian, 0 where the filter does not fit
  };
  // Per sample row of a layer, the sorted, disjoint column intervals [first, second).
  using RowSpans = std::vector<std::vector<std::pair<int, int>>>;
  // Responses of `layer` (filter_size and step set) on the whole image, or
  // only on `spans` (entries elsewhere are left as they were and must not be read).
  void BuildLayer(Layer* layer, const RowSpans* spans) const;
  // Detect (centres == nullptr) or DetectNear.
  void DetectIn(const cv::Mat& mask, const std::vector<cv::Point2f>* centres, float radius_px,
                std::vector<SurfKeypoint>* keypoints);
  // Sign of Dxx + Dyy at sample (y, x) of `layer`; computed only for the
  // keypoints, which keeps the response loop free of a second output.
  int8_t LaplacianSign(const Layer& layer, int y, int x) const;
  // Integral-image box sum over rows [r0, r0+h) x cols [c0, c0+w), clipped to the image.
  int ClippedBox(int r0, int c0, int h, int w) const;
  // Haar wavelet responses (x: right minus left, y: bottom minus top) of side
  // `side` centred at pixel (r, c).
  void Haar(int r, int c, int side, float* dx, float* dy) const;
  float Orientation(const SurfKeypoint& keypoint) const;

  SurfOptions options_;
  int rows_ = 0, cols_ = 0;
  std::vector<uint32_t>
      integral_;  // (rows+1) x (cols+1), wrapping sums: box differences stay exact
  std::vector<std::vector<Layer>> octaves_;
  RowSpans maxima_spans_, response_spans_;  // DetectNear's, kept to avoid reallocation
};

}  // namespace arreg
