// The detector's decision: does the tissue's motion around a point show two pieces separating
// along a line, or one continuous deformation?
#pragma once

#include <Eigen/Core>
#include <optional>

#include "core/mesh.h"

namespace arreg::cutting {

// The model. Around a candidate point c, the features' displacement r_l = p^1_l - p^0_l (target
// minus rest position: the motion the images show, whatever the uncut model does across a gap) is
// a function of their rest position p^0_l. Along a candidate line through c (in-plane
// normal m, direction t, signed distance s = m . (p^0 - c), arc t . (p^0 - c)), only the features
// of a strip beside the line are used, strip_half_width spacings wide on each side, so that any
// deformation that is smooth at the scale the features resolve is, in the strip, close to its
// first-order expansion on each side. Under H0 (one continuous deformation) the displacement is,
// per component, continuous across the line with a slope that may change there (a strain
// concentrated at the line is such a kink):
//   r = a0 + a1 t + a2 t^2 + (c+ + d+ t) max(s, 0) + (c- + d- t) min(s, 0) + noise,
// the noise independent Gaussian tracking noise. Under H1 (two pieces separating along the line)
// the side s > 0 is offset by a jump that may vary linearly along the line (a cut opens more at
// one end than at the other): r += (g0 + g1 t) [s > 0]. H0 is nested in H1, so
//   F = ((RSS0 - RSS1) / 6) / sigma^2,  sigma^2 = max(RSS1 / (3 (n - 9)), noise_floor^2)
// follows Fisher's F(6, 3 (n - 9)) under H0, or F(6, inf) when the tracking noise floor sets
// sigma. The line's direction and its offset from c are searched (`directions` angles, offsets of
// -1/2 to 1/2 spacing); the threshold is the F quantile at 1 - alpha / (number of lines tried)
// (Bonferroni), alpha the one number the decision has: the probability of declaring a separation
// where the displacement is continuous. Two facts of a cut, not tuned, complete it: a cut opens
// (the pieces move apart: the jump's component from side 0 to side 1 is positive; material does not
// interpenetrate), and a tracking failure concerns one feature, so the decision must hold with
// any single feature left out.
struct SeparationTestOptions {
  // alpha [-]: false-alarm probability of one test under H0. Default 1e-6.
  double false_alarm_probability = 1e-6;
  // sigma_floor [mm]: the tracking noise per component below which s is not taken (features on a
  // noise-free synthetic field would otherwise make any sub-pixel jump significant). The pipeline
  // sets it from `cutting.tracking_noise_px` at the features' median depth. Default 0.1.
  double noise_floor_mm = 0.1;
  // Features needed on each side of the line: a jump is a property of two regions, each observed
  // by more features than the jump has components. Default 4.
  int min_features_per_side = 4;
  // Directions of the line searched over 180 degrees. Default 24 (7.5-degree steps: a line off
  // by half a step is off by a quarter spacing 2 spacings from c).
  int directions = 24;
  // b [feature spacings]: width of the strip beside the line whose features are tested, on each
  // side from the feature nearest the line (the lips' features may be lost over a gap); the
  // spacing is the median distance of the given features to their nearest neighbour (rest). A
  // displacement that varies over more than about one spacing is resolved as continuous. Default 4.
  double strip_half_width = 4.0;

  // Throws arreg::Error naming the offending field.
  void Check() const;
};

struct SeparationTestResult {
  bool tested = false;            // enough features on both sides for some direction
  bool separated = false;         // H1 accepted: significant, opening, and robust to one feature
  double statistic = 0.0;         // F of the best line (with every feature)
  double robust_statistic = 0.0;  // the smallest F with one feature left out
  double threshold = 0.0;         // the F quantile it is compared with
  int num_features = 0;           // features given
  int features_side[2] = {0, 0};  // strip features with s <= 0 and s > 0 (best line)
  double spacing_mm = 0.0;        // median nearest-neighbour distance of the features (rest)
  double offset_mm = 0.0;         // the best line's offset from c along m
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();     // m: unit, rest coordinates, in-plane
  Eigen::Vector3d direction = Eigen::Vector3d::Zero();  // the line's direction (normal x m)
  // g, displacement of side 1 minus side 0, at the strip's mean position along the line
  Eigen::Vector3d jump_mm = Eigen::Vector3d::Zero();
  // g . o, o the unit direction from side 0's centroid to side 1's in the current positions
  double opening_mm = 0.0;
};

// rest_mm: (#n x 3) p^0 of the features around c; current_mm: (#n x 3) their model points p^t,
// which say in which direction the pieces separate in this frame (from the centroid of side 0 to
// that of side 1); displacement_mm: (#n x 3) p^1 - p^0; centre_mm: c (rest coordinates).
// `along` (rest coordinates), when given, restricts the line's direction to within
// `cone_deg` of it and the features to those ahead of c along it: a growing cut, c at the reach
// of the cut already applied, continues its direction into the part the model has not cut. The
// Bonferroni factor is then the number of lines tried in the cone (directions x offsets).
SeparationTestResult TestSeparation(const RowMatX3d& rest_mm, const RowMatX3d& current_mm,
                                    const RowMatX3d& displacement_mm,
                                    const Eigen::Vector3d& centre_mm,
                                    const SeparationTestOptions& options,
                                    const std::optional<Eigen::Vector3d>& along = std::nullopt,
                                    double cone_deg = 45.0);

// Regularised incomplete beta function I_x(a, b), a, b > 0, x in [0, 1].
double RegularizedIncompleteBeta(double a, double b, double x);
// The p-quantile of Fisher's F(d1, d2) distribution, p in (0, 1); d2 = infinity gives the
// chi-square(d1) quantile divided by d1.
double FisherQuantile(double p, double d1, double d2);

}  // namespace arreg::cutting
