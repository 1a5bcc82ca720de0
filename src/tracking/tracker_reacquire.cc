// Re-acquisition by Lucas-Kanade: a waiting feature that no SURF point matched is followed
// from its last look, verified by correlation and a backward check.
#include "tracking/tracker.h"

#include <algorithm>
#include <cmath>

#include "tracking/tracker_internal.h"

namespace arreg {

using tracker_internal::Correlation;
using tracker_internal::SamplePatch;

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

}  // namespace arreg
