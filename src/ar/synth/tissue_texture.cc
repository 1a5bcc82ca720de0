#include "ar/synth/tissue_texture.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"

namespace arreg::synth {

void TissueTextureOptions::Check() const {
  ARREG_CHECK_INPUT(mottling_scale_mm > 0, "", "mottling_scale_mm", "must be positive");
  ARREG_CHECK_INPUT(speckle_scale_mm > 0, "", "speckle_scale_mm", "must be positive");
  ARREG_CHECK_INPUT(vessel_scale_mm > 0, "", "vessel_scale_mm", "must be positive");
  ARREG_CHECK_INPUT(vessel_width > 0 && vessel_width < 0.5, "", "vessel_width",
                    "must be in (0, 0.5)");
}

TissueTexture::TissueTexture(const TissueTextureOptions& options) : options_(options) {
  options.Check();
}

namespace {
inline uint64_t Mix(uint64_t z) {  // splitmix64 finaliser
  z += 0x9e3779b97f4a7c15ULL;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}
inline double Lattice(int64_t i, int64_t j, int64_t k, uint64_t key) {
  const uint64_t h = Mix(key ^ Mix(static_cast<uint64_t>(i) ^
                                   Mix(static_cast<uint64_t>(j) ^ Mix(static_cast<uint64_t>(k)))));
  return static_cast<double>(h >> 11) * (1.0 / 9007199254740992.0);
}
inline double Fade(double t) { return t * t * t * (t * (t * 6 - 15) + 10); }
}  // namespace

double TissueTexture::Noise(const Eigen::Vector3d& p, uint64_t channel) const {
  const uint64_t key = Mix(options_.seed * 0x100000001b3ULL + channel);
  const double fx = std::floor(p.x()), fy = std::floor(p.y()), fz = std::floor(p.z());
  const int64_t i = static_cast<int64_t>(fx), j = static_cast<int64_t>(fy),
                k = static_cast<int64_t>(fz);
  const double u = Fade(p.x() - fx), v = Fade(p.y() - fy), w = Fade(p.z() - fz);
  double c[2][2][2];
  for (int a = 0; a < 2; ++a)
    for (int b = 0; b < 2; ++b)
      for (int d = 0; d < 2; ++d) c[a][b][d] = Lattice(i + a, j + b, k + d, key);
  const double x00 = c[0][0][0] + u * (c[1][0][0] - c[0][0][0]);
  const double x10 = c[0][1][0] + u * (c[1][1][0] - c[0][1][0]);
  const double x01 = c[0][0][1] + u * (c[1][0][1] - c[0][0][1]);
  const double x11 = c[0][1][1] + u * (c[1][1][1] - c[0][1][1]);
  const double y0 = x00 + v * (x10 - x00), y1 = x01 + v * (x11 - x01);
  return y0 + w * (y1 - y0);
}

Eigen::Vector3f TissueTexture::Albedo(const Eigen::Vector3d& p) const {
  const TissueTextureOptions& o = options_;
  // Slow mottling: two octaves.
  const double m =
      0.65 * Noise(p / o.mottling_scale_mm, 1) + 0.35 * Noise(p / (0.5 * o.mottling_scale_mm), 2);
  Eigen::Vector3f rgb = o.base_rgb.cwiseProduct(
      Eigen::Vector3f(0.80f + 0.40f * static_cast<float>(m), 0.75f + 0.5f * static_cast<float>(m),
                      0.80f + 0.40f * static_cast<float>(m)));
  // Speckles: thresholded fine noise gives blobs with high-contrast corners.
  const double s = Noise(p / o.speckle_scale_mm, 3);
  if (s > 0.80)
    rgb *= 0.55f;
  else if (s < 0.16)
    rgb = 0.6f * rgb + Eigen::Vector3f(0.38f, 0.30f, 0.28f);
  // Vessel-like lines: the level set 0.5 of a smooth noise, darkened towards red.
  const double n = Noise(p / o.vessel_scale_mm + Eigen::Vector3d(0.37, 0.11, 0.73), 4) +
                   0.3 * (Noise(p / (0.4 * o.vessel_scale_mm), 5) - 0.5);
  const double d = std::abs(n - 0.5);
  if (d < o.vessel_width) {
    const float t = static_cast<float>(1.0 - d / o.vessel_width);
    rgb = (1.0f - 0.8f * t) * rgb + 0.8f * t * Eigen::Vector3f(0.45f, 0.06f, 0.08f);
  }
  return rgb.cwiseMax(0.0f).cwiseMin(1.0f);
}

}  // namespace arreg::synth
