// `arreg bench shell`: time per implicit step of a Bezier shell sheet (seed 000
// section 5.3), with and without a mapped fine surface, and its growth with
// the number of elements; one thread.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <ostream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bench_util.h"
#include "commands.h"
#include "core/error.h"
#include "core/file_util.h"
#include "mechanics/bezier_shell.h"
#include "mechanics/generalised_solver.h"
#include "mechanics/generalised_terms.h"
#include "mechanics/linear_solver.h"
#include "mechanics/shell_mapping.h"
#include "option_parser.h"

namespace arreg::cli {

namespace {

using namespace arreg::mechanics;

struct ShellBenchSettings {
  int elements = 1000;         // target element count (a near-square sheet)
  int fine_triangles = 10000;  // mapped fine surface (0: none)
  int steps = 30;
  int repeats = 3;
  double youngs_kpa = 10.0;  // soft tissue
  double thickness_mm = 1.0;
  double cell_mm = 5.0;
  std::string solver = "cholmod";               // linear solver of the step
  std::string preconditioner = "block-jacobi";  // CG preconditioner
  std::string factorization = "auto";           // CHOLMOD: supernodal, simplicial, auto
};

struct ShellFigures {
  int elements = 0, nodes = 0, dofs = 0, fine_points = 0, fine_triangles = 0;
  double ms_per_step_median = 0;      // solver step (assembly + factorisation + solve), wall
  double cpu_ms_per_step_median = 0;  // the same in thread CPU time
  double cpu_mapping_ms_median = 0;
  double cpu_element_ms_median = 0;  // element gradients and Hessians at one state
  double mapping_ms_median = 0;      // fine positions + velocities + force projection
  double ms_per_step_with_fine_median = 0;
  double assembly_ms_median = 0, solve_ms_median = 0;
  int newton_iterations = 0;
  double factorizations_per_step = 0;  // numeric Cholesky factorisations / timed steps
  double cg_iterations_per_step = 0;   // CG iterations / timed steps (cg, cholmod-pcg)
};

// A sheet of nx x ny square cells (two triangles each) in the xy plane,
// clamped along x = 0, under gravity (-z) and pulled by springs from four
// nodes to targets that move on a slow circle (as features would).
ShellFigures RunSheet(const ShellBenchSettings& s) {
  const int cells = std::max(1, s.elements / 2);
  const int nx = std::max(1, static_cast<int>(std::lround(std::sqrt(2.0 * cells))));
  const int ny = std::max(1, (cells + nx - 1) / nx);
  GeneralisedState state;
  auto node = [&](int i, int j) { return j * (nx + 1) + i; };
  for (int j = 0; j <= ny; ++j)
    for (int i = 0; i <= nx; ++i)
      state.AddFrameNode(Eigen::Vector3d(i * s.cell_mm, j * s.cell_mm, 0),
                         Eigen::Matrix3d::Identity());
  std::vector<Eigen::Vector3i> triangles;
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      triangles.push_back({node(i, j), node(i + 1, j), node(i + 1, j + 1)});
      triangles.push_back({node(i, j), node(i + 1, j + 1), node(i, j + 1)});
    }
  for (int j = 0; j <= ny; ++j) {
    state.SetFixedTranslation(node(0, j), true);
    state.SetFixedRotation(node(0, j), true);
  }
  BezierShellOptions options;
  options.material.youngs_modulus_kpa = s.youngs_kpa;
  options.material.poisson_ratio = 0.45;
  options.material.thickness_mm = s.thickness_mm;
  BezierShell shell(state, triangles, options);
  const std::vector<NodeInertia> inertia = CollectNodeInertia(state, {&shell});
  GravityTerm gravity(inertia, Eigen::Vector3d(0, 0, -9810.0));
  ZeroLengthSpringTerm springs;
  const int pulled[4] = {node(nx, 0), node(nx, ny), node(nx / 2, ny / 2), node(nx, ny / 2)};
  std::vector<int> ids;
  for (int n : pulled)
    ids.push_back(
        springs.Add(SpringAnchor::AtNode(n), SpringAnchor::Fixed(state.position(n)), 0.5));

  // Fine surface: each element split into k^2 sub-triangles.
  const int k = s.fine_triangles > 0
                    ? std::max(1, static_cast<int>(std::lround(
                                      std::sqrt(double(s.fine_triangles) / shell.num_elements()))))
                    : 0;
  std::vector<ShellSurfacePoint> points;
  for (int e = 0; k > 0 && e < shell.num_elements(); ++e)
    for (int a = 0; a <= k; ++a)
      for (int b = 0; a + b <= k; ++b) points.push_back({e, double(a) / k, double(b) / k});
  const ShellMapping mapping(shell, points);
  RowMatX3d fine_x, fine_v, fine_f = RowMatX3d::Zero(mapping.size(), 3);
  if (mapping.size() > 0) fine_f.col(2).setConstant(-1e-3);  // contact-like pressure
  Eigen::VectorXd projected(state.num_dofs());

