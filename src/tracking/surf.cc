#include "tracking/surf.h"

#include <algorithm>
#include <array>
#include <cmath>

#include "core/error.h"

namespace arreg {

namespace {

constexpr float kPi = 3.14159265358979f;

// Filter side (pixels) of interval `i` in octave `o`: 9, 15, 21, 27 in octave
// 0, then steps doubling per octave (Bay et al. 2008, sec. 4.1).
int FilterSize(int octave, int interval) { return 3 * ((2 << octave) * (interval + 1) + 1); }

// One box of a box filter: four integral-image offsets relative to the filter
// centre and a weight.
struct Box {
  int a, b, c, d;  // offsets of corners (r0,c0), (r0,c1), (r1,c0), (r1,c1)
  int weight;
};

Box MakeBox(int stride, int dr, int dc, int h, int w, int weight) {
  return Box{dr * stride + dc, dr * stride + dc + w, (dr + h) * stride + dc,
             (dr + h) * stride + dc + w, weight};
}

inline int BoxSum(const uint32_t* p, const Box& box) {
  return static_cast<int>(p[box.d] - p[box.b] - p[box.c] + p[box.a]);
}

}  // namespace

void SurfOptions::Check() const {
  ARREG_CHECK_INPUT(hessian_threshold >= 0 && std::isfinite(hessian_threshold), "",
                    "SurfOptions.hessian_threshold", "must be >= 0, got ", hessian_threshold);
  ARREG_CHECK_INPUT(octaves >= 1 && octaves <= 8, "", "SurfOptions.octaves",
                    "must be in 1..8, got ", octaves);
  ARREG_CHECK_INPUT(intervals >= 1 && intervals <= 8, "", "SurfOptions.intervals",
                    "must be in 1..8, got ", intervals);
  ARREG_CHECK_INPUT(initial_sample_step >= 1 && initial_sample_step <= 8, "",
                    "SurfOptions.initial_sample_step", "must be in 1..8, got ",
                    initial_sample_step);
  ARREG_CHECK_INPUT(max_keypoints >= 0, "", "SurfOptions.max_keypoints", "must be >= 0, got ",
                    max_keypoints);
}

SurfDetector::SurfDetector(const SurfOptions& options) : options_(options) { options_.Check(); }

void SurfDetector::SetImage(const cv::Mat& gray) {
  ARREG_CHECK_INPUT(!gray.empty() && gray.type() == CV_8UC1, "", "SURF image",
                    "expected a non-empty 8-bit grey image");
  rows_ = gray.rows;
  cols_ = gray.cols;
  const int stride = cols_ + 1;
  integral_.assign(static_cast<size_t>(rows_ + 1) * stride, 0u);
  for (int r = 0; r < rows_; ++r) {
    const uint8_t* src = gray.ptr<uint8_t>(r);
    const uint32_t* above = &integral_[static_cast<size_t>(r) * stride];
    uint32_t* out = &integral_[static_cast<size_t>(r + 1) * stride];
    uint32_t row_sum = 0;
    for (int c = 0; c < cols_; ++c) {
      row_sum += src[c];
      out[c + 1] = above[c + 1] + row_sum;
    }
  }
}

int SurfDetector::ClippedBox(int r0, int c0, int h, int w) const {
  int r1 = std::min(r0 + h, rows_), c1 = std::min(c0 + w, cols_);
  r0 = std::max(r0, 0);
  c0 = std::max(c0, 0);
  if (r1 <= r0 || c1 <= c0) return 0;
  const int stride = cols_ + 1;
  const uint32_t* I = integral_.data();
  return static_cast<int>(I[r1 * stride + c1] - I[r0 * stride + c1] - I[r1 * stride + c0] +
                          I[r0 * stride + c0]);
}

void SurfDetector::Haar(int r, int c, int side, float* dx, float* dy) const {
  const int half = side / 2;
  const int r0 = r - half, c0 = c - half;
  if (r0 >= 0 && c0 >= 0 && r0 + side <= rows_ && c0 + side <= cols_) {
    // Interior: each wavelet from six integral values.
    const int stride = cols_ + 1;
    const uint32_t* I = integral_.data();
    const uint32_t* t = I + r0 * stride + c0;           // top-left corner
    const uint32_t* m = I + (r0 + half) * stride + c0;  // middle row
    const uint32_t* b = I + (r0 + side) * stride + c0;  // bottom row
    const int left = static_cast<int>(b[half] - t[half] - b[0] + t[0]);
    const int right = static_cast<int>(b[side] - t[side] - b[half] + t[half]);
    const int top = static_cast<int>(m[side] - t[side] - m[0] + t[0]);
    const int bottom = static_cast<int>(b[side] - m[side] - b[0] + m[0]);
    *dx = static_cast<float>(right - left);
    *dy = static_cast<float>(bottom - top);
    return;
  }
  *dx = static_cast<float>(ClippedBox(r0, c, side, half) - ClippedBox(r0, c0, side, half));
  *dy = static_cast<float>(ClippedBox(r, c0, half, side) - ClippedBox(r0, c0, half, side));
}

namespace {

// The three second-derivative box filters of one filter size (Bay et al. 2008,
// fig. 1): a (2l-1) x 3l box minus three times its middle third, and four
// l x l quadrants for Dxy. Offsets are relative to the integral-image entry of
// the centre pixel.
struct HessianBoxes {
  Box dxx_outer, dxx_middle, dyy_outer, dyy_middle, dxy[4];
  float inv_area;

