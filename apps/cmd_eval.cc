// `arreg eval`: accuracy of a registration run against ground truth (Dice,
// Hausdorff of surfaces and internal structures, feature error) as JSON/CSV/HTML.
#include <cmath>
#include <cstdio>
#include <optional>
#include <string>
#include <utility>

#include "ar/eval/evaluation.h"
#include "commands.h"
#include "core/error.h"
#include "core/progress.h"
#include "option_parser.h"

namespace arreg::cli {

namespace {

void PrintSummary(const eval::RunEvaluation& r) {
  std::printf("%s (%s): Dice%s final %.4f, mean %.4f\n", r.run_dir.c_str(), r.label.c_str(),
              r.thin.empty() ? "" : " (union silhouette)", r.dice_final, r.dice_mean);
  for (const auto& [name, h] :
       {std::pair{"surface", &r.surface}, std::pair{"internal", &r.internal}})
    if (*h)
      std::printf(
          "  Hausdorff %-8s mean model->gt %.3f mm, gt->model %.3f mm; max %.3f / %.3f mm, "
          "symmetric %.3f mm\n",
          name, (*h)->mean_model_to_gt, (*h)->mean_gt_to_model, (*h)->max_model_to_gt,
          (*h)->max_gt_to_model, (*h)->max);
  for (const eval::ThinSummary& t : r.thin) {
    std::printf("  thin %s: Dice final %.4f, mean %.4f", t.name.c_str(), t.dice_final.value_or(NAN),
                t.dice_mean.value_or(NAN));
    if (t.hausdorff)
      std::printf("; Hausdorff mean model->gt %.3f mm, gt->model %.3f mm, symmetric max %.3f mm",
                  t.hausdorff->mean_model_to_gt, t.hausdorff->mean_gt_to_model, t.hausdorff->max);
    std::printf("\n");
  }
  if (r.feature_error_mean_mm)
    std::printf("  feature error mean %.3f mm, max %.3f mm\n", *r.feature_error_mean_mm,
                r.feature_error_max_mm.value_or(0.0));
}

}  // namespace

int RunEval(int argc, char** argv) {
  std::string run_dir, gt_dir, out_dir, baseline_dir;
  eval::EvalOptions o;
  bool no_colormaps = false, quiet = false;
  int seed = static_cast<int>(o.hausdorff.sampling.seed);
  OptionParser parser(
      "arreg eval --run DIR --gt GT --out REPORT [--baseline DIR] [options]",
      "Compares an `arreg run` output with ground truth: Dice between the true mask and the "
      "registered model's silhouette per frame, both directed Hausdorff parts (mean, max) of "
      "the surface and the internal structures, and the feature error.");
  parser.AddString("run", &run_dir, "DIR", "output folder of `arreg run`", true);
  parser.AddString("gt", &gt_dir, "GT", "ground-truth folder (e.g. the gt/ of `arreg synth`)",
                   true);
  parser.AddString("out", &out_dir, "REPORT", "report folder (created)", true);
  parser.AddString("baseline", &baseline_dir, "DIR",
                   "a second run of the same ground truth (e.g. --no-topology), shown beside "
                   "the first");
  parser.AddDouble("samples-per-mm2", &o.hausdorff.sampling.samples_per_area, "N",
                   "random surface samples per mm^2 for the Hausdorff distances");
  parser.AddInt("min-samples", &o.hausdorff.sampling.min_random_samples, "N",
                "at least this many random samples per surface");
  parser.AddInt("max-samples", &o.hausdorff.sampling.max_random_samples, "N",
                "at most this many random samples per surface");
  parser.AddInt("seed", &seed, "N", "seed of the surface sampling (>= 0)");
  parser.AddDouble("colormap-max", &o.color_map_max_mm, "MM",
                   "top of the colour-map scale in mm (0: the symmetric Hausdorff distance)");
  parser.AddFlag("no-colormaps", &no_colormaps, "skip the per-vertex distance colour maps");
  parser.AddFlag("overlap-images", &o.overlap_images,
                 "write REPORT/overlap/NNNNNN.png per evaluated frame: the true mask against the "
                 "model's silhouette (grey both, red truth only, blue model only)");
  parser.AddFlag("quiet", &quiet, "no progress on stderr");
  parser.SetEpilog(
      "Writes REPORT/report.json (dice_final, dice_mean, hausdorff_surface, hausdorff_internal,\n"
      "feature_error_mm, frames; thin_structures when the run has them),\n"
      "REPORT/report.csv (one row per frame and run),\n"
      "REPORT/report.html (self-contained), REPORT/colormaps/*.obj|png and, with\n"
      "--overlap-images, REPORT/overlap/*.png. See docs/eval.md.");
  if (!parser.Parse(argc, argv)) return 0;
  ARREG_CHECK_INPUT(seed >= 0, "", "--seed", "must be >= 0, got ", seed);
  o.hausdorff.sampling.seed = static_cast<uint64_t>(seed);
  o.color_maps = !no_colormaps;
  o.Check();
  // One reporter per evaluated run: a bar on a terminal, lines in a log.
  std::optional<ProgressReporter> progress;
  if (!quiet) o.progress = [&progress](int done, int total) { progress->Update(done, total); };

  if (!quiet) progress.emplace("arreg eval: run frame", stderr, ProgressOptionsFor(stderr));
  const eval::RunEvaluation run = eval::EvaluateRun(run_dir, gt_dir, o);
  progress.reset();
  PrintSummary(run);
  std::optional<eval::RunEvaluation> baseline;
  if (!baseline_dir.empty()) {
    if (!quiet) progress.emplace("arreg eval: baseline frame", stderr, ProgressOptionsFor(stderr));
    baseline = eval::EvaluateRun(baseline_dir, gt_dir, o);
    progress.reset();
    PrintSummary(*baseline);
  }
  eval::WriteEvalReport(out_dir, gt_dir, run, baseline ? &*baseline : nullptr, o);
  std::printf("report: %s/report.html\n", out_dir.c_str());
  return 0;
}

}  // namespace arreg::cli
