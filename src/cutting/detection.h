// Cut detection from tracked surface features (thesis 7.5): pairs of neighbouring features whose
// model-versus-image displacements diverge are outliers, and their barycentres grow a cut polyline.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <functional>
#include <limits>
#include <optional>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "core/enum_names.h"
#include "core/mesh.h"
#include "cutting/separation_test.h"

namespace arreg::cutting {

// Which ratio of pair distances enters mu2 (thesis eq. 7.10).
enum class CutMeasure {
  // mu2 = delta^t / delta^0: current model positions. The model smooths jumps of the tracked
  // targets, so the detection is more stable ([78]; the thesis's choice for noisy tracking).
  kModelRegularised,
  // mu2 = delta^1 / delta^0: image targets only; independent of the model ([82]).
  kImageOnly,
};
// The spelling in scene files and records: "model", "image".
inline constexpr EnumName<CutMeasure> kCutMeasureNames[] = {
    {CutMeasure::kModelRegularised, "model"}, {CutMeasure::kImageOnly, "image"}};

// What decides that a cluster of outliers (or a growing cut's tip) is a separation.
enum class CutDecision {
  // The separation test (separation_test.h): the features' displacement p^1 - p^0 around the
  // point is tested for a jump across a line against one continuous deformation, at the
  // false-alarm probability `separation.false_alarm_probability` (scene key
  // cutting.false_alarm_probability). Used for every cut point, starts and growth alike; the
  // growth probe tests the tip's continuation the same way (probe_length_factor 0 turns both
  // probes off). The rules listed under kRules are not asked.
  kSeparationTest,
  // The thesis measure's clusters with the rule set documented on each option below
  // (reject_lone_features, min_opening_balance, min_opening_balance_bridges,
  // min_lone_growth_balance, reject_star_starts, confirm_starts_with_model_measure,
  // closing_window_frames, and the probe's pair outliers).
  kRules,
};
// The spelling in scene files and records: "separation-test", "rules".
inline constexpr EnumName<CutDecision> kCutDecisionNames[] = {
    {CutDecision::kSeparationTest, "separation-test"}, {CutDecision::kRules, "rules"}};

// Thesis defaults are those of the kidney 1 experiment (thesis 7.7 / DESIGN.md section 4), with
// the lengths rescaled to the features' spacing by default (neighbours_per_feature).
struct CutDetectorOptions {
  // r_F [mm]: two features whose frame-0 distance is below this are neighbours. Default 15.
  // With neighbours_per_feature > 0 it is replaced at Initialize (see there).
  double neighbour_radius_mm = 15.0;
  // k [-]: when > 0, Initialize sets r_F to the median over the features of the distance to
  // their k-th nearest other feature, so that a typical feature has k neighbours whatever the
  // object's size, the camera distance and the texture, and scales r_pc and
  // boundary_extension_mm by the same factor r_F / neighbour_radius_mm (their ratios to r_F stay
  // the thesis's). The thesis's band examples have 2 * 6795 / 531 = 25.6 and 2 * 9225 / 693 =
  // 26.6 pairs per feature (thesis 7.7.2). Because the count of pairs across a seam of length
  // r_pc grows like (density * r_F^2)^2, it stays the same at a fixed k, so tau and n keep their
  // meaning on every scale. 0 uses neighbour_radius_mm, cut_point_radius_mm and
  // boundary_extension_mm as given (the thesis's millimetre settings). Default 26.
  int neighbours_per_feature = 26;
  // tau [-]: a pair is an outlier when mu > tau * mean(mu) over the current pairs. The thesis
  // uses 7 (liver), 8 (kidney 1) and 10 (kidney 2); the default is the strictest, 10: with
  // outliers weighted by their excess (outlier_weight_cap), 8 let the strain concentrations at
  // the re-entrant corners of a band stretched to 166-186 % (where the coarse model cannot
  // follow the truth) make cut points on the synthetic precut bands. Default 10.
  double outlier_factor = 10.0;
  // The scale mean(mu) of tau is the mean over the pairs that are not outliers: the fixed point
  // m = mean{mu_k : mu_k <= tau m} over C_F, reached from the plain mean by iteration. mean(mu)
  // stands for the smooth misfit of a continuous deformation; the pairs across a cut and a
  // mistracked feature's pairs are what the threshold is to find, and with the plain mean they
  // raise it (the longer a precut, the more pairs cross it, the higher the bar). Where no pair
  // exceeds tau times the plain mean both are the same. false: the thesis's plain mean. It
  // helps the synthetic dev scenes, not the phantom ones (docs/detection-measured.md, "The
  // inliers' mean"). Default false.
  bool mean_of_inliers = false;
  // n [-]: outlier count (weighted, see outlier_weight_cap) at which a cut point is inserted.
  // The thesis uses 8 (kidney 1) and 3 (kidney 2, whose cuts are crossed by few tracked pairs).
  // Default 4: on the synthetic cut-while-filmed bands the tracker keeps only a few pairs across
  // a cut that opens wide, and n = 8 misses such cuts, while 4 finds the synthetic cuts and
  // makes none on stretched bands or the real clip (docs/detection.md). At least
  // n / outlier_weight_cap pairs are needed.
  int min_outliers = 4;
  // [-] An outlier counts towards n as min(mu / (tau * mean(mu)), cap): a pair far above the
  // threshold is stronger evidence than one just above it. On a cut that opens wide the lip
  // features are soon lost by the tracker, and only a few pairs stay across it (5 or 6 on the
  // synthetic v-example, 2 to 10 times the threshold). Not in the thesis; 1 gives its plain
  // count. Default 2.
  double outlier_weight_cap = 2.0;
  // r_pc [mm]: pairs whose current segment comes closer than this to a new cut point are removed,
  // and the look-ahead point lies at this distance beyond the extremity. Default 7 (scaled with
  // r_F when neighbours_per_feature > 0).
  double cut_point_radius_mm = 7.0;
  // Variant of mu2 (eq. 7.10). Default kImageOnly, as in the thesis's kidney experiments (table
  // 7.1), whose parameters are the defaults here: a pair across an opening cut gets a large
  // delta^1 while the uncut model keeps delta^t small, and pairs on one lip (whose image
  // distance shrinks as the cut side relaxes) are not amplified.
  CutMeasure measure = CutMeasure::kImageOnly;
  // Only pairs that open are outliers: their targets are farther apart than their model points
  // (delta^1 > delta^t). Not in the thesis: a cut or tear separates its two sides, so a pair
  // across it always opens, whereas a feature mistracked or left behind on one lip of a cut has
  // a large |d_l| that makes mu1 large towards its same-side neighbours too (a star of
  // outliers around one feature, which pulled the barycentre off the seam). false gives the
  // thesis's test. Default true.
  bool require_opening = true;
  // A pair with a feature whose tracking window holds an occluder this frame
  // (FrameFeatures::occluded: an instrument in the window) is no outlier. Such a window holds
  // two motions, the tissue's and the instrument's; the track follows a mixture of them, and
  // its misfit then says where the instrument moved, not where the tissue separated. Its mu
  // still counts in mean(mu). false: every pair can be an outlier. Default true.
  bool ignore_occluded_pairs = true;
  // Only one cluster of outliers makes a cut point: the outliers whose pair midpoints lie within
  // r_F of the outlier whose r_F neighbourhood has the largest sum of mu; n applies to that
  // cluster, and its pairs are removed with those crossing the r_pc sphere. Not in the thesis,
  // whose barycentre of all outliers falls between two separate groups (the two ends of a cut,
  // or a cut and a mistracked feature) and, since none of their pairs crosses the sphere there,
  // is inserted again at the same place in every following frame. false gives the thesis's
  // barycentre of all outliers. Default true.
  bool cluster_outliers = true;
  // A cluster in which one feature is an endpoint of more than 3/4 of the pairs, and whose
  // partners in those pairs are on average less than half as far from their model points
  // (|p^t - p^1|) as it is, is that feature's error, not a separation: its pairs leave the
  // candidates of this frame and the cluster is selected again. A feature that slides on the
  // image (a tracking error too slow for the jump filter of thesis 7.4.1) makes a star of
  // opening pairs towards the neighbours it moves away from, all explained by its own error;
  // across a cut the features of both lips are far from the uncut model, and with two or more
  // features on each side no single one is in more than half of the pairs across it. Not in the
  // thesis; only with cluster_outliers. false keeps such clusters. Default true.
  bool reject_lone_features = true;
  // [-] A cluster whose opening is carried by one side only is no separation: with
  // o_l = d_l . u and o_m = -d_m . u (u the unit vector from p^t_l to p^t_m, d = p^t - p^1) how
  // far each feature's target lies outward of its model point along the pair, the cluster's
  // balance is sum(mu min(o_l, o_m)) / sum(mu max(o_l, o_m)). Across a cut the uncut model spans
  // the gap and is pulled by the springs of both lips, so both targets lie outward of their model
  // points (balance 0.55-0.85 on the synthetic cuts); at a strain concentration the coarse model
  // cannot follow (the re-entrant corners of a band stretched to 166-186 %) the error sits on
  // the features of the concentrated region (balance 0.09-0.40 there). Such a cluster's pairs
  // leave the candidates of this frame and the cluster is selected again. Only asked of a
  // point that would start a polyline (none yet, or one farther than the growth radius from a
  // lone point, see grow_at_extremities_only): a point that grows a polyline is corroborated by
  // the cut point next to it, behind which the model may be cut already (pairs from the cut
  // part to the whole part ahead are one-sided by construction), and a lip on the fixed side
  // of an object barely moves (asked of growths, the test delays a cut along a fixed edge by
  // several frames). The bound 1/2 is the one reject_lone_features
  // applies to a single feature (partners less than half as far off), extended to several features
  // on the same side. Not in the thesis; only with cluster_outliers; 0 disables. Default 0.5.
  double min_opening_balance = 0.5;
  // [-] The bound of min_opening_balance for a cluster of bridges (bridge_radius_factor): one
  // whose measure comes for at least 9/10 from bridges, so that the features next to the seam
  // on both lips are lost. A bridge's endpoints lie at unequal distances from the seam, and the
  // uncut model's misfit falls off with the distance from it: where both lips open, the
  // endpoint next to the seam lies 14-16 mm outward and the one 15-25 px farther 4-7 mm on a
  // synthetic V-cut, so a bridge's balance is lower than that of a pair whose endpoints both
  // neighbour the seam (0.36-0.50 for a cut seen only through bridges, which 0.5 never starts).
  // A strain concentration's bridge clusters stay far below (at most 0.21 over 95 band-stretch
  // seeds and 81 with twice the features). Not in the thesis; used only where below
  // min_opening_balance (0 there disables both). Default 1/3.
  double min_opening_balance_bridges = 1.0 / 3.0;
  // [-] A cluster that would grow a lone point (the polyline's only point: nothing is cut yet)
  // and whose opening balance (min_opening_balance's) is at most this is rejected, and the lone
  // point is dropped. Such a growth need not open both lips as a start must (a lip on the fixed
  // side of an object barely moves), but across a cut the uncut model spans the gap and no
  // lip's targets lie inward of their model points: a balance of 0 or below means the targets
  // on one side lag their model points as those on the other lead them, a strain the coarse
  // model misses, and the lone point beside it came from the same strain. With twice the
  // features on band-stretch, 13 of the 16 false cuts of 81 seeds grew a lone point at a stem
  // corner from such a cluster (balances -0.23 to -0.06); the first growths of real cuts scored
  // 0.12-0.95 on 156 cut runs. With the rule 4 of the 81 make cuts, and none of the 156 runs
  // changes. Not in the thesis; -1 disables. Default 0.
  double min_lone_growth_balance = 0.0;
  // A cluster that would start a polyline and in which one feature is an endpoint of more than
  // 3/4 of the pairs (a star) is no separation: whatever its partners do, one feature's
  // disagreement with its neighbours is explained by that feature (its track, or a strain
  // concentration the model cannot follow) as well as by a cut, which shows two or more features
  // on each side. Its pairs leave the candidates of this frame. Not in the thesis; only with
  // cluster_outliers; false lets stars start. Default true.
  bool reject_star_starts = true;
  // Conservative starts (not in the thesis; opt-in): a point that would start a polyline must
  // be found by both variants of mu2 (eq. 7.10). With the image-only measure (the default
  // `measure`), the pairs of the frame within r_F of the point must also reach n as outliers of
  // the model-regularised one (mu2 = delta^t / delta^0, the variant of the thesis's band
  // examples; its own mean over C_F, the same tau, floor, weights and opening test). Growth is
  // not asked for it: the image-only measure keeps following a tear whose lips the tracker
  // loses, which the model-regularised measure alone can miss entirely.
  // Measured (docs/detection.md "Conservative starts"): on 81 band-stretch seeds it leaves 2
  // of the 6 false cut events (with twice the features 18 of 32), but it delays the start of
  // real cuts by up to 26 frames and no longer starts the weak middle slit of band-precut-middle
  // (cut on 5 of 13 seeds without it, 0 with it), so it is off by default. Ignored with
  // measure kModelRegularised. Default false.
  bool confirm_starts_with_model_measure = false;
  // A cut opens: the targets of its crossing pairs move apart as it does. A cluster that would
  // start a polyline is rejected when its pairs are closing instead: the median over its pairs
  // of the relative change of their targets' distance (p^1) over the last
  // closing_window_frames frames is below -max_closing_fraction. Where a stretched band is
  // released, its coarse model lags at the stem while the tissue relaxes, and opening clusters
  // of shrinking pairs form there; with the drift-corrected tracks (FeatureTracker's
  // DriftCorrectionOptions) their pairs shrank by a median 3-8.5 % over 5 frames at all ten false
  // starts on 81 seeds, while the starts of real cuts (102 scenes) changed by -0.1 % or more
  // (median +17 %) (docs/detection.md "Closing clusters start no cut"). Not in the thesis;
  // 0 frames disables. Defaults 5 and 0.01.
  int closing_window_frames = 5;
  double max_closing_fraction = 0.01;
  // The polyline grows only at its extremities (thesis 7.5.3): a cut point farther than
  // r_pc + 1.5 r_F (frame-0 coordinates) from both extremities is no growth of it. The next
  // point of a growing cut comes from pairs across the cut just outside the r_pc sphere around
  // the extremity (those inside were removed), whose midpoints lie within r_F / 2 of the cut
  // (pairs are shorter than r_F), and a cluster's barycentre lies within r_F of its seed pair.
  // A point that would turn the polyline back by more than 90 degrees at the extremity it joins
  // (a cut or tear does not reverse its direction between two cut points; the polyline would
  // fold onto itself) is tried at the other extremity and refused if it folds there too. A
  // refused cluster leaves the candidates of this frame (its pairs stay, so a real second cut
  // keeps its evidence) and the next cluster is selected. While the polyline is a single point
  // (nothing has been cut yet), a far point replaces it: a cut keeps producing outliers along
  // itself, and a lone point that got no continuation within its growth radius is not the
  // cut's; while an outlier of the frame (outside the far point's cluster) still lies within
  // that radius, its cut still opens there and the far point is refused instead. Not in the
  // thesis, whose nearest-extremity rule joins any point; false restores it.
  // Default true.
  bool grow_at_extremities_only = true;
  // Absolute floor on mu [mm]: pairs at or below it are never outliers. Not in the thesis, whose
  // test is purely relative; with real tracking, noise keeps mean(mu) away from 0, but in a
  // nearly static or noise-free sequence mean(mu) -> 0 and sub-pixel differences would pass
  // tau * mean. 0.1 mm is below tracking precision (1 px is ~0.25 mm at 200 mm with f = 800 px).
  // 0 gives the thesis's test. Default 0.1.
  double min_outlier_measure_mm = 0.1;
  // Look-ahead point (thesis 7.5.3, "Optimizations"): the extended polyline continues r_pc beyond
  // each extremity along its last segment, so a lagging detection still reaches the border.
  // Default true.
  bool look_ahead = true;
  // Boundary handling of [78, 79]: after an insertion, when no alive feature lies ahead of the
  // grown extremity (within r_F and within `boundary_cone_half_angle_deg` of the polyline's
  // direction), the extremity is at the object's border and the extended polyline continues by
  // `boundary_extension_mm` so that the cut crosses it. Default true.
  bool extend_to_boundary = true;
  // [mm] length added beyond an extremity found at the border. Default 15 (= r_F; scaled with
  // r_F when neighbours_per_feature > 0).
  double boundary_extension_mm = 15.0;
  // [deg] half-angle of the cone ahead of an extremity searched for features. Default 45.
  double boundary_cone_half_angle_deg = 45.0;
  // Cut points inserted per Update at most (the thesis inserts one per time step). Default 1.
  int max_cut_points_per_frame = 1;
  // [-] Bridging of dead neighbours, as a factor on r_F; 0 disables. When a feature d dies, each
  // alive l of its current pairs gets one new pair (l, m): m is the nearest alive feature with
  // |p0_m - p0_l| < bridge_radius_factor * r_F whose direction p0_m - p0_l lies within
  // bridge_cone_half_angle_deg of p0_d - p0_l, that was never paired with l, and whose frame-0
  // segment to l passes no cut point's frame-0 position within r_pc (those pairs were pruned or
  // are explained). Not in the thesis, whose C_F is fixed at frame 0: on a cut that opens wide
  // the tracker loses the lip features within a few frames of the tip passing (the texture
  // there turns and opens), so once every feature within r_F / 2 of the seam is gone no pair of
  // C_F spans the cut and the thesis's measure cannot see it grow (synthetic v-band: no pair
  // across the tear below its first 10 mm). A bridge takes the lost neighbour's place in the
  // same direction, so a pair that spanned the gap still does. Pairs never grow in number:
  // each dead pair gives at most one bridge. Bridges continue a cut; a point that would start a
  // polyline needs n among its cluster's pairs of C_F (weighted as any count), since features
  // also die where the strain concentrates (at a stretched band's stem corner a cluster of 3
  // pairs with bridges, weighted above n, would start a false cut). Only while there is no
  // polyline, and only in a frame where the pairs of C_F started none, a second pass takes the
  // bridges as candidates too and starts one from a cluster of n pairs, counted one each as in
  // the thesis: the lips' features can die before the cut opens enough to show (no pair of C_F
  // is left across it). Likewise a point that would replace a lone first point (nothing
  // cut yet) needs n among its pairs of C_F or n pairs counted one each: the lips beyond that
  // point can be lost too widely for bridges, and the bridges farther along are then no growth
  // of it. Default 2.
  double bridge_radius_factor = 2.0;
  // [deg] half-angle of the cone around a dead neighbour's direction searched for its bridge.
  // Default 30.
  double bridge_cone_half_angle_deg = 30.0;
  // [-] Growth probe ahead of an extremity, its length as a factor on r_F; 0 disables. Not in
  // the thesis. Once a tear's lips are lost, neither C_F nor the bridges span its continuation
  // (the synthetic v-band after frame 90: every feature within ~15 mm of the seam below the
  // model's crack is gone). Long pairs across it still see it. For each extremity of a polyline
  // of >= 2 points (at the border too: the border test sees only the alive features), the
  // probe is the segment of this length that continues the last segment (frame 0) from the end
  // of the extremity's extension (look-ahead or border extension). Its pairs are the pairs of
  // alive features at most probe_pair_length_factor * r_F apart (frame 0) whose segment crosses
  // the probe's plane (spanned by the direction and the local surface normal, from the frame-0
  // features around the probe's start) over the probe, and crosses neither the polyline nor
  // its r_pc spheres. They are measured with the same mu; a pair is a probe outlier when mu >
  // probe_outlier_factor * mean(mu) (the mean over C_F, as for tau) and it opens
  // (require_opening), and a feature's star is dropped as by reject_lone_features. When their
  // weighted count reaches n, a cut point is inserted at that extremity: across the probe at the
  // mu-weighted barycentre of the pairs' midpoints, along it at that of their crossings. It only
  // grows a cut: a scene with no polyline is not probed, and at most one point per frame is
  // inserted, only when C^t gave none. Default 2.
  double probe_length_factor = 2.0;
  // [-] Longest probe pair, frame 0, as a factor on r_F. Default 3.
  double probe_pair_length_factor = 3.0;
  // tau_p [-]: outlier factor of the probe pairs. Longer than r_F, a pair carries more of the
  // model's smooth misfit in mu1 than one of C_F; across a tear ahead of the model's crack it
  // reaches 15-30 mean(mu) on the synthetic v-band, against at most 11 for pairs across the
  // uncut band beyond the tear's tip (docs/detection.md). Default 12.
  double probe_outlier_factor = 12.0;
  // [-] A tear grows from its tip: the probe grows the polyline only when its nearest outlier
  // crosses it within r_pc + this factor times r_F of the extremity (frame 0), whatever the
  // extension (a border extension is a guess of how far S reaches, not an observation).
  // Outliers found only farther ahead are strain beyond the tear's tip that the model does not
  // follow, not its continuation (e.g. a band's junction with its stem, 28-50 mm ahead of a
  // V-tear; docs/detection.md, "A tear grows from its tip"). Default 1.
  double probe_max_lead_factor = 1.0;
  // The decision (see CutDecision). Default kRules: on the synthetic development scenes the
  // separation test matches the rules on the side precut, the S-cut and the kidney and makes no
  // cut on stretched bands, but follows a V-tear whose lips the tracker loses less far and
  // misses a middle precut (docs/detection-measured.md, "The two decisions").
  CutDecision decision = CutDecision::kRules;
  // The separation test's options (kSeparationTest).
  SeparationTestOptions separation;
  // [-] Radius of the neighbourhood whose alive features the separation test uses, around the
  // tested point (frame 0), as a factor on r_F. Default 2.
  double separation_radius_factor = 2.0;
  // [deg] A growing cut's continuation is tested for lines within this angle of its last
  // segment's direction. Default 30.
  double growth_cone_deg = 30.0;

