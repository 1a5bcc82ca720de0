// `arreg bench align`: accuracy and speed of `arreg align` on synthetic scenes (kidney-cut,
// band-stretch) started from seeded perturbations of the true pose, the refusal of the wrong
// organ's outline, and the search without an initial pose. `--perturb` writes a scene with a
// perturbed pose (for trying `arreg align` by hand).
#include <Eigen/Core>
#include <algorithm>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <random>
#include <string>
#include <vector>

#include "ar/align/align_eval.h"
#include "ar/align/align_job.h"
#include "ar/synth/generator.h"
#include "bench_util.h"
#include "commands.h"
#include "core/error.h"
#include "core/file_util.h"
#include "core/scene.h"
#include "option_parser.h"

namespace arreg::cli {

namespace {

std::string EnsureScene(const std::string& scenario, const std::string& given,
                        const std::string& work) {
  if (!given.empty()) return given;
  const std::string dir = work + "/" + scenario;
  if (FileExists(dir + "/scene.json") && FileExists(dir + "/gt/masks/000000.png")) return dir;
  synth::SynthOptions o;
  o.scenario = scenario;
  o.out_dir = dir;
  o.frames = 2;
  o.write_video = false;
  std::fprintf(stderr, "bench align: generating %s in %s\n", scenario.c_str(), dir.c_str());
  synth::GenerateSyntheticScene(o);
  return dir;
}

double Fraction(const std::vector<align::TrialResult>& trials, double deg, double mm) {
  int ok = 0;
  for (const auto& t : trials)
    ok += t.fits && t.rotation_error_deg <= deg && t.translation_error_mm <= mm;
  return trials.empty() ? 0.0 : static_cast<double>(ok) / trials.size();
}

nlohmann::json TrialsJson(const std::vector<align::TrialResult>& trials, double deg, double mm) {
  std::vector<double> rot, trans, seconds;
  for (const auto& t : trials) {
    rot.push_back(t.rotation_error_deg);
    trans.push_back(t.translation_error_mm);
    seconds.push_back(t.seconds);
  }
  return {{"runs", trials.size()},
          {"success_rate", Fraction(trials, deg, mm)},
          {"threshold_deg", deg},
          {"threshold_mm", mm},
          {"median_rotation_error_deg", Median(rot)},
          {"max_rotation_error_deg", rot.empty() ? 0.0 : *std::max_element(rot.begin(), rot.end())},
          {"median_translation_error_mm", Median(trans)},
          {"max_translation_error_mm",
           trans.empty() ? 0.0 : *std::max_element(trans.begin(), trans.end())},
          {"median_seconds", Median(seconds)}};
}

}  // namespace

int RunBenchAlign(int argc, char** argv) {
  std::string kidney_dir, band_dir, work = "/tmp/arreg-bench-align", json_path;
  std::string perturb_scene, perturb_out;
  int runs = 100, landmark_count = 4;
  double max_deg = 20, max_mm = 20, landmark_noise_px = 0.25;
  uint64_t seed = 1;
  int seed_int = 1;
  OptionParser parser(
      "arreg bench align [--runs N] [--kidney DIR] [--band DIR] [--json OUT] | --perturb S.json "
      "--out P.json",
      "Aligns the kidney-cut and band-stretch models (arreg synth, frame 0, mask "
      "gt/masks/000000.png) from N seeded perturbations of their true pose (random axis and "
      "direction, up to --max-deg and --max-mm about the centroid): with the outline alone "
      "(success: <= 2 deg and <= 2 mm at the centroid) and with landmarks too (<= 1 deg, 1 mm); "
      "then the other scene's outline (must be refused) and a search without initial pose. "
      "Times are per frame on one thread.");
  parser.AddInt("runs", &runs, "N", "perturbations per scene");
  parser.AddString("kidney", &kidney_dir, "DIR", "kidney-cut scene (default: generated in --work)");
  parser.AddString("band", &band_dir, "DIR", "band-stretch scene (default: generated in --work)");
  parser.AddString("work", &work, "DIR", "where missing scenes are generated (2 frames, no video)");
  parser.AddDouble("max-deg", &max_deg, "DEG", "largest rotation of a perturbation");
  parser.AddDouble("max-mm", &max_mm, "MM", "largest translation of a perturbation");
  parser.AddInt("landmarks", &landmark_count, "N", "landmarks in the second series");
  parser.AddDouble("landmark-noise", &landmark_noise_px, "PX", "Gaussian noise of their pixels");
  parser.AddInt("seed", &seed_int, "N", "first seed (run k uses seed + k)");
  parser.AddString("json", &json_path, "OUT", "also write the figures to this JSON file");
  parser.AddString("perturb", &perturb_scene, "S.json",
                   "instead: write S.json with its model pose perturbed (--seed, --max-deg, "
                   "--max-mm) to --out");
  parser.AddString("out", &perturb_out, "P.json", "output of --perturb");
  align::AlignOptions options;
  parser.AddDouble("silhouette-weight", &options.silhouette_weight, "W",
                   "weight of the silhouette relative to one landmark");
  bool chord_contour = false;
  parser.AddFlag("chord-contour", &chord_contour,
                 "contour on the mesh's straight edges, not the smooth surface (AlignOptions)");
  if (!parser.Parse(argc, argv)) return 0;
  if (chord_contour) options.smooth_contour = false;
  seed = static_cast<uint64_t>(seed_int);
  if (runs < 1) throw UsageError("--runs", "must be >= 1");

  if (!perturb_scene.empty()) {
    if (perturb_out.empty()) throw UsageError("--out", "needed with --perturb");
    ReadSceneOptions o;
    o.check_files_exist = false;
    Scene scene = ReadScene(perturb_scene, o);
    const align::ModelSurface surface = align::LoadModelSurface(scene);
    std::mt19937_64 rng(seed);
    const align::ModelPose p =
        align::PerturbPose(align::ModelPose::FromRigid(scene.world_from_model), surface.centroid(),
                           max_deg, max_mm, &rng);
    const align::ModelPose truth = align::ModelPose::FromRigid(scene.world_from_model);
    scene.world_from_model = p.Rigid();
    WriteScene(perturb_out, scene);
    std::printf("wrote %s: pose perturbed by %.2f deg, %.2f mm at the centroid (seed %d)\n",
                perturb_out.c_str(), align::RotationErrorDeg(p, truth),
                align::PointErrorMm(p, truth, surface.centroid()), seed_int);
    return 0;
  }

  CreateDirectories(work);
  const std::string names[2] = {"kidney-cut", "band-stretch"};
  const align::SceneCase scenes[2] = {
      align::LoadSceneCase(EnsureScene(names[0], kidney_dir, work), options.contour_spacing_px),
      align::LoadSceneCase(EnsureScene(names[1], band_dir, work), options.contour_spacing_px)};
  nlohmann::json out = {{"runs", runs},
                        {"max_deg", max_deg},
                        {"max_mm", max_mm},
                        {"landmarks", landmark_count},
                        {"landmark_noise_px", landmark_noise_px},
                        {"seed", seed_int}};
  for (int i = 0; i < 2; ++i) {
    const align::SceneCase& s = scenes[i];
    const align::SceneCase& other = scenes[1 - i];
    const align::AlignInput input = s.Input();
    std::vector<align::TrialResult> outline_only, with_landmarks;
    std::vector<double> cpu_ms;
    for (int k = 0; k < runs; ++k) {
      std::mt19937_64 rng(seed + k);
      const align::TrialPair t =
          align::RunTrialPair(s, options, max_deg, max_mm, landmark_count, landmark_noise_px, &rng);
      outline_only.push_back(t.outline_only);
      with_landmarks.push_back(t.with_landmarks);
      cpu_ms.push_back(1000 * t.outline_only.cpu_seconds);
      std::fprintf(stderr, "\r%s %d/%d", names[i].c_str(), k + 1, runs);
    }
    std::fprintf(stderr, "\n");
    // The other organ's outline, from this scene's true pose: must be refused.
    align::Outline wrong = align::OutlineFromMask(other.outline->mask, s.scene.camera,
                                                  options.contour_spacing_px, "wrong organ");
    align::AlignInput wrong_input = input;
    wrong_input.outline = &wrong;
    wrong_input.initial_pose = s.truth;
    const align::AlignResult wrong_result = align::Align(wrong_input, options);
    // Search without an initial pose.
    align::AlignInput search = input;
    const double t0 = ThreadCpuMs();
    const align::AlignResult found = align::Align(search, options);
    const double search_ms = ThreadCpuMs() - t0;

    const nlohmann::json a = TrialsJson(outline_only, 2, 2), b = TrialsJson(with_landmarks, 1, 1);
    std::printf(
        "%s (%dx%d): outline only: %.0f %% within 2 deg/2 mm (target >= 90 %%; median %.3f deg, "
        "%.3f mm; max %.2f deg, %.2f mm), %.0f ms CPU per frame (median)\n",
        names[i].c_str(), s.scene.camera.width, s.scene.camera.height,
        100 * a["success_rate"].get<double>(), a["median_rotation_error_deg"].get<double>(),
        a["median_translation_error_mm"].get<double>(), a["max_rotation_error_deg"].get<double>(),
        a["max_translation_error_mm"].get<double>(), Median(cpu_ms));
    std::printf(
        "%s: + %d landmarks: %.0f %% within 1 deg/1 mm (target 100 %%; median %.3f deg, %.3f mm; "
        "max %.2f deg, %.2f mm)\n",
        names[i].c_str(), landmark_count, 100 * b["success_rate"].get<double>(),
        b["median_rotation_error_deg"].get<double>(),
        b["median_translation_error_mm"].get<double>(), b["max_rotation_error_deg"].get<double>(),
        b["max_translation_error_mm"].get<double>());
    std::printf("%s: %s's outline: %s (IoU %.3f)\n", names[i].c_str(), names[1 - i].c_str(),
                wrong_result.fits ? "ACCEPTED (wrong)" : "refused", wrong_result.iou);
    std::printf(
        "%s: search without initial pose: %.2f deg, %.2f mm, %s%s, %d of %zu starts at the "
        "optimum, %.0f ms CPU\n",
        names[i].c_str(), align::RotationErrorDeg(found.pose, s.truth),
        align::PointErrorMm(found.pose, s.truth, s.surface->centroid()),
        found.fits ? "fits" : "refused", found.ambiguous ? " (ambiguous)" : "",
        found.starts_at_optimum, found.starts.size(), search_ms);
    out[names[i]] = {
        {"outline_only", a},
        {"with_landmarks", b},
        {"cpu_ms_per_frame_median", Median(cpu_ms)},
        {"wrong_organ_refused", !wrong_result.fits},
        {"wrong_organ_iou", wrong_result.iou},
        {"search",
         {{"rotation_error_deg", align::RotationErrorDeg(found.pose, s.truth)},
          {"translation_error_mm", align::PointErrorMm(found.pose, s.truth, s.surface->centroid())},
          {"fits", found.fits},
          {"ambiguous", found.ambiguous},
          {"starts", found.starts.size()},
          {"starts_at_optimum", found.starts_at_optimum},
          {"cpu_ms", search_ms}}}};
  }
  if (!json_path.empty())
    WriteFileAtomic(json_path, [&](std::ostream& os) { os << out.dump(2) << "\n"; });
  return 0;
}

}  // namespace arreg::cli
