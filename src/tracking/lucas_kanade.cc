#include "tracking/lucas_kanade.h"

#include <algorithm>
#include <cmath>

#include <opencv2/video/tracking.hpp>

#include "core/error.h"

namespace arreg {

namespace {
// Coarse levels stop at this update, pixels of the level (LucasKanadeOptions::epsilon_px
// applies at level 0): their result is only the start of the next level, and
// converging them to a few hundredths of a pixel costs a third of the iterations.
constexpr float kCoarseEpsilonPx = 0.1f;
}  // namespace

const char* LucasKanadeBackendName(LucasKanadeBackend backend) {
  return NameOf(kLucasKanadeBackendNames, backend);
}

void LucasKanadeOptions::Check() const {
  ARREG_CHECK_INPUT(backend == LucasKanadeBackend::kArreg || backend == LucasKanadeBackend::kOpenCv,
                    "", "LucasKanadeOptions.backend", "unknown backend ",
                    static_cast<int>(backend));
  ARREG_CHECK_INPUT(window_px >= 5 && window_px % 2 == 1, "", "LucasKanadeOptions.window_px",
                    "must be odd and >= 5, got ", window_px);
  ARREG_CHECK_INPUT(coarse_window_px >= 5 && coarse_window_px % 2 == 1, "",
                    "LucasKanadeOptions.coarse_window_px", "must be odd and >= 5, got ",
                    coarse_window_px);
  ARREG_CHECK_INPUT(window_px <= 63, "", "LucasKanadeOptions.window_px", "must be <= 63, got ",
                    window_px);
  ARREG_CHECK_INPUT(pyramid_levels >= 0 && pyramid_levels <= 8, "",
                    "LucasKanadeOptions.pyramid_levels", "must be in 0..8, got ", pyramid_levels);
  ARREG_CHECK_INPUT(max_iterations >= 1, "", "LucasKanadeOptions.max_iterations",
                    "must be >= 1, got ", max_iterations);
  ARREG_CHECK_INPUT(epsilon_px > 0, "", "LucasKanadeOptions.epsilon_px", "must be > 0, got ",
                    epsilon_px);
  ARREG_CHECK_INPUT(min_eigen_threshold >= 0, "", "LucasKanadeOptions.min_eigen_threshold",
                    "must be >= 0, got ", min_eigen_threshold);
  ARREG_CHECK_INPUT(backward_pyramid_levels >= -1 && backward_pyramid_levels <= 8, "",
                    "LucasKanadeOptions.backward_pyramid_levels", "must be in -1..8, got ",
                    backward_pyramid_levels);
  ARREG_CHECK_INPUT(backward_epsilon_px > 0, "", "LucasKanadeOptions.backward_epsilon_px",
                    "must be > 0, got ", backward_epsilon_px);
}

namespace {

#if defined(__GNUC__) && defined(__x86_64__) && !defined(__clang__)
// Also compiled for AVX + FMA, chosen at load time.
#define ARREG_LK_TARGETS __attribute__((target_clones("fma", "default")))
#else
#define ARREG_LK_TARGETS
#endif

// Scharr gradient of one row of `image` (grey levels per pixel: the kernels
// [3 10 3]^T [-1 0 1] / 32 and its transpose), columns 1 .. cols-2.
ARREG_LK_TARGETS void ScharrRow(const float* __restrict above, const float* __restrict row,
                                const float* __restrict below, int cols, float* __restrict gx,
                                float* __restrict gy) {
  constexpr float a = 3.f / 32, b = 10.f / 32;
  for (int c = 1; c + 1 < cols; ++c) {
    gx[c] = a * (above[c + 1] - above[c - 1] + below[c + 1] - below[c - 1]) +
            b * (row[c + 1] - row[c - 1]);
    gy[c] =
        a * (below[c - 1] - above[c - 1] + below[c + 1] - above[c + 1]) + b * (below[c] - above[c]);
  }
}

}  // namespace

Margins MarginsOf(const cv::Mat& view) {
  cv::Size whole;
  cv::Point offset;
  view.locateROI(whole, offset);
  return {offset.x, offset.y, whole.width - offset.x - view.cols,
          whole.height - offset.y - view.rows};
}

void LucasKanadePyramid::Build(const cv::Mat& gray, int pyramid_levels, int window_px) {
  ARREG_ASSERT(gray.type() == CV_8UC1, "");
  // OpenCV's pyramid (the 8-bit levels, padded by one window, reflected) ...
  cv::buildOpticalFlowPyramid(gray, levels_, cv::Size(window_px, window_px), pyramid_levels, false,
                              cv::BORDER_REFLECT_101, cv::BORDER_CONSTANT, true);
  // ... turned into floats with the gradient over the whole padded buffer (zero
  // on its outermost ring), so that windows reaching into the margin see the
  // reflected image's gradient.
  const int n = static_cast<int>(levels_.size());
  float_.resize(n);
  buffers_.resize(n);
  for (int l = 0; l < n; ++l) {
    const cv::Mat& view = levels_[l];
    cv::Size whole;
    cv::Point offset;
    view.locateROI(whole, offset);
    cv::Mat padded = view;
    padded.adjustROI(offset.y, whole.height - offset.y - view.rows, offset.x,
                     whole.width - offset.x - view.cols);
    std::array<cv::Mat, 3>& buffer = buffers_[l];
    padded.convertTo(buffer[0], CV_32F);
    for (int k = 1; k < 3; ++k) {
      buffer[k].create(padded.size(), CV_32F);
      buffer[k].row(0).setTo(0.f);
      buffer[k].row(padded.rows - 1).setTo(0.f);
    }
    for (int r = 1; r + 1 < padded.rows; ++r) {
      float* gx = buffer[1].ptr<float>(r);
      float* gy = buffer[2].ptr<float>(r);
      ScharrRow(buffer[0].ptr<float>(r - 1), buffer[0].ptr<float>(r), buffer[0].ptr<float>(r + 1),
                padded.cols, gx, gy);
      gx[0] = gy[0] = gx[padded.cols - 1] = gy[padded.cols - 1] = 0.f;
    }
    for (int k = 0; k < 3; ++k) float_[l][k] = buffer[k](cv::Rect(offset, view.size()));
  }
}

namespace {

// The window kernels run over `cols` (a multiple of 8) columns, of which the
// first `win` belong to the window: `mask` is 1 there and 0 beyond, so the
// loops need no remainder. All planes of a level share one row step (same
// padded size). kCols > 0 fixes the width at compile time, so that the
// per-column sums stay in registers; 0 takes `cols` at run time.
struct WindowArgs {
  const float* value;  // template window, top-left
  const float* gx;
  const float* gy;
  ptrdiff_t step;  // floats per row, every plane
  int rows;
  int cols;
  const float* mask;
};

// Gradient matrix of the template window: sums of gx^2, gx gy, gy^2.
template <int kCols>
inline __attribute__((always_inline)) void GradientMatrixImpl(const WindowArgs& w, float* g) {
  const int cols = kCols > 0 ? kCols : w.cols;
  float xx[kCols > 0 ? kCols : 64] = {}, xy[kCols > 0 ? kCols : 64] = {},
                               yy[kCols > 0 ? kCols : 64] = {};
  const float* __restrict gx = w.gx;
  const float* __restrict gy = w.gy;
  const float* __restrict mask = w.mask;
  for (int r = 0; r < w.rows; ++r, gx += w.step, gy += w.step)
    for (int c = 0; c < cols; ++c) {
      const float mx = mask[c] * gx[c], my = mask[c] * gy[c];
      xx[c] += mx * gx[c];
      xy[c] += mx * gy[c];
      yy[c] += my * gy[c];
    }
  g[0] = g[1] = g[2] = 0.f;
  for (int c = 0; c < cols; ++c) g[0] += xx[c], g[1] += xy[c], g[2] += yy[c];
}

// The template window against the target `j` (top-left sample) bilinearly
// warped with the weights of its four neighbours: b = sum of residual x gradient.
template <int kCols>
inline __attribute__((always_inline)) void MismatchImpl(const WindowArgs& w, const float* j,
                                                        const float* weights, float* b) {
  const int cols = kCols > 0 ? kCols : w.cols;
  float sx[kCols > 0 ? kCols : 64] = {}, sy[kCols > 0 ? kCols : 64] = {};
  const float w00 = weights[0], w01 = weights[1], w10 = weights[2], w11 = weights[3];
  const float* __restrict value = w.value;
  const float* __restrict gx = w.gx;
  const float* __restrict gy = w.gy;
  const float* __restrict mask = w.mask;
  for (int r = 0; r < w.rows; ++r, j += w.step, value += w.step, gx += w.step, gy += w.step) {
    const float* __restrict j0 = j;
    const float* __restrict j1 = j + w.step;
    for (int c = 0; c < cols; ++c) {
      const float warped = w00 * j0[c] + w01 * j0[c + 1] + w10 * j1[c] + w11 * j1[c + 1];
      const float e = mask[c] * (warped - value[c]);
      sx[c] += e * gx[c];
      sy[c] += e * gy[c];
    }
  }
  b[0] = b[1] = 0.f;
  for (int c = 0; c < cols; ++c) b[0] += sx[c], b[1] += sy[c];
}

using GradientMatrixFn = void (*)(const WindowArgs&, float*);
using MismatchFn = void (*)(const WindowArgs&, const float*, const float*, float*);

// Each width compiled twice: for AVX + FMA (8 floats a step) and the baseline.
#if defined(__GNUC__) && defined(__x86_64__)
#define ARREG_LK_FMA __attribute__((target("avx,fma")))
#else
#define ARREG_LK_FMA
#endif
#define ARREG_LK_KERNELS(N)                                                                   \
  ARREG_LK_FMA void GradientMatrixFma##N(const WindowArgs& w, float* g) {                     \
    GradientMatrixImpl<N>(w, g);                                                              \
  }                                                                                           \
  void GradientMatrixBase##N(const WindowArgs& w, float* g) { GradientMatrixImpl<N>(w, g); }  \
  ARREG_LK_FMA void MismatchFma##N(const WindowArgs& w, const float* j, const float* weights, \
                                   float* b) {                                                \
    MismatchImpl<N>(w, j, weights, b);                                                        \
  }                                                                                           \
  void MismatchBase##N(const WindowArgs& w, const float* j, const float* weights, float* b) { \
    MismatchImpl<N>(w, j, weights, b);                                                        \
  }
