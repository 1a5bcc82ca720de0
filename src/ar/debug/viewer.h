// The offline debug viewer (`arreg debug --run DIR --out VIEWER`): one self-contained folder
// (index.html, viewer.js, per-frame data scripts, frame images) that works from file://.
#pragma once

#include <string>

namespace arreg::debug {

struct ViewerOptions {
  // Frames copied at most, taken from the start; -1 (default) = every recorded frame.
  int max_frames = -1;
  // Title shown in the page; "" (default) uses the run folder's name.
  std::string title;
  void Check() const;  // throws arreg::Error naming the field
};

struct ViewerSummary {
  int frames = 0;          // frames in the viewer
  int features = 0;        // distinct feature ids over all frames
  int topology_files = 0;  // mesh edge files
  long long bytes = 0;     // size of the viewer folder
};

// Reads run_dir/debug/ (written by DebugRecorder) and writes the viewer into out_dir. The folder
// is built beside out_dir and renamed into place, so an existing viewer is replaced whole or not
// at all. Throws arreg::Error naming the file when the records are missing or malformed.
ViewerSummary WriteDebugViewer(const std::string& run_dir, const std::string& out_dir,
                               const ViewerOptions& options = {});

}  // namespace arreg::debug
