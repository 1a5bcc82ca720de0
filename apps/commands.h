// The `arreg` subcommands. Each RunX() parses its own options, calls into the
// library and returns the process exit code; errors propagate as exceptions
// and main() turns them into a one-line message and exit code 1 (2 for usage).
#pragma once

namespace arreg::cli {

int RunAlign(int argc, char** argv);
int RunBench(int argc, char** argv);
int RunDebug(int argc, char** argv);
int RunEval(int argc, char** argv);
int RunInfo(int argc, char** argv);
int RunReport(int argc, char** argv);
int RunRun(int argc, char** argv);
int RunSynth(int argc, char** argv);

// Benchmarks dispatched by RunBench (apps/bench_*.cc).
int RunBenchAccuracy(int argc, char** argv);
int RunBenchAlign(int argc, char** argv);
int RunBenchCutting(int argc, char** argv);
int RunBenchDetection(int argc, char** argv);
int RunBenchMechanics(int argc, char** argv);
int RunBenchFrames(int argc, char** argv);
int RunBenchPipeline(int argc, char** argv);
int RunBenchShell(int argc, char** argv);
int RunBenchTracking(int argc, char** argv);

}  // namespace arreg::cli
