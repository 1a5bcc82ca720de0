// The frame loop of RegistrationPipeline::Run (thesis ch. 7), one method per stage of the data
// flow: decode -> track -> lift -> mechanics -> detect and cut -> output -> render -> encode ->
// record. Step() runs them in that order, timing each on the run's clock.
#pragma once

#include <chrono>
#include <opencv2/core.hpp>
#include <optional>
#include <vector>

#include "ar/lift/lifting.h"
#include "ar/pipeline/cut_handler.h"
#include "ar/pipeline/feature_rows.h"
#include "ar/pipeline/frame_observer.h"
#include "ar/pipeline/overlay.h"
#include "ar/pipeline/registration_pipeline.h"
#include "ar/pipeline/run_mechanics.h"
#include "ar/render/rasterizer.h"
#include "cutting/detection.h"
#include "mechanics/curved_tet.h"
#include "tracking/tracker.h"
#include "tracking/video_io.h"

namespace arreg::pipeline {

class FrameLoop {
 public:
  // The run's model and mechanics, at frame 0 of `reader`. The arguments must outlive this.
  FrameLoop(const Scene& scene, const PipelineOptions& options, const LoadedModel& model,
            VideoReader* reader, const RunOptions& run_options,
            const std::vector<FrameObserver*>& observers);
  FrameLoop(const FrameLoop&) = delete;
  FrameLoop& operator=(const FrameLoop&) = delete;

  int num_frames() const { return num_frames_; }
  // Frame 0: features detected inside the model's silhouette and attached by ray casting, their
  // springs, the detector, the overlay writer; then the observers' OnStart.
  void Start();
  // Processes frame `frame` (0 first); false at the end of the video or when stopped.
  bool Step(int frame);
  // Closes the video and tells the observers; returns the run's summary.
  RunSummary Finish();

 private:
  // What a frame's stages hand on to the next ones.
  struct FrameWork {
    int frame = 0;
    FrameStats stats;
    // Features past their probation this frame (tracking.redetect_every_frames): they join.
    std::vector<const FeatureState*> detected;
    const RowMatX3d* shown = nullptr;            // the organ's output configuration
    const SurfaceMesh* shown_surface = nullptr;  // what is drawn, saved and evaluated
  };

  // Runs `stage` with its time added to `ms_`'s member `field`.
  template <class Stage>
  decltype(auto) Timed(double StageTimes::*field, Stage&& stage);

  // Stages of frame 0 (Start).
  void DetectInitialFeatures();
  std::vector<lift::FeatureAttachment> LiftInitialFeatures();
  void AttachSprings(const std::vector<lift::FeatureAttachment>& attachments);
  void StartDetector();
  void OpenOverlayVideo();
  // Stages of every frame (Step).
  bool Decode(FrameWork* w);
  void Track(FrameWork* w);
  void JoinDetected(FrameWork* w);
  void Lift();
  void StepMechanics(FrameWork* w);
  void DetectAndCut(FrameWork* w);
  void ApplyCut(FrameWork* w);
  void FollowCurvedCut();
  void Output(FrameWork* w);
  void Render(FrameWork* w);
  FrameState Describe(const FrameWork& w, bool is_last) const;

  // The surface features are lifted onto: the organ's boundary, and with thin structures the
  // shells' frame-0 mid-surfaces after it (vertices: the organ's, then ThinSystem's lift
  // vertices).
  const SurfaceMesh& Lifted() const { return mech_.thin ? lift_surface_ : surface_; }
  RowMatX3d LiftVertices() const;
  bool OnShell(const lift::FeatureAttachment& a) const {
    return mech_.thin && a.attached && a.face >= organ_faces0_;
  }

  const Scene& scene_;
  const PipelineOptions& o_;
  const LoadedModel& model_;
  VideoReader& reader_;
  const RunOptions& run_options_;
  const std::vector<FrameObserver*>& observers_;
  const PinholeCamera& camera_;
  const render::RasterCamera raster_;
  double fps_ = 25.0;
  bool cpu_clock_ = false;
  int num_frames_ = 0;
  int save_every_ = 1;

  RunMechanics mech_;
  SurfaceMesh surface_;       // the organ's boundary (cuts add to it), current configuration
  SurfaceMesh lift_surface_;  // with thin structures: organ boundary + shells (frame 0 faces)
  int organ_vertices_ = 0;
  int organ_faces0_ = 0;
  EmbeddedStructures internal_;
  std::vector<mechanics::HighOrderEmbedding> internal_curved_;  // degree 2 and 3
  std::vector<SurfaceMesh> thin_surfaces_;
  RowMatX3d cast_vertices_;  // the lifting surface's vertices, scratch of the lift stages

  FeatureTracker tracker_;
  lift::FeatureLifter lifter_;
  FeatureRows rows_;
  int attached_ = 0, on_thin_ = 0;
  double feature_spacing_mm_ = 0.0;
  SpringStiffness stiffness_;

  std::optional<cutting::CutDetector> detector_;
  std::optional<CutHandler> cut_handler_;
  cutting::DetectionResult detection_;
  std::optional<SurfaceMesh> cut_surface_;
  std::vector<CutEvent> events_;  // this frame's

  OverlayRenderer overlay_;
  VideoWriter writer_;
  cv::Mat bgr_, overlay_image_;
  StageTimes ms_;  // this frame's (frame 0's include the set-up of Start)
  RunSummary summary_;
  std::chrono::steady_clock::time_point run_start_;
};

}  // namespace arreg::pipeline
