// Synthetic images shared by the tracking tests.
#pragma once

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

namespace arreg::testing {

// Band-limited random texture: normalised Gaussian noise blurred at three
// scales (2, 4, 8 px) and summed, mapped to 8 bits with the given mean and
// standard deviation (grey levels). Deterministic for a seed.
inline cv::Mat BandLimitedTexture(int rows, int cols, unsigned seed, double mean_level,
                                  double stddev_level) {
  cv::RNG rng(seed);
  cv::Mat sum = cv::Mat::zeros(rows, cols, CV_32F);
  for (double sigma : {2.0, 4.0, 8.0}) {
    cv::Mat noise(rows, cols, CV_32F);
    rng.fill(noise, cv::RNG::NORMAL, 0, 1);
    cv::GaussianBlur(noise, noise, cv::Size(), sigma, sigma, cv::BORDER_REFLECT);
    cv::Scalar mean, stddev;
    cv::meanStdDev(noise, mean, stddev);
    sum += noise / stddev[0];
  }
  cv::Scalar mean, stddev;
  cv::meanStdDev(sum, mean, stddev);
  cv::Mat out;
  sum.convertTo(out, CV_8U, stddev_level / stddev[0],
                mean_level - stddev_level * mean[0] / stddev[0]);
  return out;
}

// A CV_32F view of `image` padded by `pad` reflected pixels, as LucasKanadePyramid levels are
// (what MakeAffineAnchor and RefineAffine read).
inline cv::Mat PaddedFloatView(const cv::Mat& image, int pad) {
  cv::Mat padded, f;
  cv::copyMakeBorder(image, padded, pad, pad, pad, pad, cv::BORDER_REFLECT_101);
  padded.convertTo(f, CV_32F);
  return f(cv::Rect(pad, pad, image.cols, image.rows));
}

}  // namespace arreg::testing