  // Throws arreg::Error naming the offending field.
  void Check() const;
};

// A pair (l, m) of C_F as indices into the features given to Initialize (l < m).
struct FeaturePair {
  int first = 0;
  int second = 0;
  bool bridge = false;  // added in place of a dead pair (bridge_radius_factor), not in C_F
};

// One frame of tracked features. Rows correspond to `ids`; a feature given to Initialize and
// absent here has died and loses its pairs for good.
struct FrameFeatures {
  std::vector<int> ids;  // ids of the alive features (any order, each at most once)
  RowMatX3d target_mm;   // (#ids x 3) p^1_l: targets lifted from the image
  RowMatX3d model_mm;    // (#ids x 3) p^t_l(P_V): embedded feature points on the current model
  // Empty, or (#ids) 1 where an occluder (an instrument) lies in the feature's tracking window
  // this frame: with ignore_occluded_pairs, its pairs cannot be outliers this frame.
  std::vector<char> occluded;
};

struct CutPoint {
  Eigen::Vector3d position_mm;  // mu-weighted barycentre of the outlier pairs' midpoints (p^t)
  Eigen::Vector3d initial_position_mm;  // the same weights applied to the frame-0 midpoints (p^0)
  int frame = 0;                        // Update count (0-based) at insertion
  int num_outliers = 0;                 // outliers that produced it
  bool probe = false;  // found by the growth probe (probe_length_factor) rather than C^t
};

struct DetectionResult {
  int frame = 0;                   // Update count (0-based)
  std::vector<FeaturePair> pairs;  // C^t evaluated this frame (before this frame's removals)
  std::vector<double> measure;     // (#pairs) mu_lm = mu1 * mu2 [mm]
  double mean_measure = 0.0;       // mean of `measure` [mm]
  std::vector<int> outliers;       // indices into pairs/measure with mu > tau * mean
  std::vector<CutPoint> new_cut_points;
  int pairs_removed_by_cut = 0;  // pairs crossing the r_pc sphere of the new cut points
  // Clusters rejected this frame as one feature's star (reject_lone_features).
  int lone_features = 0;
  // Clusters rejected this frame by min_opening_balance (starts) or min_lone_growth_balance.
  int one_sided_clusters = 0;
  int star_starts = 0;  // clusters rejected this frame by reject_star_starts
  // Clusters whose start the model-regularised measure did not confirm
  // (confirm_starts_with_model_measure).
  int unconfirmed_starts = 0;
  // Clusters whose pairs were closing (closing_window_frames, max_closing_fraction).
  int closing_starts = 0;
  int refused_points = 0;  // cut points refused this frame as no growth of the polyline
  // (or with too few pairs to start one). Each of these counts a cluster once: a frame
  // without a polyline makes a second pass, with bridges, and reports the larger count.
  // Points refused this frame by the segment check (CutDetector::SetSegmentCheck): the segment
  // they would add makes a cut the caller cannot apply.
  int refused_segments = 0;
  int pairs_removed_by_death = 0;  // pairs with a feature that died this frame
  int pairs_bridged = 0;   // pairs added this frame in place of dead ones (bridge_radius_factor)
  int probe_pairs = 0;     // alive probe pairs evaluated this frame (probe_length_factor)
  int probe_outliers = 0;  // of which outliers (after dropping a feature's star)
  // Separation tests of this frame (kSeparationTest): the tested point (frame 0) and the result.
  std::vector<std::pair<Eigen::Vector3d, SeparationTestResult>> separation_tests;
  int not_separated = 0;       // clusters and probes the separation test rejected this frame
  bool segment_added = false;  // the polyline has >= 2 points and grew this frame
  std::vector<Eigen::Vector3d> polyline_mm;  // cut points in order (p^t at insertion)
  std::optional<Eigen::Vector3d>
      look_ahead_mm;  // r_pc beyond the extremity grown this frame (if look_ahead)
  std::vector<Eigen::Vector3d> extended_polyline_mm;  // polyline with look-ahead/border extensions
};

// Median over the points (at most 1000 evenly strided) of the distance to their k-th nearest
// other point, mm; 0 when fewer than two. O(#samples * #points).
double MedianKthNeighbourDistance(const RowMatX3d& points_mm, int k);

// Stateful detector: C_F is built once, then every Update evaluates mu on the remaining pairs,
// inserts cut points and prunes pairs. Single-threaded; Update allocates nothing once the result
// vectors have reached their size, except in frames where features die (bridges).
class CutDetector {
 public:
  explicit CutDetector(const CutDetectorOptions& options = {});

