// Reading back what `arreg run` and `arreg synth` write for other tools (docs/run-format.md):
// a run's summary (run.json), its per-frame records (frames.jsonl) and a ground-truth folder's
// meta.json. `arreg eval` reads a run through these; they are fuzzed (tests/fuzz/).
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "core/camera.h"

namespace arreg {

// run.json: the fields the evaluation needs.
struct RunSummaryRecord {
  PinholeCamera camera;
  int frames = 0;                            // >= 1
  bool topology = true;                      // cut handling was on
  bool interrupted = false;                  // stopped early (Ctrl-C, SIGTERM, --frames)
  std::vector<std::string> thin_structures;  // names, unique; empty when absent
};
// Throws arreg::Error naming the file and key.
RunSummaryRecord ReadRunSummary(const std::string& path);

// One line of frames.jsonl: the fields the evaluation needs.
struct FrameRecord {
  std::optional<double> feature_error_mean_mm;  // absent or null: no alive springs
  std::optional<double> feature_error_max_mm;
};
// Exactly `num_frames` records numbered 0, 1, ...; blank lines are skipped. Throws arreg::Error
// naming the file and line.
std::vector<FrameRecord> ReadFrameRecords(const std::string& path, int num_frames);

// A ground-truth folder's meta.json: its frame count and, when given, the image size.
struct GroundTruthMeta {
  int frames = 0;
  std::optional<int> width, height;
};
// Throws arreg::Error naming the file and key.
GroundTruthMeta ReadGroundTruthMeta(const std::string& path);

}  // namespace arreg