  HessianBoxes(int stride, int L) {
    const int lobe = L / 3, border = (L - 1) / 2;
    dxx_outer = MakeBox(stride, -(lobe - 1), -border, 2 * lobe - 1, L, 1);
    dxx_middle = MakeBox(stride, -(lobe - 1), -(lobe - 1) / 2, 2 * lobe - 1, lobe, -3);
    dyy_outer = MakeBox(stride, -border, -(lobe - 1), L, 2 * lobe - 1, 1);
    dyy_middle = MakeBox(stride, -(lobe - 1) / 2, -(lobe - 1), lobe, 2 * lobe - 1, -3);
    dxy[0] = MakeBox(stride, -lobe, -lobe, lobe, lobe, 1);
    dxy[1] = MakeBox(stride, -lobe, 1, lobe, lobe, -1);
    dxy[2] = MakeBox(stride, 1, -lobe, lobe, lobe, -1);
    dxy[3] = MakeBox(stride, 1, 1, lobe, lobe, 1);
    inv_area = 1.f / static_cast<float>(L * L);
  }
  float Dxx(const uint32_t* p) const {
    return static_cast<float>(BoxSum(p, dxx_outer) - 3 * BoxSum(p, dxx_middle)) * inv_area;
  }
  float Dyy(const uint32_t* p) const {
    return static_cast<float>(BoxSum(p, dyy_outer) - 3 * BoxSum(p, dyy_middle)) * inv_area;
  }
  float Dxy(const uint32_t* p) const {
    return static_cast<float>(BoxSum(p, dxy[0]) - BoxSum(p, dxy[1]) - BoxSum(p, dxy[2]) +
                              BoxSum(p, dxy[3])) *
           inv_area;
  }
};

// One row of determinant responses at samples x_begin..x_end-1 (pixel x * kStep).
// kStep is a template argument so that the unit-step first octave, which holds
// most of the work, runs over contiguous memory and vectorises.
template <int kStep>
void HessianRow(const HessianBoxes& h, const uint32_t* row, int step, int x_begin, int x_end,
                float* out) {
  const int s = kStep > 0 ? kStep : step;
  for (int x = x_begin; x < x_end; ++x) {
    const uint32_t* p = row + x * s;
    const float Dxx = h.Dxx(p), Dyy = h.Dyy(p), Dxy = h.Dxy(p);
    // 0.9: relative weight that balances the box approximations (paper eq. 3).
    out[x] = Dxx * Dyy - 0.81f * Dxy * Dxy;
  }
}

}  // namespace

void SurfDetector::BuildLayer(Layer* layer, const RowSpans* spans) const {
  const int L = layer->filter_size, step = layer->step;
  const int border = (L - 1) / 2;
  const int stride = cols_ + 1;
  layer->rows = (rows_ + step - 1) / step;
  layer->cols = (cols_ + step - 1) / step;
  const size_t size = static_cast<size_t>(layer->rows) * layer->cols;
  if (spans == nullptr)
    layer->response.assign(size, 0.f);
  else
    layer->response.resize(size);
  const HessianBoxes boxes(stride, L);
  // Rows/columns (in response samples) where the whole filter fits.
  const int y_begin = (border + step - 1) / step, x_begin = (border + step - 1) / step;
  const int y_end = std::min(layer->rows, (rows_ - 1 - border) / step + 1);
  const int x_end = std::min(layer->cols, (cols_ - 1 - border) / step + 1);
  const uint32_t* I = integral_.data();
  auto row_of = [&](int y, int x0, int x1) {
    float* out = &layer->response[static_cast<size_t>(y) * layer->cols];
    if (spans != nullptr) std::fill(out + x0, out + x1, 0.f);
    if (y < y_begin || y >= y_end) return;
    x0 = std::max(x0, x_begin);
    x1 = std::min(x1, x_end);
    if (x1 <= x0) return;
    const uint32_t* row = I + static_cast<size_t>(y) * step * stride;
    if (step == 1)
      HessianRow<1>(boxes, row, step, x0, x1, out);
    else
      HessianRow<0>(boxes, row, step, x0, x1, out);
  };
  if (spans == nullptr) {
    for (int y = y_begin; y < y_end; ++y) row_of(y, x_begin, x_end);
  } else {
    for (int y = 0; y < layer->rows; ++y)
      for (const auto& [x0, x1] : (*spans)[y]) row_of(y, x0, x1);
  }
}

int8_t SurfDetector::LaplacianSign(const Layer& layer, int y, int x) const {
  const int stride = cols_ + 1;
  const HessianBoxes boxes(stride, layer.filter_size);
  const uint32_t* p = integral_.data() + static_cast<size_t>(y) * layer.step * stride +
                      static_cast<size_t>(x) * layer.step;
  return boxes.Dxx(p) + boxes.Dyy(p) >= 0 ? 1 : -1;
}

namespace {

// Per row of a rows x cols sample grid, the column intervals covered by
// `boxes` (sample coordinates, clipped to the grid), merged where they overlap
// or touch. Boxes taken in order of their left edge reach every row in order,
// so each merges with the row's last interval or starts a new one.
void SpansOfBoxes(std::vector<cv::Rect>* boxes, int rows, int cols,
                  std::vector<std::vector<std::pair<int, int>>>* spans) {
  spans->resize(rows);
  for (auto& row : *spans) row.clear();
  const cv::Rect grid(0, 0, cols, rows);
  for (cv::Rect& box : *boxes) box &= grid;
  std::sort(boxes->begin(), boxes->end(),
            [](const cv::Rect& a, const cv::Rect& b) { return a.x < b.x; });
  for (const cv::Rect& b : *boxes) {
    if (b.empty()) continue;
    for (int y = b.y; y < b.br().y; ++y) {
      auto& row = (*spans)[y];
      if (!row.empty() && b.x <= row.back().second)
        row.back().second = std::max(row.back().second, b.br().x);
      else
        row.emplace_back(b.x, b.br().x);
    }
  }
}

}  // namespace

void SurfDetector::Detect(const cv::Mat& mask, std::vector<SurfKeypoint>* keypoints) {
  DetectIn(mask, nullptr, 0.f, keypoints);
}

void SurfDetector::DetectNear(const cv::Mat& mask, const std::vector<cv::Point2f>& centres,
                              float radius_px, std::vector<SurfKeypoint>* keypoints) {
  ARREG_CHECK_INPUT(radius_px >= 0 && std::isfinite(radius_px), "", "SURF DetectNear",
                    "radius must be >= 0, got ", radius_px);
  DetectIn(mask, &centres, radius_px, keypoints);
}

void SurfDetector::DetectIn(const cv::Mat& mask, const std::vector<cv::Point2f>* centres,
                            float radius_px, std::vector<SurfKeypoint>* keypoints) {
  ARREG_ASSERT(keypoints != nullptr, "");
  ARREG_CHECK_INPUT(rows_ > 0, "", "SURF", "Detect() before SetImage()");
  ARREG_CHECK_INPUT(
      mask.empty() || (mask.type() == CV_8UC1 && mask.rows == rows_ && mask.cols == cols_), "",
      "SURF mask", "expected an empty mask or CV_8UC1 of ", cols_, "x", rows_);
  keypoints->clear();
  if (centres != nullptr && centres->empty()) return;
  const int num_layers = options_.intervals + 2;
  octaves_.resize(options_.octaves);
  const float threshold = static_cast<float>(options_.hessian_threshold);
  // Near centres: maxima are looked for on `maxima` and responses computed on
  // `responses` (the same samples and their 3 x 3 neighbours).
  RowSpans& maxima = maxima_spans_;
  RowSpans& responses = response_spans_;
  std::vector<cv::Rect> boxes;
  for (int o = 0; o < options_.octaves; ++o) {
    const int step = options_.initial_sample_step << o;
    // An octave whose largest filter does not fit the image gives nothing.
    if (FilterSize(o, num_layers - 1) >= std::min(rows_, cols_)) break;
    const int rows = (rows_ + step - 1) / step, cols = (cols_ + step - 1) / step;
    if (centres != nullptr) {
      // A point interpolated from sample x lies within half a step of x * step.
      boxes.clear();
      for (const cv::Point2f& c : *centres) {
        const int x0 = static_cast<int>(std::floor((c.x - radius_px) / step - 0.5f));
        const int x1 = static_cast<int>(std::ceil((c.x + radius_px) / step + 0.5f));
        const int y0 = static_cast<int>(std::floor((c.y - radius_px) / step - 0.5f));
        const int y1 = static_cast<int>(std::ceil((c.y + radius_px) / step + 0.5f));
        boxes.emplace_back(x0, y0, x1 - x0 + 1, y1 - y0 + 1);
      }
      std::vector<cv::Rect> dilated;
      for (const cv::Rect& b : boxes)
        dilated.emplace_back(b.x - 1, b.y - 1, b.width + 2, b.height + 2);
      SpansOfBoxes(&boxes, rows, cols, &maxima);
      SpansOfBoxes(&dilated, rows, cols, &responses);
    }
    std::vector<Layer>& layers = octaves_[o];
    layers.resize(num_layers);
    for (int i = 0; i < num_layers; ++i) {
      layers[i].filter_size = FilterSize(o, i);
      layers[i].step = step;
      BuildLayer(&layers[i], centres != nullptr ? &responses : nullptr);
    }
    for (int i = 1; i + 1 < num_layers; ++i) {
      // The largest neighbouring filter must fit around the sample and its neighbours.
      const int border = (layers[i + 1].filter_size - 1) / 2;
      const int margin = (border + step - 1) / step + 1;
      const float* below = layers[i - 1].response.data();
      const float* here = layers[i].response.data();
      const float* above = layers[i + 1].response.data();
      auto consider = [&](int y, int x) {
        const int k = y * cols + x;
        const float v = here[k];
        if (v <= threshold) return;
        // 3x3x3 non-maximum suppression.
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const int n = k + dy * cols + dx;
            if (below[n] >= v || above[n] >= v || (n != k && here[n] >= v)) return;
          }
        if (!mask.empty() && mask.at<uint8_t>(y * step, x * step) == 0) return;
        // Sub-pixel / sub-scale: Newton step on the quadratic fit (x, y, scale).
        const float gx = 0.5f * (here[k + 1] - here[k - 1]);
        const float gy = 0.5f * (here[k + cols] - here[k - cols]);
        const float gs = 0.5f * (above[k] - below[k]);
        const float hxx = here[k + 1] + here[k - 1] - 2 * v;
        const float hyy = here[k + cols] + here[k - cols] - 2 * v;
        const float hss = above[k] + below[k] - 2 * v;
        const float hxy = 0.25f * (here[k + cols + 1] - here[k + cols - 1] - here[k - cols + 1] +
                                   here[k - cols - 1]);
        const float hxs = 0.25f * (above[k + 1] - above[k - 1] - below[k + 1] + below[k - 1]);
        const float hys =
            0.25f * (above[k + cols] - above[k - cols] - below[k + cols] + below[k - cols]);
        const cv::Matx33f H(hxx, hxy, hxs, hxy, hyy, hys, hxs, hys, hss);
        cv::Vec3f offset;
        if (!cv::solve(H, cv::Vec3f(-gx, -gy, -gs), offset, cv::DECOMP_LU)) return;
        if (std::abs(offset[0]) >= 0.5f || std::abs(offset[1]) >= 0.5f ||
            std::abs(offset[2]) >= 0.5f)
          return;
        SurfKeypoint kp;
        kp.position_px = cv::Point2f((x + offset[0]) * step, (y + offset[1]) * step);
        const float size =
            layers[i].filter_size + offset[2] * (layers[i + 1].filter_size - layers[i].filter_size);
        kp.scale_px = 1.2f / 9.f * size;
        kp.response = v + 0.5f * (gx * offset[0] + gy * offset[1] + gs * offset[2]);
        kp.laplacian_sign = LaplacianSign(layers[i], y, x);
        kp.octave = o;
        keypoints->push_back(kp);
      };
      for (int y = margin; y < rows - margin; ++y) {
        if (centres == nullptr) {
          for (int x = margin; x < cols - margin; ++x) consider(y, x);
        } else {
          for (const auto& [x0, x1] : maxima[y])
            for (int x = std::max(x0, margin); x < std::min(x1, cols - margin); ++x) consider(y, x);
        }
      }
    }
  }
  if (centres != nullptr) {
    const float r2 = radius_px * radius_px;
    keypoints->erase(std::remove_if(keypoints->begin(), keypoints->end(),
                                    [&](const SurfKeypoint& kp) {
                                      for (const cv::Point2f& c : *centres) {
                                        const cv::Point2f d = kp.position_px - c;
                                        if (d.dot(d) <= r2) return false;
                                      }
                                      return true;
                                    }),
                     keypoints->end());
  }
  std::sort(keypoints->begin(), keypoints->end(),
            [](const SurfKeypoint& a, const SurfKeypoint& b) { return a.response > b.response; });
  if (centres == nullptr && options_.max_keypoints > 0 &&
      static_cast<int>(keypoints->size()) > options_.max_keypoints)
    keypoints->resize(options_.max_keypoints);
  if (!options_.upright) ComputeOrientations(keypoints);
}