  GeneralisedImplicitEulerOptions euler;
  euler.dt_s = 1.0 / 30.0;
  euler.linear_solver.type = ParseLinearSolverType(s.solver);
  euler.linear_solver.preconditioner = ParsePreconditioner(s.preconditioner);
  euler.linear_solver.factorization = ParseCholmodFactorization(s.factorization);
  GeneralisedImplicitEuler integrator(euler);
  ShellFigures f;
  f.elements = shell.num_elements();
  f.nodes = state.num_nodes();
  f.dofs = state.num_dofs();
  f.fine_points = mapping.size();
  f.fine_triangles = k * k * shell.num_elements();
  std::vector<double> step_ms, map_ms, assembly_ms, solve_ms, cpu_ms, cpu_map_ms, update_ms;
  const GeneralisedState start = state;
  for (int r = 0; r < s.repeats; ++r) {
    state = start;
    for (int step = 0; step < s.steps + 2; ++step) {
      const double phase = 2 * M_PI * step / 60.0;
      for (size_t i = 0; i < ids.size(); ++i)
        springs.SetFixedPoint(ids[i],
                              state.rest_positions().row(pulled[i]).transpose() +
                                  10.0 * Eigen::Vector3d(0, std::sin(phase), 1 - std::cos(phase)));
      // The element work alone (frame, log maps, gradient, Gauss-Newton blocks), timed
      // apart: the step below repeats it.
      const double u0 = ThreadCpuMs();
      projected.setZero();
      shell.AddGradient(state, &projected);
      update_ms.push_back(ThreadCpuMs() - u0);
      const double t0 = WallMs(), c0 = ThreadCpuMs();
      const GeneralisedSummary summary =
          integrator.Step(&state, {&shell}, {&gravity, &springs}, inertia);
      const double t1 = WallMs(), c1 = ThreadCpuMs();
      if (mapping.size() > 0) {
        mapping.Positions(state, &fine_x);
        mapping.Velocities(state, &fine_v);
        projected.setZero();
        mapping.AddForces(state, fine_f, &projected);
      }
      const double t2 = WallMs(), c2 = ThreadCpuMs();
      if (summary.status == StepStatus::kLinearSolveFailed)
        throw Error("", "arreg bench shell", "linear solve failed: " + summary.message);
      if (step < 2) {  // pattern, symbolic factorisation
        update_ms.pop_back();
        continue;
      }
      step_ms.push_back(t1 - t0);
      map_ms.push_back(t2 - t1);
      cpu_ms.push_back(c1 - c0);
      cpu_map_ms.push_back(c2 - c1);
      assembly_ms.push_back(summary.assembly_ms);
      solve_ms.push_back(summary.solve_ms);
      f.newton_iterations += summary.newton_iterations;
      f.factorizations_per_step += summary.factorizations;
      f.cg_iterations_per_step += summary.linear_iterations;
    }
  }
  f.factorizations_per_step /= static_cast<double>(step_ms.size());
  f.cg_iterations_per_step /= static_cast<double>(step_ms.size());
  f.ms_per_step_median = Median(step_ms);
  f.mapping_ms_median = Median(map_ms);
  f.cpu_ms_per_step_median = Median(cpu_ms);
  f.cpu_mapping_ms_median = Median(cpu_map_ms);
  f.cpu_element_ms_median = Median(update_ms);
  std::vector<double> total(step_ms.size());
  for (size_t i = 0; i < step_ms.size(); ++i) total[i] = step_ms[i] + map_ms[i];
  f.ms_per_step_with_fine_median = Median(total);
  f.assembly_ms_median = Median(assembly_ms);
  f.solve_ms_median = Median(solve_ms);
  return f;
}

nlohmann::json ToJson(const ShellFigures& f) {
  return {{"elements", f.elements},
          {"nodes", f.nodes},
          {"dofs", f.dofs},
          {"fine_triangles", f.fine_triangles},
          {"fine_points", f.fine_points},
          {"ms_per_step_median", f.ms_per_step_median},
          {"cpu_ms_per_step_median", f.cpu_ms_per_step_median},
          {"cpu_mapping_ms_median", f.cpu_mapping_ms_median},
          {"cpu_element_ms_median", f.cpu_element_ms_median},
          {"assembly_ms_median", f.assembly_ms_median},
          {"solve_ms_median", f.solve_ms_median},
          {"factorizations_per_step", f.factorizations_per_step},
          {"cg_iterations_per_step", f.cg_iterations_per_step},
          {"mapping_ms_median", f.mapping_ms_median},
          {"ms_per_step_with_fine_median", f.ms_per_step_with_fine_median}};
}

void Print(const ShellFigures& f) {
  std::printf(
      "%6d elements %6d dofs: %8.3f ms/step (cpu %.3f, of which elements %.3f; assembly %.3f, "
      "solve %.3f; %.2f factorisations, %.1f CG iterations per step) | fine %6d tris: mapping "
      "%.3f ms (cpu %.3f), total %8.3f ms\n",
      f.elements, f.dofs, f.ms_per_step_median, f.cpu_ms_per_step_median, f.cpu_element_ms_median,
      f.assembly_ms_median, f.solve_ms_median, f.factorizations_per_step, f.cg_iterations_per_step,
      f.fine_triangles, f.mapping_ms_median, f.cpu_mapping_ms_median,
      f.ms_per_step_with_fine_median);
}

}  // namespace

