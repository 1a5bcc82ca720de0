// `arreg report`: one table over many evaluated runs (a dataset of scenes, each with named
// settings variants), as a self-contained HTML page with distribution plots, CSV and JSON.
#pragma once

#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

namespace arreg::eval {

// One scene and variant: `dir` is a job folder holding eval/report.json (`arreg eval --out`) and
// run/run.json (`arreg run --out`), or an evaluation folder holding report.json itself.
struct AggregateEntry {
  std::string scene;
  std::string variant;
  std::string dir;
};

// "SCENE/VARIANT=DIR", or "DIR": then the scene is the name of DIR's parent folder and the
// variant DIR's own name. Throws arreg::Error naming the argument when a part is empty.
AggregateEntry ParseAggregateEntry(const std::string& argument);

struct AggregateRow {
  std::string scene, variant, dir;
  bool ok = false;     // false: no (readable) evaluation; `error` says why
  std::string error;   // one line: the failing step's error line from its log, or what is missing
  std::string log;     // the log the error line came from ("" when none)
  std::string report;  // path of the scene's own report.html ("" when failed)
  std::string label;   // report.json `label` ("with topology", ...)
  std::optional<double> dice_final, dice_mean;
  std::optional<double> surface_mean_model_to_gt, surface_mean_gt_to_model, surface_max;
  std::optional<double> internal_mean_model_to_gt, internal_mean_gt_to_model, internal_max;
  std::optional<double> feature_error_mean_mm;
  std::optional<double> fps;      // run.json totals.fps_end_to_end (absent without run.json)
  std::optional<double> seconds;  // run.json seconds
  std::optional<int> frames, cuts_applied;
};

// Reads one entry. Never throws for a missing or unreadable evaluation: the row is then failed,
// with the error line (`arreg <cmd>: error: ...`) of the most recent log under DIR/logs/ or
// DIR/../logs/ that has one, else that log's last line, else what is missing.
AggregateRow ReadAggregateRow(const AggregateEntry& entry);

// The rows as report.json holds them: {"rows": [...], "summary": {...}}.
nlohmann::json AggregateToJson(const std::vector<AggregateRow>& rows);

// Writes OUT/report.html (sortable table, strip/box plots of Dice, Hausdorff means and
// frames/s per variant, worst scenes linked to their reports, failed rows with their error),
// OUT/report.csv and OUT/report.json, each atomically.
void WriteAggregateReport(const std::string& out_dir, const std::vector<AggregateRow>& rows);

}  // namespace arreg::eval