  // initial_positions_mm: (#F x 3) p^0_l on the model at frame 0; ids: (#F) distinct feature ids.
  // Resolves r_F (and r_pc, the border extension) from the features' spacing when
  // neighbours_per_feature > 0, then builds C_F with a uniform grid of cell size r_F. Resets the
  // polyline.
  void Initialize(const RowMatX3d& initial_positions_mm, const std::vector<int>& ids);

  // Features attached after frame 0 (the tracker's fill-in of areas whose features were lost):
  // rest_positions_mm (#N x 3) are their points on the model's rest configuration, the frame
  // the measure compares with (delta^0). Each joins C_F with every alive feature, and every
  // other new one, within r_F at rest whose segment passes no cut point within r_pc (as a
  // bridge would). The radii stay those resolved at Initialize. Throws arreg::Error for ids
  // already known or mismatched rows.
  void AddFeatures(const RowMatX3d& rest_positions_mm, const std::vector<int>& ids);

  // Evaluates one frame; throws arreg::Error for unknown or repeated ids or mismatched rows.
  void Update(const FrameFeatures& frame, DetectionResult* result);

  // A test of the polyline a new segment would make, given with its extensions (as
  // ExtendedPolyline) in this frame's positions p^t and at frame 0. False refuses the point:
  // its cluster leaves the frame's candidates (DetectionResult::refused_segments) and its pairs
  // stay. The pipeline refuses a segment whose cut surface would split the model at every
  // depth (cutting.keep_connected): a cut that would separate the object is no cut the model
  // can follow, and the strain concentrations at the two re-entrant corners of a stretched
  // band's stem, joined into one polyline, make exactly that (docs/detection.md, "Segments
  // that would split the model"). A point within r_pc (frame 0) of one refused at the same
  // extremity is refused without a new test until the polyline changes. Not set: every
  // segment is accepted.
  using SegmentCheck = std::function<bool(const std::vector<Eigen::Vector3d>& extended_mm,
                                          const std::vector<Eigen::Vector3d>& extended_initial_mm)>;
  void SetSegmentCheck(SegmentCheck check) { segment_check_ = std::move(check); }