int RunBenchShell(int argc, char** argv) {
  ShellBenchSettings s;
  std::string json_path;
  bool sweep = false;
  OptionParser parser(
      "arreg bench shell [--elements N] [--fine N] [--steps N] [--sweep] [--json OUT]",
      "Times one implicit Euler step (one Newton step, CHOLMOD) of a Bezier shell sheet "
      "clamped on one side, under gravity and pulled by four springs, and the update of a "
      "mapped fine surface (positions, velocities, force projection). Medians over "
      "--repeats runs of --steps steps.");
  parser.AddInt("elements", &s.elements, "N", "shell elements (a near-square sheet); 1000");
  parser.AddInt("fine", &s.fine_triangles, "N",
                "triangles of the mapped fine surface (0: none); 10000");
  parser.AddInt("steps", &s.steps, "N", "timed steps per run; 30");
  parser.AddString("solver", &s.solver, "S", "linear solver: cholmod (default), cg, cholmod-pcg");
  parser.AddString("preconditioner", &s.preconditioner, "P",
                   "CG preconditioner: none, jacobi, block-jacobi (default), ichol");
  parser.AddString("factorization", &s.factorization, "F",
                   "CHOLMOD factorisation: supernodal, simplicial, auto (default)");
  parser.AddInt("repeats", &s.repeats, "N", "runs; 3");
  parser.AddFlag("sweep", &sweep,
                 "also time 100, 300, 1000, 3000 and 10000 elements (fine surface 10x the "
                 "elements) and fit the growth exponent");
  parser.AddString("json", &json_path, "OUT", "also write the figures to this JSON file");
  parser.SetEpilog(
      "Figures: elements, dofs, ms_per_step_median (the solver step: assembly + numeric\n"
      "factorisation + solve, wall), cpu_ms_per_step_median (thread CPU), cpu_element_ms_median\n"
      "(the shell's element work alone), assembly_ms_median, solve_ms_median,\n"
      "mapping_ms_median and cpu_mapping_ms_median (fine positions + velocities + force\n"
      "projection), ms_per_step_with_fine_median (step + mapping), factorizations_per_step\n"
      "and cg_iterations_per_step.\n"
      "--sweep adds \"sweep\" and \"growth_exponent\". Run with OMP_NUM_THREADS=1.");
  if (!parser.Parse(argc, argv)) return 0;
  auto require = [](bool ok, const std::string& option, const std::string& message) {
    if (!ok) throw UsageError(option, message);
  };
  require(s.elements >= 2, "--elements", "must be >= 2, got " + std::to_string(s.elements));
  require(s.fine_triangles >= 0, "--fine", "must be >= 0");
  require(s.steps >= 1, "--steps", "must be >= 1");
  require(s.repeats >= 1, "--repeats", "must be >= 1");
  ParseLinearSolverType(s.solver);
  ParsePreconditioner(s.preconditioner);
  ParseCholmodFactorization(s.factorization);

  const ShellFigures main = RunSheet(s);
  Print(main);
  nlohmann::json out = ToJson(main);
  if (sweep) {
    nlohmann::json series = nlohmann::json::array();
    std::vector<double> elements, ms;
    for (int e : {100, 300, 1000, 3000, 10000}) {
      ShellBenchSettings t = s;
      t.elements = e;
      t.fine_triangles = 10 * e;
      t.steps = std::max(3, std::min(s.steps, 300000 / e / 10));
      const ShellFigures f = RunSheet(t);
      Print(f);
      series.push_back(ToJson(f));
      elements.push_back(f.elements);
      ms.push_back(f.ms_per_step_median);
    }
    const double exponent = GrowthExponent(elements, ms);
    std::printf("growth exponent (ms per step ~ elements^k, least squares): k = %.2f\n", exponent);
    out["sweep"] = series;
    out["growth_exponent"] = exponent;
  }
  if (!json_path.empty())
    WriteFileAtomic(json_path, [&](std::ostream& os) { os << out.dump(2) << "\n"; });
  return 0;
}

}  // namespace arreg::cli
