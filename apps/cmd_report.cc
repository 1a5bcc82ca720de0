// `arreg report`: one aggregated report over many evaluated runs (scenes x settings variants):
// a sortable HTML table with distribution plots, and the same rows as CSV and JSON.
#include <cstdio>
#include <string>
#include <vector>

#include "ar/eval/aggregate.h"
#include "commands.h"
#include "core/error.h"
#include "option_parser.h"

namespace arreg::cli {

int RunReport(int argc, char** argv) {
  // `--runs A B C` takes every argument up to the next option: rewrite it as repeated --runs.
  std::vector<std::string> args(argv, argv + argc);
  std::vector<std::string> expanded;
  for (size_t i = 0; i < args.size(); ++i) {
    expanded.push_back(args[i]);
    if (args[i] != "--runs") continue;
    bool first = true;
    while (i + 1 < args.size() && args[i + 1].rfind("--", 0) != 0) {
      if (!first) expanded.emplace_back("--runs");
      expanded.push_back(args[++i]);
      first = false;
    }
  }
  std::vector<char*> expanded_argv;
  expanded_argv.reserve(expanded.size());
  for (std::string& a : expanded) expanded_argv.push_back(a.data());

  std::vector<std::string> runs;
  std::string out_dir;
  bool quiet = false;
  OptionParser parser(
      "arreg report --runs DIR... --out AGG",
      "Aggregates the evaluations of many runs (each scene with its settings variants) into one "
      "report: a sortable table, distribution plots of Dice, Hausdorff means and frames/s, the "
      "worst runs linked to their own reports, and failed runs with their one-line error.");
  parser.AddStringList("runs", &runs, "DIR",
                       "[SCENE/VARIANT=]DIR, one or more: a job folder (eval/report.json, "
                       "run/run.json, logs/*.log) or an `arreg eval` folder; without a label the "
                       "scene is DIR's parent folder name and the variant DIR's name");
  parser.AddString("out", &out_dir, "AGG", "report folder (created)", true);
  parser.AddFlag("quiet", &quiet, "print only the report's path");
  parser.SetEpilog(
      "Writes AGG/report.html (self-contained), AGG/report.csv and AGG/report.json (one row per\n"
      "scene and variant; `summary` holds n/min/median/mean/max per metric). A folder without\n"
      "an evaluation is a failed row carrying the error line of its most recent log (DIR/logs/,\n"
      "DIR/../logs/). Exits 0 when the report was written, failed rows or not. See\n"
      "docs/workflow.md.");
  if (!parser.Parse(static_cast<int>(expanded_argv.size()), expanded_argv.data())) return 0;
  if (runs.empty()) throw UsageError("--runs", "at least one DIR is required");

  std::vector<eval::AggregateRow> rows;
  for (const std::string& r : runs) {
    eval::AggregateEntry entry = eval::ParseAggregateEntry(r);
    for (const eval::AggregateRow& seen : rows)
      ARREG_CHECK_INPUT(seen.scene != entry.scene || seen.variant != entry.variant, "",
                        "--runs " + r, "scene ", entry.scene, " variant ", entry.variant,
                        " given twice");
    rows.push_back(eval::ReadAggregateRow(entry));
  }
  eval::WriteAggregateReport(out_dir, rows);
  size_t failed = 0;
  for (const eval::AggregateRow& row : rows) {
    if (row.ok) continue;
    ++failed;
    if (!quiet)
      std::printf("failed: %s / %s: %s\n", row.scene.c_str(), row.variant.c_str(),
                  row.error.c_str());
  }
  if (!quiet)
    std::printf("%zu runs, %zu evaluated, %zu failed\n", rows.size(), rows.size() - failed, failed);
  std::printf("report: %s/report.html\n", out_dir.c_str());
  return 0;
}

}  // namespace arreg::cli
