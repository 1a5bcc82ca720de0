// `arreg bench mechanics`: time per implicit step of a spring-driven body like
// the registration's (element rotations, assembly, solve), one thread.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>
#include <ostream>
#include <random>
#include <regex>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bench_util.h"
#include "commands.h"
#include "core/error.h"
#include "core/file_util.h"
#include "core/mesh_generators.h"
#include "core/mesh_io.h"
#include "mechanics/embedding.h"
#include "mechanics/integrator.h"
#include "mechanics/spring_energy.h"
#include "option_parser.h"

namespace arreg::cli {

namespace {

using namespace arreg::mechanics;

double Mean(const std::vector<double>& values) {
  ARREG_ASSERT(!values.empty(), "");
  double sum = 0;
  for (double v : values) sum += v;
  return sum / static_cast<double>(values.size());
}

// "box:NXxNYxNZ" (Kuhn 6-tet split, 10 mm cells) or "box5:..." (5-tet split),
// otherwise a mesh file.
TetMesh LoadMesh(const std::string& spec) {
  static const std::regex box(R"((box5?):(\d+)x(\d+)x(\d+))");
  std::smatch m;
  if (std::regex_match(spec, m, box)) {
    const Eigen::Vector3i cells(std::stoi(m[2]), std::stoi(m[3]), std::stoi(m[4]));
    return MakeBoxTetMesh(10.0 * cells.cast<double>(), cells,
                          m[1] == "box5" ? BoxTetSplit::kFive : BoxTetSplit::kSix);
  }
  return ReadTetMesh(spec);
}

struct Figures {
  int tets = 0, dofs = 0, springs = 0, steps = 0, repeats = 0;
  double ms_per_step_median = 0, cpu_ms_per_step_median = 0;
  double ms_per_step_mean = 0, cpu_ms_per_step_mean = 0, cpu_ms_per_step_max = 0;
  double rotation_ms = 0, assembly_ms = 0, solve_ms = 0;
  double cg_iterations_mean = 0, rotation_iterations_mean = 0, max_displacement_mm = 0;
  int inverted_elements = 0, factorizations = 0, line_search_cuts = 0;
  // --check-accuracy: per step, |y - y_ref| / |y_ref - x_n| of the benchmarked
  // step against one Newton step solved by exact Cholesky (solver error) and of
  // that against the fully converged implicit Euler step (linearisation error
  // of one Newton step).
  bool accuracy_checked = false;
  double solver_error_median = 0, solver_error_max = 0;
  double newton_error_median = 0, newton_error_max = 0;
};

struct BenchSettings {
  std::string solver = "cholmod-pcg", preconditioner = "jacobi", rotation = "polar";
  std::string factorization = "auto";
  int steps = 200, warmup = 5, repeats = 5, springs = 200;
  double dt_s = 1.0 / 30.0, stiffness = 10.0, youngs_pa = 3000.0, poisson = 0.45;
  double cg_tolerance = 1e-3, amplitude = 0.05;
  int refactor_iterations = 20;
  bool refactor_by_cost = true, check_accuracy = false, line_search = true;
  std::string warm_start = "extrapolate";
  unsigned seed = 1;
};

// Springs from random points near the mesh surface to targets moving along
// a smooth field (a few percent of the organ size), as tracked features do.
Figures RunScene(const TetMesh& mesh, const BenchSettings& s) {
  Figures f;
  const Material material{s.youngs_pa, s.poisson, 1000.0};
  std::mt19937 rng(s.seed);
  const Eigen::RowVector3d lo = mesh.vertices.colwise().minCoeff();
  const Eigen::RowVector3d hi = mesh.vertices.colwise().maxCoeff();
  const double size = (hi - lo).norm();
  // Anchors: vertices picked at random (surface or not), nudged by 1 % of the size.
  std::uniform_int_distribution<int> pick(0, mesh.num_vertices() - 1);
  std::normal_distribution<double> nudge(0.0, 0.01 * size);
  RowMatX3d anchors(s.springs, 3);
  for (int i = 0; i < s.springs; ++i)
    anchors.row(i) =
        mesh.vertices.row(pick(rng)) + Eigen::RowVector3d(nudge(rng), nudge(rng), nudge(rng));
  const EmbeddedPoints embedded = EmbeddedPoints::Embed(anchors, mesh.vertices, mesh.tetrahedra);

  ImplicitEulerOptions options;
  options.dt_s = s.dt_s;
  options.rayleigh_mass_alpha = 1.0;
  options.linear_solver.type = ParseLinearSolverType(s.solver);
  options.linear_solver.preconditioner = ParsePreconditioner(s.preconditioner);
  options.linear_solver.relative_tolerance = s.cg_tolerance;
  options.linear_solver.factorization = ParseCholmodFactorization(s.factorization);
  options.linear_solver.refactor_iterations = s.refactor_iterations;
  options.linear_solver.refactor_by_cost = s.refactor_by_cost;
  options.warm_start = s.warm_start == "velocity" ? WarmStart::kVelocity : WarmStart::kExtrapolate;
  options.line_search = s.line_search;
  // References for --check-accuracy: one Newton step by exact Cholesky, and
  // Newton iterated to convergence.
  ImplicitEulerOptions exact_options = options;
  exact_options.linear_solver.type = LinearSolverType::kCholmod;
  ImplicitEulerOptions newton_options = exact_options;
  newton_options.newton_mode = NewtonMode::kFullNewton;
  newton_options.max_newton_iterations = 50;
  newton_options.newton_tolerance_mm = 1e-9;
  std::vector<double> solver_errors, newton_errors;
  CorotationalOptions corotational;
  corotational.rotation_method = ParseRotationMethod(s.rotation);

  std::vector<double> wall, cpu, rotation, assembly, solve;
  double cg_iterations = 0, rotation_iterations = 0;
  int timed_steps = 0;
  for (int run = 0; run < s.repeats; ++run) {
    MechanicalState state(mesh, material);
    CorotationalElasticity elastic(corotational);
    SpringEnergy springs;
    for (int i = 0; i < embedded.size(); ++i)
      springs.Add(embedded[i], anchors.row(i).transpose(), s.stiffness);
    ImplicitEulerIntegrator integrator(options);
    ImplicitEulerIntegrator exact(exact_options), newton(newton_options);
    for (int step = 0; step < s.warmup + s.steps; ++step) {
      // Targets: a travelling wave of amplitude `amplitude * size`.
      const double phase = 2 * M_PI * step / 60.0;
      for (int i = 0; i < springs.size(); ++i) {
        const Eigen::Vector3d a = anchors.row(i).transpose();
        const double w = std::sin(phase + 3.0 * (a - lo.transpose()).x() / size);
        springs.SetTarget(i,
                          a + s.amplitude * size * w * Eigen::Vector3d(0.3, 1.0, 0.2).normalized());
      }
      std::optional<MechanicalState> exact_state, newton_state;
      std::optional<CorotationalElasticity> exact_elastic, newton_elastic;
      if (s.check_accuracy && step >= s.warmup) {
        exact_state.emplace(state);
        newton_state.emplace(state);
        exact_elastic.emplace(elastic);
        newton_elastic.emplace(elastic);
      }
      const double cpu0 = ThreadCpuMs();
      const StepSummary summary = integrator.Step(&state, &elastic, {&springs});
      const double cpu_ms = ThreadCpuMs() - cpu0;
      ARREG_CHECK_INPUT(summary.status == StepStatus::kConverged, "",
                        "step " + std::to_string(step),
                        "the implicit step failed: ", summary.message);
      if (step >= s.warmup) f.factorizations += summary.factorizations;
      if (exact_state) {
        const RowMatX3d x_n = exact_state->positions();
        const StepSummary e = exact.Step(&*exact_state, &*exact_elastic, {&springs});
        const StepSummary n = newton.Step(&*newton_state, &*newton_elastic, {&springs});
        ARREG_CHECK_INPUT(e.status == StepStatus::kConverged && n.status == StepStatus::kConverged,
                          "", "step " + std::to_string(step), "a reference step failed");
        const double step_norm = (newton_state->positions() - x_n).norm();
        solver_errors.push_back((state.positions() - exact_state->positions()).norm() / step_norm);
        newton_errors.push_back((exact_state->positions() - newton_state->positions()).norm() /
                                step_norm);
      }
      if (step < s.warmup) continue;
      wall.push_back(summary.total_ms);
      cpu.push_back(cpu_ms);
      rotation.push_back(summary.rotation_ms);
      assembly.push_back(summary.assembly_ms);
      solve.push_back(summary.solve_ms);
      cg_iterations += summary.linear_iterations;
      rotation_iterations += elastic.mean_rotation_iterations();
      ++timed_steps;
      f.inverted_elements = std::max(f.inverted_elements, summary.inverted_elements);
      f.line_search_cuts += summary.line_search_cuts;
    }
    f.max_displacement_mm =
        (state.positions() - state.rest_positions()).rowwise().norm().maxCoeff();
    f.tets = state.num_tetrahedra();
    f.dofs = state.num_dofs();
  }
  f.springs = s.springs;
  f.steps = s.steps;
  f.repeats = s.repeats;
  f.ms_per_step_median = Median(wall);
  f.cpu_ms_per_step_median = Median(cpu);
  f.ms_per_step_mean = Mean(wall);
  f.cpu_ms_per_step_mean = Mean(cpu);
  f.cpu_ms_per_step_max = *std::max_element(cpu.begin(), cpu.end());
  f.rotation_ms = Median(rotation);
  f.assembly_ms = Median(assembly);
  f.solve_ms = Median(solve);
  f.cg_iterations_mean = cg_iterations / std::max(1, timed_steps);
  f.rotation_iterations_mean = rotation_iterations / std::max(1, timed_steps);
  if (!solver_errors.empty()) {
    f.accuracy_checked = true;
    f.solver_error_median = Median(solver_errors);
    f.solver_error_max = *std::max_element(solver_errors.begin(), solver_errors.end());
    f.newton_error_median = Median(newton_errors);
    f.newton_error_max = *std::max_element(newton_errors.begin(), newton_errors.end());
  }
  return f;
}

nlohmann::json ToJson(const std::string& mesh, const BenchSettings& s, const Figures& f) {
  nlohmann::json j = {{"mesh", mesh},
                      {"solver", s.solver},
                      {"preconditioner", s.solver == "cg" ? s.preconditioner : ""},
                      {"factorization", s.solver != "cg" ? s.factorization : ""},
                      {"rotation", s.rotation},
                      {"cg_tolerance", s.cg_tolerance},
                      {"warm_start", s.warm_start},
                      {"line_search", s.line_search},
                      {"tets", f.tets},
                      {"dofs", f.dofs},
                      {"springs", f.springs},
                      {"steps", f.steps},
                      {"repeats", f.repeats},
                      {"dt_s", s.dt_s},
                      {"amplitude", s.amplitude},
                      {"ms_per_step_median", f.ms_per_step_median},
                      {"cpu_ms_per_step_median", f.cpu_ms_per_step_median},
                      {"ms_per_step_mean", f.ms_per_step_mean},
                      {"cpu_ms_per_step_mean", f.cpu_ms_per_step_mean},
                      {"cpu_ms_per_step_max", f.cpu_ms_per_step_max},
                      {"cpu_us_per_tet", 1e3 * f.cpu_ms_per_step_median / f.tets},
                      {"rotation_ms", f.rotation_ms},
                      {"assembly_ms", f.assembly_ms},
                      {"solve_ms", f.solve_ms},
                      {"cg_iterations_mean", f.cg_iterations_mean},
                      {"factorizations", f.factorizations},
                      {"rotation_iterations_mean", f.rotation_iterations_mean},
                      {"max_displacement_mm", f.max_displacement_mm},
                      {"inverted_elements", f.inverted_elements},
                      {"line_search_cuts", f.line_search_cuts}};
  if (f.accuracy_checked) {
    j["solver_error_median"] = f.solver_error_median;
    j["solver_error_max"] = f.solver_error_max;
    j["newton_error_median"] = f.newton_error_median;
    j["newton_error_max"] = f.newton_error_max;
  }
  return j;
}

void PrintHeader() {
  std::printf("%-22s %-11s %7s %7s %9s %9s %9s %7s %8s %8s %8s %6s %5s %6s\n", "mesh", "solver",
              "tets", "dofs", "ms/step", "cpu_ms", "cpu_mean", "us/tet", "rot_ms", "asm_ms",
              "solve_ms", "cg_it", "facts", "rot_it");
}

void Print(const std::string& mesh, const BenchSettings& s, const Figures& f) {
  const std::string name = mesh.size() > 22 ? "..." + mesh.substr(mesh.size() - 19) : mesh;
  std::printf("%-22s %-11s %7d %7d %9.3f %9.3f %9.3f %7.3f %8.3f %8.3f %8.3f %6.2f %5d %6.2f\n",
              name.c_str(), s.solver.c_str(), f.tets, f.dofs, f.ms_per_step_median,
              f.cpu_ms_per_step_median, f.cpu_ms_per_step_mean,
              1e3 * f.cpu_ms_per_step_median / f.tets, f.rotation_ms, f.assembly_ms, f.solve_ms,
              f.cg_iterations_mean, f.factorizations, f.rotation_iterations_mean);
  if (f.accuracy_checked)
    std::printf(
        "  step error vs exact Cholesky: median %.2e max %.2e; one Newton step vs converged "
        "Newton: median %.2e max %.2e\n",
        f.solver_error_median, f.solver_error_max, f.newton_error_median, f.newton_error_max);
}

std::vector<std::string> SplitCommas(const std::string& list) {
  std::vector<std::string> items;
  size_t start = 0;
  while (start <= list.size()) {
    const size_t end = std::min(list.find(',', start), list.size());
    if (end > start) items.push_back(list.substr(start, end - start));
    start = end + 1;
  }
  return items;
}

}  // namespace

int RunBenchMechanics(int argc, char** argv) {
  std::string mesh_spec, json_path, sweep_boxes;
  BenchSettings s;
  int seed = 1;
  bool sweep = false, no_cost_refactor = false, no_line_search = false;
  OptionParser parser(
      "arreg bench mechanics --mesh M [--solver cg|cholmod|cholmod-pcg] [--steps N] [--json OUT]",
      "Times the registration's mechanical step: corotational tetrahedra pulled by "
      "springs from embedded points to moving targets, implicit Euler with one Newton "
      "step per frame. Prints medians over --repeats runs of --steps steps each.");
  parser.AddString("mesh", &mesh_spec, "M",
                   "mesh file (.msh, .vtk) or box:NXxNYxNZ / box5:NXxNYxNZ (10 mm cells, "
                   "6- or 5-tetrahedra split)",
                   true);
  parser.AddString("solver", &s.solver, "S",
                   "linear solver: cg, cholmod, or cholmod-pcg (CG preconditioned by an "
                   "earlier CHOLMOD factor, refactorised when that pays off)");
  parser.AddFlag("no-cost-refactor", &no_cost_refactor,
                 "cholmod-pcg: refactorise only after more than --refactor-iterations "
                 "iterations, not by the amortised cost rule");
  parser.AddInt("refactor-iterations", &s.refactor_iterations, "N",
                "cholmod-pcg: refactorise after a solve that needed more CG iterations");
  parser.AddString("preconditioner", &s.preconditioner, "P",
                   "CG preconditioner: none, jacobi, block-jacobi, ichol");
  parser.AddString("factorization", &s.factorization, "F",
                   "CHOLMOD factorisation: supernodal, simplicial, auto");
  parser.AddString("rotation", &s.rotation, "R", "element rotation: polar, polar-svd, qr");
  parser.AddString("warm-start", &s.warm_start, "W",
                   "iterative solvers' first guess: extrapolate (h (2 v_n - v_n-1)) or "
                   "velocity (h v_n)");
  parser.AddFlag("no-line-search", &no_line_search,
                 "take every Newton increment whole (no line search on the incremental "
                 "potential, docs/mechanics.md \"Line search\")");
  parser.AddInt("steps", &s.steps, "N", "timed steps per run");
  parser.AddInt("repeats", &s.repeats, "N", "runs (medians over all timed steps)");
  parser.AddInt("springs", &s.springs, "N", "number of springs (features)");
  parser.AddDouble("spring-stiffness", &s.stiffness, "K", "stiffness per spring in N/m");
  parser.AddDouble("youngs-modulus", &s.youngs_pa, "PA", "Young's modulus in Pa");
  parser.AddDouble("dt", &s.dt_s, "S", "time step in s (one video frame)");
  parser.AddDouble("amplitude", &s.amplitude, "A",
                   "amplitude of the targets' travelling wave, fraction of the mesh diagonal");
  parser.AddDouble("cg-tolerance", &s.cg_tolerance, "T",
                   "CG relative residual tolerance (the integrator's default 1e-3)");
  parser.AddInt("seed", &seed, "N", "seed of the random spring anchors");
  parser.AddFlag("check-accuracy", &s.check_accuracy,
                 "also solve every timed step by exact Cholesky and by Newton to convergence "
                 "and report the step's relative errors (slow; not in the timings)");
  parser.AddFlag("sweep", &sweep,
                 "also run a series of boxes (--sweep-boxes) and fit the growth exponent of "
                 "the time per step in the number of tetrahedra");
  parser.AddString("sweep-boxes", &sweep_boxes, "LIST",
                   "comma-separated meshes of --sweep; default 540 to 9,600 tetrahedra of the "
                   "shape of box:20x6x6");
  parser.AddString("json", &json_path, "OUT", "also write the figures to this JSON file");
  parser.SetEpilog(
      "Figures: tets, dofs, ms_per_step_median (wall), cpu_ms_per_step_median (thread CPU\n"
      "time, robust on a shared machine), cpu_us_per_tet, *_mean and cpu_ms_per_step_max\n"
      "(they include cholmod-pcg's occasional refactorisations), rotation_ms (polar\n"
      "decompositions), assembly_ms (gradients, Hessian into precomputed slots, Dirichlet\n"
      "rows), solve_ms (CHOLMOD numeric factorisation + solve, or warm-started CG),\n"
      "cg_iterations_mean (0 for CHOLMOD), factorizations (numeric, over all timed steps),\n"
      "line_search_cuts (halvings of Newton increments, over all timed steps).\n"
      "--sweep adds \"sweep\" (one entry per mesh) and \"growth_exponent\" to the JSON.\n"
      "Run with OMP_NUM_THREADS=1 for one thread.");
  if (!parser.Parse(argc, argv)) return 0;
  // Bad option values are usage errors (exit code 2).
  auto require = [](bool ok, const std::string& option, const std::string& message) {
    if (!ok) throw UsageError(option, message);
  };
  require(s.steps >= 1, "--steps", "must be >= 1, got " + std::to_string(s.steps));
  require(s.refactor_iterations >= 0, "--refactor-iterations",
          "must be >= 0, got " + std::to_string(s.refactor_iterations));
  require(s.repeats >= 1, "--repeats", "must be >= 1, got " + std::to_string(s.repeats));
  require(s.springs >= 1, "--springs", "must be >= 1, got " + std::to_string(s.springs));
  require(seed >= 0, "--seed", "must be >= 0, got " + std::to_string(seed));
  require(std::isfinite(s.cg_tolerance) && s.cg_tolerance > 0, "--cg-tolerance",
          "must be > 0, got " + std::to_string(s.cg_tolerance));
  require(std::isfinite(s.amplitude) && s.amplitude >= 0 && s.amplitude <= 1, "--amplitude",
          "must be in [0, 1], got " + std::to_string(s.amplitude));
  require(s.warm_start == "extrapolate" || s.warm_start == "velocity", "--warm-start",
          "must be extrapolate or velocity, got '" + s.warm_start + "'");
  ParseLinearSolverType(s.solver);
  ParsePreconditioner(s.preconditioner);
  ParseRotationMethod(s.rotation);
  ParseCholmodFactorization(s.factorization);
  s.seed = static_cast<unsigned>(seed);
  s.refactor_by_cost = !no_cost_refactor;
  s.line_search = !no_line_search;
  const std::vector<std::string> boxes = SplitCommas(
      sweep_boxes.empty() ? "box:10x3x3,box:14x4x4,box:17x5x5,box:20x6x6,box:23x7x7,box:25x8x8"
                          : sweep_boxes);
  require(!sweep || boxes.size() >= 2, "--sweep-boxes",
          "needs at least two meshes, got '" + sweep_boxes + "'");

  PrintHeader();
  const TetMesh mesh = LoadMesh(mesh_spec);
  const Figures main_figures = RunScene(mesh, s);
  Print(mesh_spec, s, main_figures);
  nlohmann::json out = ToJson(mesh_spec, s, main_figures);
  if (sweep) {
    nlohmann::json series = nlohmann::json::array();
    std::vector<Figures> figures;
    for (const std::string& box : boxes) {
      figures.push_back(RunScene(LoadMesh(box), s));
      Print(box, s, figures.back());
      series.push_back(ToJson(box, s, figures.back()));
    }
    std::vector<double> tets, cpu_ms;
    for (const Figures& f : figures) {
      tets.push_back(f.tets);
      cpu_ms.push_back(f.cpu_ms_per_step_median);
    }
    const double exponent = GrowthExponent(tets, cpu_ms);
    std::printf("growth exponent (cpu ms per step ~ tets^k, least squares): k = %.2f\n", exponent);
    out["sweep"] = series;
    out["growth_exponent"] = exponent;
  }
  if (!json_path.empty())
    WriteFileAtomic(json_path, [&](std::ostream& os) { os << out.dump(2) << "\n"; });
  return 0;
}

}  // namespace arreg::cli
