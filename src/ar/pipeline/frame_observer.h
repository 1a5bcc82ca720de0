// Read-only view of one registration frame and the observer interface through which the
// progress bar, the record writer and the debug recorder follow a run.
#pragma once

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "ar/lift/lifting.h"
#include "ar/pipeline/pipeline_options.h"
#include "core/mesh.h"
#include "core/scene.h"
#include "cutting/detection.h"
#include "mechanics/mechanical_state.h"
#include "tracking/tracker.h"

namespace arreg::pipeline {

struct PipelineOptions;
struct SpringStiffness;

// Milliseconds spent per stage in one frame (or summed over a run).
struct StageTimes {
  double decode = 0, track = 0, lift = 0, mechanics = 0, cutting = 0, render = 0, encode = 0;
  double record = 0;  // observers (records, debug); not part of `Total()` of the frame itself
  double Total() const { return decode + track + lift + mechanics + cutting + render + encode; }
  StageTimes& operator+=(const StageTimes& o);
  nlohmann::json ToJson() const;  // {"decode": ms, ...}
};

// One feature attached at frame 0 (row r of every per-feature matrix below).
struct FeatureView {
  int id = 0;  // tracker id (TrackStore)
  // Where the tracker has it now (last position when lost).
  Eigen::Vector2d pixel = Eigen::Vector2d::Zero();
  TrackStatus track_status = TrackStatus::kTracked;  // this frame (final once not kTracked)
  // Its tracking window overlaps the instrument mask this frame (FeatureTracker::
  // WindowOnInstrument): its pairs are no evidence of a cut (cutting.ignore_occluded_pairs).
  bool window_on_instrument = false;
  lift::LiftStatus lift_status = lift::LiftStatus::kNotAttached;
  bool alive = false;  // tracked and attached: its spring acts
  int spring = -1;     // SpringEnergy id, -1 when never attached to the organ
  // Attached to the organ (spring >= 0) or to a thin structure (a ThinSystem spring): the
  // cut detector's features, in row order.
  bool attached = false;
  bool spring_active = false;     // false once lost or removed near a cut
  double spring_length_mm = 0.0;  // |anchor - target| (0 for inactive springs)
};

// What a topology event did.
enum class CutEventStatus {
  kCut,         // the model (or a thin structure) was cut
  kNoCrossing,  // S crossed nothing: nothing changed
  kRejected,    // the cut would have damaged the mesh: nothing changed (message says why)
  kFailed,      // the cut or the mechanics after it failed (message says why)
};
// The spelling in frames.jsonl: "cut", "no-crossing", "rejected", "failed".
inline const char* CutEventStatusName(CutEventStatus status) {
  switch (status) {
    case CutEventStatus::kCut:
      return "cut";
    case CutEventStatus::kNoCrossing:
      return "no-crossing";
    case CutEventStatus::kRejected:
      return "rejected";
    case CutEventStatus::kFailed:
      return "failed";
  }
  return "?";
}

// A topology event of the cutting stage.
struct CutEvent {
  int frame = 0;
  CutEventStatus status = CutEventStatus::kNoCrossing;
  std::string message;  // why, for rejected/failed
  int polyline_points = 0;
  int new_tetrahedra = 0;              // #T after - #T before
  int new_vertices = 0;                // inserted + duplicated
  int springs_removed = 0;             // within the margin of S
  int internal_triangles_removed = 0;  // deleted (CuttingStageOptions::internal_caps false)
  // Faces the internal structures gained on the crack: caps, both sides (internal_caps).
  int internal_cap_faces = 0;
  // Depth of the applied S behind the polyline, as a fraction of the extent that covers the
  // model (below 1 when CuttingStageOptions::keep_connected cut again shallower); 0 if none.
  double depth_fraction = 0.0;
  // Configuration S was built and cut in (CuttingStageOptions::cut_configuration; kCurrent also
  // when the rest one could not apply); none when nothing was cut. Written as "rest", "current"
  // or "".
  std::optional<CutConfiguration> configuration;
  // Vertices of debris (pieces below 0.5 % of the rest volume) welded to the nearest piece by
  // this event (CutHandler::FollowWelds).
  int welded_vertices = 0;
  // The polyline S was extruded from, in the rest (frame-0, world mm) configuration: in the
  // rest configuration the line that was cut (its ends carried across the outline), in the
  // current one the frame-0 positions of the detector's points. Empty unless status is kCut.
  std::vector<Eigen::Vector3d> polyline_rest_mm;
  // Thin structures the same cut separated (written only for scenes with thin structures).
  bool thin = false;
  int thin_shells_cut = 0, thin_shell_nodes_added = 0;
  int thin_vessels_cut = 0, thin_vessel_frames_added = 0;
  nlohmann::json ToJson() const;
};

// Per-frame figures written to frames.jsonl.
struct FrameStats {
  int features_alive = 0;  // springs acting this frame
  int outliers = 0;        // features dropped by the spatio-temporal filter this frame
  int lost = 0;            // features lost this frame (any reason)
  int added = 0;           // features re-detected and attached this frame (fill-in of holes)
  // The video's frame was damaged (the reader stood the last good frame in for it): it was
  // not tracked; the model stepped towards the targets it already had.
  bool damaged = false;
  double spring_length_mean_mm = 0, spring_length_max_mm = 0;  // over alive springs
  int inverted_elements = 0;
  std::string mechanics_status;   // StepStatusName of the integrator
  int linear_iterations = 0;      // CG iterations of the step (0 with a direct solve)
  int factorizations = 0;         // numeric Cholesky factorisations in the step
  int line_search_cuts = 0;       // halvings of the step's Newton increment (integrator)
  std::string output_fit_status;  // StepStatusName of the output fit; empty when it is off
};

// Everything known about one frame; valid only during FrameObserver::OnFrame.
struct FrameState {
  int frame = 0;
  double time_s = 0;                 // frame / fps
  bool is_last = false;              // last frame of the run (end of video, max_frames or Ctrl-C)
  bool save_meshes = false;          // a record frame (ground-truth frames, every k-th, the last)
  const cv::Mat* image = nullptr;    // decoded BGR frame
  const cv::Mat* overlay = nullptr;  // rendered overlay (empty Mat when rendering is off)
  const std::vector<FeatureView>* features = nullptr;
  // The tracker's instrument mask of this frame (CV_8UC1, 255 on instruments); empty when
  // instrument rejection is off. Features on it are dropped (TrackStatus::kInstrument).
  const cv::Mat* instrument_mask = nullptr;
  const RowMatX3d* targets_mm = nullptr;  // (#features x 3) p^1_F, world
  const RowMatX3d* anchors_mm = nullptr;  // (#features x 3) p^t_F on the current model, world
  // Cut detection this frame; nullptr without topology handling.
  const cutting::DetectionResult* detection = nullptr;
  const std::vector<CutEvent>* cut_events = nullptr;  // of this frame
  const SurfaceMesh* cut_surface = nullptr;           // last S (world), nullptr before any
  const mechanics::MechanicalState* state = nullptr;  // the dynamic model (world, mm)
  // (#V x 3) the output configuration in mm (world): the output fit, else the state's
  // positions. surface and internal are at these positions.
  const RowMatX3d* positions = nullptr;
  const SurfaceMesh* surface = nullptr;  // boundary of the model, current positions (world)
  // Internal structures at their current positions (world), one per scene structure.
  const std::vector<SurfaceMesh>* internal = nullptr;
  const std::vector<std::string>* internal_names = nullptr;
  // Thin structures at their current positions (world): a shell's visual surface (else its
  // mid-surface), a vessel's tube; one per scene thin structure. nullptr when there are none.
  const std::vector<SurfaceMesh>* thin = nullptr;
  const std::vector<std::string>* thin_names = nullptr;
  FrameStats stats;
  StageTimes ms;
};

struct RunStart {
  const Scene* scene = nullptr;
  const PipelineOptions* options = nullptr;
  int expected_frames = 0;  // frames the run will process unless stopped
  double fps = 0;
  int width = 0, height = 0;
  int model_vertices = 0, model_tetrahedra = 0;
  int thin_shell_elements = 0, thin_nodes = 0;  // the generalised system (0 without thin)
  int features_on_thin = 0;                     // of features_attached: on a shell
  int features_detected = 0, features_attached = 0;
  const SpringStiffness* springs = nullptr;  // the feature spring stiffness resolved at frame 0
  int tethered_vertices = 0;  // model vertices out of view held by the out-of-view tether
  // The cut detector's options in use: radii resolved from the features at Initialize. Null
  // without cut handling.
  const cutting::CutDetectorOptions* detector = nullptr;
};

struct RunSummary {
  int frames = 0;            // processed
  bool interrupted = false;  // stopped by the stop flag (Ctrl-C)
  bool topology = true;      // cut handling on
  StageTimes total_ms;       // summed over frames
  int cut_events = 0;
  int cuts_applied = 0;
  std::vector<int> damaged_frames;  // frames the video had damaged (not tracked), ascending
  double seconds = 0;               // wall time of the run loop
};

// Hooks called by RegistrationPipeline::Run, in the order observers were added.
// Exceptions thrown by an observer abort the run.
class FrameObserver {
 public:
  virtual ~FrameObserver() = default;
  virtual void OnStart(const RunStart& start) {}
  virtual void OnFrame(const FrameState& frame) = 0;
  virtual void OnFinish(const RunSummary& summary) {}
};

}  // namespace arreg::pipeline
