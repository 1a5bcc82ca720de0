// The registration controller of `arreg run` (thesis ch. 7): per video frame it tracks,
// lifts, steps the mechanics, handles cuts, renders the overlay and tells its observers.
#pragma once

#include <atomic>
#include <memory>
#include <string>
#include <vector>

#include "ar/pipeline/frame_observer.h"
#include "ar/pipeline/pipeline_options.h"
#include "ar/pipeline/thin_model.h"
#include "core/scene.h"

namespace arreg::pipeline {

// The model as loaded for frame 0: world frame, millimetres.
struct LoadedModel {
  TetMesh mesh;  // scaled by mm_per_unit, world_from_model applied; empty without a model
  std::vector<SurfaceMesh> internal;        // the same transform
  std::vector<std::string> internal_names;  // scene names
  std::vector<Eigen::Vector3d> internal_colors;
  std::vector<double> internal_opacity;
  std::vector<LoadedThin> thin;  // the scene's thin structures, the same transform
};
// Reads the scene's model, internal and thin structures; throws arreg::Error naming the file.
LoadedModel LoadSceneModel(const Scene& scene);

struct RunOptions {
  std::string overlay_video_path;  // "" = no video (the render stage still runs when enabled)
  // Checked after every frame; when set the run stops there (outputs stay complete).
  const std::atomic<bool>* stop = nullptr;
  // Frames whose meshes are saved: every k-th (and the last). 0 (default) uses the ground
  // truth's surface_every_k when the scene names one, else options.output.save_every.
  int save_every = 0;
  // Stage times on this thread's CPU clock instead of the wall clock (benchmarks on a busy
  // machine; decoding and encoding run on this thread with one thread each). Default false.
  bool thread_cpu_clock = false;
};

class RegistrationPipeline {
 public:
  // Validates the options, opens the video and loads the model. Throws arreg::Error.
  RegistrationPipeline(const Scene& scene, const PipelineOptions& options);
  ~RegistrationPipeline();
  RegistrationPipeline(const RegistrationPipeline&) = delete;
  RegistrationPipeline& operator=(const RegistrationPipeline&) = delete;

  // Observers are not owned and must outlive Run().
  void AddObserver(FrameObserver* observer);

  // Processes the video (or options.max_frames frames). Throws arreg::Error on bad input.
  RunSummary Run(const RunOptions& run_options = {});

  const Scene& scene() const;
  const PipelineOptions& options() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace arreg::pipeline