ARREG_LK_KERNELS(0)
ARREG_LK_KERNELS(8)
ARREG_LK_KERNELS(16)
ARREG_LK_KERNELS(24)
ARREG_LK_KERNELS(32)
#undef ARREG_LK_KERNELS

bool CpuHasFma() {
#if defined(__GNUC__) && defined(__x86_64__)
  static const bool has = __builtin_cpu_supports("avx") && __builtin_cpu_supports("fma");
  return has;
#else
  return false;
#endif
}

void ChooseKernels(int cols, GradientMatrixFn* gradient_matrix, MismatchFn* mismatch) {
  const bool fma = CpuHasFma();
#define ARREG_LK_CASE(N)                                                   \
  case N:                                                                  \
    *gradient_matrix = fma ? GradientMatrixFma##N : GradientMatrixBase##N; \
    *mismatch = fma ? MismatchFma##N : MismatchBase##N;                    \
    return;
  switch (cols) {
    ARREG_LK_CASE(8)
    ARREG_LK_CASE(16)
    ARREG_LK_CASE(24)
    ARREG_LK_CASE(32)
    default:
      *gradient_matrix = fma ? GradientMatrixFma0 : GradientMatrixBase0;
      *mismatch = fma ? MismatchFma0 : MismatchBase0;
  }
#undef ARREG_LK_CASE
}

}  // namespace

