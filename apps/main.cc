// `arreg`: one binary, one subcommand per job (COLMAP-style dispatch).
#include <cstdio>
#include <cstring>
#include <exception>
#include <string>

#include "commands.h"
#include "core/error.h"
#include "core/version.h"
#include "mechanics/blas_binding.h"
#include "option_parser.h"

namespace {

struct Command {
  const char* name;
  int (*run)(int argc, char** argv);
  const char* summary;
};

// Keep in step with README.md ("Commands").
constexpr Command kCommands[] = {
    {"align", arreg::cli::RunAlign, "place the model from one frame's outline/landmarks (Ceres)"},
    {"bench", arreg::cli::RunBench, "speed benchmarks that print figures and write JSON"},
    {"debug", arreg::cli::RunDebug, "viewer of a run recorded with --debug; annotated frame PNGs"},
    {"eval", arreg::cli::RunEval, "accuracy against ground truth: Dice, Hausdorff, feature error"},
    {"info", arreg::cli::RunInfo, "describe a mesh file (counts, volume, quality)"},
    {"report", arreg::cli::RunReport, "one report over many evaluated runs (table, plots, CSV)"},
    {"run", arreg::cli::RunRun, "register a model to a video (overlay, records)"},
    {"synth", arreg::cli::RunSynth,
     "synthetic benchmark scenes with ground truth (video, masks, cut)"},
};

void PrintUsage(std::FILE* out) {
  std::fprintf(out,
               "usage: arreg <command> [options]\n"
               "       arreg <command> --help\n"
               "       arreg --version\n\n"
               "Registers a pre-operative organ model to laparoscopic video and keeps the\n"
               "registration right through cuts and tears.\n\ncommands:\n");
  for (const auto& c : kCommands) std::fprintf(out, "  %-8s %s\n", c.name, c.summary);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    PrintUsage(stderr);
    return 2;
  }
  const std::string name = argv[1];
  if (name == "--help" || name == "-h" || name == "help") {
    PrintUsage(stdout);
    return 0;
  }
  if (name == "--version") {
    std::printf("arreg %s\n", arreg::kVersion);
    std::printf(
        "blas: %s\n",
        arreg::mechanics::DescribeBlasBinding(arreg::mechanics::ProbeBlasBinding()).c_str());
    return 0;
  }
  for (const auto& c : kCommands) {
    if (name != c.name) continue;
    try {
      // Subcommands see argv shifted by one: argv[0] = "arreg <name>".
      return c.run(argc - 1, argv + 1);
    } catch (const arreg::cli::UsageError& e) {
      std::fprintf(stderr, "arreg %s: usage error: %s\n", c.name, e.what());
      return 2;
    } catch (const arreg::Error& e) {
      std::fprintf(stderr, "arreg %s: error: %s\n", c.name, e.what());
      return 1;
    } catch (const std::exception& e) {
      std::fprintf(stderr, "arreg %s: internal error: %s\n", c.name, e.what());
      return 3;
    }
  }
  std::fprintf(stderr, "arreg: unknown command '%s' (see arreg --help)\n", name.c_str());
  return 2;
}
