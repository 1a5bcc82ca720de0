// `arreg synth`: generates a synthetic benchmark scene with ground truth.
#include <cstdio>
#include <optional>
#include <string>

#include "ar/synth/generator.h"
#include "ar/synth/scenarios.h"
#include "commands.h"
#include "core/error.h"
#include "core/progress.h"
#include "option_parser.h"

namespace arreg::cli {

int RunSynth(int argc, char** argv) {
  synth::SynthOptions o;
  bool list = false, no_video = false, quiet = false;
  std::string size = "640x512";
  int seed = 1;
  OptionParser parser(
      "arreg synth --scenario NAME --out DIR [options]",
      "Simulates a scenario with a fine hyperelastic truth (real cuts by vertex duplication), "
      "renders it to video and writes the registration's inputs (scene.json, coarse model) and "
      "the ground truth (masks, surfaces, internal structures, cut).");
  parser.AddFlag("list", &list, "describe the scenarios and exit");
  parser.AddString("scenario", &o.scenario, "NAME", "scenario to generate (see --list)");
  parser.AddString("out", &o.out_dir, "DIR", "output folder (created)");
  parser.AddInt("seed", &seed, "N",
                "seed of texture, sensor noise and occluder; membrane sizes, pull and cut, vessel "
                "branch ends (>= 0)");
  parser.AddInt("frames", &o.frames, "N", "number of frames");
  parser.AddString("size", &size, "WxH", "image size in pixels (even numbers)");
  parser.AddDouble("fps", &o.fps, "HZ", "video frame rate");
  parser.AddDouble("amplitude", &o.amplitude, "A",
                   "scales the grip motions: manipulation speed (and stretch) at fixed frames, "
                   "in (0, 1.5]");
  parser.AddDouble("zoom", &o.zoom, "Z",
                   "focal length relative to the scenario's 60-degree view, in [0.5, 4] (2: the "
                   "organ covers 4x the pixels, parts may leave the image)");
  parser.AddInt("gt-every", &o.surface_every_k, "K", "write gt surfaces every K-th frame");
  parser.AddDouble("cell", &o.fine_cell_mm, "MM",
                   "band truth mesh spacing in mm (membranes: half of it in-plane)");
  parser.AddDouble("kidney-cell", &o.kidney_cell_mm, "MM", "kidney truth mesh size in mm");
  parser.AddDouble("membrane-cell", &o.membrane_cell_mm, "MM",
                   "membranes' model shell grid spacing in mm, in [2, 10] (default 5)");
  parser.AddDouble("noise", &o.noise_sigma, "SIGMA", "sensor noise, 8-bit grey levels");
  parser.AddDouble("blur", &o.blur_sigma_px, "PX", "Gaussian blur of the video in px (0: off)");
  parser.AddFlag("occluder", &o.occluder, "draw an instrument-like occluder over the video");
  parser.AddInt("supersampling", &o.supersampling, "S", "anti-aliasing samples per pixel and axis");
  parser.AddInt("crf", &o.crf, "Q", "x264 constant rate factor (lower is better quality)");
  parser.AddFlag("no-video", &no_video, "write the ground truth only (no rendering, no video)");
  parser.AddFlag("quiet", &quiet, "no progress on stderr");
  parser.SetEpilog(
      "Writes in DIR: video.mp4, scene.json, model.vtk (not for membranes), internal.obj\n"
      "(kidney), membrane.obj / vessel.obj (thin structures), gt/meta.json,\n"
      "gt/masks/NNNNNN.png, gt/surface/NNNNNN.obj, gt/internal/NNNNNN.obj,\n"
      "gt/thin/NNNNNN.obj, gt/cut.json, gt/cut_surface.obj. See docs/synth.md.");
  if (!parser.Parse(argc, argv)) return 0;
  if (list) {
    for (const auto& s : synth::ListScenarios())
      std::printf("%-20s %s\n", s.name.c_str(), s.description.c_str());
    return 0;
  }
  ARREG_CHECK_INPUT(parser.Given("out"), "", "--out", "an output folder is required");
  ARREG_CHECK_INPUT(seed >= 0, "", "--seed", "must be >= 0");
  o.seed = static_cast<uint64_t>(seed);
  {
    int w = 0, h = 0;
    char extra = 0;
    ARREG_CHECK_INPUT(std::sscanf(size.c_str(), "%dx%d%c", &w, &h, &extra) == 2, "", "--size",
                      "expected WxH, got '", size, "'");
    o.width = w;
    o.height = h;
  }
  o.write_video = !no_video;
  std::optional<ProgressReporter> progress;
  if (!quiet) {
    progress.emplace("arreg synth: frame", stderr, ProgressOptionsFor(stderr));
    o.progress = [&progress](int done, int total) { progress->Update(done, total); };
  }
  const synth::SynthSummary s = synth::GenerateSyntheticScene(o);
  progress.reset();
  std::printf("scenario %s: %d frames in %.1f s -> %s\n", o.scenario.c_str(), s.frames, s.seconds,
              o.out_dir.c_str());
  std::printf("truth: %d tetrahedra, %d vertices (%d after the cut); model: %d tetrahedra\n",
              s.truth_tetrahedra, s.truth_vertices, s.final_truth_vertices, s.model_tetrahedra);
  std::printf("newton: %d iterations, %d unconverged frames; max volume change %.3f %%\n",
              s.newton_iterations, s.unconverged_frames, 100 * s.max_volume_change);
  if (s.cut_first_frame >= 0)
    std::printf(
        "cut: opens in frames %d..%d; final opening > 2 mm over %.0f %% of its length "
        "(max %.1f mm)\n",
        s.cut_first_frame, s.cut_last_frame, 100 * s.cut_open_fraction, s.max_cut_opening_mm);
  if (s.unconverged_frames == 0) return 0;
  std::fprintf(stderr,
               "arreg synth: error: %s: the truth's Newton solve did not converge in %d frame(s)\n",
               o.out_dir.c_str(), s.unconverged_frames);
  return 1;
}

}  // namespace arreg::cli
