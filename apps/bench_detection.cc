// `arreg bench detection`: time per frame of the cut detection (thesis 7.5) on a synthetic
// feature field of the thesis's size (700 features, ~9,000 neighbour pairs at r_F = 15 mm).
#include <Eigen/Core>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <nlohmann/json.hpp>
#include <ostream>
#include <random>
#include <string>
#include <vector>

#include "bench_util.h"
#include "commands.h"
#include "core/error.h"
#include "core/file_util.h"
#include "cutting/detection.h"
#include "option_parser.h"

namespace arreg::cli {

namespace {

using Clock = std::chrono::steady_clock;

double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const size_t k = std::min(v.size() - 1, static_cast<size_t>(std::ceil(q * v.size())) - 1);
  return v[k];
}

struct Field {
  RowMatX3d p0;  // (#F x 3) features on z = 0
  std::vector<int> ids;
};

Field MakeField(int nx, int ny, double spacing_mm) {
  Field f;
  f.p0.resize(nx * ny, 3);
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      f.p0.row(j * nx + i) << spacing_mm * (i + 0.5), spacing_mm * (j - ny / 2 + 0.5), 0.0;
      f.ids.push_back(j * nx + i);
    }
  return f;
}

// One frame of a cut opening along y = 0 from x = 0 (tip advancing), the model following the
// targets where the detector has already cut and staying connected elsewhere, with tracking
// noise: frames without and with cut-point insertions, as in a real sequence. Features closer
// than lip_loss_mm to the cut and beyond x = lip_loss_from_mm die once the gap at their place
// is 1 mm wide (*alive, per
// feature, is updated; the tracker loses the lips of a tear), which makes the detector bridge
// their pairs. Returns the number of features that died in this frame.
int MakeFrame(const Field& field, double tip_mm, double cut_extent_mm, double noise_mm,
              double lip_loss_mm, double lip_loss_from_mm, double fade_mm, std::mt19937* rng,
              std::vector<char>* alive, cutting::FrameFeatures* frame) {
  std::normal_distribution<double> noise(0.0, noise_mm);
  const int n = static_cast<int>(field.p0.rows());
  frame->ids.clear();
  frame->target_mm.resize(n, 3);
  frame->model_mm.resize(n, 3);
  int rows = 0, died = 0;
  for (int r = 0; r < n; ++r) {
    const double x = field.p0(r, 0), y = field.p0(r, 1);
    const double open = x < tip_mm ? std::min(10.0, 0.5 * (tip_mm - x)) : 0.0;
    const double side = y > 0 ? 1.0 : -1.0;
    const double follow = x <= cut_extent_mm ? 1.0 : 1.0 - std::exp(-std::abs(y) / fade_mm);
    // Drawn for every feature, so the noise does not depend on which features are alive.
    const double nx = noise(*rng), ny = noise(*rng);
    if ((*alive)[r] && std::abs(y) < lip_loss_mm && x > lip_loss_from_mm && open >= 1.0) {
      (*alive)[r] = 0;
      ++died;
    }
    if (!(*alive)[r]) continue;
    frame->ids.push_back(field.ids[r]);
    frame->target_mm.row(rows) = field.p0.row(r);
    frame->model_mm.row(rows) = field.p0.row(r);
    frame->target_mm(rows, 1) += side * 0.5 * open;
    frame->model_mm(rows, 1) += side * 0.5 * open * follow;
    frame->target_mm(rows, 0) += nx;
    frame->target_mm(rows, 1) += ny;
    ++rows;
  }
  frame->target_mm.conservativeResize(rows, 3);
  frame->model_mm.conservativeResize(rows, 3);
  return died;
}

}  // namespace

