// `arreg bench mechanics`: time per implicit step of a spring-driven body like
// the registration's (element rotations, assembly, solve), one thread.
#include <time.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ostream>
#include <random>
#include <regex>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

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

double Median(std::vector<double> values) {
  ARREG_ASSERT(!values.empty(), "");
  std::sort(values.begin(), values.end());
  const size_t n = values.size();
  return n % 2 ? values[n / 2] : 0.5 * (values[n / 2 - 1] + values[n / 2]);
}

double Mean(const std::vector<double>& values) {
  ARREG_ASSERT(!values.empty(), "");
  double sum = 0;
  for (double v : values) sum += v;
  return sum / static_cast<double>(values.size());
}

// CPU time of the calling thread in ms: robust to other processes sharing the machine.
double ThreadCpuMs() {
  timespec ts;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
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
  int inverted_elements = 0;
};

struct BenchSettings {
  std::string solver = "cholmod-pcg", preconditioner = "jacobi", rotation = "polar";
  std::string factorization = "auto";
  int steps = 200, warmup = 5, repeats = 5, springs = 200;
  double dt_s = 1.0 / 30.0, stiffness = 10.0, youngs_pa = 3000.0, poisson = 0.45;
  double cg_tolerance = 1e-3, amplitude = 0.05;
  int refactor_iterations = 20;
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
    for (int step = 0; step < s.warmup + s.steps; ++step) {
      // Targets: a travelling wave of amplitude `amplitude * size`.
      const double phase = 2 * M_PI * step / 60.0;
      for (int i = 0; i < springs.size(); ++i) {
        const Eigen::Vector3d a = anchors.row(i).transpose();
        const double w = std::sin(phase + 3.0 * (a - lo.transpose()).x() / size);
        springs.SetTarget(i,
                          a + s.amplitude * size * w * Eigen::Vector3d(0.3, 1.0, 0.2).normalized());
      }
      const double cpu0 = ThreadCpuMs();
      const StepSummary summary = integrator.Step(&state, &elastic, {&springs});
      const double cpu_ms = ThreadCpuMs() - cpu0;
      ARREG_CHECK_INPUT(summary.status == StepStatus::kConverged, "",
                        "step " + std::to_string(step),
                        "the implicit step failed: ", summary.message);
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
  return f;
}

nlohmann::json ToJson(const std::string& mesh, const BenchSettings& s, const Figures& f) {
  return {{"mesh", mesh},
          {"solver", s.solver},
          {"preconditioner", s.solver == "cg" ? s.preconditioner : ""},
          {"factorization", s.solver != "cg" ? s.factorization : ""},
          {"rotation", s.rotation},
          {"tets", f.tets},
          {"dofs", f.dofs},
          {"springs", f.springs},
          {"steps", f.steps},
          {"repeats", f.repeats},
          {"dt_s", s.dt_s},
          {"ms_per_step_median", f.ms_per_step_median},
          {"cpu_ms_per_step_median", f.cpu_ms_per_step_median},
          {"ms_per_step_mean", f.ms_per_step_mean},
          {"cpu_ms_per_step_mean", f.cpu_ms_per_step_mean},
          {"cpu_ms_per_step_max", f.cpu_ms_per_step_max},
          {"rotation_ms", f.rotation_ms},
          {"assembly_ms", f.assembly_ms},
          {"solve_ms", f.solve_ms},
          {"cg_iterations_mean", f.cg_iterations_mean},
          {"rotation_iterations_mean", f.rotation_iterations_mean},
          {"max_displacement_mm", f.max_displacement_mm},
          {"inverted_elements", f.inverted_elements}};
}

void Print(const std::string& mesh, const BenchSettings& s, const Figures& f) {
  std::printf("%-28s %-11s %7d %7d %9.3f %9.3f %9.3f %9.3f %9.3f %9.3f %8.1f %7.2f\n", mesh.c_str(),
              s.solver.c_str(), f.tets, f.dofs, f.ms_per_step_median, f.cpu_ms_per_step_median,
              f.cpu_ms_per_step_mean, f.rotation_ms, f.assembly_ms, f.solve_ms,
              f.cg_iterations_mean, f.rotation_iterations_mean);
}

}  // namespace

