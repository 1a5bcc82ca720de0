#include "tracking/affine_refine.h"

#include <cmath>

#if defined(__GNUC__) && defined(__x86_64__)
#include <immintrin.h>
#endif

#include "core/error.h"
#include "tracking/lucas_kanade.h"

namespace arreg {

void DriftCorrectionOptions::Check() const {
  ARREG_CHECK_INPUT(window_px >= 9 && window_px <= 63 && window_px % 2 == 1, "",
                    "DriftCorrectionOptions.window_px", "must be odd in [9, 63], got ", window_px);
  ARREG_CHECK_INPUT(every_frames >= 1, "", "DriftCorrectionOptions.every_frames",
                    "must be >= 1, got ", every_frames);
  ARREG_CHECK_INPUT(max_iterations >= 1, "", "DriftCorrectionOptions.max_iterations",
                    "must be >= 1, got ", max_iterations);
  ARREG_CHECK_INPUT(std::isfinite(epsilon_px) && epsilon_px > 0, "",
                    "DriftCorrectionOptions.epsilon_px", "must be > 0, got ", epsilon_px);
  ARREG_CHECK_INPUT(min_correlation >= -1 && min_correlation <= 1, "",
                    "DriftCorrectionOptions.min_correlation", "must be in [-1, 1], got ",
                    min_correlation);
  ARREG_CHECK_INPUT(std::isfinite(max_correction_px) && max_correction_px > 0, "",
                    "DriftCorrectionOptions.max_correction_px", "must be > 0, got ",
                    max_correction_px);
  ARREG_CHECK_INPUT(std::isfinite(max_scale) && max_scale > 1, "",
                    "DriftCorrectionOptions.max_scale", "must be > 1, got ", max_scale);
}

namespace {

// The rectangle of a view that may be read: its rows and columns plus the
// padding of the buffer it views, less one pixel for bilinear interpolation.
struct Readable {
  float x0, y0, x1, y1;
};

Readable ReadableArea(const cv::Mat& image) {
  const Margins m = MarginsOf(image);
  return {static_cast<float>(-m.left), static_cast<float>(-m.top),
          static_cast<float>(image.cols + m.right - 2),
          static_cast<float>(image.rows + m.bottom - 2)};
}

bool Inside(const Readable& area, float x, float y) {
  return x >= area.x0 && y >= area.y0 && x <= area.x1 && y <= area.y1;
}

float Bilinear(const float* origin, ptrdiff_t step, float x, float y) {
  const int ix = static_cast<int>(std::floor(x)), iy = static_cast<int>(std::floor(y));
  const float fx = x - ix, fy = y - iy;
  const float* a = origin + iy * step + ix;
  const float* b = a + step;
  return (1 - fy) * ((1 - fx) * a[0] + fx * a[1]) + fy * ((1 - fx) * b[0] + fx * b[1]);
}

}  // namespace

bool MakeAffineAnchor(const cv::Mat& image, cv::Point2f p, const DriftCorrectionOptions& options,
                      double min_eigen_threshold, const cv::Mat& mask, AffineAnchor* anchor) {
  const int side = options.window_px;
  ARREG_ASSERT(image.type() == CV_32F && side % 2 == 1, "");
  ARREG_ASSERT(mask.empty() || (mask.type() == CV_8UC1 && mask.size() == image.size()), "");
  anchor->side = 0;
  const int h = side / 2, cs = side + 2;
  const Readable area = ReadableArea(image);
  if (!Inside(area, p.x - h - 1, p.y - h - 1) || !Inside(area, p.x + h + 1, p.y + h + 1))
    return false;
  const ptrdiff_t step = static_cast<ptrdiff_t>(image.step[0] / sizeof(float));
  // The window with a one-pixel ring for the central differences.
  std::vector<float> ring(static_cast<size_t>(cs) * cs);
  for (int r = 0; r < cs; ++r)
    for (int c = 0; c < cs; ++c)
      ring[r * cs + c] = Bilinear(image.ptr<float>(), step, p.x + (c - h - 1), p.y + (r - h - 1));
  AffineAnchor& a = *anchor;
  a.ox.clear(), a.oy.clear(), a.t.clear();
  std::vector<float> gx, gy;
  for (int r = 0; r < side; ++r)
    for (int c = 0; c < side; ++c) {
      if (!mask.empty()) {
        const int mx = static_cast<int>(std::lround(p.x)) + c - h;
        const int my = static_cast<int>(std::lround(p.y)) + r - h;
        if (mx < 0 || my < 0 || mx >= mask.cols || my >= mask.rows || !mask.at<uint8_t>(my, mx))
          continue;
      }
      const int q = (r + 1) * cs + c + 1;
      a.ox.push_back(static_cast<float>(c - h));
      a.oy.push_back(static_cast<float>(r - h));
      a.t.push_back(ring[q]);
      gx.push_back(0.5f * (ring[q + 1] - ring[q - 1]));
      gy.push_back(0.5f * (ring[q + cs] - ring[q - cs]));
    }
  const int n = static_cast<int>(a.t.size());
  // At least half the window must be on the object to fix six parameters.
  if (2 * n < side * side) return false;
  double sum = 0, ss = 0;
  for (float x : a.t) sum += x;
  const double mean = sum / n;
  for (float x : a.t) ss += (x - mean) * (x - mean);
  if (!(ss > 1e-12)) return false;
  // The normalisation's scale applies to the gradients as well.
  const double scale = 1.0 / std::sqrt(ss);
  for (float& x : a.t) x = static_cast<float>((x - mean) * scale);
  a.sd.resize(static_cast<size_t>(n) * 6);
  cv::Matx<double, 6, 6> hessian = cv::Matx<double, 6, 6>::zeros();
  a.sd_sum = a.sd_t = cv::Vec<double, 6>::all(0);
  double sxx = 0, sxy = 0, syy = 0;
  for (int k = 0; k < n; ++k) {
    sxx += gx[k] * gx[k], sxy += gx[k] * gy[k], syy += gy[k] * gy[k];
    const double tx = gx[k] * scale, ty = gy[k] * scale, u = a.ox[k], v = a.oy[k];
    const double sk[6] = {tx * u, ty * u, tx * v, ty * v, tx, ty};
    for (int i = 0; i < 6; ++i) {
      a.sd[static_cast<size_t>(i) * n + k] = static_cast<float>(sk[i]);
      a.sd_sum[i] += sk[i];
      a.sd_t[i] += sk[i] * a.t[k];
      for (int j = 0; j < 6; ++j) hessian(i, j) += sk[i] * sk[j];
    }
  }
  const double min_eig =
      (sxx + syy - std::sqrt((sxx - syy) * (sxx - syy) + 4 * sxy * sxy)) / (2.0 * n);
  if (min_eig < min_eigen_threshold) return false;
  bool invertible = false;
  a.h_inv = hessian.inv(cv::DECOMP_CHOLESKY, &invertible);
  if (invertible) a.side = side;
  return invertible;
}

namespace {

// The sums over the warped window's pixels (grey levels v, less `offset`):
// sum v, sum v^2, sum t v, and sum sd_i v for the six parameters.
struct WindowSums {
  double s1 = 0, s2 = 0, st = 0, si[6] = {0, 0, 0, 0, 0, 0};
};

struct WarpArgs {
  const float* origin;
  ptrdiff_t step;
  float cx, cy, l00, l01, l10, l11, offset;
};

// Pixels [begin, end) of the anchor, one at a time.
void SumPixels(const AffineAnchor& a, const WarpArgs& w, size_t begin, size_t end,
               WindowSums* sums) {
  const size_t n = a.t.size();
  for (size_t k = begin; k < end; ++k) {
    const double v = Bilinear(w.origin, w.step, w.cx + w.l00 * a.ox[k] + w.l01 * a.oy[k],
                              w.cy + w.l10 * a.ox[k] + w.l11 * a.oy[k]) -
                     w.offset;
    sums->s1 += v, sums->s2 += v * v, sums->st += a.t[k] * v;
    for (int i = 0; i < 6; ++i) sums->si[i] += a.sd[i * n + k] * v;
  }
}

#if defined(__GNUC__) && defined(__x86_64__)
// Eight pixels a step (AVX2 gathers, FMA); returns how many pixels it summed.
__attribute__((target("avx2,fma"))) size_t SumPixelsAvx2(const AffineAnchor& a, const WarpArgs& w,
                                                         WindowSums* sums) {
  const size_t n = a.t.size(), blocks = n / 8 * 8;
  const __m256 cx = _mm256_set1_ps(w.cx), cy = _mm256_set1_ps(w.cy);
  const __m256 l00 = _mm256_set1_ps(w.l00), l01 = _mm256_set1_ps(w.l01);
  const __m256 l10 = _mm256_set1_ps(w.l10), l11 = _mm256_set1_ps(w.l11);
  const __m256 offset = _mm256_set1_ps(w.offset);
  const __m256i step = _mm256_set1_epi32(static_cast<int>(w.step));
  __m256 s1 = _mm256_setzero_ps(), s2 = s1, st = s1, si[6] = {s1, s1, s1, s1, s1, s1};
  for (size_t k = 0; k < blocks; k += 8) {
    const __m256 ox = _mm256_loadu_ps(&a.ox[k]), oy = _mm256_loadu_ps(&a.oy[k]);
    const __m256 x = _mm256_fmadd_ps(l01, oy, _mm256_fmadd_ps(l00, ox, cx));
    const __m256 y = _mm256_fmadd_ps(l11, oy, _mm256_fmadd_ps(l10, ox, cy));
    const __m256 fx0 = _mm256_floor_ps(x), fy0 = _mm256_floor_ps(y);
    const __m256 fx = _mm256_sub_ps(x, fx0), fy = _mm256_sub_ps(y, fy0);
    const __m256i index = _mm256_add_epi32(_mm256_mullo_epi32(_mm256_cvtps_epi32(fy0), step),
                                           _mm256_cvtps_epi32(fx0));
    const __m256 p00 = _mm256_i32gather_ps(w.origin, index, 4);
    const __m256 p01 = _mm256_i32gather_ps(w.origin + 1, index, 4);
    const __m256 p10 = _mm256_i32gather_ps(w.origin + w.step, index, 4);
    const __m256 p11 = _mm256_i32gather_ps(w.origin + w.step + 1, index, 4);
    const __m256 top = _mm256_fmadd_ps(fx, _mm256_sub_ps(p01, p00), p00);
    const __m256 bottom = _mm256_fmadd_ps(fx, _mm256_sub_ps(p11, p10), p10);
    const __m256 v = _mm256_sub_ps(_mm256_fmadd_ps(fy, _mm256_sub_ps(bottom, top), top), offset);
    s1 = _mm256_add_ps(s1, v);
    s2 = _mm256_fmadd_ps(v, v, s2);
    st = _mm256_fmadd_ps(_mm256_loadu_ps(&a.t[k]), v, st);
    for (int i = 0; i < 6; ++i)
      si[i] = _mm256_fmadd_ps(_mm256_loadu_ps(&a.sd[i * n + k]), v, si[i]);
  }
  const __m256 all[9] = {s1, s2, st, si[0], si[1], si[2], si[3], si[4], si[5]};
  double* targets[9] = {&sums->s1,    &sums->s2,    &sums->st,    &sums->si[0], &sums->si[1],
                        &sums->si[2], &sums->si[3], &sums->si[4], &sums->si[5]};
  alignas(32) float lanes[8];
  for (int j = 0; j < 9; ++j) {
    _mm256_store_ps(lanes, all[j]);
    for (float x : lanes) *targets[j] += x;
  }
  return blocks;
}

bool CpuHasAvx2() {
  static const bool has = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  return has;
}
#endif

// The anchor's window warped into `image` by (centre, linear), compared with
// the anchor in one pass: the normalised cross-correlation and the
// inverse-compositional right-hand side sum_k sd(k) (I_n(k) - t(k)), I_n the
// warped grey levels normalised like t. False when the window leaves the
// readable area or is flat there.
struct WarpedWindow {
  double ncc = 0;
  cv::Vec<double, 6> b;
};

bool CompareWarped(const AffineAnchor& a, const cv::Mat& image, const Readable& area,
                   const cv::Vec2d& centre, const cv::Matx22d& linear, WarpedWindow* out) {
  const float h = static_cast<float>(a.side / 2);
  for (float su : {-h, h})
    for (float sv : {-h, h}) {
      const cv::Vec2d corner = centre + linear * cv::Vec2d(su, sv);
      if (!Inside(area, static_cast<float>(corner[0]), static_cast<float>(corner[1]))) return false;
    }
  WarpArgs w;
  w.origin = image.ptr<float>();
  w.step = static_cast<ptrdiff_t>(image.step[0] / sizeof(float));
  w.cx = static_cast<float>(centre[0]), w.cy = static_cast<float>(centre[1]);
  w.l00 = static_cast<float>(linear(0, 0)), w.l01 = static_cast<float>(linear(0, 1));
  w.l10 = static_cast<float>(linear(1, 0)), w.l11 = static_cast<float>(linear(1, 1));
  // Sums of grey levels less the one at the centre: small, so that single
  // precision keeps the variance.
  w.offset = Bilinear(w.origin, w.step, w.cx, w.cy);
  const size_t n = a.t.size();
  WindowSums sums;
  size_t done = 0;
#if defined(__GNUC__) && defined(__x86_64__)
  if (CpuHasAvx2()) done = SumPixelsAvx2(a, w, &sums);
#endif
  SumPixels(a, w, done, n, &sums);
  const double mean = sums.s1 / n, ss = sums.s2 - sums.s1 * mean;
  if (!(ss > 1e-9)) return false;
  const double scale = 1.0 / std::sqrt(ss);
  // sum t = 0, so the mean drops out of the correlation.
  out->ncc = scale * sums.st;
  for (int i = 0; i < 6; ++i) out->b[i] = scale * (sums.si[i] - mean * a.sd_sum[i]) - a.sd_t[i];
  return true;
}

}  // namespace

AffineRefinement RefineAffine(const AffineAnchor& anchor, const cv::Mat& image,
                              const AffineWarp& start, const DriftCorrectionOptions& options) {
  ARREG_ASSERT(image.type() == CV_32F && anchor.side > 0, "");
  const Readable area = ReadableArea(image);
  const double h = anchor.side / 2;
  AffineRefinement result;
  result.warp = start;
  cv::Matx22d best_linear = start.linear;
  cv::Vec2d best_centre(start.centre.x, start.centre.y);
  // Gauss-Newton from the start, with the step halved once when it does not
  // raise the correlation: where the window's texture constrains one direction
  // weakly (stretched across its stripes) full steps can creep along it at a
  // growing error instead of converging.
  WarpedWindow best, trial;
  if (!CompareWarped(anchor, image, area, best_centre, best_linear, &best)) return result;
  for (int it = 0; it < options.max_iterations; ++it) {
    const cv::Vec<double, 6> full = anchor.h_inv * best.b;
    result.iterations = it + 1;
    bool improved = false;
    double moved = 0;
    for (double scale : {1.0, 0.5}) {
      const cv::Vec<double, 6> dp = scale * full;
      // W <- W o W(dp)^-1, with W(dp) x = (I + D) x + d.
      const cv::Matx22d step_inv = cv::Matx22d(1 + dp[0], dp[2], dp[1], 1 + dp[3]).inv();
      const cv::Matx22d linear = best_linear * step_inv;
      const cv::Vec2d centre = best_centre - best_linear * (step_inv * cv::Vec2d(dp[4], dp[5]));
      if (!std::isfinite(centre[0]) || !std::isfinite(centre[1]) ||
          !CompareWarped(anchor, image, area, centre, linear, &trial) || trial.ncc <= best.ncc)
        continue;
      improved = true;
      best = trial, best_linear = linear, best_centre = centre;
      // How far the step moves the window's centre and corners.
      moved = std::abs(dp[4]) + std::abs(dp[5]) +
              h * (std::abs(dp[0]) + std::abs(dp[1]) + std::abs(dp[2]) + std::abs(dp[3]));
      break;
    }
    if (!improved || moved < options.epsilon_px) break;
  }
  result.warp.centre =
      cv::Point2f(static_cast<float>(best_centre[0]), static_cast<float>(best_centre[1]));
  result.warp.linear = best_linear;
  result.correlation = best.ncc;
  cv::Matx22d u, vt;
  cv::Matx21d w;
  cv::SVD::compute(best_linear, w, u, vt);
  const cv::Point2f moved = result.warp.centre - start.centre;
  result.accepted = best.ncc >= options.min_correlation &&
                    moved.dot(moved) <= options.max_correction_px * options.max_correction_px &&
                    w(0) <= options.max_scale && w(1) >= 1.0 / options.max_scale;
  return result;
}

}  // namespace arreg
