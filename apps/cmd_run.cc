// `arreg run`: registers the scene's model to its video (overlay video and records).
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <optional>
#include <string>
#include <vector>

#include "ar/debug/recorder.h"
#include "ar/pipeline/record_writer.h"
#include "ar/pipeline/registration_pipeline.h"
#include "commands.h"
#include "core/error.h"
#include "core/file_util.h"
#include "core/progress.h"
#include "core/scene.h"
#include "option_parser.h"

namespace arreg::cli {
namespace {

std::atomic<bool> g_stop{false};
extern "C" void OnStopSignal(int) { g_stop.store(true); }

// Progress with frames per second, springs and their mean length: a bar on a
// terminal, a line every 10 % or 10 s in a log (core/progress.h).
class RunProgress : public pipeline::FrameObserver {
 public:
  void OnStart(const pipeline::RunStart& start) override {
    total_ = start.expected_frames;
    std::fprintf(stderr, "arreg run: %d frames, %d features attached of %d detected\n", total_,
                 start.features_attached, start.features_detected);
    reporter_.emplace("arreg run: frame", stderr, ProgressOptionsFor(stderr));
    t0_ = std::chrono::steady_clock::now();
  }
  void OnFrame(const pipeline::FrameState& f) override {
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0_).count();
    const int done = f.frame + 1;
    char detail[128];
    std::snprintf(detail, sizeof detail, "%.1f fps  springs %d  mean %.2f mm",
                  s > 0 ? done / s : 0.0, f.stats.features_alive, f.stats.spring_length_mean_mm);
    if (reporter_) reporter_->Update(done, total_, detail);
  }
  void OnFinish(const pipeline::RunSummary& s) override {
    reporter_.reset();
    if (s.interrupted) std::fprintf(stderr, "arreg run: interrupted\n");
  }

 private:
  int total_ = 0;
  std::optional<ProgressReporter> reporter_;
  std::chrono::steady_clock::time_point t0_;
};

}  // namespace

