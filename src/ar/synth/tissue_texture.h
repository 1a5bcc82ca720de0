// Deterministic procedural tissue appearance defined in rest (material)
// coordinates, so the pattern moves with the deforming tissue in the video.
#pragma once

#include <Eigen/Core>
#include <cstdint>

namespace arreg::synth {

struct TissueTextureOptions {
  uint64_t seed = 1;                              // pattern seed
  Eigen::Vector3f base_rgb{0.80f, 0.38f, 0.36f};  // mean tissue colour (linear RGB)
  double mottling_scale_mm = 14.0;  // size of the slow colour variation (mm), default 14
  double speckle_scale_mm =
      3.0;  // size of the small dark/bright spots that give corners (mm), default 3
  double vessel_scale_mm = 22.0;  // spacing of the vessel-like lines (mm), default 22
  double vessel_width = 0.05;     // line half-width as a fraction of the noise range, default 0.05
  void Check() const;
};

class TissueTexture {
 public:
  explicit TissueTexture(const TissueTextureOptions& options);
  // Albedo (linear RGB in [0, 1]) at a rest-coordinate point (mm).
  Eigen::Vector3f Albedo(const Eigen::Vector3d& point_in_rest_mm) const;
  // Smooth value noise in [0, 1] (trilinear, quintic fade), for tests and backgrounds.
  double Noise(const Eigen::Vector3d& p, uint64_t channel) const;

 private:
  TissueTextureOptions options_;
};

}  // namespace arreg::synth