int RunBenchMechanics(int argc, char** argv) {
  std::string mesh_spec, json_path;
  BenchSettings s;
  int seed = 1;
  bool scaling = false;
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
                   "linear solver: cg, cholmod, or cholmod-pcg (CG preconditioned by the last "
                   "CHOLMOD factor, refactorised when CG needs more than --refactor-iterations)");
  parser.AddInt("refactor-iterations", &s.refactor_iterations, "N",
                "cholmod-pcg: refactorise after a solve that needed more CG iterations");
  parser.AddString("preconditioner", &s.preconditioner, "P",
                   "CG preconditioner: none, jacobi, block-jacobi, ichol");
  parser.AddString("factorization", &s.factorization, "F",
                   "CHOLMOD factorisation: supernodal, simplicial, auto");
  parser.AddString("rotation", &s.rotation, "R", "element rotation: polar, polar-svd, qr");
  parser.AddInt("steps", &s.steps, "N", "timed steps per run");
  parser.AddInt("repeats", &s.repeats, "N", "runs (medians over all timed steps)");
  parser.AddInt("springs", &s.springs, "N", "number of springs (features)");
  parser.AddDouble("spring-stiffness", &s.stiffness, "K", "stiffness per spring in N/m");
  parser.AddDouble("youngs-modulus", &s.youngs_pa, "PA", "Young's modulus in Pa");
  parser.AddDouble("dt", &s.dt_s, "S", "time step in s (one video frame)");
  parser.AddDouble("cg-tolerance", &s.cg_tolerance, "T", "CG relative residual tolerance");
  parser.AddInt("seed", &seed, "N", "seed of the random spring anchors");
  parser.AddFlag("scaling", &scaling,
                 "also run boxes of 1x to 16x the mesh's size class to show the growth in #tets");
  parser.AddString("json", &json_path, "OUT", "also write the figures to this JSON file");
  parser.SetEpilog(
      "Figures: tets, dofs, ms_per_step_median (wall), cpu_ms_per_step_median (thread CPU\n"
      "time, robust on a shared machine), *_mean and cpu_ms_per_step_max (they show the\n"
      "occasional refactorisation of cholmod-pcg), rotation_ms (polar decompositions),\n"
      "assembly_ms (gradients, Hessian into precomputed slots, Dirichlet rows),\n"
      "solve_ms (CHOLMOD numeric refactorisation + solve, or warm-started CG),\n"
      "cg_iterations_mean (0 for CHOLMOD). Run with OMP_NUM_THREADS=1 for one thread.");
  if (!parser.Parse(argc, argv)) return 0;
  ARREG_CHECK_INPUT(s.steps >= 1, "", "--steps", "must be >= 1, got ", s.steps);
  ARREG_CHECK_INPUT(s.refactor_iterations >= 0, "", "--refactor-iterations", "must be >= 0, got ",
                    s.refactor_iterations);
  ARREG_CHECK_INPUT(s.repeats >= 1, "", "--repeats", "must be >= 1, got ", s.repeats);
  ARREG_CHECK_INPUT(s.springs >= 1, "", "--springs", "must be >= 1, got ", s.springs);
  ARREG_CHECK_INPUT(seed >= 0, "", "--seed", "must be >= 0, got ", seed);
  ParseLinearSolverType(s.solver);
  ParsePreconditioner(s.preconditioner);
  ParseRotationMethod(s.rotation);
  ParseCholmodFactorization(s.factorization);
  s.seed = static_cast<unsigned>(seed);

  std::printf("%-28s %-11s %7s %7s %9s %9s %9s %9s %9s %9s %8s %7s\n", "mesh", "solver", "tets",
              "dofs", "ms/step", "cpu_ms", "cpu_mean", "rot_ms", "asm_ms", "solve_ms", "cg_it",
              "rot_it");
  const TetMesh mesh = LoadMesh(mesh_spec);
  const Figures main_figures = RunScene(mesh, s);
  Print(mesh_spec, s, main_figures);
  nlohmann::json out = ToJson(mesh_spec, s, main_figures);
  if (scaling) {
    nlohmann::json series = nlohmann::json::array();
    for (const char* box : {"box:10x3x3", "box:20x6x6", "box:30x9x9", "box:40x12x12"}) {
      const Figures f = RunScene(LoadMesh(box), s);
      Print(box, s, f);
      series.push_back(ToJson(box, s, f));
    }
    out["scaling"] = series;
  }
  if (!json_path.empty())
    WriteFileAtomic(json_path, [&](std::ostream& os) { os << out.dump(2) << "\n"; });
  return 0;
}

}  // namespace arreg::cli
