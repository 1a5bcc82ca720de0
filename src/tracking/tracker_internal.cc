#include "tracking/tracker_internal.h"

#include <cstddef>

namespace arreg::tracker_internal {

void SamplePatch(const cv::Mat& image, cv::Point2f p, int side, std::vector<float>* patch) {
  patch->resize(static_cast<size_t>(side) * side);
  const float x0 = p.x - side / 2, y0 = p.y - side / 2;
  const int ix = static_cast<int>(std::floor(x0)), iy = static_cast<int>(std::floor(y0));
  const float fx = x0 - ix, fy = y0 - iy;
  const ptrdiff_t step = static_cast<ptrdiff_t>(image.step[0] / sizeof(float));
  for (int r = 0; r < side; ++r) {
    const float* a = image.ptr<float>() + (iy + r) * step + ix;
    const float* b = a + step;
    for (int c = 0; c < side; ++c)
      (*patch)[r * side + c] =
          (1 - fy) * ((1 - fx) * a[c] + fx * a[c + 1]) + fy * ((1 - fx) * b[c] + fx * b[c + 1]);
  }
}

double Correlation(const std::vector<float>& a, const std::vector<float>& b) {
  const size_t n = a.size();
  double ma = 0, mb = 0;
  for (size_t i = 0; i < n; ++i) ma += a[i], mb += b[i];
  ma /= n, mb /= n;
  double ab = 0, aa = 0, bb = 0;
  for (size_t i = 0; i < n; ++i) {
    ab += (a[i] - ma) * (b[i] - mb);
    aa += (a[i] - ma) * (a[i] - ma);
    bb += (b[i] - mb) * (b[i] - mb);
  }
  return aa > 0 && bb > 0 ? ab / std::sqrt(aa * bb) : 0.0;
}

}  // namespace arreg::tracker_internal
