// `arreg bench <what>`: speed and accuracy benchmarks that print figures and write JSON.
// Each benchmark lives in its own apps/bench_*.cc; this file only dispatches.
#include <cstdio>
#include <string>

#include "commands.h"
#include "core/error.h"
#include "option_parser.h"

namespace arreg::cli {

namespace {
struct Bench {
  const char* name;
  int (*run)(int argc, char** argv);
  const char* summary;
};

// Keep in step with README.md ("Benchmarks").
const Bench kBenches[] = {
    {"accuracy", RunBenchAccuracy,
     "cut detection and registration accuracy over the scene manifest (dev/test splits)"},
    {"align", RunBenchAlign,
     "align from perturbed poses (kidney, band): success rates, time per frame"},
    {"cutting", RunBenchCutting, "beam cut: ours vs Bielser (growth, conditioning), event time"},
    {"detection", RunBenchDetection, "cut detection per frame (700 features, ~9,000 pairs)"},
    {"frames", RunBenchFrames,
     "6-DOF frame model: implicit step of 72 frames / 408 samples (ms/step), cost growth"},
    {"mechanics", RunBenchMechanics,
     "implicit corotational step driven by springs (ms/step, phases)"},
    {"pipeline", RunBenchPipeline,
     "arreg run per stage (decode .. encode), fps with/without video"},
    {"shell", RunBenchShell,
     "Bezier shell: implicit step of 1,000 elements (+10,000 mapped triangles), cost growth"},
    {"tracking", RunBenchTracking, "video decode, SURF detection and LK tracking speed"},
    {nullptr, nullptr, nullptr},  // end marker; keeps the table valid while it grows
};

void PrintBenchUsage(std::FILE* out) {
  std::fprintf(out,
               "usage: arreg bench <what> [options]\n"
               "       arreg bench <what> --help\n\n"
               "Speed benchmarks print their figures (medians over repeated runs, one\n"
               "thread); `accuracy` scores registration and cut detection against ground\n"
               "truth. Each writes its figures as JSON with --json OUT.\n\nbenchmarks:\n");
  for (const auto& b : kBenches)
    if (b.name) std::fprintf(out, "  %-10s %s\n", b.name, b.summary);
}
}  // namespace

int RunBench(int argc, char** argv) {
  if (argc < 2) {
    PrintBenchUsage(stderr);
    return 2;
  }
  const std::string what = argv[1];
  if (what == "--help" || what == "-h") {
    PrintBenchUsage(stdout);
    return 0;
  }
  for (const auto& b : kBenches)
    if (b.name && what == b.name) return b.run(argc - 1, argv + 1);
  throw UsageError("bench '" + what + "'", "unknown benchmark (see arreg bench --help)");
}

}  // namespace arreg::cli