int RunRun(int argc, char** argv) {
  std::string scene_path, out_dir, lifting, lift_update;
  std::vector<std::string> overrides;
  bool no_topology = false, no_video = false, png = false, quiet = false, wireframe = false;
  bool show_features = false, show_targets = false, show_springs = false, no_render = false;
  bool record_debug = false;
  // Shown as the defaults in --help; applied only when given (the scene's values stand otherwise).
  const pipeline::MechanicsStageOptions mechanics_defaults;
  const pipeline::RenderStageOptions render_defaults;
  int frames = -1, save_every = 0, supersampling = render_defaults.supersampling;
  int substeps = mechanics_defaults.substeps, crf = pipeline::OutputStageOptions().crf;
  double stiffness = 0, opacity = render_defaults.organ_opacity;
  double stiffness_relative = mechanics_defaults.spring_stiffness_relative;
  double output_factor = mechanics_defaults.output_spring_factor;
  OptionParser parser(
      "arreg run --scene S.json --out DIR [options]",
      "Registers the scene's organ model to its video: tracks features, lifts them to 3D, "
      "pulls the FEM model with springs (one implicit step per frame), follows cuts, and writes "
      "the overlay video and the records of docs/run-format.md.");
  parser.AddString("scene", &scene_path, "S.json", "scene file (docs/scene-format.md)", true);
  parser.AddString("out", &out_dir, "DIR", "output folder (created)", true);
  parser.AddStringList("set", &overrides, "SECTION.KEY=VALUE",
                       "set a module option of the scene (docs/pipeline-options.md), e.g. "
                       "cutting.enabled=false or tracking.redetect_every_frames=5");
  parser.AddFlag("no-topology", &no_topology, "register without cut handling");
  parser.AddInt("frames", &frames, "N", "process at most N frames (-1: all)");
  parser.AddInt(
      "save-every", &save_every, "K",
      "save meshes every K-th frame (default: the ground truth's, else output.save_every)");
  parser.AddFlag("no-video", &no_video, "do not write overlay.mp4");
  parser.AddFlag("no-render", &no_render, "skip the overlay rendering (and the video)");
  parser.AddFlag("png", &png, "also write frames/NNNNNN.png of the overlay");
  parser.AddFlag("wireframe", &wireframe, "draw the model's surface edges");
  parser.AddFlag("show-features", &show_features, "draw the tracked features");
  parser.AddFlag("show-targets", &show_targets, "draw the lifted targets");
  parser.AddFlag("show-springs", &show_springs, "draw the springs (anchor to target)");
  parser.AddDouble("opacity", &opacity, "A",
                   "organ opacity in [0, 1] of the tint style (--set render.style=tint)");
  parser.AddInt("supersampling", &supersampling, "S",
                "1: one sample per pixel with analytic edge anti-aliasing; 2..8: "
                "supersampled reference renderer");
  parser.AddInt("crf", &crf, "Q", "x264 quality of overlay.mp4 (0..51)");
  parser.AddDouble("stiffness", &stiffness, "N_PER_M",
                   "absolute feature spring stiffness; 0 = from --stiffness-relative");
  parser.AddDouble("stiffness-relative", &stiffness_relative, "KAPPA",
                   "springs' total stiffness / (E x volume / seen area), dimensionless");
  parser.AddInt("substeps", &substeps, "N", "implicit Euler sub-steps per frame");
  parser.AddDouble("output-spring-factor", &output_factor, "F",
                   "output the quasi-static fit with F times stiffer springs; 0 = the "
                   "dynamic model (docs/springs.md, \"Output fit\")");
  parser.AddString("lifting", &lifting, "surface|plane", "lifting target (default surface)");
  parser.AddString("lift-update", &lift_update, "intercept|raycast",
                   "surface target update (default intercept, thesis eq. 7.1)");
  parser.AddFlag("quiet", &quiet, "no progress on stderr");
  parser.AddFlag("debug", &record_debug,
                 "record per-frame debug state in DIR/debug/ for `arreg debug`, and the inputs of "
                 "any refused internal-structure split (docs/debug.md)");
  parser.SetEpilog(
      "Options given here override the scene's module sections (docs/pipeline-options.md).\n"
      "Writes in DIR: overlay.mp4, frames.jsonl, run.json, mesh/NNNNNN.vtk, surface/NNNNNN.obj,\n"
      "internal/NNNNNN.obj (docs/run-format.md). Ctrl-C stops after the current frame and\n"
      "leaves complete outputs.");
  if (!parser.Parse(argc, argv)) return 0;

  Scene scene = ReadScene(scene_path);
  for (const std::string& o : overrides) SetSceneOption(&scene, o, "--set");
  pipeline::PipelineOptions options = pipeline::ReadPipelineOptions(scene);
  if (no_topology) options.cutting.enabled = false;
  if (record_debug) options.cutting.refused_split_dir = out_dir + "/debug";
  if (frames != -1) options.max_frames = frames;
  if (png) options.output.png_frames = true;
  if (no_video || no_render) options.output.video = false;
  if (no_render) options.render.enabled = false;
  if (wireframe) options.render.wireframe = true;
  if (show_features) options.render.show_features = true;
  if (show_targets) options.render.show_targets = true;
  if (show_springs) options.render.show_springs = true;
  if (parser.Given("opacity")) options.render.organ_opacity = opacity;
  if (parser.Given("supersampling")) options.render.supersampling = supersampling;
  if (parser.Given("crf")) options.output.crf = crf;
  if (parser.Given("stiffness")) options.mechanics.spring_stiffness_n_per_m = stiffness;
  if (parser.Given("stiffness-relative"))
    options.mechanics.spring_stiffness_relative = stiffness_relative;
  if (parser.Given("substeps")) options.mechanics.substeps = substeps;
  if (parser.Given("output-spring-factor")) options.mechanics.output_spring_factor = output_factor;
  if (parser.Given("lifting"))
    options.lifting.target = ParseName(lift::kLiftTargetNames, lifting, "", "--lifting");
  if (parser.Given("lift-update"))
    options.lifting.surface_update =
        ParseName(lift::kSurfaceUpdateNames, lift_update, "", "--lift-update");
  ARREG_CHECK_INPUT(save_every >= 0, "", "--save-every", "must be >= 1");
  options.Check();

  CreateDirectories(out_dir);
  pipeline::RegistrationPipeline pipe(scene, options);
  RunProgress progress;
  pipeline::RecordWriter records(out_dir, options.output.png_frames);
  if (!quiet) pipe.AddObserver(&progress);
  pipe.AddObserver(&records);
  std::optional<debug::DebugRecorder> debug_recorder;
  if (record_debug) pipe.AddObserver(&debug_recorder.emplace(debug::DebugRecorderOptions{out_dir}));

  pipeline::RunOptions run;
  if (options.output.video && options.render.enabled)
    run.overlay_video_path = out_dir + "/overlay.mp4";
  run.stop = &g_stop;
  run.save_every = save_every;
  g_stop.store(false);
  // Ctrl-C, and SIGTERM (what kill and batch schedulers such as Slurm send at a time limit),
  // stop after the current frame with complete records.
  struct sigaction action = {}, previous_int = {}, previous_term = {};
  action.sa_handler = OnStopSignal;
  sigemptyset(&action.sa_mask);
  sigaction(SIGINT, &action, &previous_int);
  sigaction(SIGTERM, &action, &previous_term);
  const auto restore = [&] {
    sigaction(SIGINT, &previous_int, nullptr);
    sigaction(SIGTERM, &previous_term, nullptr);
  };
  pipeline::RunSummary s;
  try {
    s = pipe.Run(run);
  } catch (...) {
    restore();
    throw;
  }
  restore();

  const double fps = s.total_ms.Total() > 0 ? 1000.0 * s.frames / s.total_ms.Total() : 0.0;
  const double n = s.frames > 0 ? s.frames : 1;
  std::printf(
      "%d frames%s, %.1f fps (decode %.2f, track %.2f, lift %.2f, mechanics %.2f, "
      "cutting %.2f, render %.2f, encode %.2f ms/frame); %d cut events, %d applied\n",
      s.frames, s.interrupted ? " (interrupted)" : "", fps, s.total_ms.decode / n,
      s.total_ms.track / n, s.total_ms.lift / n, s.total_ms.mechanics / n, s.total_ms.cutting / n,
      s.total_ms.render / n, s.total_ms.encode / n, s.cut_events, s.cuts_applied);
  std::printf("outputs in %s\n", out_dir.c_str());
  return s.interrupted ? 130 : 0;
}

}  // namespace arreg::cli
