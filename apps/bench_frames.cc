// `arreg bench frames`: time per implicit step of a 6-DOF frame model (frames
// skinning samples, Saint Venant-Kirchhoff), a clamped beam sagging under its
// weight, one thread; and how the cost grows with the number of samples.
#include <algorithm>
#include <cstdio>
#include <ostream>
#include <regex>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bench_util.h"
#include "commands.h"
#include "core/error.h"
#include "core/file_util.h"
#include "core/mesh_generators.h"
#include "mechanics/frame_model.h"
#include "mechanics/generalised_solver.h"
#include "mechanics/generalised_terms.h"
#include "mechanics/units.h"
#include "option_parser.h"

namespace arreg::cli {

namespace {

using namespace arreg::mechanics;

struct FrameBenchSettings {
  int steps = 60, warmup = 3, repeats = 5, points_per_tet = 4;
  double dt_s = 1.0 / 30.0, youngs_pa = 30000.0, poisson = 0.3, cell_mm = 10.0;
};

struct FrameFigures {
  std::string grid;
  int frames = 0, samples = 0, dofs = 0;
  double ms_per_step_median = 0, cpu_ms_per_step_median = 0, assembly_ms = 0, solve_ms = 0;
  double tip_sag_mm = 0;
};

Eigen::Vector3i ParseGrid(const std::string& spec, const std::string& option) {
  static const std::regex grid(R"((\d+)x(\d+)x(\d+))");
  std::smatch m;
  if (!std::regex_match(spec, m, grid))
    throw UsageError(option, "expected NXxNYxNZ cells, got '" + spec + "'");
  const Eigen::Vector3i cells(std::stoi(m[1]), std::stoi(m[2]), std::stoi(m[3]));
  if (cells.minCoeff() < 1) throw UsageError(option, "cell counts must be >= 1");
  return cells;
}

// A beam of `cells` tet-split cells (frames at the vertices, barycentric
// weights), clamped at x = 0, released from rest under gravity; each step is
// one implicit-Euler Newton step (the registration's setting).
FrameFigures RunBeam(const Eigen::Vector3i& cells, const FrameBenchSettings& s) {
  const TetMesh mesh = MakeBoxTetMesh(s.cell_mm * cells.cast<double>(), cells);
  const FrameSampling sampling = SampleTetMesh(mesh, s.points_per_tet);
  const Material material{s.youngs_pa, s.poisson, 1000.0};
  GeneralisedImplicitEulerOptions options;
  options.dt_s = s.dt_s;
  options.rayleigh_mass_alpha = 1.0;
  std::vector<double> wall, cpu, assembly, solve;
  FrameFigures f;
  for (int run = 0; run < s.repeats; ++run) {
    GeneralisedState state;
    const std::vector<int> nodes = AddFrameNodes(sampling.frame_positions, &state);
    FrameModel model(state, nodes, sampling.samples, material);
    FrameGravity gravity(&model, {0, 0, -kStandardGravityMmPerS2});
    for (int n : nodes)
      if (state.rest_positions()(n, 0) == 0) {
        state.SetFixedTranslation(n, true);
        state.SetFixedRotation(n, true);
      }
    const std::vector<NodeInertia> inertia = CollectNodeInertia(state, {&model});
    GeneralisedImplicitEuler integrator(options);
    for (int step = 0; step < s.warmup + s.steps; ++step) {
      const double cpu0 = ThreadCpuMs();
      const GeneralisedSummary summary = integrator.Step(&state, {&model}, {&gravity}, inertia);
      const double cpu_ms = ThreadCpuMs() - cpu0;
      ARREG_CHECK_INPUT(summary.status == StepStatus::kConverged, "",
                        "step " + std::to_string(step), "the implicit step failed");
      if (step < s.warmup) continue;
      wall.push_back(summary.total_ms);
      cpu.push_back(cpu_ms);
      assembly.push_back(summary.assembly_ms);
      solve.push_back(summary.solve_ms);
    }
    f.tip_sag_mm = -(state.positions().col(2) - state.rest_positions().col(2)).minCoeff();
    f.frames = model.num_frames();
    f.samples = model.num_samples();
    f.dofs = state.num_dofs();
  }
  f.grid =
      std::to_string(cells.x()) + "x" + std::to_string(cells.y()) + "x" + std::to_string(cells.z());
  f.ms_per_step_median = Median(wall);
  f.cpu_ms_per_step_median = Median(cpu);
  f.assembly_ms = Median(assembly);
  f.solve_ms = Median(solve);
  return f;
}

nlohmann::json FiguresJson(const FrameFigures& f) {
  return {{"grid", f.grid},
          {"frames", f.frames},
          {"samples", f.samples},
          {"dofs", f.dofs},
          {"ms_per_step_median", f.ms_per_step_median},
          {"cpu_ms_per_step_median", f.cpu_ms_per_step_median},
          {"assembly_ms", f.assembly_ms},
          {"solve_ms", f.solve_ms},
          {"tip_sag_mm", f.tip_sag_mm}};
}

void PrintRow(const FrameFigures& f) {
  std::printf("%-10s %7d %8d %7d %9.3f %9.3f %8.3f %8.3f %9.3f\n", f.grid.c_str(), f.frames,
              f.samples, f.dofs, f.ms_per_step_median, f.cpu_ms_per_step_median, f.assembly_ms,
              f.solve_ms, 1e3 * f.cpu_ms_per_step_median / f.samples);
}

}  // namespace

int RunBenchFrames(int argc, char** argv) {
  std::string grid = "17x1x1", sweep_grids = "4x1x1,17x1x1,20x2x2,26x4x4", json_path;
  FrameBenchSettings s;
  bool sweep = false;
  OptionParser parser(
      "arreg bench frames [--grid NXxNYxNZ] [--sweep] [--json OUT]",
      "Times one implicit-Euler step (one Newton step, CHOLMOD) of a 6-DOF frame model: "
      "a beam of tet-split cubic cells with a frame at every vertex and Gauss-point "
      "samples skinned by barycentric weights (4 frames per sample), clamped at one "
      "end, sagging under gravity. The default 17x1x1 grid has 72 frames and 408 "
      "samples. Prints medians over --repeats runs of --steps steps.");
  parser.AddString("grid", &grid, "G", "cells NXxNYxNZ of the beam (default 17x1x1)");
  parser.AddInt("points-per-tet", &s.points_per_tet, "N", "samples per tetrahedron: 1 or 4");
  parser.AddInt("steps", &s.steps, "N", "timed steps per run");
  parser.AddInt("repeats", &s.repeats, "N", "runs (medians over all timed steps)");
  parser.AddDouble("youngs-modulus", &s.youngs_pa, "PA", "Young's modulus in Pa");
  parser.AddDouble("dt", &s.dt_s, "S", "time step in s");
  parser.AddFlag("sweep", &sweep, "also run the grids of --sweep-grids (cost growth table)");
  parser.AddString("sweep-grids", &sweep_grids, "LIST",
                   "comma-separated grids of --sweep (default 96 to 9,984 samples)");
  parser.AddString("json", &json_path, "OUT", "also write the figures to this JSON file");
  parser.SetEpilog(
      "Figures: frames, samples, dofs, ms_per_step_median (wall), cpu_ms_per_step_median\n"
      "(thread CPU time), assembly_ms and solve_ms (medians), tip_sag_mm (largest downward\n"
      "displacement at the end). --sweep adds \"sweep\" (one entry per grid) to the JSON.\n"
      "Run with OMP_NUM_THREADS=1 for one thread.");
  if (!parser.Parse(argc, argv)) return 0;
  if (s.steps < 1) throw UsageError("--steps", "must be >= 1");
  if (s.repeats < 1) throw UsageError("--repeats", "must be >= 1");
  if (s.points_per_tet != 1 && s.points_per_tet != 4)
    throw UsageError("--points-per-tet", "must be 1 or 4");
  if (!(s.dt_s > 0)) throw UsageError("--dt", "must be > 0");
  if (!(s.youngs_pa > 0)) throw UsageError("--youngs-modulus", "must be > 0");
  const Eigen::Vector3i cells = ParseGrid(grid, "--grid");
  std::vector<Eigen::Vector3i> sweep_cells;
  if (sweep) {
    size_t start = 0;
    while (start <= sweep_grids.size()) {
      const size_t end = std::min(sweep_grids.find(',', start), sweep_grids.size());
      if (end > start)
        sweep_cells.push_back(ParseGrid(sweep_grids.substr(start, end - start), "--sweep-grids"));
      start = end + 1;
    }
  }
  std::printf("%-10s %7s %8s %7s %9s %9s %8s %8s %9s\n", "grid", "frames", "samples", "dofs",
              "ms/step", "cpu_ms", "asm_ms", "solve_ms", "us/sample");
  const FrameFigures main_figures = RunBeam(cells, s);
  PrintRow(main_figures);
  nlohmann::json out = FiguresJson(main_figures);
  out["steps"] = s.steps;
  out["repeats"] = s.repeats;
  out["dt_s"] = s.dt_s;
  if (sweep) {
    nlohmann::json series = nlohmann::json::array();
    for (const Eigen::Vector3i& c : sweep_cells) {
      const FrameFigures f = RunBeam(c, s);
      PrintRow(f);
      series.push_back(FiguresJson(f));
    }
    out["sweep"] = series;
  }
  if (!json_path.empty())
    WriteFileAtomic(json_path, [&](std::ostream& os) { os << out.dump(2) << "\n"; });
  return 0;
}

}  // namespace arreg::cli
