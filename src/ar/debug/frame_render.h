// One annotated debug frame as an image (`arreg debug --frame N --png OUT.png`): the layers of
// the viewer drawn with OpenCV over the recorded input frame, for reports and bug tickets.
#pragma once

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <string>

namespace arreg::debug {

// Layers that can be drawn; the names are those of `--layers` and of the viewer's checkboxes.
struct DebugLayers {
  bool features =
      true;  // tracked pixels, coloured by status (green alive, grey lost, red not attached)
  bool targets = true;      // projected targets p^1 (blue crosses)
  bool springs = true;      // model point p^t to target p^1 (yellow segments)
  bool pairs = false;       // neighbour graph coloured by mu / (tau * mean mu)
  bool outliers = true;     // outlier pairs (red, thick)
  bool cut = true;          // cut points, polyline (extended dashed), cut surface
  bool mesh = false;        // wireframe of the model surface
  bool internal = false;    // wireframe of the internal structures
  bool numbers = true;      // text panel with the frame's figures
  bool instruments = true;  // instrument outlines and features dropped on them (orange)

  // Parses "features,targets,..." ("all" and "none" too); throws arreg::Error naming the bad
  // layer and listing the valid ones.
  static DebugLayers Parse(const std::string& list);
};

// Colour (BGR) for a ratio r = mu / (tau * mean mu): blue at 0, green at 0.5, red at >= 1.
cv::Scalar RatioColor(double ratio);

// Draws `layers` of the frame record `record` over `image` (BGR, modified in place).
// `topology` is the edge file the record refers to (may be null when mesh/internal are off).
void DrawDebugLayers(const nlohmann::json& record, const nlohmann::json& topology,
                     const DebugLayers& layers, cv::Mat* image);

// Reads run_dir/debug/NNNNNN.json, its image and edges, draws and writes `png_path` atomically.
// Throws arreg::Error naming the file when the frame was not recorded.
void RenderDebugFrame(const std::string& run_dir, int frame, const DebugLayers& layers,
                      const std::string& png_path);

}  // namespace arreg::debug
