#include "cutting/detection.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <iterator>
#include <string>
#include <utility>

#include "core/error.h"

namespace arreg::cutting {

namespace {

constexpr double kPi = 3.14159265358979323846;

// Squared distance from c to the segment [a, b].
double SquaredDistanceToSegment(const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a;
  const double len2 = ab.squaredNorm();
  double s = len2 > 0.0 ? (c - a).dot(ab) / len2 : 0.0;
  s = std::clamp(s, 0.0, 1.0);
  return (a + s * ab - c).squaredNorm();
}

// C^t is kept sorted by (first, second).
bool PairLess(const FeaturePair& a, const FeaturePair& b) {
  return a.first != b.first ? a.first < b.first : a.second < b.second;
}

}  // namespace

double MedianKthNeighbourDistance(const RowMatX3d& points_mm, int k) {
  constexpr int kMaxSamples = 1000;
  const int n = static_cast<int>(points_mm.rows());
  if (n < 2) return 0.0;
  k = std::min(k, n - 1);
  const int stride = (n + kMaxSamples - 1) / kMaxSamples;
  std::vector<double> kth, distances(n - 1);
  for (int i = 0; i < n; i += stride) {
    int c = 0;
    for (int j = 0; j < n; ++j)
      if (j != i) distances[c++] = (points_mm.row(i) - points_mm.row(j)).squaredNorm();
    std::nth_element(distances.begin(), distances.begin() + (k - 1), distances.end());
    kth.push_back(distances[k - 1]);
  }
  const auto mid = kth.begin() + kth.size() / 2;
  std::nth_element(kth.begin(), mid, kth.end());
  return std::sqrt(*mid);
}

void CutDetectorOptions::Check() const {
  auto positive = [](double v) { return std::isfinite(v) && v > 0.0; };
  ARREG_CHECK_INPUT(positive(neighbour_radius_mm), "", "cutting.neighbour_radius_mm",
                    "must be > 0, got ", neighbour_radius_mm);
  ARREG_CHECK_INPUT(positive(outlier_factor), "", "cutting.outlier_factor", "must be > 0, got ",
                    outlier_factor);
  ARREG_CHECK_INPUT(min_outliers >= 1, "", "cutting.min_outliers", "must be >= 1, got ",
                    min_outliers);
  ARREG_CHECK_INPUT(std::isfinite(outlier_weight_cap) && outlier_weight_cap >= 1.0, "",
                    "cutting.outlier_weight_cap", "must be >= 1, got ", outlier_weight_cap);
  ARREG_CHECK_INPUT(neighbours_per_feature >= 0, "", "cutting.neighbours_per_feature",
                    "must be >= 0 (0: use neighbour_radius_mm), got ", neighbours_per_feature);
  ARREG_CHECK_INPUT(positive(cut_point_radius_mm), "", "cutting.cut_point_radius_mm",
                    "must be > 0, got ", cut_point_radius_mm);
  ARREG_CHECK_INPUT(std::isfinite(min_outlier_measure_mm) && min_outlier_measure_mm >= 0.0, "",
                    "cutting.min_outlier_measure_mm", "must be >= 0, got ", min_outlier_measure_mm);
  ARREG_CHECK_INPUT(std::isfinite(boundary_extension_mm) && boundary_extension_mm >= 0.0, "",
                    "CutDetectorOptions.boundary_extension_mm", "must be >= 0, got ",
                    boundary_extension_mm);
  const auto check_cone = [](double degrees, const char* field) {
    ARREG_CHECK_INPUT(degrees > 0.0 && degrees < 90.0, "", field, "must be in (0, 90), got ",
                      degrees);
  };
  check_cone(boundary_cone_half_angle_deg, "CutDetectorOptions.boundary_cone_half_angle_deg");
  ARREG_CHECK_INPUT(closing_window_frames >= 0, "", "cutting.closing_window_frames",
                    "must be >= 0, got ", closing_window_frames);
  ARREG_CHECK_INPUT(std::isfinite(max_closing_fraction) && max_closing_fraction >= 0.0, "",
                    "cutting.max_closing_fraction", "must be >= 0, got ", max_closing_fraction);
  ARREG_CHECK_INPUT(std::isfinite(min_opening_balance) && min_opening_balance >= 0.0 &&
                        min_opening_balance <= 1.0,
                    "", "cutting.min_opening_balance", "must be in [0, 1], got ",
                    min_opening_balance);
  ARREG_CHECK_INPUT(std::isfinite(min_opening_balance_bridges) &&
                        min_opening_balance_bridges >= 0.0 && min_opening_balance_bridges <= 1.0,
                    "", "cutting.min_opening_balance_bridges", "must be in [0, 1], got ",
                    min_opening_balance_bridges);
  ARREG_CHECK_INPUT(std::isfinite(min_lone_growth_balance) && min_lone_growth_balance >= -1.0 &&
                        min_lone_growth_balance <= 1.0,
                    "", "cutting.min_lone_growth_balance", "must be in [-1, 1], got ",
                    min_lone_growth_balance);
  ARREG_CHECK_INPUT(std::isfinite(bridge_radius_factor) && bridge_radius_factor >= 0.0, "",
                    "cutting.bridge_radius_factor", "must be >= 0 (0: no bridges), got ",
                    bridge_radius_factor);
  check_cone(bridge_cone_half_angle_deg, "cutting.bridge_cone_half_angle_deg");
  ARREG_CHECK_INPUT(max_cut_points_per_frame >= 1, "",
                    "CutDetectorOptions.max_cut_points_per_frame", "must be >= 1, got ",
                    max_cut_points_per_frame);
  ARREG_CHECK_INPUT(std::isfinite(probe_length_factor) && probe_length_factor >= 0.0, "",
                    "cutting.probe_length_factor", "must be >= 0 (0: no probe), got ",
                    probe_length_factor);
  ARREG_CHECK_INPUT(positive(probe_pair_length_factor), "", "cutting.probe_pair_length_factor",
                    "must be > 0, got ", probe_pair_length_factor);
  ARREG_CHECK_INPUT(positive(probe_outlier_factor), "", "cutting.probe_outlier_factor",
                    "must be > 0, got ", probe_outlier_factor);
  separation.Check();
  ARREG_CHECK_INPUT(positive(separation_radius_factor), "", "cutting.separation_radius_factor",
                    "must be > 0, got ", separation_radius_factor);
  ARREG_CHECK_INPUT(growth_cone_deg > 0.0 && growth_cone_deg <= 90.0, "", "cutting.growth_cone_deg",
                    "must be in (0, 90], got ", growth_cone_deg);
  ARREG_CHECK_INPUT(positive(probe_max_lead_factor), "", "cutting.probe_max_lead_factor",
                    "must be > 0, got ", probe_max_lead_factor);
}

CutDetector::CutDetector(const CutDetectorOptions& options) : given_(options), options_(options) {
  options_.Check();
}

void CutDetector::Initialize(const RowMatX3d& initial_positions_mm, const std::vector<int>& ids) {
  const int n = static_cast<int>(initial_positions_mm.rows());
  ARREG_CHECK_INPUT(static_cast<int>(ids.size()) == n, "", "CutDetector::Initialize", "ids has ",
                    ids.size(), " entries for ", n, " positions");
  ARREG_CHECK_INPUT(initial_positions_mm.allFinite(), "", "CutDetector::Initialize",
                    "initial positions must be finite");
  initial_mm_ = initial_positions_mm;
  options_ = given_;
  if (given_.neighbours_per_feature > 0) {
    // The k-th neighbour itself must pass the strict test |p0_l - p0_m| < r_F.
    const double radius_mm =
        (1.0 + 1e-9) * MedianKthNeighbourDistance(initial_mm_, given_.neighbours_per_feature);
    if (radius_mm > 0.0) {
      const double scale = radius_mm / given_.neighbour_radius_mm;
      options_.neighbour_radius_mm = radius_mm;
      options_.cut_point_radius_mm *= scale;
      options_.boundary_extension_mm *= scale;
    }
  }
  index_of_id_.clear();
  index_of_id_.reserve(2 * static_cast<size_t>(n));
  for (int i = 0; i < n; ++i) {
    const bool inserted = index_of_id_.emplace(ids[i], i).second;
    ARREG_CHECK_INPUT(inserted, "", "CutDetector::Initialize", "feature id ", ids[i],
                      " appears twice");
  }
  alive_.assign(n, 1);
  polyline_.clear();
  refused_segments_.clear();
  for (Probe& probe : probes_) probe = Probe();
  front_at_border_ = back_at_border_ = false;
  frame_ = 0;
  row_of_feature_.assign(n, -1);
  cluster_count_.assign(n, 0);
  bridge_candidates_.assign(n, {});
  bridge_candidates_known_.assign(n, 0);
  model_mm_.setZero(n, 3);
  target_mm_.setZero(n, 3);
  // No history without the closing rule: nothing reads it.
  target_history_.assign(
      options_.closing_window_frames > 0 ? options_.closing_window_frames + 1 : 0, RowMatX3d());

  // Uniform grid with cell size r_F: neighbours lie in the 27 surrounding cells.
  pairs_.clear();
  grid_.clear();
  cell_of_.clear();
  ever_paired_.clear();
  if (n == 0) return;
  const double r2 = options_.neighbour_radius_mm * options_.neighbour_radius_mm;
  grid_origin_mm_ = initial_mm_.colwise().minCoeff();
  std::vector<Eigen::Matrix<long long, 3, 1>>& key = cell_of_;
  key.resize(n);
  grid_.reserve(2 * static_cast<size_t>(n));
  for (int i = 0; i < n; ++i) {
    key[i] = CellKey(initial_mm_.row(i).transpose());
    grid_.emplace(CellHash(key[i](0), key[i](1), key[i](2)), i);
  }
  for (int i = 0; i < n; ++i)
    ForEachInCellsAround(key[i], 1, [&](int j) {
      if (j > i && (initial_mm_.row(i) - initial_mm_.row(j)).squaredNorm() < r2)
        pairs_.push_back({i, j});
    });
  ever_paired_.reserve(2 * pairs_.size());
  for (const FeaturePair& p : pairs_) ever_paired_.insert(PairKey(p.first, p.second));
  std::sort(pairs_.begin(), pairs_.end(), PairLess);
}

void CutDetector::AddFeatures(const RowMatX3d& rest_positions_mm, const std::vector<int>& ids) {
  const int added = static_cast<int>(rest_positions_mm.rows());
  ARREG_CHECK_INPUT(static_cast<int>(ids.size()) == added, "", "CutDetector::AddFeatures",
                    "ids has ", ids.size(), " entries for ", added, " positions");
  ARREG_CHECK_INPUT(rest_positions_mm.allFinite(), "", "CutDetector::AddFeatures",
                    "rest positions must be finite");
  if (added == 0) return;
  const int old_n = num_features(), n = old_n + added;
  std::unordered_set<int> fresh;
  for (int id : ids)
    ARREG_CHECK_INPUT(!index_of_id_.count(id) && fresh.insert(id).second, "",
                      "CutDetector::AddFeatures", "feature id ", id, " is already known");
  for (int i = 0; i < added; ++i) index_of_id_.emplace(ids[i], old_n + i);
  initial_mm_.conservativeResize(n, 3);
  initial_mm_.bottomRows(added) = rest_positions_mm;
  alive_.resize(n, 1);
  row_of_feature_.resize(n, -1);
  cluster_count_.resize(n, 0);
  bridge_candidates_.resize(n);
  // Lists of nearby features are cached: the new ones belong in them.
  bridge_candidates_known_.assign(n, 0);
  for (RowMatX3d* m : {&model_mm_, &target_mm_}) {
    m->conservativeResize(n, 3);
    m->bottomRows(added).setZero();
  }
  for (RowMatX3d& past : target_history_)
    if (past.rows() > 0) {
      past.conservativeResize(n, 3);
      past.bottomRows(added).setConstant(std::numeric_limits<double>::quiet_NaN());
    }
  if (old_n == 0) grid_origin_mm_ = initial_mm_.colwise().minCoeff();
  cell_of_.resize(n);
  for (int i = old_n; i < n; ++i) {
    cell_of_[i] = CellKey(initial_mm_.row(i).transpose());
    grid_.emplace(CellHash(cell_of_[i](0), cell_of_[i](1), cell_of_[i](2)), i);
  }
  const double r2 = options_.neighbour_radius_mm * options_.neighbour_radius_mm;
  const size_t kept = pairs_.size();
  for (int i = old_n; i < n; ++i) {
    const Eigen::Vector3d pi = initial_mm_.row(i).transpose();
    ForEachInCellsAround(cell_of_[i], 1, [&](int j) {
      // New-new pairs once (j < i).
      if (j == i || (j >= old_n && j > i) || !alive_[j]) return;
      const Eigen::Vector3d pj = initial_mm_.row(j).transpose();
      if ((pi - pj).squaredNorm() >= r2 || CrossesCut(pi, pj)) return;
      pairs_.push_back({std::min(i, j), std::max(i, j)});
      ever_paired_.insert(PairKey(i, j));
    });
  }
  std::sort(pairs_.begin() + kept, pairs_.end(), PairLess);
  std::inplace_merge(pairs_.begin(), pairs_.begin() + kept, pairs_.end(), PairLess);
}

bool CutDetector::CrossesCut(const Eigen::Vector3d& a, const Eigen::Vector3d& b) const {
  const double r_pc2 = options_.cut_point_radius_mm * options_.cut_point_radius_mm;
  for (const CutPoint& q : polyline_)
    if (SquaredDistanceToSegment(a, b, q.initial_position_mm) < r_pc2) return true;
  return false;
}

Eigen::Matrix<long long, 3, 1> CutDetector::CellKey(const Eigen::Vector3d& p0) const {
  const double cell = options_.neighbour_radius_mm;
  Eigen::Matrix<long long, 3, 1> key;
  for (int k = 0; k < 3; ++k)
    key(k) = static_cast<long long>(std::floor((p0(k) - grid_origin_mm_(k)) / cell));
  return key;
}

const std::vector<int>& CutDetector::BridgeCandidates(int l) {
  std::vector<int>& list = bridge_candidates_[l];
  if (bridge_candidates_known_[l]) return list;
  bridge_candidates_known_[l] = 1;
  const double radius = options_.bridge_radius_factor * options_.neighbour_radius_mm;
  const Eigen::RowVector3d pl = initial_mm_.row(l);
  const long long reach = static_cast<long long>(std::ceil(options_.bridge_radius_factor));
  const Eigen::Matrix<long long, 3, 1> key = CellKey(pl.transpose());
  std::vector<std::pair<double, int>> found;
  ForEachInCellsAround(key, reach, [&](int m) {
    const double d2 = (initial_mm_.row(m) - pl).squaredNorm();
    if (m != l && d2 > 0.0 && d2 < radius * radius) found.emplace_back(d2, m);
  });
  // Nearest first, ties to the lower index: the result does not depend on the grid's order.
  std::sort(found.begin(), found.end());
  list.reserve(found.size());
  for (const auto& [d2, m] : found) list.push_back(m);
  return list;
}

int CutDetector::BridgeFeature(int l, int dead) {
  const Eigen::Vector3d pl = initial_mm_.row(l).transpose();
  const Eigen::Vector3d towards = initial_mm_.row(dead).transpose() - pl;
  const double towards_norm = towards.norm();
  if (options_.bridge_radius_factor <= 0.0 || towards_norm == 0.0) return -1;
  const double cos_cone = std::cos(options_.bridge_cone_half_angle_deg * kPi / 180.0);
  for (int m : BridgeCandidates(l)) {
    if (!alive_[m]) continue;
    const Eigen::Vector3d v = initial_mm_.row(m).transpose() - pl;
    if (v.dot(towards) < cos_cone * v.norm() * towards_norm) continue;
    if (ever_paired_.count(PairKey(l, m))) continue;
    if (!CrossesCut(pl, initial_mm_.row(m).transpose())) return m;
  }
  return -1;
}

void CutDetector::Update(const FrameFeatures& frame, DetectionResult* result) {
  ARREG_ASSERT(result != nullptr, "");
  const int n = num_features();
  const int rows = static_cast<int>(frame.ids.size());
  const std::string where = "frame " + std::to_string(frame_);
  ARREG_CHECK_INPUT(frame.target_mm.rows() == rows && frame.model_mm.rows() == rows, "", where,
                    "target (", frame.target_mm.rows(), ") and model (", frame.model_mm.rows(),
                    ") rows must match the ", rows, " ids");

  ARREG_CHECK_INPUT(frame.occluded.empty() || static_cast<int>(frame.occluded.size()) == rows, "",
                    where, "occluded (", frame.occluded.size(), ") must be empty or match the ",
                    rows, " ids");
  // Map this frame's rows to features; features not listed die.
  std::fill(row_of_feature_.begin(), row_of_feature_.end(), -1);
  occluded_.assign(n, 0);
  for (int r = 0; r < rows; ++r) {
    const auto it = index_of_id_.find(frame.ids[r]);
    ARREG_CHECK_INPUT(it != index_of_id_.end(), "", where, "unknown feature id ", frame.ids[r]);
    const int f = it->second;
    ARREG_CHECK_INPUT(row_of_feature_[f] < 0, "", where, "feature id ", frame.ids[r],
                      " appears twice");
    ARREG_CHECK_INPUT(alive_[f], "", where, "feature id ", frame.ids[r],
                      " was lost in an earlier frame and cannot come back");
    row_of_feature_[f] = r;
    if (!frame.occluded.empty()) occluded_[f] = frame.occluded[r];
    model_mm_.row(f) = frame.model_mm.row(r);
    target_mm_.row(f) = frame.target_mm.row(r);
  }
  bool any_died = false;
  for (int f = 0; f < n; ++f)
    if (alive_[f] && row_of_feature_[f] < 0) {
      alive_[f] = 0;
      any_died = true;
    }
  if (!target_history_.empty()) target_history_[frame_ % target_history_.size()] = target_mm_;

  result->frame = frame_;
  result->new_cut_points.clear();
  result->outliers.clear();
  result->pairs_removed_by_cut = 0;
  result->lone_features = 0;
  result->one_sided_clusters = 0;
  result->star_starts = 0;
  result->unconfirmed_starts = 0;
  result->closing_starts = 0;
  result->refused_points = 0;
  result->refused_segments = 0;
  result->pairs_removed_by_death = 0;
  result->segment_added = false;
  result->look_ahead_mm.reset();
  result->pairs_bridged = 0;
  result->probe_pairs = 0;
  result->probe_outliers = 0;
  result->separation_tests.clear();
  undirected_tests_.clear();
  result->not_separated = 0;
  if (any_died) {
    // (alive feature, dead neighbour) of the pairs that die, for their bridges.
    std::vector<std::pair<int, int>> lost;
    if (options_.bridge_radius_factor > 0.0)
      for (const FeaturePair& p : pairs_)
        if (alive_[p.first] != alive_[p.second])
          lost.emplace_back(alive_[p.first] ? p.first : p.second,
                            alive_[p.first] ? p.second : p.first);
    const size_t before = pairs_.size();
    pairs_.erase(
        std::remove_if(pairs_.begin(), pairs_.end(),
                       [&](const FeaturePair& p) { return !alive_[p.first] || !alive_[p.second]; }),
        pairs_.end());
    result->pairs_removed_by_death = static_cast<int>(before - pairs_.size());
    const size_t kept = pairs_.size();
    for (const auto& [l, dead] : lost) {
      const int m = BridgeFeature(l, dead);
      if (m < 0) continue;
      const FeaturePair bridge{std::min(l, m), std::max(l, m), true};
      ever_paired_.insert(PairKey(l, m));
      pairs_.push_back(bridge);
      ++result->pairs_bridged;
    }
    // Sorted kept pairs, then the few bridges: sort these and merge (linear in #pairs).
    std::sort(pairs_.begin() + kept, pairs_.end(), PairLess);
    std::inplace_merge(pairs_.begin(), pairs_.begin() + kept, pairs_.end(), PairLess);
  }

  // mu_lm = |d_l - d_m| * delta_lm / delta^0_lm with d = p^t - p^1 (eq. 7.9-7.11).
  const int num_pairs = static_cast<int>(pairs_.size());
  result->pairs.assign(pairs_.begin(), pairs_.end());
  result->measure.resize(num_pairs);
  for (int k = 0; k < num_pairs; ++k)
    result->measure[k] = Measure(pairs_[k].first, pairs_[k].second);
  const double mean = options_.mean_of_inliers
                          ? MeanOfInliers(pairs_, result->measure, options_.outlier_factor)
                          : MeanOverCf(pairs_, result->measure);
  result->mean_measure = mean;
  model_threshold_ = -1.0;  // the model-regularised measure is computed when a start asks
  threshold_ = OutlierThreshold(options_.outlier_factor, mean);
  for (int k = 0; k < num_pairs; ++k) {
    if (result->measure[k] <= threshold_) continue;
    if (options_.require_opening && !Opens(pairs_[k])) continue;
    if (options_.ignore_occluded_pairs &&
        (occluded_[pairs_[k].first] || occluded_[pairs_[k].second]))
      continue;
    result->outliers.push_back(k);
  }

  // Cut points: the mean stays that of the frame while further points are inserted, and only the
  // pairs still present count (removed ones were pruned around earlier points).
  // Bridges continue a cut. Before the first point they are no candidates, except in a second
  // pass of a frame where the pairs of C_F started nothing: there a point needs n pairs in its
  // cluster, bridges included (see bridge_radius_factor).
  // The bridges' pass meets the clusters the first pass rejected again: each rejection count
  // of the frame is the larger of the two passes', so that a cluster is counted once.
  const bool starting = polyline_.empty();
  int* const rejections[] = {&result->lone_features,  &result->one_sided_clusters,
                             &result->star_starts,    &result->unconfirmed_starts,
                             &result->closing_starts, &result->refused_points};
  constexpr int kRejections = static_cast<int>(std::size(rejections));
  std::array<int, kRejections> first_pass{};
  for (int pass = 0; pass < (starting ? 2 : 1) && result->new_cut_points.empty(); ++pass) {
    const bool bridge_pass = pass == 1;
    if (bridge_pass)
      for (int c = 0; c < kRejections; ++c) first_pass[c] = std::exchange(*rejections[c], 0);
    candidates_ = result->outliers;
    if (starting && !bridge_pass)
      candidates_.erase(std::remove_if(candidates_.begin(), candidates_.end(),
                                       [&](int k) { return result->pairs[k].bridge; }),
                        candidates_.end());
    InsertCutPoints(bridge_pass, result);
    if (bridge_pass)
      for (int c = 0; c < kRejections; ++c)
        *rejections[c] = std::max(*rejections[c], first_pass[c]);
  }

  // The growth probe, when C^t inserted nothing: the back extremity first, then the front.
  if (result->new_cut_points.empty() && options_.probe_length_factor > 0.0 &&
      polyline_.size() >= 2) {
    for (const bool front : {false, true}) {
      CutPoint point;
      const bool found = options_.decision == CutDecision::kRules
                             ? ProbeGrowth(front, result, &point)
                             : TipGrowth(front, result, &point);
      if (!found) continue;
      const Placement placement = front ? Placement::kFront : Placement::kBack;
      if (!SegmentAccepted(point, placement)) {
        ++result->refused_segments;
        continue;
      }
      CommitCutPoint(point, placement, result);
      break;
    }
  }

  result->polyline_mm.clear();
  for (const CutPoint& p : polyline_) result->polyline_mm.push_back(p.position_mm);
  result->extended_polyline_mm = ExtendedPolyline(false);
  ++frame_;
}

void CutDetector::InsertCutPoints(bool bridge_pass, DetectionResult* result) {
  const bool rules = options_.decision == CutDecision::kRules;
  for (int inserted = 0; inserted < options_.max_cut_points_per_frame; ++inserted) {
    // Select a cluster and its point; clusters rejected as one feature's star, as one-sided or
    // as no growth of the polyline leave the candidates and the next one is tried.
    CutPoint point;
    Placement placement = Placement::kRefuse;
    while (placement == Placement::kRefuse) {
      if (OutlierCount(candidates_, *result) < options_.min_outliers) break;
      if (options_.cluster_outliers) {
        SelectCluster(*result);
        while (rules && options_.reject_lone_features &&
               OutlierCount(cluster_, *result) >= options_.min_outliers &&
               RemoveLoneFeature(*result)) {
          ++result->lone_features;
          SelectCluster(*result);
        }
        if (OutlierCount(cluster_, *result) < options_.min_outliers) break;
      } else {
        cluster_ = candidates_;
      }
      Eigen::Vector3d current = Eigen::Vector3d::Zero(), initial = Eigen::Vector3d::Zero();
      double weight = 0.0;
      for (int k : cluster_) {
        const int l = result->pairs[k].first, m = result->pairs[k].second;
        const double w = result->measure[k];
        current += w * CurrentMidpoint(l, m);
        initial += w * 0.5 * (initial_mm_.row(l) + initial_mm_.row(m)).transpose();
        weight += w;
      }
      point.position_mm = current / weight;
      point.initial_position_mm = initial / weight;
      point.frame = frame_;
      point.num_outliers = static_cast<int>(cluster_.size());
      // Only a point that would start a polyline must show both lips: one that grows it is
      // corroborated by the cut point next to it, behind which the model may already be cut
      // (pairs from the cut part to the whole part ahead are one-sided by construction).
      const bool grows = !polyline_.empty() && (NearExtremity(point, polyline_.front()) ||
                                                NearExtremity(point, polyline_.back()));
      // A point that would start a polyline needs n among its cluster's pairs of C_F (weighted as
      // any count); in the bridges' pass, n pairs, bridges included, counted one each as in the
      // thesis (see bridge_radius_factor). One that would replace a lone first point (nothing is
      // cut yet) may have either: the tracker may lose the lips beyond that point too widely for
      // bridges, and the bridges farther along the cut are then no growth of it.
      if (!grows) {
        bool enough = false;
        if (bridge_pass) {
          enough = static_cast<int>(cluster_.size()) >= options_.min_outliers;
        } else {
          cluster_of_cf_.clear();
          for (int k : cluster_)
            if (!result->pairs[k].bridge) cluster_of_cf_.push_back(k);
          enough =
              OutlierCount(cluster_of_cf_, *result) >= options_.min_outliers ||
              (polyline_.size() == 1 && static_cast<int>(cluster_.size()) >= options_.min_outliers);
        }
        if (!enough) {
          ++result->refused_points;
          DropClusterFromCandidates();
          continue;
        }
      }
      if (!rules) {
        // One decision for starts and growth: does the misfit around the point jump across a
        // line? (The rules below are not asked.)
        const SeparationTestResult test =
            SeparationAt(point.initial_position_mm, std::nullopt, result);
        if (!test.separated) {
          ++result->not_separated;
          DropClusterFromCandidates();
          continue;
        }
      } else if (options_.confirm_starts_with_model_measure &&
                 options_.measure == CutMeasure::kImageOnly && !grows &&
                 !ConfirmedByModelMeasure(point.position_mm, *result)) {
        ++result->unconfirmed_starts;
        DropClusterFromCandidates();
        continue;
      }
      if (rules && options_.closing_window_frames > 0 && !grows &&
          ClusterDistanceChange(*result) < -options_.max_closing_fraction) {
        ++result->closing_starts;
        DropClusterFromCandidates();
        continue;
      }
      if (rules && options_.cluster_outliers && options_.min_opening_balance > 0.0 && !grows &&
          OpeningBalance(*result) < MinOpeningBalance(*result)) {
        ++result->one_sided_clusters;
        DropClusterFromCandidates();
        continue;
      }
      // A lone point's growth (nothing is cut yet) must not close one lip (on the whole, one
      // side's targets inward of their model points): that is a strain concentration, and the
      // lone point beside it is taken as its work and dropped.
      if (rules && options_.cluster_outliers && grows && polyline_.size() == 1 &&
          OpeningBalance(*result) <= options_.min_lone_growth_balance) {
        ++result->one_sided_clusters;
        DropClusterFromCandidates();
        polyline_.clear();
        continue;
      }
      if (rules && options_.cluster_outliers && options_.reject_star_starts && !grows &&
          StarHub(static_cast<int>(cluster_.size()),
                  [&](int i) -> const FeaturePair& { return result->pairs[cluster_[i]]; }) >= 0) {
        ++result->star_starts;
        DropClusterFromCandidates();
        continue;
      }
      placement = PlaceCutPoint(point, *result);
      if (placement == Placement::kRefuse) {
        ++result->refused_points;
        DropClusterFromCandidates();
      } else if (!SegmentAccepted(point, placement)) {
        placement = Placement::kRefuse;
        ++result->refused_segments;
        DropClusterFromCandidates();
      }
    }
    if (placement == Placement::kRefuse) break;
    CommitCutPoint(point, placement, result);
    // The outliers that made the point are explained by it: without their removal, a cluster
    // whose pairs pass outside the r_pc sphere would insert the same point again next frame.
    if (options_.cluster_outliers) {
      for (int k : cluster_) {
        const FeaturePair& p = result->pairs[k];
        const auto it = std::lower_bound(pairs_.begin(), pairs_.end(), p, PairLess);
        if (it != pairs_.end() && it->first == p.first && it->second == p.second) {
          pairs_.erase(it);
          ++result->pairs_removed_by_cut;
        }
      }
      DropClusterFromCandidates();
    }
    // Outliers whose pair has just been removed no longer count.
    candidates_.erase(
        std::remove_if(candidates_.begin(), candidates_.end(),
                       [&](int k) {
                         const FeaturePair& p = result->pairs[k];
                         return SquaredDistanceToSegment(model_mm_.row(p.first).transpose(),
                                                         model_mm_.row(p.second).transpose(),
                                                         point.position_mm) <
                                options_.cut_point_radius_mm * options_.cut_point_radius_mm;
                       }),
        candidates_.end());
  }
}

double CutDetector::MeanOverCf(const std::vector<FeaturePair>& pairs,
                               const std::vector<double>& values, double at_most, int* counted) {
  double sum = 0.0, bridge_sum = 0.0;
  int of_cf = 0, bridges = 0;
  for (size_t k = 0; k < pairs.size(); ++k) {
    if (values[k] > at_most) continue;
    if (pairs[k].bridge) {
      bridge_sum += values[k];
      ++bridges;
    } else {
      sum += values[k];
      ++of_cf;
    }
  }
  if (counted) *counted = of_cf + bridges;
  return of_cf > 0 ? sum / of_cf : (bridges > 0 ? bridge_sum / bridges : 0.0);
}

double CutDetector::MeanOfInliers(const std::vector<FeaturePair>& pairs,
                                  const std::vector<double>& values, double factor) const {
  double mean = MeanOverCf(pairs, values);
  int inliers = static_cast<int>(pairs.size());
  for (;;) {
    int kept = 0;
    const double next = MeanOverCf(pairs, values, OutlierThreshold(factor, mean), &kept);
    if (kept == inliers || kept == 0) return mean;
    inliers = kept;
    mean = next;
  }
}

bool CutDetector::ConfirmedByModelMeasure(const Eigen::Vector3d& point_mm,
                                          const DetectionResult& result) {
  const std::vector<FeaturePair>& pairs = result.pairs;
  if (model_threshold_ < 0.0) {
    model_measure_.resize(pairs.size());
    for (size_t k = 0; k < pairs.size(); ++k)
      model_measure_[k] = Measure(pairs[k].first, pairs[k].second, CutMeasure::kModelRegularised);
    model_threshold_ = OutlierThreshold(options_.outlier_factor, MeanOverCf(pairs, model_measure_));
  }
  const double r2 = options_.neighbour_radius_mm * options_.neighbour_radius_mm;
  double count = 0.0;
  for (size_t k = 0; k < pairs.size(); ++k) {
    if (model_measure_[k] <= model_threshold_) continue;
    const FeaturePair& p = pairs[k];
    if (options_.require_opening && !Opens(p)) continue;
    if ((CurrentMidpoint(p.first, p.second) - point_mm).squaredNorm() > r2) continue;
    count += std::min(model_measure_[k] / model_threshold_, options_.outlier_weight_cap);
  }
  return count >= options_.min_outliers;
}

double CutDetector::Measure(int l, int m, CutMeasure variant) const {
  Eigen::Vector3d misfit, span;
  PairDifferences(l, m, variant, &misfit, &span);
  // mu1 * delta / delta0 under one square root (the measure of every pair, every frame).
  const double delta0_2 = (initial_mm_.row(l) - initial_mm_.row(m)).squaredNorm();
  // Coincident initial features carry no length information; treat them as unstretched.
  if (delta0_2 == 0.0) return misfit.norm();
  return std::sqrt(misfit.squaredNorm() * span.squaredNorm() / delta0_2);
}

void CutDetector::CommitCutPoint(const CutPoint& point, Placement placement,
                                 DetectionResult* result) {
  const bool front = InsertCutPoint(point, placement);
  refused_segments_.clear();
  result->new_cut_points.push_back(point);
  if (polyline_.size() >= 2) {
    result->segment_added = true;
    const CutPoint& end = front ? polyline_[0] : polyline_.back();
    const CutPoint& prev = front ? polyline_[1] : polyline_[polyline_.size() - 2];
    const Eigen::Vector3d dir = end.position_mm - prev.position_mm;
    if (options_.look_ahead && dir.norm() > 0.0)
      result->look_ahead_mm = end.position_mm + options_.cut_point_radius_mm * dir.normalized();
    UpdateBorderState(front);
  }
  RemovePairsNear(point.position_mm, &result->pairs_removed_by_cut);
}

void CutDetector::UpdateBorderState(bool front) {
  if (polyline_.size() == 2) {
    front_at_border_ = ExtremityAtBorder(true);
    back_at_border_ = ExtremityAtBorder(false);
  } else if (front) {
    front_at_border_ = ExtremityAtBorder(true);
  } else {
    back_at_border_ = ExtremityAtBorder(false);
  }
}

bool CutDetector::SegmentAccepted(const CutPoint& point, Placement placement) {
  if (!segment_check_ || polyline_.empty() || placement == Placement::kReplace) return true;
  // The extremity it joins (InsertCutPoint puts a point beside a lone one at the back).
  const bool front = placement == Placement::kFront && polyline_.size() >= 2;
  const Eigen::Vector3d end = (front ? polyline_.front() : polyline_.back()).initial_position_mm;
  const double r_pc2 = options_.cut_point_radius_mm * options_.cut_point_radius_mm;
  for (const auto& [extremity, refused] : refused_segments_)
    if (extremity == end && (refused - point.initial_position_mm).squaredNorm() < r_pc2)
      return false;
  // Tried on the polyline as it would be, then restored.
  const std::vector<CutPoint> polyline = polyline_;
  const bool front_at_border = front_at_border_, back_at_border = back_at_border_;
  UpdateBorderState(InsertCutPoint(point, placement));
  const bool accepted = segment_check_(ExtendedPolyline(false), ExtendedPolyline(true));
  polyline_ = polyline;
  front_at_border_ = front_at_border;
  back_at_border_ = back_at_border;
  if (!accepted) refused_segments_.emplace_back(end, point.initial_position_mm);
  return accepted;
}

void CutDetector::BuildProbe(bool front) {
  Probe& probe = probes_[front ? 1 : 0];
  const size_t last = polyline_.size() - 1;
  const Eigen::Vector3d end = polyline_[front ? 0 : last].initial_position_mm;
  const Eigen::Vector3d prev = polyline_[front ? 1 : last - 1].initial_position_mm;
  const bool at_border = front ? front_at_border_ : back_at_border_;
  if (end == probe.end && prev == probe.prev && at_border == probe.at_border) return;
  probe.end = end;
  probe.prev = prev;
  probe.at_border = at_border;
  probe.pairs.clear();
  const double r_f = options_.neighbour_radius_mm;
  const double r_pc = options_.cut_point_radius_mm;
  Eigen::Vector3d dir = end - prev;
  if (dir.norm() == 0.0) return;
  dir.normalize();
  // From the end of the extension (ExtendedPolyline): S reaches that far already. An extremity
  // found at the border is probed too: the border test sees the alive features only, and
  // beyond a real border no pair crosses the probe.
  const double extension = ExtensionLength(at_border);
  const Eigen::Vector3d origin = end + extension * dir;
  const double length = options_.probe_length_factor * r_f;
  const Eigen::Vector3d tip = origin + length * dir;

  // Local surface normal: the least principal direction of the frame-0 features (alive or not)
  // within r_F of the probe's origin, or of 2 r_F when fewer than 3 are that close.
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();
  for (const double radius : {r_f, 2.0 * r_f}) {
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    Eigen::Matrix3d second = Eigen::Matrix3d::Zero();
    int count = 0;
    for (int f = 0; f < num_features(); ++f) {
      const Eigen::Vector3d p = initial_mm_.row(f).transpose() - origin;
      if (p.squaredNorm() >= radius * radius) continue;
      mean += p;
      second += p * p.transpose();
      ++count;
    }
    if (count < 3) continue;
    mean /= count;
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(second / count -
                                                               mean * mean.transpose());
    normal = eigen.eigenvectors().col(0);
    break;
  }
  normal -= normal.dot(dir) * dir;
  if (normal.norm() < 1e-6) return;
  normal.normalize();
  const Eigen::Vector3d across = dir.cross(normal);

  // Frame-0 coordinates (along, across, normal) relative to the origin; the polyline's in the
  // probe's plane.
  const auto frame = [&](const Eigen::Vector3d& p) {
    const Eigen::Vector3d r = p - origin;
    return Eigen::Vector3d(r.dot(dir), r.dot(across), r.dot(normal));
  };
  const auto cross2 = [](double ax, double ay, double bx, double by) { return ax * by - ay * bx; };
  // The open segments ab and cd (plane coordinates, x = along, y = across) cross.
  const auto segments_cross = [&](const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                  const Eigen::Vector3d& c, const Eigen::Vector3d& d) {
    const double ab_c = cross2(b.x() - a.x(), b.y() - a.y(), c.x() - a.x(), c.y() - a.y());
    const double ab_d = cross2(b.x() - a.x(), b.y() - a.y(), d.x() - a.x(), d.y() - a.y());
    const double cd_a = cross2(d.x() - c.x(), d.y() - c.y(), a.x() - c.x(), a.y() - c.y());
    const double cd_b = cross2(d.x() - c.x(), d.y() - c.y(), b.x() - c.x(), b.y() - c.y());
    return ab_c * ab_d < 0.0 && cd_a * cd_b < 0.0;
  };
  // The polyline's points and segments that a probe pair can reach: a pair lies within its
  // length of its crossing, on the probe. A segment is kept by its midpoint (any of its points
  // is within half its length of it).
  const double pair_length = options_.probe_pair_length_factor * r_f;
  const double pair_length2 = pair_length * pair_length;
  const Eigen::Vector3d probe_start = Eigen::Vector3d::Zero(), probe_end(length, 0.0, 0.0);
  const auto reachable = [&](const Eigen::Vector3d& p, double slack) {
    const double reach = pair_length + r_pc + slack;
    return SquaredDistanceToSegment(probe_start, probe_end, p) <= reach * reach;
  };
  std::vector<Eigen::Vector3d> cut_points;
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> cut_segments;
  for (size_t k = 0; k < polyline_.size(); ++k) {
    const Eigen::Vector3d a = frame(polyline_[k].initial_position_mm);
    if (reachable(a, 0.0)) cut_points.push_back(a);
    if (k + 1 == polyline_.size()) continue;
    const Eigen::Vector3d b = frame(polyline_[k + 1].initial_position_mm);
    if (reachable(0.5 * (a + b), 0.5 * (b - a).norm())) cut_segments.emplace_back(a, b);
  }

  // Alive features within the longest pair of the probe, split by side.
  std::vector<int> sides[2];
  std::vector<Eigen::Vector3d> local(num_features());
  for (int f = 0; f < num_features(); ++f) {
    if (!alive_[f]) continue;
    const Eigen::Vector3d p = initial_mm_.row(f).transpose();
    if (SquaredDistanceToSegment(origin, tip, p) >= pair_length2) continue;
    local[f] = frame(p);
    if (local[f].y() != 0.0) sides[local[f].y() > 0.0 ? 1 : 0].push_back(f);
  }
  // A pair is at least as long as its features' distances to the probe's plane: with the
  // other side sorted by that distance, each feature's partners are a prefix.
  const auto by_distance = [&](int a, int b) {
    return std::abs(local[a].y()) < std::abs(local[b].y());
  };
  std::sort(sides[1].begin(), sides[1].end(), by_distance);
  for (int a : sides[0])
    for (int b : sides[1]) {
      const Eigen::Vector3d& la = local[a];
      const Eigen::Vector3d& lb = local[b];
      if (lb.y() - la.y() > pair_length) break;
      const double length2 = (la - lb).squaredNorm();
      if (length2 > pair_length2 || length2 == 0.0) continue;
      const double s = la.y() / (la.y() - lb.y());
      const Eigen::Vector3d crossing = la + s * (lb - la);
      if (crossing.x() < 0.0 || crossing.x() > length || std::abs(crossing.z()) > r_f) continue;
      bool crosses_cut = false;
      for (size_t k = 0; k < cut_points.size() && !crosses_cut; ++k)
        crosses_cut = SquaredDistanceToSegment(la, lb, cut_points[k]) < r_pc * r_pc;
      for (size_t k = 0; k < cut_segments.size() && !crosses_cut; ++k)
        crosses_cut = segments_cross(la, lb, cut_segments[k].first, cut_segments[k].second);
      if (crosses_cut) continue;
      const int first = std::min(a, b), second = std::max(a, b);
      probe.pairs.push_back({first, second, first == a ? s : 1.0 - s, 1.0 / std::sqrt(length2),
                             extension + crossing.x()});
    }
}

bool CutDetector::ProbeGrowth(bool front, DetectionResult* result, CutPoint* point) {
  BuildProbe(front);  // when the extremity has changed
  const Probe& probe = probes_[front ? 1 : 0];
  const double threshold = OutlierThreshold(options_.probe_outlier_factor, result->mean_measure);
  probe_outliers_.clear();
  Eigen::Vector3d misfit, span;
  for (size_t k = 0; k < probe.pairs.size(); ++k) {
    const ProbePair& p = probe.pairs[k];
    if (!alive_[p.first] || !alive_[p.second]) continue;
    ++result->probe_pairs;
    // mu as in Measure, with the frame-0 length kept, compared squared (most pairs are far
    // below the threshold).
    PairDifferences(p.first, p.second, &misfit, &span);
    const double mu2 =
        misfit.squaredNorm() * span.squaredNorm() * p.inverse_length * p.inverse_length;
    if (mu2 <= threshold * threshold) continue;
    const double mu = std::sqrt(mu2);
    if (options_.require_opening && !Opens({p.first, p.second})) continue;
    probe_outliers_.emplace_back(static_cast<int>(k), mu);
  }
  // A feature in more than 3/4 of the outliers whose partners lie near their model points is a
  // sliding feature's star, as for C^t (reject_lone_features).
  if (options_.reject_lone_features) {
    const int lone = LoneFeature(
        static_cast<int>(probe_outliers_.size()),
        [&](int i) -> const ProbePair& { return probe.pairs[probe_outliers_[i].first]; });
    if (lone >= 0)
      probe_outliers_.erase(std::remove_if(probe_outliers_.begin(), probe_outliers_.end(),
                                           [&](const std::pair<int, double>& o) {
                                             const ProbePair& p = probe.pairs[o.first];
                                             return p.first == lone || p.second == lone;
                                           }),
                            probe_outliers_.end());
  }
  result->probe_outliers += static_cast<int>(probe_outliers_.size());
  // A tear's continuation starts at its tip: outliers found only farther ahead are strain
  // beyond it (probe_max_lead_factor).
  double lead = std::numeric_limits<double>::infinity();
  for (const auto& outlier : probe_outliers_)
    lead = std::min(lead, probe.pairs[outlier.first].along);
  if (lead >
      options_.cut_point_radius_mm + options_.probe_max_lead_factor * options_.neighbour_radius_mm)
    return false;
  // Across the probe, the point lies at the mu-weighted barycentre of the pairs' midpoints, as
  // for C^t: the pairs that open straddle the tear, so it follows the tear when the probe
  // points off it (the crossings lie on the probe by construction, and an error in its
  // direction would never be corrected). Along it, the point lies at the barycentre of the
  // crossings, all ahead of the look-ahead.
  double count = 0.0, weight = 0.0;
  Eigen::Vector3d mid_t = Eigen::Vector3d::Zero(), mid_0 = Eigen::Vector3d::Zero();
  Eigen::Vector3d cross_t = Eigen::Vector3d::Zero(), cross_0 = Eigen::Vector3d::Zero();
  for (const auto& [k, mu] : probe_outliers_) {
    count += std::min(mu / threshold, options_.outlier_weight_cap);
    const ProbePair& p = probe.pairs[k];
    mid_t += mu * CurrentMidpoint(p.first, p.second);
    mid_0 += mu * 0.5 * (initial_mm_.row(p.first) + initial_mm_.row(p.second)).transpose();
    cross_t +=
        mu * ((1.0 - p.s) * model_mm_.row(p.first) + p.s * model_mm_.row(p.second)).transpose();
    cross_0 +=
        mu * ((1.0 - p.s) * initial_mm_.row(p.first) + p.s * initial_mm_.row(p.second)).transpose();
    weight += mu;
  }
  if (count < options_.min_outliers) return false;
  const size_t last = polyline_.size() - 1;
  const CutPoint& end = polyline_[front ? 0 : last];
  const CutPoint& prev = polyline_[front ? 1 : last - 1];
  const auto place = [&](const Eigen::Vector3d& mid, const Eigen::Vector3d& cross,
                         const Eigen::Vector3d& along) -> Eigen::Vector3d {
    const Eigen::Vector3d u = along.normalized();
    return mid / weight + u.dot(cross / weight - mid / weight) * u;
  };
  point->position_mm = place(mid_t, cross_t, end.position_mm - prev.position_mm);
  point->initial_position_mm =
      place(mid_0, cross_0, end.initial_position_mm - prev.initial_position_mm);
  point->frame = frame_;
  point->num_outliers = static_cast<int>(probe_outliers_.size());
  point->probe = true;
  return true;
}

void CutDetector::SelectCluster(const DetectionResult& result) {
  // Seed: the candidate whose r_F neighbourhood (of current pair midpoints) holds the largest
  // sum of mu; the cluster is that neighbourhood. O(#candidates^2), and candidates are few.
  const double r2 = options_.neighbour_radius_mm * options_.neighbour_radius_mm;
  auto midpoint = [&](int k) -> Eigen::Vector3d {
    return CurrentMidpoint(result.pairs[k].first, result.pairs[k].second);
  };
  double best_sum = -1.0;
  int best = -1;
  for (int a : candidates_) {
    const Eigen::Vector3d ca = midpoint(a);
    double sum = 0.0;
    for (int b : candidates_)
      if ((midpoint(b) - ca).squaredNorm() <= r2) sum += result.measure[b];
    if (sum > best_sum) {
      best_sum = sum;
      best = a;
    }
  }
  cluster_.clear();
  if (best < 0) return;
  const Eigen::Vector3d centre = midpoint(best);
  for (int b : candidates_)
    if ((midpoint(b) - centre).squaredNorm() <= r2) cluster_.push_back(b);
}

double CutDetector::OutlierCount(const std::vector<int>& outliers,
                                 const DetectionResult& result) const {
  double count = 0.0;
  for (int k : outliers)
    count += std::min(result.measure[k] / threshold_, options_.outlier_weight_cap);
  return count;
}

bool CutDetector::Opens(const FeaturePair& p) const {
  return (target_mm_.row(p.first) - target_mm_.row(p.second)).squaredNorm() >
         (model_mm_.row(p.first) - model_mm_.row(p.second)).squaredNorm();
}

template <typename PairOf>
int CutDetector::StarHub(int num_pairs, const PairOf& pair_of, int* most_out) {
  if (num_pairs < 2) return -1;
  int hub = -1, most = 0;
  for (int i = 0; i < num_pairs; ++i)
    for (int f : {pair_of(i).first, pair_of(i).second})
      if (++cluster_count_[f] > most) {
        most = cluster_count_[f];
        hub = f;
      }
  for (int i = 0; i < num_pairs; ++i)
    cluster_count_[pair_of(i).first] = cluster_count_[pair_of(i).second] = 0;
  if (most_out) *most_out = most;
  return 4 * most > 3 * num_pairs ? hub : -1;
}

template <typename PairOf>
int CutDetector::LoneFeature(int num_pairs, const PairOf& pair_of) {
  int most = 0;
  const int lone = StarHub(num_pairs, pair_of, &most);
  if (lone < 0) return -1;
  // The hub's own displacement error explains its pairs when its partners' are small (across
  // a cut, the features on the other side are as far from their model points).
  const auto error_mm = [&](int f) { return (model_mm_.row(f) - target_mm_.row(f)).norm(); };
  double partners_mm = 0.0;
  for (int i = 0; i < num_pairs; ++i) {
    const auto& p = pair_of(i);
    if (p.first == lone || p.second == lone)
      partners_mm += error_mm(p.first == lone ? p.second : p.first);
  }
  return partners_mm / most < 0.5 * error_mm(lone) ? lone : -1;
}

bool CutDetector::RemoveLoneFeature(const DetectionResult& result) {
  const int lone = LoneFeature(static_cast<int>(cluster_.size()), [&](int i) -> const FeaturePair& {
    return result.pairs[cluster_[i]];
  });
  if (lone < 0) return false;
  candidates_.erase(
      std::remove_if(
          candidates_.begin(), candidates_.end(),
          [&](int k) { return result.pairs[k].first == lone || result.pairs[k].second == lone; }),
      candidates_.end());
  return true;
}

void CutDetector::RemovePairsNear(const Eigen::Vector3d& centre_mm, int* removed) {
  const double r2 = options_.cut_point_radius_mm * options_.cut_point_radius_mm;
  const size_t before = pairs_.size();
  pairs_.erase(std::remove_if(pairs_.begin(), pairs_.end(),
                              [&](const FeaturePair& p) {
                                return SquaredDistanceToSegment(model_mm_.row(p.first).transpose(),
                                                                model_mm_.row(p.second).transpose(),
                                                                centre_mm) < r2;
                              }),
               pairs_.end());
  *removed += static_cast<int>(before - pairs_.size());
}

bool CutDetector::LonePointSupported(const DetectionResult& result) const {
  for (int k : result.outliers) {
    if (std::find(cluster_.begin(), cluster_.end(), k) != cluster_.end()) continue;
    const FeaturePair& p = result.pairs[k];
    const Eigen::Vector3d mid =
        0.5 * (initial_mm_.row(p.first) + initial_mm_.row(p.second)).transpose();
    if (WithinGrowthRadius(mid, polyline_[0])) return true;
  }
  return false;
}

CutDetector::Placement CutDetector::PlaceCutPoint(const CutPoint& point,
                                                  const DetectionResult& result) const {
  if (polyline_.empty()) return Placement::kBack;
  const double to_front = (point.position_mm - polyline_.front().position_mm).squaredNorm();
  const double to_back = (point.position_mm - polyline_.back().position_mm).squaredNorm();
  const Placement nearest = to_front < to_back ? Placement::kFront : Placement::kBack;
  if (!options_.grow_at_extremities_only) return nearest;
  const Eigen::Vector3d& p = point.initial_position_mm;
  const auto near = [&](const CutPoint& end) { return NearExtremity(point, end); };
  if (polyline_.size() == 1) {
    if (near(polyline_[0])) return Placement::kBack;
    return LonePointSupported(result) ? Placement::kRefuse : Placement::kReplace;
  }
  // Joining at an extremity must not turn the polyline back by more than 90 degrees.
  const size_t last = polyline_.size() - 1;
  const auto continues = [&](bool front) {
    const CutPoint& end = polyline_[front ? 0 : last];
    const CutPoint& prev = polyline_[front ? 1 : last - 1];
    return near(end) &&
           (p - end.initial_position_mm).dot(end.initial_position_mm - prev.initial_position_mm) >=
               0.0;
  };
  const bool front_first = nearest == Placement::kFront;
  if (continues(front_first)) return nearest;
  if (continues(!front_first)) return front_first ? Placement::kBack : Placement::kFront;
  return Placement::kRefuse;
}

bool CutDetector::WithinGrowthRadius(const Eigen::Vector3d& p0, const CutPoint& end) const {
  // Frame-0 coordinates: r_F and the pair lengths of the growth radius are frame-0 lengths.
  const double growth_mm = options_.cut_point_radius_mm + 1.5 * options_.neighbour_radius_mm;
  return (p0 - end.initial_position_mm).squaredNorm() <= growth_mm * growth_mm;
}

bool CutDetector::NearExtremity(const CutPoint& point, const CutPoint& end) const {
  return WithinGrowthRadius(point.initial_position_mm, end);
}

bool CutDetector::InsertCutPoint(const CutPoint& point, Placement placement) {
  ARREG_ASSERT(placement != Placement::kRefuse, "");
  if (placement == Placement::kReplace) {
    polyline_.assign(1, point);
    return false;
  }
  if (placement == Placement::kFront && polyline_.size() >= 2) {
    polyline_.insert(polyline_.begin(), point);
    return true;
  }
  polyline_.push_back(point);
  return false;
}

void CutDetector::DropClusterFromCandidates() {
  std::sort(cluster_.begin(), cluster_.end());
  candidates_.erase(std::remove_if(candidates_.begin(), candidates_.end(),
                                   [&](int k) {
                                     return std::binary_search(cluster_.begin(), cluster_.end(), k);
                                   }),
                    candidates_.end());
}

double CutDetector::ClusterDistanceChange(const DetectionResult& result) const {
  const int window = std::min(frame_, options_.closing_window_frames);
  if (window == 0 || cluster_.empty()) return 0.0;
  const RowMatX3d& past = target_history_[(frame_ - window) % target_history_.size()];
  std::vector<double> change;
  change.reserve(cluster_.size());
  for (int k : cluster_) {
    const int l = result.pairs[k].first, m = result.pairs[k].second;
    const double before = (past.row(l) - past.row(m)).norm();
    if (before > 0.0) change.push_back((target_mm_.row(l) - target_mm_.row(m)).norm() / before - 1);
  }
  if (change.empty()) return 0.0;
  std::nth_element(change.begin(), change.begin() + change.size() / 2, change.end());
  return change[change.size() / 2];
}

double CutDetector::OpeningBalance(const DetectionResult& result) const {
  // Per pair, how far each target lies outward of its model point along the pair.
  double low = 0.0, high = 0.0;
  for (int k : cluster_) {
    const int l = result.pairs[k].first, m = result.pairs[k].second;
    const Eigen::Vector3d along = model_mm_.row(m) - model_mm_.row(l);
    const double length = along.norm();
    if (length == 0.0) continue;
    const Eigen::Vector3d u = along / length;
    const double out_l = (model_mm_.row(l) - target_mm_.row(l)).dot(u);
    const double out_m = (target_mm_.row(m) - model_mm_.row(m)).dot(u);
    low += result.measure[k] * std::min(out_l, out_m);
    high += result.measure[k] * std::max(out_l, out_m);
  }
  return high > 0.0 ? low / high : 0.0;
}

double CutDetector::MinOpeningBalance(const DetectionResult& result) const {
  // A cluster of bridges: at least this share of its mu from bridges.
  constexpr double kBridgeShare = 0.9;
  double bridges = 0.0, all = 0.0;
  for (int k : cluster_) {
    all += result.measure[k];
    if (result.pairs[k].bridge) bridges += result.measure[k];
  }
  return bridges >= kBridgeShare * all
             ? std::min(options_.min_opening_balance_bridges, options_.min_opening_balance)
             : options_.min_opening_balance;
}

bool CutDetector::ExtremityAtBorder(bool front) const {
  const size_t count = polyline_.size();
  ARREG_ASSERT(count >= 2, "");
  const Eigen::Vector3d end = (front ? polyline_[0] : polyline_[count - 1]).position_mm;
  const Eigen::Vector3d prev = (front ? polyline_[1] : polyline_[count - 2]).position_mm;
  const Eigen::Vector3d dir = end - prev;
  if (dir.norm() == 0.0) return false;
  const Eigen::Vector3d u = dir.normalized();
  const double cos_cone = std::cos(options_.boundary_cone_half_angle_deg * kPi / 180.0);
  const double r = options_.neighbour_radius_mm;
  for (int f = 0; f < num_features(); ++f) {
    if (!alive_[f]) continue;
    const Eigen::Vector3d v = model_mm_.row(f).transpose() - end;
    const double dist = v.norm();
    if (dist > 0.0 && dist < r && v.dot(u) >= cos_cone * dist) return false;
  }
  return true;
}

std::vector<Eigen::Vector3d> CutDetector::ExtendedPolyline(bool initial_frame) const {
  std::vector<Eigen::Vector3d> out;
  auto pos = [&](size_t i) {
    return initial_frame ? polyline_[i].initial_position_mm : polyline_[i].position_mm;
  };
  const size_t count = polyline_.size();
  if (count < 2) {
    if (count == 1) out.push_back(pos(0));
    return out;
  }
  // Extension beyond an extremity: the look-ahead (r_pc) or, at the border, the border
  // extension, whichever is longer.
  auto extension = [&](size_t end, size_t prev, bool at_border) -> std::optional<Eigen::Vector3d> {
    const double length = ExtensionLength(at_border);
    const Eigen::Vector3d dir = pos(end) - pos(prev);
    if (length <= 0.0 || dir.norm() == 0.0) return std::nullopt;
    return pos(end) + length * dir.normalized();
  };
  if (auto e = extension(0, 1, front_at_border_)) out.push_back(*e);
  for (size_t i = 0; i < count; ++i) out.push_back(pos(i));
  if (auto e = extension(count - 1, count - 2, back_at_border_)) out.push_back(*e);
  return out;
}

double CutDetector::ExtensionLength(bool at_border) const {
  const double look_ahead = options_.look_ahead ? options_.cut_point_radius_mm : 0.0;
  return options_.extend_to_boundary && at_border
             ? std::max(look_ahead, options_.boundary_extension_mm)
             : look_ahead;
}

std::vector<int> CutDetector::AliveWithin(const Eigen::Vector3d& initial_mm,
                                          double radius_mm) const {
  std::vector<int> near;
  for (int f = 0; f < num_features(); ++f)
    if (alive_[f] &&
        (initial_mm_.row(f).transpose() - initial_mm).squaredNorm() < radius_mm * radius_mm)
      near.push_back(f);
  return near;
}

SeparationTestResult CutDetector::SeparationAt(const Eigen::Vector3d& initial_mm,
                                               const std::optional<Eigen::Vector3d>& along,
                                               DetectionResult* result) const {
  if (!along)
    for (const auto& [point, earlier] : undirected_tests_)
      if (point == initial_mm) return earlier;
  const std::vector<int> near =
      AliveWithin(initial_mm, options_.separation_radius_factor * options_.neighbour_radius_mm);
  const int n = static_cast<int>(near.size());
  RowMatX3d rest(n, 3), current(n, 3), displacement(n, 3);
  for (int k = 0; k < n; ++k) {
    rest.row(k) = initial_mm_.row(near[k]);
    current.row(k) = model_mm_.row(near[k]);
    displacement.row(k) = target_mm_.row(near[k]) - initial_mm_.row(near[k]);
  }
  SeparationTestResult test = TestSeparation(rest, current, displacement, initial_mm,
                                             options_.separation, along, options_.growth_cone_deg);
  result->separation_tests.emplace_back(initial_mm, test);
  if (!along) undirected_tests_.emplace_back(initial_mm, test);
  return test;
}

Eigen::Vector3d CutDetector::CurrentPosition(const Eigen::Vector3d& initial_mm) const {
  const std::vector<int> near = AliveWithin(initial_mm, options_.neighbour_radius_mm);
  const int n = static_cast<int>(near.size());
  if (n == 0) return initial_mm;
  Eigen::MatrixXd design(n, 4), current(n, 3);
  for (int k = 0; k < n; ++k) {
    design.row(k) << 1.0, (initial_mm_.row(near[k]).transpose() - initial_mm).transpose();
    current.row(k) = model_mm_.row(near[k]);
  }
  if (n < 4)
    return current.colwise().mean().transpose() -
           (design.rightCols(3).colwise().mean()).transpose();
  // The map's value at the point itself is its constant term.
  const Eigen::MatrixXd coefficients = design.colPivHouseholderQr().solve(current);
  return coefficients.row(0).transpose();
}

bool CutDetector::TipGrowth(bool front, DetectionResult* result, CutPoint* point) {
  const size_t last = polyline_.size() - 1;
  const CutPoint& end = polyline_[front ? 0 : last];
  Eigen::Vector3d dir =
      end.initial_position_mm - polyline_[front ? 1 : last - 1].initial_position_mm;
  if (dir.norm() == 0.0) return false;
  dir.normalize();
  // Tested over the part ahead of the cut's reach (the end of its extension, ExtendedPolyline);
  // the new point lies r_pc into it, on the line the test found.
  const Eigen::Vector3d reach =
      end.initial_position_mm + ExtensionLength(front ? front_at_border_ : back_at_border_) * dir;
  const SeparationTestResult test = SeparationAt(reach, dir, result);
  if (!test.separated) {
    if (test.tested) ++result->not_separated;
    return false;
  }
  const Eigen::Vector3d ahead =
      test.direction.dot(dir) < 0.0 ? Eigen::Vector3d(-test.direction) : test.direction;
  point->initial_position_mm =
      reach + test.offset_mm * test.normal + options_.cut_point_radius_mm * ahead;
  point->position_mm = CurrentPosition(point->initial_position_mm);
  point->frame = frame_;
  point->num_outliers = test.features_side[0] + test.features_side[1];
  point->probe = true;
  return true;
}

}  // namespace arreg::cutting
