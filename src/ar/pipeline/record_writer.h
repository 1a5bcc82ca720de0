// The records of a run (docs/run-format.md): frames.jsonl, the model, its surface and the
// internal structures at record frames, optional PNG frames, and run.json; all atomic.
#pragma once

#include <fstream>
#include <string>

#include "ar/pipeline/frame_observer.h"

namespace arreg::pipeline {

// One JSON object of frames.jsonl for a frame.
nlohmann::json FrameRecord(const FrameState& frame);

class RecordWriter : public FrameObserver {
 public:
  // `out_dir` is created. `write_png` also writes frames/NNNNNN.png of the overlay.
  RecordWriter(std::string out_dir, bool write_png);
  ~RecordWriter() override;

  void OnStart(const RunStart& start) override;
  void OnFrame(const FrameState& frame) override;
  // Commits frames.jsonl and writes run.json.
  void OnFinish(const RunSummary& summary) override;

 private:
  std::string out_dir_;
  bool write_png_ = false;
  std::string jsonl_temporary_;
  std::ofstream jsonl_;
  nlohmann::json run_;  // run.json being filled
};

}  // namespace arreg::pipeline
