// `arreg synth` controller: simulates a scenario's truth frame by frame,
// renders the video and writes the scene file and the ground truth folder.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace arreg::synth {

struct SynthOptions {
  std::string scenario = "band-stretch";  // see ListScenarios()
  std::string out_dir;                    // output folder (created), required
  uint64_t seed = 1;                      // texture, sensor noise and occluder path
  int frames = 120;                       // number of frames, >= 2, default 120
  int width = 640;                        // image width (px), default 640
  int height = 512;                       // image height (px), default 512
  double fps = 25.0;                      // video frame rate, default 25
  int surface_every_k = 1;  // gt/surface and gt/internal every k-th frame (and the last), default 1
  double amplitude =
      1.0;            // scales the grip motions (manipulation speed at fixed frames), default 1
  double zoom = 1.0;  // focal length relative to the scenario's 60-degree view, default 1
  double fine_cell_mm = 5.0;      // band truth mesh spacing (mm), default 5
  double kidney_cell_mm = 2.6;    // kidney truth mesh size (mm), default 2.6
  double membrane_cell_mm = 5.0;  // membranes' model shell grid spacing (mm), default 5
  double noise_sigma = 2.0;       // Gaussian sensor noise (8-bit grey levels), default 2
  double blur_sigma_px = 0.0;     // optional Gaussian blur of the video (px), default 0 (off)
  bool occluder = false;          // draw an instrument-like occluder over the video, default off
  int supersampling = 2;    // anti-aliasing samples per pixel and axis for the video, default 2
  int crf = 14;             // x264 quality (lower is better), default 14
  bool write_video = true;  // false skips rendering and encoding (ground-truth-only runs)
  // Called after each frame with (frames done, total).
  std::function<void(int, int)> progress;
  void Check() const;
};

struct SynthSummary {
  int frames = 0;
  int truth_tetrahedra = 0, truth_vertices = 0;  // at frame 0
  int model_tetrahedra = 0, model_vertices = 0;
  int final_truth_vertices = 0;  // after the cut's vertex duplication
  int newton_iterations = 0;     // over all frames
  int unconverged_frames = 0;
  int snapped_vertices = 0;
  std::vector<double> volume_ratio;  // per frame: truth volume / rest volume
  double max_volume_change = 0;      // max |volume ratio - 1|
  // Cut opening at the last frame: share of the opened cut length (5 mm bins
  // along the cut's path) where the two sides are more than 2 mm apart, and
  // the largest separation (mm). Zero without a cut.
  double cut_open_fraction = 0;
  double max_cut_opening_mm = 0;
  int cut_first_frame = -1, cut_last_frame = -1;  // frames in which cut faces opened
  // Per frame: the largest separation between the copies of a split vertex, over all split
  // vertices (mm); 0 before the cut opens. Empty without a cut.
  std::vector<double> opening_mm;
  double seconds = 0;
};

// Writes video.mp4, scene.json, model.vtk, internal.obj (when present) and gt/
// (meta.json, masks/, surface/, internal/, cut.json, cut_surface.obj) in out_dir.
SynthSummary GenerateSyntheticScene(const SynthOptions& options);

}  // namespace arreg::synth
