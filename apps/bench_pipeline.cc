// `arreg bench pipeline`: per-stage milliseconds of `arreg run` on a scene (decode, track,
// lift, mechanics, cutting, render, encode) and frames per second with and without video.
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "ar/pipeline/registration_pipeline.h"
#include "bench_util.h"
#include "commands.h"
#include "core/error.h"
#include "core/file_util.h"
#include "core/scene.h"
#include "option_parser.h"

namespace arreg::cli {
namespace {

// Sums the stage times of frames 1.. (frame 0 holds the one-off detection and attachment).
class TimeCollector : public pipeline::FrameObserver {
 public:
  void OnFrame(const pipeline::FrameState& f) override {
    if (f.frame == 0) {
      frame0_ms = f.ms.Total();
      return;
    }
    sum += f.ms;
    ++frames;
    features += f.stats.features_alive;
    linear_iterations += f.stats.linear_iterations;
    factorizations += f.stats.factorizations;
    if (f.cut_events)
      for (const pipeline::CutEvent& e : *f.cut_events)
        cuts_applied += e.status == pipeline::CutEventStatus::kCut;
  }
  pipeline::StageTimes sum;
  int frames = 0;
  double frame0_ms = 0;
  double features = 0;
  // The mechanics stage's cost follows these: CG iterations and refactorisations of the implicit
  // step, and cuts (each one enlarges the mesh and changes the matrix pattern).
  double linear_iterations = 0, factorizations = 0;
  int cuts_applied = 0;
};

struct Measurement {
  std::vector<double> stage[7];  // ms per frame per run, in kStages order
  std::vector<double> total, frame0;
  double mean_features = 0;
  double mean_linear_iterations = 0, factorizations_per_frame = 0;
  int cuts_applied = 0;
  int frames = 0;
};
const char* kStages[7] = {"decode", "track", "lift", "mechanics", "cutting", "render", "encode"};

Measurement Measure(const Scene& scene, const pipeline::PipelineOptions& options, bool video,
                    int repeats, bool cpu_clock) {
  Measurement m;
  const std::string video_path = (std::filesystem::temp_directory_path() /
                                  ("arreg-bench-pipeline-" + std::to_string(getpid()) + ".mp4"))
                                     .string();
  for (int r = 0; r < repeats; ++r) {
    pipeline::RegistrationPipeline pipe(scene, options);
    TimeCollector c;
    pipe.AddObserver(&c);
    pipeline::RunOptions run;
    if (video) run.overlay_video_path = video_path;
    run.thread_cpu_clock = cpu_clock;
    pipe.Run(run);
    ARREG_CHECK_INPUT(c.frames > 0, scene.video_path, "", "needs at least two frames");
    const pipeline::StageTimes& s = c.sum;
    const double v[7] = {s.decode, s.track, s.lift, s.mechanics, s.cutting, s.render, s.encode};
    for (int k = 0; k < 7; ++k) m.stage[k].push_back(v[k] / c.frames);
    m.total.push_back(s.Total() / c.frames);
    m.frame0.push_back(c.frame0_ms);
    m.mean_features = c.features / c.frames;
    m.mean_linear_iterations = c.linear_iterations / c.frames;
    m.factorizations_per_frame = c.factorizations / c.frames;
    m.cuts_applied = c.cuts_applied;
    m.frames = c.frames + 1;
  }
  std::error_code ec;
  std::filesystem::remove(video_path, ec);
  return m;
}

nlohmann::json Report(const Measurement& m) {
  nlohmann::json j;
  for (int k = 0; k < 7; ++k) j["ms_per_frame"][kStages[k]] = Median(m.stage[k]);
  j["ms_per_frame"]["total"] = Median(m.total);
  j["fps"] = 1000.0 / Median(m.total);
  j["frame0_ms"] = Median(m.frame0);
  j["mean_alive_features"] = m.mean_features;
  j["mean_cg_iterations"] = m.mean_linear_iterations;
  j["factorizations_per_frame"] = m.factorizations_per_frame;
  j["cuts_applied"] = m.cuts_applied;
  return j;
}

void Print(const char* title, const Measurement& m) {
  std::printf("%s\n", title);
  // Share of each stage in the sum of the stage medians (where the time goes).
  double sum = 0;
  for (int k = 0; k < 7; ++k) sum += Median(m.stage[k]);
  for (int k = 0; k < 7; ++k)
    std::printf("  %-10s %8.3f ms  %5.1f %%\n", kStages[k], Median(m.stage[k]),
                sum > 0 ? 100.0 * Median(m.stage[k]) / sum : 0.0);
  std::printf("  %-10s %8.3f ms  -> %.1f frames/s (frame 0: %.1f ms)\n", "total", Median(m.total),
              1000.0 / Median(m.total), Median(m.frame0));
  std::printf(
      "  mechanics: %.2f CG iterations and %.3f factorisations per frame, %d cuts applied\n",
      m.mean_linear_iterations, m.factorizations_per_frame, m.cuts_applied);
}

}  // namespace

int RunBenchPipeline(int argc, char** argv) {
  std::string scene_path, json_path;
  int repeats = 3, frames = -1, crf = -1, max_features = -1, supersampling = 0;
  double hessian_threshold = -1, min_distance_px = -1, output_spring_factor = -1;
  bool no_topology = false;
  std::string clock = "wall";
  OptionParser parser(
      "arreg bench pipeline --scene S.json [--json OUT] [options]",
      "Runs the registration of a scene without writing records and prints the median (over "
      "--repeats runs) milliseconds per frame of each stage and the frames per second, with and "
      "without encoding the overlay video. Single-threaded (decoder, encoder and OpenCV on one "
      "thread). Frame 0 (detection and attachment) is reported separately. The tracking and "
      "video options below override the scene's (e.g. --hessian-threshold 0.5 --min-distance 2 "
      "for ~450 features at frame 0 on band-stretch); their defaults keep the scene's.");
  parser.AddString("scene", &scene_path, "S.json", "scene file", true);
  parser.AddString("json", &json_path, "OUT", "also write the figures to this JSON file");
  parser.AddInt("repeats", &repeats, "N", "runs per measurement (median taken)");
  parser.AddInt("frames", &frames, "N", "frames per run (-1: the whole video)");
  parser.AddFlag("no-topology", &no_topology, "without cut detection and handling");
  parser.AddInt("crf", &crf, "N", "x264 quality of the overlay video (0..51)");
  parser.AddInt("max-features", &max_features, "N", "tracking.max_features");
  parser.AddDouble("hessian-threshold", &hessian_threshold, "T",
                   "tracking.hessian_threshold (lower: more features)");
  parser.AddDouble("min-distance", &min_distance_px, "PX", "tracking.min_distance_px");
  parser.AddInt("supersampling", &supersampling, "S",
                "render.supersampling (1: analytic edge anti-aliasing, >= 2: reference)");
  parser.AddDouble("output-spring-factor", &output_spring_factor, "F",
                   "mechanics.output_spring_factor (0: output the dynamic model, no fit)");
  parser.AddString("clock", &clock, "wall|cpu",
                   "stage times on the wall clock or on the thread's CPU clock (busy machines)");
  if (!parser.Parse(argc, argv)) return 0;
  ARREG_CHECK_INPUT(repeats >= 1, "", "--repeats", "must be >= 1, got ", repeats);
  ARREG_CHECK_INPUT(clock == "wall" || clock == "cpu", "", "--clock", "expected wall or cpu, got '",
                    clock, "'");
  const bool cpu = clock == "cpu";
  // One core: OpenCV's parallel loops (pyramids, colour conversion) would otherwise run on
  // other threads, outside the thread CPU clock.
  cv::setNumThreads(1);

  const Scene scene = ReadScene(scene_path);
  pipeline::PipelineOptions options = pipeline::ReadPipelineOptions(scene);
  options.max_frames = frames;
  options.output.encode_threads = 1;
  if (parser.Given("crf")) options.output.crf = crf;
  if (parser.Given("max-features")) options.tracking.max_features = max_features;
  if (parser.Given("hessian-threshold"))
    options.tracking.surf.hessian_threshold = hessian_threshold;
  if (parser.Given("min-distance")) options.tracking.min_distance_px = min_distance_px;
  if (parser.Given("supersampling")) options.render.supersampling = supersampling;
  if (parser.Given("output-spring-factor"))
    options.mechanics.output_spring_factor = output_spring_factor;
  if (no_topology) options.cutting.enabled = false;
  options.Check();

  const Measurement with_video = Measure(scene, options, true, repeats, cpu);
  const Measurement without_video = Measure(scene, options, false, repeats, cpu);
  pipeline::PipelineOptions bare = options;
  bare.render.enabled = false;
  const Measurement without_render = Measure(scene, bare, false, repeats, cpu);

  std::printf(
      "scene %s: %dx%d, %d frames, %.0f alive features on average, topology %s, "
      "%d repeats, %s clock, x264 %s crf %d, render supersampling %d, output spring factor %g\n",
      scene_path.c_str(), scene.camera.width, scene.camera.height, with_video.frames,
      with_video.mean_features, options.cutting.enabled ? "on" : "off", repeats, clock.c_str(),
      options.output.preset.c_str(), options.output.crf, options.render.supersampling,
      options.mechanics.output_spring_factor);
  Print("with overlay video (end to end):", with_video);
  Print("without video encoding:", without_video);
  Print("without rendering and encoding:", without_render);

  if (!json_path.empty()) {
    nlohmann::json out;
    out["scene"] = scene_path;
    out["width"] = scene.camera.width;
    out["height"] = scene.camera.height;
    out["frames"] = with_video.frames;
    out["repeats"] = repeats;
    out["clock"] = clock;
    out["topology"] = options.cutting.enabled;
    out["crf"] = options.output.crf;
    out["preset"] = options.output.preset;
    out["supersampling"] = options.render.supersampling;
    out["max_features"] = options.tracking.max_features;
    out["hessian_threshold"] = options.tracking.surf.hessian_threshold;
    out["output_spring_factor"] = options.mechanics.output_spring_factor;
    out["with_video"] = Report(with_video);
    out["without_video"] = Report(without_video);
    out["without_render"] = Report(without_render);
    WriteFileAtomic(json_path, [&out](std::ostream& os) { os << out.dump(2) << '\n'; });
  }
  return 0;
}

}  // namespace arreg::cli