int RunBenchDetection(int argc, char** argv) {
  int nx = 35, ny = 20, frames = 200, repeats = 5, seed = 1;
  double spacing_mm = 4.8, noise_mm = 0.25, lip_loss_mm = 0.0, lip_loss_from_mm = 30.0,
         fade_mm = 8.0;
  std::string json_path;
  cutting::CutDetectorOptions options;
  OptionParser parser(
      "arreg bench detection [options] [--json OUT]",
      "Times CutDetector::Update per frame (single thread) on a grid of features on a plane "
      "while a cut opens along its middle: the default grid has 700 features and 8,828 "
      "neighbour pairs (thesis 7.8.2 reports ~0.15 ms per frame for its detection).");
  parser.AddInt("nx", &nx, "N", "features per row");
  parser.AddInt("ny", &ny, "N", "rows of features");
  parser.AddDouble("spacing", &spacing_mm, "MM", "feature spacing in mm");
  parser.AddInt("frames", &frames, "N", "frames per sequence (the tip advances 1 mm a frame)");
  parser.AddInt("repeats", &repeats, "N", "sequences timed (figures are medians over all frames)");
  parser.AddDouble("noise", &noise_mm, "MM", "tracking noise (std. dev.) added to the targets");
  parser.AddDouble("lip-loss", &lip_loss_mm, "MM",
                   "features closer than this to the cut die once it opens 1 mm there, and the "
                   "detector bridges their pairs (0: none die)");
  parser.AddDouble("lip-loss-from", &lip_loss_from_mm, "MM",
                   "lips are lost only beyond this distance along the cut (bridges continue a "
                   "cut that pairs of tracked features started)");
  parser.AddDouble("model-fade", &fade_mm, "MM",
                   "the uncut model follows the opening by 1 - exp(-d / MM) at distance d from "
                   "the cut");
  double fixed_radius_mm = 0.0;
  parser.AddDouble("neighbour-radius", &fixed_radius_mm, "MM",
                   "r_F in mm, with r_pc at 7 mm (0: both from the features' spacing)");
  parser.AddInt("seed", &seed, "N", "seed of the noise (>= 0)");
  parser.AddString("json", &json_path, "OUT", "also write the figures as JSON");
  if (!parser.Parse(argc, argv)) return 0;
  ARREG_CHECK_INPUT(nx >= 2 && ny >= 2, "", "--nx/--ny", "must be >= 2");
  ARREG_CHECK_INPUT(spacing_mm > 0.0, "", "--spacing", "must be > 0, got ", spacing_mm);
  ARREG_CHECK_INPUT(frames >= 1, "", "--frames", "must be >= 1, got ", frames);
  ARREG_CHECK_INPUT(repeats >= 1, "", "--repeats", "must be >= 1, got ", repeats);
  ARREG_CHECK_INPUT(noise_mm >= 0.0, "", "--noise", "must be >= 0, got ", noise_mm);
  ARREG_CHECK_INPUT(lip_loss_mm >= 0.0, "", "--lip-loss", "must be >= 0, got ", lip_loss_mm);
  ARREG_CHECK_INPUT(fade_mm > 0.0, "", "--model-fade", "must be > 0, got ", fade_mm);
  ARREG_CHECK_INPUT(seed >= 0, "", "--seed", "must be >= 0, got ", seed);
  if (fixed_radius_mm > 0.0) {
    options.neighbour_radius_mm = fixed_radius_mm;
    options.neighbours_per_feature = 0;
  }
  options.Check();

  const Field field = MakeField(nx, ny, spacing_mm);
  std::vector<double> update_ms, insert_ms, death_ms, init_ms;
  int pairs = 0, cut_points = 0, bridged = 0;
  double radius_mm = options.neighbour_radius_mm;  // r_F in use (resolved by Initialize)
  for (int rep = 0; rep < repeats; ++rep) {
    std::mt19937 rng(static_cast<unsigned>(seed) + rep);
    cutting::CutDetector detector(options);
    const auto t0 = Clock::now();
    detector.Initialize(field.p0, field.ids);
    init_ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
    pairs = static_cast<int>(detector.pairs().size());
    radius_mm = detector.options().neighbour_radius_mm;
    cutting::FrameFeatures frame;
    cutting::DetectionResult result;
    cut_points = bridged = 0;
    std::vector<char> alive(field.p0.rows(), 1);
    for (int k = 0; k < frames; ++k) {
      double cut_extent = -std::numeric_limits<double>::infinity();
      for (const Eigen::Vector3d& p : detector.ExtendedPolyline(true))
        cut_extent = std::max(cut_extent, p.x());
      const int died = MakeFrame(field, -5.0 + k, cut_extent, noise_mm, lip_loss_mm,
                                 lip_loss_from_mm, fade_mm, &rng, &alive, &frame);
      const auto start = Clock::now();
      detector.Update(frame, &result);
      const double ms = std::chrono::duration<double, std::milli>(Clock::now() - start).count();
      update_ms.push_back(ms);
      if (!result.new_cut_points.empty()) insert_ms.push_back(ms);
      if (died > 0) death_ms.push_back(ms);
      cut_points += static_cast<int>(result.new_cut_points.size());
      bridged += result.pairs_bridged;
    }
  }

  const double median = Median(update_ms), p95 = Percentile(update_ms, 0.95),
               worst = *std::max_element(update_ms.begin(), update_ms.end());
  std::printf("cut detection: %d features, %d pairs (r_F = %.1f mm), %d frames x %d sequences\n",
              static_cast<int>(field.p0.rows()), pairs, radius_mm, frames, repeats);
  std::printf("  Update per frame      median %.4f ms   p95 %.4f ms   max %.4f ms\n", median, p95,
              worst);
  std::printf("  frames with insertion median %.4f ms   (%zu frames)\n", Median(insert_ms),
              insert_ms.size());
  if (lip_loss_mm > 0.0)
    std::printf(
        "  frames with deaths    median %.4f ms   (%zu frames, %d pairs bridged per "
        "sequence)\n",
        Median(death_ms), death_ms.size(), bridged);
  std::printf("  Initialize (C_F)      median %.4f ms\n", Median(init_ms));
  std::printf("  cut points per sequence: %d\n", cut_points);

  if (!json_path.empty()) {
    nlohmann::json j;
    j["benchmark"] = "detection";
    j["features"] = field.p0.rows();
    j["pairs"] = pairs;
    j["frames"] = frames;
    j["repeats"] = repeats;
    j["noise_mm"] = noise_mm;
    j["update_ms_median"] = median;
    j["update_ms_p95"] = p95;
    j["update_ms_max"] = worst;
    j["update_with_insertion_ms_median"] = Median(insert_ms);
    j["lip_loss_mm"] = lip_loss_mm;
    j["lip_loss_from_mm"] = lip_loss_from_mm;
    j["model_fade_mm"] = fade_mm;
    j["update_with_deaths_ms_median"] = Median(death_ms);
    j["frames_with_deaths"] = death_ms.size();
    j["pairs_bridged_per_sequence"] = bridged;
    j["initialize_ms_median"] = Median(init_ms);
    j["cut_points_per_sequence"] = cut_points;
    WriteFileAtomic(json_path, [&](std::ostream& os) { os << j.dump(2) << "\n"; });
  }
  return 0;
}

}  // namespace arreg::cli