float SurfDetector::Orientation(const SurfKeypoint& kp) const {
  // Haar responses of side 4s at steps of s within radius 6s, Gaussian-weighted
  // (sigma 2s); the orientation is that of the largest sum inside a sliding
  // pi/3 window (Bay et al. 2008, sec. 4.3).
  constexpr int kMaxSamples = 113;
  // The Gaussian weight of sample (i, j) is exp(-(i^2 + j^2) s^2 / (2 (2s)^2)): independent of s.
  static const std::array<float, 169> kWeights = [] {
    std::array<float, 169> w{};
    for (int i = -6; i <= 6; ++i)
      for (int j = -6; j <= 6; ++j) w[(i + 6) * 13 + (j + 6)] = std::exp(-(i * i + j * j) / 8.f);
    return w;
  }();
  struct Sample {
    float angle, wx, wy;
  };
  std::array<Sample, 2 * kMaxSamples> samples;
  int n = 0;
  const float s = kp.scale_px;
  const int side = std::max(2, 2 * static_cast<int>(std::lround(2 * s)));
  for (int i = -6; i <= 6; ++i) {
    for (int j = -6; j <= 6; ++j) {
      if (i * i + j * j >= 36) continue;
      const int r = static_cast<int>(std::lround(kp.position_px.y + j * s));
      const int c = static_cast<int>(std::lround(kp.position_px.x + i * s));
      float dx, dy;
      Haar(r, c, side, &dx, &dy);
      if (dx == 0 && dy == 0) continue;
      const float g = kWeights[(i + 6) * 13 + (j + 6)];
      samples[n++] = {cv::fastAtan2(dy, dx) * (kPi / 180.f), g * dx, g * dy};  // [0, 2pi)
    }
  }
  if (n == 0) return 0.f;
  // Sorted by angle and repeated one turn later, every window is a contiguous
  // range: prefix sums give each window's sum in O(log n).
  std::sort(samples.begin(), samples.begin() + n,
            [](const Sample& a, const Sample& b) { return a.angle < b.angle; });
  for (int k = 0; k < n; ++k) {
    samples[n + k] = samples[k];
    samples[n + k].angle += 2 * kPi;
  }
  std::array<float, 2 * kMaxSamples + 1> sum_x, sum_y;
  sum_x[0] = sum_y[0] = 0;
  for (int k = 0; k < 2 * n; ++k) {
    sum_x[k + 1] = sum_x[k] + samples[k].wx;
    sum_y[k + 1] = sum_y[k] + samples[k].wy;
  }
  auto first_at_or_after = [&](float angle) {
    return static_cast<int>(std::lower_bound(samples.begin(), samples.begin() + 2 * n, angle,
                                             [](const Sample& a, float v) { return a.angle < v; }) -
                            samples.begin());
  };
  float best_norm = -1, best_x = 0, best_y = 0;
  constexpr int kWindows = 42;
  for (int w = 0; w < kWindows; ++w) {
    const float start = w * (2 * kPi / kWindows);
    const int lo = first_at_or_after(start), hi = first_at_or_after(start + kPi / 3);
    const float sx = sum_x[hi] - sum_x[lo], sy = sum_y[hi] - sum_y[lo];
    const float norm = sx * sx + sy * sy;
    if (norm > best_norm) {
      best_norm = norm;
      best_x = sx;
      best_y = sy;
    }
  }
  return std::atan2(best_y, best_x);
}