LucasKanadeSummary TrackLucasKanade(const LucasKanadePyramid& from, const LucasKanadePyramid& to,
                                    const std::vector<cv::Point2f>& start_px,
                                    const LucasKanadeOptions& options, bool use_initial_guess,
                                    std::vector<cv::Point2f>* end_px, std::vector<uint8_t>* found) {
  const int n = static_cast<int>(start_px.size());
  LucasKanadeSummary summary;
  summary.points = n;
  if (use_initial_guess)
    ARREG_ASSERT(static_cast<int>(end_px->size()) == n, "initial guesses ", end_px->size(), " for ",
                 n, " points");
  else
    end_px->assign(start_px.begin(), start_px.end());
  found->assign(n, 0);
  if (n == 0) return summary;
  ARREG_ASSERT(
      !from.empty() && !to.empty() && from.float_image(0).size() == to.float_image(0).size(), "");
  const int top_level =
      std::min({options.pyramid_levels, from.num_levels() - 1, to.num_levels() - 1});

  if (options.backend == LucasKanadeBackend::kOpenCv) {
    // end_px holds the start (no guess) or the guess: OpenCV starts there.
    thread_local std::vector<float> error;
    cv::calcOpticalFlowPyrLK(from.opencv_levels(), to.opencv_levels(), start_px, *end_px, *found,
                             error, cv::Size(options.window_px, options.window_px), top_level,
                             cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS,
                                              options.max_iterations, options.epsilon_px),
                             cv::OPTFLOW_USE_INITIAL_FLOW, options.min_eigen_threshold);
    for (int i = 0; i < n; ++i) {
      (*found)[i] = (*found)[i] && std::isfinite((*end_px)[i].x) && std::isfinite((*end_px)[i].y);
      summary.found += (*found)[i];
    }
    return summary;
  }

  // Per level: window side, padded width, kernels (level 0 window_px, the
  // coarser levels coarse_window_px).
  struct LevelWindow {
    int win, half, cols;
    GradientMatrixFn gradient_matrix;
    MismatchFn mismatch;
  };
  std::array<LevelWindow, 9> windows;
  alignas(32) float mask[2][64];
  for (int level = 0; level <= 8; ++level) {
    LevelWindow& w = windows[level];
    w.win = level == 0 ? options.window_px : std::min(options.coarse_window_px, options.window_px);
    w.half = w.win / 2;
    w.cols = (w.win + 7) / 8 * 8;
    ARREG_ASSERT(w.cols <= 64, "");
    ChooseKernels(w.cols, &w.gradient_matrix, &w.mismatch);
  }
  for (int k = 0; k < 2; ++k)
    for (int c = 0; c < 64; ++c) mask[k][c] = c < windows[k].win ? 1.f : 0.f;
  const float eps2 = static_cast<float>(options.epsilon_px * options.epsilon_px);
  const float coarse_eps2 = std::max(eps2, kCoarseEpsilonPx * kCoarseEpsilonPx);
  const float min_eigen = static_cast<float>(options.min_eigen_threshold);

  // Per level: the planes, how far they may be read outside (the least margin
  // of image and gradient) and their common row step.
  struct LevelView {
    const cv::Mat *value, *gx, *gy, *target;
    Margins value_margins, target_margins;
    ptrdiff_t step;
  };
  std::array<LevelView, 9> views;
  for (int level = 0; level <= top_level; ++level) {
    LevelView& lv = views[level];
    lv.value = &from.float_image(level);
    lv.gx = &from.gradient_x(level);
    lv.gy = &from.gradient_y(level);
    lv.target = &to.float_image(level);
    const Margins mv = MarginsOf(*lv.value), mg = MarginsOf(*lv.gx);
    lv.value_margins = {std::min(mv.left, mg.left), std::min(mv.top, mg.top),
                        std::min(mv.right, mg.right), std::min(mv.bottom, mg.bottom)};
    lv.target_margins = MarginsOf(*lv.target);
    lv.step = static_cast<ptrdiff_t>(lv.value->step[0] / sizeof(float));
    ARREG_ASSERT(lv.gx->step[0] == lv.value->step[0] && lv.gy->step[0] == lv.value->step[0] &&
                     lv.target->step[0] == lv.value->step[0],
                 "");
  }

  // Points in bands of 32 rows, left to right within a band: neighbouring
  // windows then share cache lines and a band of every plane stays in the L2
  // cache, where the features' own order (by strength) jumps across the image.
  thread_local std::vector<std::pair<int64_t, int>> order;
  order.resize(n);
  for (int i = 0; i < n; ++i) {
    const int64_t band = static_cast<int64_t>(std::floor(start_px[i].y / 32.f));
    order[i] = {band * (1 << 20) + static_cast<int64_t>(std::floor(start_px[i].x)), i};
  }
  std::sort(order.begin(), order.end());

  for (const auto& [key, i] : order) {
    cv::Point2f d = ((*end_px)[i] - start_px[i]) * (1.f / (1 << top_level));
    bool ok = true;
    for (int level = top_level; level >= 0; --level) {
      if (level != top_level) d *= 2.f;
      const LevelView& lv = views[level];
      const cv::Mat& value = *lv.value;
      const cv::Mat& target = *lv.target;
      const Margins& mv = lv.value_margins;
      const Margins& mt = lv.target_margins;
      const ptrdiff_t step = lv.step;
      const float scale = 1.f / (1 << level);
      const cv::Point2f p = start_px[i] * scale;
      // Window on the integer grid around the point: the translation estimated
      // is the same, and the template needs no interpolation.
      const LevelWindow& lw = windows[level];
      const int win = lw.win, cols = lw.cols;
      const int x0 = static_cast<int>(std::floor(p.x + 0.5f)) - lw.half;
      const int y0 = static_cast<int>(std::floor(p.y + 0.5f)) - lw.half;
      if (x0 < -mv.left || y0 < -mv.top || x0 + cols > value.cols + mv.right ||
          y0 + win > value.rows + mv.bottom) {
        if (level == 0) ok = false;
        continue;
      }
      const WindowArgs window{value.ptr<float>() + y0 * step + x0,
                              lv.gx->ptr<float>() + y0 * step + x0,
                              lv.gy->ptr<float>() + y0 * step + x0,
                              step,
                              win,
                              cols,
                              mask[level == 0 ? 0 : 1]};
      float g[3];
      lw.gradient_matrix(window, g);
      const float sxx = g[0], sxy = g[1], syy = g[2];
      const float det = sxx * syy - sxy * sxy;
      const float min_eig =
          (sxx + syy - std::sqrt((sxx - syy) * (sxx - syy) + 4.f * sxy * sxy)) / (2.f * win * win);
      if (min_eig < min_eigen || det < 1e-6f) {
        if (level == 0) ok = false;
        continue;
      }
      const float inv_det = 1.f / det;
      cv::Point2f previous_step(0, 0);
      for (int it = 0; it < options.max_iterations; ++it) {
        const float qx = x0 + d.x, qy = y0 + d.y;
        const int jx = static_cast<int>(std::floor(qx)), jy = static_cast<int>(std::floor(qy));
        if (jx < -mt.left || jy < -mt.top || jx + cols + 1 > target.cols + mt.right ||
            jy + win + 1 > target.rows + mt.bottom) {
          if (level == 0) ok = false;
          break;
        }
        const float fx = qx - jx, fy = qy - jy;
        const float weights[4] = {(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy};
        float b[2];
        lw.mismatch(window, target.ptr<float>() + jy * step + jx, weights, b);
        const float bx = b[0], by = b[1];
        ++summary.iterations;
        ++summary.iterations_at_level[level];
        const cv::Point2f step((sxy * by - syy * bx) * inv_det, (sxy * bx - sxx * by) * inv_det);
        d += step;
        if (step.dot(step) <= (level == 0 ? eps2 : coarse_eps2)) break;
        // Oscillating between two positions: settle in the middle (as OpenCV does).
        const cv::Point2f back = step + previous_step;
        if (it > 0 && std::abs(back.x) < 0.01f && std::abs(back.y) < 0.01f) {
          d -= step * 0.5f;
          break;
        }
        previous_step = step;
      }
      if (!ok) break;
    }
    (*end_px)[i] = start_px[i] + d;
    (*found)[i] = ok && std::isfinite(d.x) && std::isfinite(d.y);
    summary.found += (*found)[i];
  }
  return summary;
}

}  // namespace arreg
