// Debug records of `arreg run --debug`: per frame, everything needed to see why a cut
// was or was not detected, with 2D projections precomputed (docs/debug.md describes the files).
#pragma once

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <string>

#include "ar/pipeline/frame_observer.h"
#include "core/camera.h"
#include "core/mesh.h"

namespace arreg::debug {

struct DebugRecorderOptions {
  std::string run_dir;    // the run folder; records go to run_dir/debug/. Required.
  int jpeg_quality = 90;  // [1, 100] quality of debug/frames/NNNNNN.jpg; default 90
  // Pixel coordinates are rounded to this many decimals in the records (file size). Default 2.
  int pixel_decimals = 2;
  // Throws arreg::Error naming the field.
  void Check() const;
};

// What a mesh wireframe needs in 2D: its unique undirected edges, (#E x 2) flattened as
// [a0, b0, a1, b1, ...], sorted so that the same topology always gives the same list.
std::vector<int> UniqueEdges(const RowMatX3i& faces);

// Builds the JSON record of one frame (docs/debug.md, "Frame record"). `topology_id` is the
// id of the edge file (debug/topology/NNNNNN.json) valid for this frame's surface and internal
// structures. Pure function: used by the recorder and by tests.
nlohmann::json MakeFrameRecord(const pipeline::FrameState& frame, const PinholeCamera& camera,
                               const cutting::CutDetectorOptions& detector, int topology_id,
                               int pixel_decimals = 2);

// The edge file of the surface and the internal structures of `frame`.
nlohmann::json MakeTopologyRecord(const pipeline::FrameState& frame);

// A FrameObserver that writes run_dir/debug/: meta.json (camera, options, frame list), one
// NNNNNN.json per frame, frames/NNNNNN.jpg (the decoded input, encoded once) and
// topology/NNNNNN.json whenever the surface or internal topology changed. Files are written
// atomically; meta.json is rewritten at the end with the final frame count.
class DebugRecorder : public pipeline::FrameObserver {
 public:
  // Throws arreg::Error for invalid options or when run_dir/debug cannot be created.
  explicit DebugRecorder(const DebugRecorderOptions& options);

  void OnStart(const pipeline::RunStart& start) override;
  void OnFrame(const pipeline::FrameState& frame) override;
  void OnFinish(const pipeline::RunSummary& summary) override;

  // Frames recorded so far.
  int frames_recorded() const { return frames_recorded_; }

 private:
  void WriteMeta(bool finished, const pipeline::RunSummary* summary) const;
  bool TopologyChanged(const pipeline::FrameState& frame) const;

  DebugRecorderOptions options_;
  std::string debug_dir_;
  PinholeCamera camera_;
  cutting::CutDetectorOptions detector_;
  nlohmann::json start_json_;
  bool started_ = false;
  int frames_recorded_ = 0;
  int last_frame_ = -1;
  int topology_id_ = -1;  // frame whose topology file is current
  RowMatX3i last_surface_faces_;
  std::vector<RowMatX3i> last_internal_faces_;
  std::vector<int> topology_frames_;
};

// Paths inside a run folder.
std::string DebugDir(const std::string& run_dir);
std::string FrameRecordPath(const std::string& run_dir, int frame);
std::string FrameImagePath(const std::string& run_dir, int frame);
std::string TopologyRecordPath(const std::string& run_dir, int topology_id);
std::string FrameName(int frame);  // "000042"

}  // namespace arreg::debug