  // The options in use: after Initialize, the radii are those resolved from the features.
  const CutDetectorOptions& options() const { return options_; }
  const std::vector<FeaturePair>& pairs() const { return pairs_; }
  const std::vector<CutPoint>& polyline() const { return polyline_; }
  // Polyline with the look-ahead and border extensions at both ends; `initial_frame` selects
  // the frame-0 coordinates (for cutting the rest configuration) instead of p^t.
  std::vector<Eigen::Vector3d> ExtendedPolyline(bool initial_frame = false) const;
  int num_features() const { return static_cast<int>(initial_mm_.rows()); }
  bool alive(int feature) const { return alive_[feature] != 0; }

 private:
  void RemovePairsNear(const Eigen::Vector3d& centre_mm, int* removed);
  // Where a new cut point goes (see CutDetectorOptions::grow_at_extremities_only).
  enum class Placement { kFront, kBack, kReplace, kRefuse };
  Placement PlaceCutPoint(const CutPoint& point, const DetectionResult& result) const;
  // An outlier of this frame outside cluster_ lies within the growth radius of the lone first
  // point (frame-0 midpoint): the cut it marks still opens there.
  bool LonePointSupported(const DetectionResult& result) const;
  // The point lies within the growth radius r_pc + 1.5 r_F of the extremity (frame 0).
  bool NearExtremity(const CutPoint& point, const CutPoint& end) const;
  // The frame-0 position p0 lies within that radius of `end`.
  bool WithinGrowthRadius(const Eigen::Vector3d& p0, const CutPoint& end) const;
  // Inserts at the nearest extremity (or as placed); returns true when it went to the front.
  bool InsertCutPoint(const CutPoint& point, Placement placement);
  // Removes cluster_'s pairs from candidates_.
  void DropClusterFromCandidates();
  // Opening balance of cluster_ (see CutDetectorOptions::min_opening_balance).
  double OpeningBalance(const DetectionResult& result) const;
  // The bound it must reach: min_opening_balance, or min_opening_balance_bridges for a cluster
  // of bridges.
  double MinOpeningBalance(const DetectionResult& result) const;
  // The median over cluster_'s pairs of the relative change of their targets' distance since
  // closing_window_frames frames ago (or the first frame, if fewer); 0 in the first frame.
  double ClusterDistanceChange(const DetectionResult& result) const;
  bool ExtremityAtBorder(bool front) const;
  // The bridge of the pair (l, dead) (see CutDetectorOptions::bridge_radius_factor), -1 if none.
  int BridgeFeature(int l, int dead);
  // Features within the bridge radius of l (frame 0), nearest first; computed at first use.
  const std::vector<int>& BridgeCandidates(int l);
  // Whether the frame-0 segment [a, b] passes within r_pc of a cut point.
  bool CrossesCut(const Eigen::Vector3d& a, const Eigen::Vector3d& b) const;
  // Grid cell key of a frame-0 position (cell size r_F) and its hash.
  Eigen::Matrix<long long, 3, 1> CellKey(const Eigen::Vector3d& p0) const;
  // Calls visit(j) for every feature j in the cells within `reach` cells of `key` (per axis).
  template <typename Visit>
  void ForEachInCellsAround(const Eigen::Matrix<long long, 3, 1>& key, long long reach,
                            Visit&& visit) const {
    for (long long dx = -reach; dx <= reach; ++dx)
      for (long long dy = -reach; dy <= reach; ++dy)
        for (long long dz = -reach; dz <= reach; ++dz) {
          const Eigen::Matrix<long long, 3, 1> c = key + Eigen::Matrix<long long, 3, 1>(dx, dy, dz);
          auto range = grid_.equal_range(CellHash(c(0), c(1), c(2)));
          for (auto it = range.first; it != range.second; ++it)
            // The hash may collide: only the features of this very cell.
            if (cell_of_[it->second] == c) visit(it->second);
        }
  }
  static long long CellHash(long long x, long long y, long long z) {
    return (x * 73856093LL) ^ (y * 19349663LL) ^ (z * 83492791LL);
  }
  // Inserts a selected point at the given place and updates the look-ahead, the border state
  // and C^t (pairs crossing its r_pc sphere).
  void CommitCutPoint(const CutPoint& point, Placement placement, DetectionResult* result);
  // The border state of the extremities after a point went to the front or the back.
  void UpdateBorderState(bool front);
  // Whether the segment check (SetSegmentCheck) accepts the polyline with the point placed so;
  // true when no check is set or the point adds no segment.
  bool SegmentAccepted(const CutPoint& point, Placement placement);
  // d_l - d_m (d = p^t - p^1, eq. 7.9) and the pair's vector in the positions mu2 compares with
  // frame 0 (eq. 7.10: p^t or p^1, CutDetectorOptions::measure), this frame.
  // Inline: it is in the per-frame loop over C^t.
  void PairDifferences(int l, int m, Eigen::Vector3d* misfit, Eigen::Vector3d* span) const {
    PairDifferences(l, m, options_.measure, misfit, span);
  }
  void PairDifferences(int l, int m, CutMeasure variant, Eigen::Vector3d* misfit,
                       Eigen::Vector3d* span) const {
    const RowMatX3d& ratio_positions =
        variant == CutMeasure::kModelRegularised ? model_mm_ : target_mm_;
    *misfit = ((model_mm_.row(l) - target_mm_.row(l)) - (model_mm_.row(m) - target_mm_.row(m)))
                  .transpose();
    *span = (ratio_positions.row(l) - ratio_positions.row(m)).transpose();
  }
  // mu of the pair (l, m) from this frame's positions (eq. 7.9-7.11), with the options' variant
  // of mu2 or the one given.
  double Measure(int l, int m) const { return Measure(l, m, options_.measure); }
  double Measure(int l, int m, CutMeasure variant) const;
  // The mean of per-pair values over the pairs of C_F, or over the bridges when no pair of C_F
  // is left (bridges are up to 2 r_F long and would shift the threshold tau refers to). Only
  // values <= at_most count; *counted (when given) receives how many did.
  static double MeanOverCf(const std::vector<FeaturePair>& pairs, const std::vector<double>& values,
                           double at_most = std::numeric_limits<double>::infinity(),
                           int* counted = nullptr);
  // The fixed point m = mean{v_k : v_k <= OutlierThreshold(factor, m)} of MeanOverCf, from the
  // plain mean (CutDetectorOptions::mean_of_inliers); m only decreases, so the inliers only
  // shrink and the iteration ends.
  double MeanOfInliers(const std::vector<FeaturePair>& pairs, const std::vector<double>& values,
                       double factor) const;
  // Whether the pairs of this frame within r_F of the point (current midpoints) reach n as
  // outliers of the model-regularised measure (confirm_starts_with_model_measure). Computes
  // that measure for the frame on its first call.
  bool ConfirmedByModelMeasure(const Eigen::Vector3d& point_mm, const DetectionResult& result);
  // Inserts up to max_cut_points_per_frame points from candidates_ (clusters, their tests, the
  // polyline's growth rule, pair removal). In the bridges' pass (see bridge_radius_factor) a
  // point that would start a polyline needs n pairs counted one each, else n among its pairs
  // of C_F, or either when it would replace a lone first point.
  void InsertCutPoints(bool bridge_pass, DetectionResult* result);
  // The growth probe of an extremity (see CutDetectorOptions::probe_length_factor): evaluates
  // its pairs and fills *point when their count reaches n.
  bool ProbeGrowth(bool front, DetectionResult* result, CutPoint* point);
  // The separation test at a frame-0 point over the displacements p^1 - p^0 of the alive
  // features within separation_radius_factor * r_F of it; `along` restricts the line's direction.
  // Recorded in result->separation_tests. A test without `along` at a point already tested so
  // in this frame (the bridge pass meets the clusters the first pass refused) is answered from
  // the frame's earlier result, neither recomputed nor recorded twice.
  SeparationTestResult SeparationAt(const Eigen::Vector3d& initial_mm,
                                    const std::optional<Eigen::Vector3d>& along,
                                    DetectionResult* result) const;
  // The growth test of an extremity (kSeparationTest): the separation test over the part ahead
  // of the end of its extension, within growth_cone_deg of its last segment's direction; fills
  // *point (r_pc into that part, on the line found) when it separates.
  bool TipGrowth(bool front, DetectionResult* result, CutPoint* point);
  // The length of the extension beyond an extremity (ExtendedPolyline): the look-ahead r_pc or,
  // at the border, the border extension, whichever is longer.
  double ExtensionLength(bool at_border) const;
  // The alive features whose frame-0 positions lie within radius_mm of initial_mm.
  std::vector<int> AliveWithin(const Eigen::Vector3d& initial_mm, double radius_mm) const;
  // This frame's model position of a frame-0 point: the least-squares affine map from p^0 to p^t
  // of the alive features within r_F of it (their mean translation when fewer than 4).
  Eigen::Vector3d CurrentPosition(const Eigen::Vector3d& initial_mm) const;
  // Builds the probe's pairs, when its extremity has changed since the last build.
  void BuildProbe(bool front);
  // Fills cluster_ from candidates_ (see CutDetectorOptions::cluster_outliers).
  void SelectCluster(const DetectionResult& result);
  // When one feature is in more than 3/4 of cluster_'s pairs and their other features are
  // near their model points, removes its pairs from candidates_ and returns true (see
  // CutDetectorOptions::reject_lone_features).
  bool RemoveLoneFeature(const DetectionResult& result);
  // The feature in more than 3/4 of the pairs pair_of(0 .. num_pairs - 1) (each with .first and
  // .second feature indices) whose partners lie on average less than half as far from their
  // model points as it does; -1 if none (see CutDetectorOptions::reject_lone_features).
  template <typename PairOf>
  int LoneFeature(int num_pairs, const PairOf& pair_of);
  // The feature in more than 3/4 of the pairs pair_of(0 .. num_pairs - 1), or -1; *most (when
  // given, and num_pairs >= 2) receives the largest number of those pairs any one feature is in.
  template <typename PairOf>
  int StarHub(int num_pairs, const PairOf& pair_of, int* most = nullptr);
  // The outlier threshold max(factor * mean, min_outlier_measure_mm) [mm] (tau for C^t and its
  // model-regularised confirmation, probe_outlier_factor for the growth probe).
  double OutlierThreshold(double factor, double mean) const {
    return std::max(factor * mean, options_.min_outlier_measure_mm);
  }
  // The midpoint of features l and m in this frame's model positions p^t.
  Eigen::Vector3d CurrentMidpoint(int l, int m) const {
    return 0.5 * (model_mm_.row(l) + model_mm_.row(m)).transpose();
  }
  // Sum over `outliers` (indices into result.pairs) of min(mu / threshold, outlier_weight_cap).
  double OutlierCount(const std::vector<int>& outliers, const DetectionResult& result) const;
  // The pair's targets are farther apart than its model points (delta^1 > delta^t).
  bool Opens(const FeaturePair& p) const;

