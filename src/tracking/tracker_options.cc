// Names of the track statuses and the checks of the tracker's options.
#include "tracking/tracker.h"

#include <cmath>

#include "core/error.h"

namespace arreg {

const char* TrackStatusName(TrackStatus status) {
  switch (status) {
    case TrackStatus::kTracked:
      return "tracked";
    case TrackStatus::kLostBorder:
      return "lost-border";
    case TrackStatus::kLostRoi:
      return "lost-roi";
    case TrackStatus::kLostFlow:
      return "lost-flow";
    case TrackStatus::kLostForwardBackward:
      return "lost-fb";
    case TrackStatus::kOutlierSpatioTemporal:
      return "outlier-spatiotemporal";
    case TrackStatus::kSpecular:
      return "specular";
    case TrackStatus::kLostAppearance:
      return "lost-appearance";
    case TrackStatus::kInstrument:
      return "instrument";
  }
  return "unknown";
}

void OutlierFilterOptions::Check() const {
  ARREG_CHECK_INPUT(neighbours >= 0, "", "OutlierFilterOptions.neighbours", "must be >= 0, got ",
                    neighbours);
  ARREG_CHECK_INPUT(ratio >= 1, "", "OutlierFilterOptions.ratio", "must be >= 1, got ", ratio);
  ARREG_CHECK_INPUT(slack_px >= 0, "", "OutlierFilterOptions.slack_px", "must be >= 0, got ",
                    slack_px);
}

void SpecularOptions::Check() const {
  ARREG_CHECK_INPUT(min_value >= 0 && min_value <= 255, "", "SpecularOptions.min_value",
                    "must be in 0..255, got ", min_value);
  ARREG_CHECK_INPUT(max_saturation >= 0 && max_saturation <= 255, "",
                    "SpecularOptions.max_saturation", "must be in 0..255, got ", max_saturation);
  ARREG_CHECK_INPUT(radius_px >= 0 && radius_px <= 32, "", "SpecularOptions.radius_px",
                    "must be in 0..32, got ", radius_px);
}

void ReidentifyOptions::Check() const {
  ARREG_CHECK_INPUT(every_frames >= 1, "", "ReidentifyOptions.every_frames", "must be >= 1, got ",
                    every_frames);
  ARREG_CHECK_INPUT(max_lost_frames >= 1, "", "ReidentifyOptions.max_lost_frames",
                    "must be >= 1, got ", max_lost_frames);
  ARREG_CHECK_INPUT(neighbours >= 1, "", "ReidentifyOptions.neighbours", "must be >= 1, got ",
                    neighbours);
  ARREG_CHECK_INPUT(min_neighbours >= 1 && min_neighbours <= neighbours, "",
                    "ReidentifyOptions.min_neighbours", "must be in 1..neighbours, got ",
                    min_neighbours);
  ARREG_CHECK_INPUT(gate_px > 0, "", "ReidentifyOptions.gate_px", "must be > 0, got ", gate_px);
  ARREG_CHECK_INPUT(max_descriptor_distance > 0 && max_descriptor_distance <= 2, "",
                    "ReidentifyOptions.max_descriptor_distance", "must be in (0, 2], got ",
                    max_descriptor_distance);
  ARREG_CHECK_INPUT(ratio > 0 && ratio <= 1, "", "ReidentifyOptions.ratio",
                    "must be in (0, 1], got ", ratio);
  ARREG_CHECK_INPUT(max_scale_factor >= 1, "", "ReidentifyOptions.max_scale_factor",
                    "must be >= 1, got ", max_scale_factor);
  ARREG_CHECK_INPUT(min_patch_correlation >= -1 && min_patch_correlation <= 1, "",
                    "ReidentifyOptions.min_patch_correlation", "must be in [-1, 1], got ",
                    min_patch_correlation);
  ARREG_CHECK_INPUT(min_lk_correlation >= -1 && min_lk_correlation <= 1, "",
                    "ReidentifyOptions.min_lk_correlation", "must be in [-1, 1], got ",
                    min_lk_correlation);
}

void AppearanceCheckOptions::Check() const {
  ARREG_CHECK_INPUT(every_frames >= 1, "", "AppearanceCheckOptions.every_frames",
                    "must be >= 1, got ", every_frames);
  ARREG_CHECK_INPUT(min_correlation >= -1 && min_correlation <= 1, "",
                    "AppearanceCheckOptions.min_correlation", "must be in [-1, 1], got ",
                    min_correlation);
}

void FeatureTrackerOptions::Check() const {
  surf.Check();
  reidentify.Check();
  appearance.Check();
  drift.Check();
  instruments.Check();
  lk.Check();
  outliers.Check();
  specular.Check();
  ARREG_CHECK_INPUT(max_features >= 1, "", "FeatureTrackerOptions.max_features",
                    "must be >= 1, got ", max_features);
  ARREG_CHECK_INPUT(min_features >= 0, "", "FeatureTrackerOptions.min_features",
                    "must be >= 0, got ", min_features);
  ARREG_CHECK_INPUT(std::isfinite(min_hessian_threshold) && min_hessian_threshold >= 0, "",
                    "FeatureTrackerOptions.min_hessian_threshold", "must be >= 0, got ",
                    min_hessian_threshold);
  ARREG_CHECK_INPUT(min_distance_px >= 0, "", "FeatureTrackerOptions.min_distance_px",
                    "must be >= 0, got ", min_distance_px);
  ARREG_CHECK_INPUT(border_px >= 0, "", "FeatureTrackerOptions.border_px", "must be >= 0, got ",
                    border_px);
  ARREG_CHECK_INPUT(redetect_every_frames >= 0, "", "FeatureTrackerOptions.redetect_every_frames",
                    "must be >= 0, got ", redetect_every_frames);
  ARREG_CHECK_INPUT(redetect_hole_factor >= 0 && std::isfinite(redetect_hole_factor), "",
                    "FeatureTrackerOptions.redetect_hole_factor", "must be >= 0, got ",
                    redetect_hole_factor);
}

}  // namespace arreg