void SurfDetector::ComputeOrientations(std::vector<SurfKeypoint>* keypoints) const {
  ARREG_ASSERT(keypoints != nullptr, "");
  for (SurfKeypoint& kp : *keypoints) kp.orientation_rad = Orientation(kp);
}

void SurfDetector::Describe(const std::vector<SurfKeypoint>& keypoints,
                            cv::Mat* descriptors) const {
  ARREG_ASSERT(descriptors != nullptr, "");
  ARREG_CHECK_INPUT(rows_ > 0, "", "SURF", "Describe() before SetImage()");
  descriptors->create(static_cast<int>(keypoints.size()), kSurfDescriptorSize, CV_32F);
  // Gaussian weights (sigma 3.3s) of the 20 x 20 grid, in units of s.
  static const std::array<float, 400> kWeights = [] {
    std::array<float, 400> w{};
    for (int k = 0; k < 20; ++k)
      for (int m = 0; m < 20; ++m) {
        const float u = k - 9.5f, v = m - 9.5f;
        w[k * 20 + m] = std::exp(-(u * u + v * v) / (2.f * 3.3f * 3.3f));
      }
    return w;
  }();
  for (size_t p = 0; p < keypoints.size(); ++p) {
    const SurfKeypoint& kp = keypoints[p];
    const float s = kp.scale_px;
    const float co = std::cos(kp.orientation_rad), si = std::sin(kp.orientation_rad);
    const int side = std::max(2, 2 * static_cast<int>(std::lround(s)));
    float* out = descriptors->ptr<float>(static_cast<int>(p));
    std::fill(out, out + kSurfDescriptorSize, 0.f);
    // 20s x 20s window along the orientation, 4 x 4 sub-regions of 5 x 5
    // samples; Haar responses of side 2s turned into the keypoint's frame.
    for (int m = 0; m < 20; ++m) {
      const float v = (m - 9.5f) * s;
      for (int k = 0; k < 20; ++k) {
        const float u = (k - 9.5f) * s;
        const int c = static_cast<int>(std::lround(kp.position_px.x + co * u - si * v));
        const int r = static_cast<int>(std::lround(kp.position_px.y + si * u + co * v));
        float rx, ry;
        Haar(r, c, side, &rx, &ry);
        const float g = kWeights[m * 20 + k];
        const float du = g * (co * rx + si * ry);
        const float dv = g * (-si * rx + co * ry);
        float* bin = out + ((m / 5) * 4 + (k / 5)) * 4;
        bin[0] += du;
        bin[1] += dv;
        bin[2] += std::abs(du);
        bin[3] += std::abs(dv);
      }
    }
    float norm = 0;
    for (int i = 0; i < kSurfDescriptorSize; ++i) norm += out[i] * out[i];
    norm = std::sqrt(norm);
    if (norm > 0)
      for (int i = 0; i < kSurfDescriptorSize; ++i) out[i] /= norm;
  }
}

void SurfDetector::DetectAndDescribe(const cv::Mat& gray, const cv::Mat& mask,
                                     std::vector<SurfKeypoint>* keypoints, cv::Mat* descriptors) {
  SetImage(gray);
  Detect(mask, keypoints);
  Describe(*keypoints, descriptors);
}

}  // namespace arreg