  CutDetectorOptions given_;    // as passed to the constructor
  CutDetectorOptions options_;  // given_ with the radii resolved by Initialize
  RowMatX3d initial_mm_;        // (#F x 3) p^0
  std::unordered_map<int, int> index_of_id_;
  std::vector<char> alive_;
  std::vector<char> occluded_;  // per feature, this frame (FrameFeatures::occluded)
  std::vector<FeaturePair> pairs_;
  Eigen::RowVector3d grid_origin_mm_ = Eigen::RowVector3d::Zero();
  std::unordered_multimap<long long, int> grid_;         // frame-0 positions by cell (size r_F)
  std::vector<Eigen::Matrix<long long, 3, 1>> cell_of_;  // per feature, its cell key
  std::unordered_set<long long> ever_paired_;            // PairKey of every pair C^t has held
  // Key of the pair {a, b} in ever_paired_ (independent of the feature count, which grows).
  static long long PairKey(int a, int b) {
    return (static_cast<long long>(std::min(a, b)) << 32) | std::max(a, b);
  }
  std::vector<std::vector<int>> bridge_candidates_;  // per feature, see BridgeCandidates
  std::vector<char> bridge_candidates_known_;
  std::vector<CutPoint> polyline_;  // front() and back() are the extremities
  // A probe pair: features l < m and the parameter s in [0, 1] of the crossing on their frame-0
  // segment.
  struct ProbePair {
    int first = 0;
    int second = 0;
    double s = 0.0;
    double inverse_length = 0.0;  // 1 / |p0_first - p0_second|
    double along = 0.0;           // the crossing's distance from the extremity (frame 0)
  };
  struct Probe {
    // The extremity it was built for (frame 0) and whether it was at the border then.
    Eigen::Vector3d end = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
    Eigen::Vector3d prev = end;
    bool at_border = false;
    std::vector<ProbePair> pairs;
  };
  Probe probes_[2];                                     // [0] back, [1] front
  std::vector<std::pair<int, double>> probe_outliers_;  // (index into the probe's pairs, mu)
  bool front_at_border_ = false;
  bool back_at_border_ = false;
  SegmentCheck segment_check_;
  // Points the segment check refused since the polyline last changed: (extremity, point), at
  // frame 0.
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> refused_segments_;
  int frame_ = 0;
  double threshold_ = 0.0;  // this frame's outlier threshold max(tau * mean(mu), floor) [mm]
  // The model-regularised mu of this frame's pairs and its threshold, for the start
  // confirmation; the threshold is negative until computed in the frame.
  std::vector<double> model_measure_;
  double model_threshold_ = -1.0;
  // Per-frame scratch, indexed by feature.
  std::vector<int> row_of_feature_;
  RowMatX3d model_mm_;   // (#F x 3) p^t of the alive features
  RowMatX3d target_mm_;  // (#F x 3) p^1
  // target_mm_ of the last closing_window_frames + 1 frames, frame f in slot f % size (none
  // when closing_window_frames is 0).
  std::vector<RowMatX3d> target_history_;
  std::vector<int> candidates_;
  std::vector<int> cluster_;
  std::vector<int> cluster_of_cf_;  // cluster_ without its bridges
  std::vector<int> cluster_count_;  // per feature: pairs of cluster_ it is in (0 between uses)
  // This frame's separation tests without a direction, by point (SeparationAt).
  mutable std::vector<std::pair<Eigen::Vector3d, SeparationTestResult>> undirected_tests_;
};

}  // namespace arreg::cutting
