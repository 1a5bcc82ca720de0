// `arreg bench cutting`: the thesis beam experiment (5.2.2) comparing our remesher with
// the Bielser-style baseline per snapping threshold, the time of one remeshing event and of
// splitting an internal structure along the crack; with --random N, the random-cut sweep
// (sequences of random cuts on the SOFA livers, the kidney and a beam, checked after every cut).
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <ostream>
#include <sstream>
#include <string>
#include <vector>

#include "ar/synth/shapes.h"
#include "bench_util.h"
#include "commands.h"
#include "core/error.h"
#include "core/file_util.h"
#include "core/mesh_generators.h"
#include "core/mesh_io.h"
#include "core/mesh_ops.h"
#include "core/progress.h"
#include "cutting/mechanics_update.h"
#include "cutting/mesh_checks.h"
#include "cutting/quadratic_cutter.h"
#include "cutting/random_cuts.h"
#include "cutting/structure_split.h"
#include "cutting/system_conditioning.h"
#include "cutting/tet_cutter.h"
#include "mechanics/high_order_mesh.h"
#include "option_parser.h"

namespace arreg::cli {

namespace {

using Clock = std::chrono::steady_clock;
using cutting::CutOptions;
using cutting::CutStatus;
using cutting::CutSummary;
using cutting::CuttableMesh;
using cutting::RemeshMethod;

// The beam: 100 x 30 x 20 mm, 10 x 3 x 2 hexahedral cells of 6 tetrahedra
// (132 vertices, 360 tetrahedra; the thesis beam has 131 and 371).
TetMesh MakeBeam() {
  return MakeBoxTetMesh(Eigen::Vector3d(100, 30, 20), Eigen::Vector3i(10, 3, 2), BoxTetSplit::kSix);
}

// The cut plane: across the beam axis, 0.3 mm from the vertex layer x = 50 mm at
// y = z = 0 and tilted so that its distance to that layer's vertices grows to about
// 5 mm (half a cell): it passes close to many vertices, at varied distances.
const Eigen::Vector3d kPlanePoint(50.3, 0, 0);
const Eigen::Vector3d kPlaneNormal = Eigen::Vector3d(1, -0.12, -0.08).normalized();

// The part of the plane with y below `front_mm` (the cut advancing along y).
cutting::CutSurface PlaneUpTo(double front_mm) {
  const Eigen::Vector3d u = kPlaneNormal.cross(Eigen::Vector3d::UnitZ()).normalized();
  const Eigen::Vector3d w = kPlaneNormal.cross(u).normalized();
  const double t0 = (-5 - kPlanePoint.y()) / u.y(), t1 = (front_mm - kPlanePoint.y()) / u.y();
  return cutting::MakeGridSurface(
      [&](double a, double b) {
        return Eigen::Vector3d(kPlanePoint + (-20 + 40 * a) * w + (t0 + (t1 - t0) * b) * u);
      },
      1, 1);
}

struct StepRecord {
  int step = 0;
  int num_vertices = 0, num_tetrahedra = 0, crossed = 0;
  double min_dihedral_deg = 0, condition_number = 0;
  bool rejected = false;
};

struct Run {
  std::string method;
  double eps = 0;
  std::vector<StepRecord> steps;
  int nv_crossed = 0;  // n(v): original tetrahedra crossed by the whole plane
  double vertices_per_nv = 0, tetrahedra_per_nv = 0;
};

Run RunBeam(RemeshMethod method, double eps, int num_steps, int nv_crossed,
            const cutting::ConditioningOptions& cond) {
  Run run;
  run.method = method == RemeshMethod::kFlips ? "ours" : "bielser";
  run.eps = eps;
  run.nv_crossed = nv_crossed;
  const TetMesh beam = MakeBeam();
  CuttableMesh mesh(beam);
  CutOptions opt;
  opt.method = method;
  opt.snap_epsilon = eps;
  for (int step = 0; step <= num_steps; ++step) {
    StepRecord r;
    r.step = step;
    if (step > 0) {
      // The front passes the far side of the beam (y = 30) at the last step.
      const double front = -2 + 34.0 * step / num_steps;
      const CutSummary s = mesh.Cut(PlaneUpTo(front), opt);
      r.crossed = s.num_crossed_tetrahedra;
      r.rejected = s.status == CutStatus::kRejected;
    }
    const TetMesh rest = mesh.RestMesh();
    const cutting::MeshInvariants inv = cutting::CheckMeshInvariants(rest);
    ARREG_CHECK_INPUT(inv.ok(), "", "bench cutting", "invariants broken: ", inv.ToString());
    r.num_vertices = rest.num_vertices();
    r.num_tetrahedra = rest.num_tetrahedra();
    r.min_dihedral_deg = inv.min_dihedral_deg;
    r.condition_number = cutting::SystemConditioning(rest, cond).condition_number;
    run.steps.push_back(r);
  }
  run.vertices_per_nv =
      static_cast<double>(run.steps.back().num_vertices - run.steps.front().num_vertices) /
      nv_crossed;
  run.tetrahedra_per_nv =
      static_cast<double>(run.steps.back().num_tetrahedra - run.steps.front().num_tetrahedra) /
      nv_crossed;
  return run;
}

// A two-panel SVG: vertex count and log10 condition number per step.
std::string Plot(const std::vector<Run>& runs) {
  const int W = 480, H = 320, pad = 50;
  const char* colors[] = {"#1f77b4", "#ff7f0e", "#2ca02c", "#d62728"};
  std::ostringstream s;
  s << "<svg xmlns='http://www.w3.org/2000/svg' width='" << 2 * W << "' height='" << H + 40
    << "' font-family='sans-serif' font-size='11'>\n";
  for (int panel = 0; panel < 2; ++panel) {
    double lo = 1e300, hi = -1e300;
    int max_step = 1;
    auto value = [&](const StepRecord& r) {
      return panel == 0 ? r.num_vertices : std::log10(std::max(r.condition_number, 1.0));
    };
    for (const Run& run : runs)
      for (const StepRecord& r : run.steps) {
        lo = std::min(lo, value(r));
        hi = std::max(hi, value(r));
        max_step = std::max(max_step, r.step);
      }
    if (hi <= lo) hi = lo + 1;
    const int x0 = panel * W;
    s << "<text x='" << x0 + W / 2 << "' y='16' text-anchor='middle'>"
      << (panel == 0 ? "number of vertices" : "log10 condition number of M + dt^2 K")
      << " per step</text>\n";
    s << "<rect x='" << x0 + pad << "' y='" << pad / 2 << "' width='" << W - 2 * pad << "' height='"
      << H - pad << "' fill='none' stroke='#888'/>\n";
    s << "<text x='" << x0 + pad - 4 << "' y='" << pad / 2 + 10 << "' text-anchor='end'>" << hi
      << "</text><text x='" << x0 + pad - 4 << "' y='" << H - pad / 2 << "' text-anchor='end'>"
      << lo << "</text>\n";
    for (size_t k = 0; k < runs.size(); ++k) {
      const Run& run = runs[k];
      s << "<polyline fill='none' stroke='" << colors[std::lround(run.eps * 10) % 4]
        << "' stroke-dasharray='" << (run.method == "ours" ? "none" : "5,3") << "' points='";
      for (const StepRecord& r : run.steps)
        s << x0 + pad + (W - 2 * pad) * r.step / max_step << ","
          << pad / 2.0 + (H - pad) * (1 - (value(r) - lo) / (hi - lo)) << " ";
      s << "'/>\n";
    }
  }
  for (size_t k = 0; k < runs.size(); ++k)
    s << "<text x='" << 20 + 120 * (k % 8) << "' y='" << H + 20 + 14 * (k / 8) << "' fill='"
      << colors[std::lround(runs[k].eps * 10) % 4] << "'>" << runs[k].method
      << (runs[k].method == "ours" ? " (solid)" : " (dashed)") << " eps " << runs[k].eps
      << "</text>\n";
  s << "</svg>\n";
  return s.str();
}

// The meshes of the random-cut sweep: the SOFA livers (when ../shared/data has them), the
// kidney with its internal structure (the boundary of its label-2 elements) and the beam.
std::vector<cutting::SweepMesh> SweepMeshes(const std::string& shared_data) {
  std::vector<cutting::SweepMesh> meshes;
  for (const char* name : {"liver", "liver2"}) {
    const std::string path = shared_data + "/meshes/sofa/" + name + ".msh";
    if (!std::filesystem::exists(path)) {
      std::printf("%s: %s not found, skipped\n", name, path.c_str());
      continue;
    }
    cutting::SweepMesh m;
    m.name = name;
    m.mesh = ReadTetMesh(path);
    m.mesh.triangles.resize(0, 3);
    FixOrientation(&m.mesh);
    meshes.push_back(std::move(m));
  }
  {
    // The registration model's resolution class (docs/synth.md: the coarse kidney is 7 mm).
    synth::KidneyMeshOptions o;
    o.cell_size_mm = o.facet_size_mm = 6;
    o.facet_distance_mm = 1.0;
    const synth::LabeledTetMesh kidney = synth::MeshKidney(synth::KidneyShape(), o);
    cutting::SweepMesh m;
    m.name = "kidney";
    m.mesh = kidney.mesh;
    std::vector<bool> internal(kidney.labels.size());
    for (int t = 0; t < kidney.labels.size(); ++t) internal[t] = kidney.labels[t] == 2;
    m.structure.vertices = kidney.mesh.vertices;
    m.structure.faces = synth::BoundaryFaces(kidney.mesh.tetrahedra, internal);
    RemoveUnreferencedVertices(&m.structure);
    meshes.push_back(std::move(m));
  }
  meshes.push_back({"beam", MakeBeam(), {}, {}});
  return meshes;
}

// Degree 2: the meshes raised straight, and the beam again with its faces bulged by 3 mm (curved
// rest elements).
void AddCurvedBeam(std::vector<cutting::SweepMesh>* meshes) {
  cutting::SweepMesh m{"beam-curved", MakeBeam(), {}, {}};
  m.quadratic_nodes = cutting::BulgedBoxQuadraticNodes(m.mesh, Eigen::Vector3d(100, 30, 20), 3);
  meshes->push_back(std::move(m));
}

int RunRandomSweep(int num_cuts, int seed, int threads, int degree, const std::string& shared_data,
                   const std::string& json_path, const std::string& failures_dir) {
  std::vector<cutting::SweepMesh> meshes = SweepMeshes(shared_data);
  if (degree == 2) AddCurvedBeam(&meshes);
  for (const cutting::SweepMesh& m : meshes)
    std::printf(
        "%s: %d vertices, %d tetrahedra%s\n", m.name.c_str(), m.mesh.num_vertices(),
        m.mesh.num_tetrahedra(),
        m.structure.num_faces() > 0
            ? (", internal structure of " + std::to_string(m.structure.num_faces()) + " triangles")
                  .c_str()
            : "");
  cutting::SweepOptions options;
  options.num_cuts = num_cuts;
  options.seed = static_cast<std::uint64_t>(seed);
  options.save_failures_dir = failures_dir;
  options.threads = threads;
  options.degree = degree;
  std::optional<ProgressReporter> progress;
  progress.emplace("arreg bench cutting: random cut", stderr, ProgressOptionsFor(stderr));
  const cutting::SweepResult r = cutting::RunRandomCutSweep(
      meshes, options, [&](int done, int total) { progress->Update(done, total); });
  progress.reset();

  std::printf("\n%-8s %-13s | %6s %7s %8s %8s %10s | %8s\n", "mesh", "kind", "cuts", "crossed",
              "no cross", "rejected", "violations", "ms/cut");
  const auto counts_json = [](const cutting::KindCounts& c) {
    return nlohmann::json{
        {"cuts", c.cuts},         {"crossed", c.crossed},       {"no_crossing", c.no_crossing},
        {"rejected", c.rejected}, {"violations", c.violations}, {"seconds", c.seconds}};
  };
  nlohmann::json per_mesh = nlohmann::json::object();
  std::map<std::string, cutting::KindCounts> per_kind;
  for (const auto& [mesh, kinds] : r.counts)
    for (const auto& [kind, c] : kinds) {
      std::printf("%-8s %-13s | %6d %7d %8d %8d %10d | %8.2f\n", mesh.c_str(), kind.c_str(), c.cuts,
                  c.crossed, c.no_crossing, c.rejected, c.violations,
                  1e3 * c.seconds / std::max(c.cuts, 1));
      per_mesh[mesh][kind] = counts_json(c);
      per_kind[kind].Add(c);
    }
  nlohmann::json kinds_json = nlohmann::json::object();
  for (const auto& [kind, c] : per_kind) kinds_json[kind] = counts_json(c);
  nlohmann::json violations = nlohmann::json::array();
  for (const cutting::Violation& v : r.violations) {
    std::printf("VIOLATION %s seed %llu sequence %d cut %d (%s): %s: %s%s%s\n", v.mesh.c_str(),
                static_cast<unsigned long long>(v.seed), v.sequence, v.index,
                cutting::RandomCutKindName(v.kind), v.check.c_str(), v.detail.c_str(),
                v.saved_dir.empty() ? "" : "; saved to ", v.saved_dir.c_str());
    violations.push_back({{"mesh", v.mesh},
                          {"seed", v.seed},
                          {"sequence", v.sequence},
                          {"index", v.index},
                          {"kind", cutting::RandomCutKindName(v.kind)},
                          {"check", v.check},
                          {"detail", v.detail},
                          {"saved", v.saved_dir}});
  }
  std::printf(
      "degree %d: %d cuts made of %d drawn in %d sequences (%d ended early above %d elements), "
      "%zu violations, %.1f s\n",
      degree, r.cuts, num_cuts, r.sequences, r.stopped_by_growth, options.max_tetrahedra,
      r.violations.size(), r.seconds);
  if (!json_path.empty()) {
    nlohmann::json j = {{"cuts", r.cuts},
                        {"cuts_drawn", num_cuts},
                        {"sequences", r.sequences},
                        {"sequences_ended_by_growth", r.stopped_by_growth},
                        {"max_tetrahedra", options.max_tetrahedra},
                        {"threads", threads},
                        {"degree", degree},
                        {"violations", r.violations.size()},
                        {"seconds", r.seconds},
                        {"seed", seed},
                        {"per_kind", kinds_json},
                        {"per_mesh", per_mesh},
                        {"violation_list", violations}};
    WriteFileAtomic(json_path, [&](std::ostream& out) { out << j.dump(2) << "\n"; });
  }
  return r.violations.empty() ? 0 : 1;
}

// n(v): the elements of `beam` the whole plane crosses (no snapping; the cut is not kept).
int CrossedByThePlane(const TetMesh& beam) {
  CuttableMesh probe(beam);
  CutOptions o;
  o.snap_epsilon = 0;
  return probe.Cut(PlaneUpTo(40), o).num_crossed_tetrahedra;
}

// The thesis' quadratic beam experiment (6.1.4, table 6.4): the plane of the linear experiment
// through beams of three resolutions raised to degree 2, in one event with separation; control
// points added per crossed element n(v).
int RunQuadraticBeams(const std::string& json_path) {
  struct Beam {
    Eigen::Vector3i cells;
    int thesis_elements;
    double thesis_nodes_per_nv;
  };
  const Beam beams[] = {{{10, 3, 2}, 371, 10.6}, {{12, 5, 2}, 712, 10.2}, {{22, 7, 5}, 4621, 9.6}};
  std::printf(
      "quadratic beams 100 x 30 x 20 mm, the plane of the linear experiment in one event "
      "with separation:\ncontrol points added per n(v) (thesis table 6.4: 10.6, 10.2, 9.6 "
      "n(v) at 371, 712, 4,621 elements)\n");
  std::printf("%8s %6s %6s | %-8s %4s | %8s %8s %9s\n", "elements", "nodes", "n(v)", "method",
              "eps", "added", "per n(v)", "thesis");
  nlohmann::json rows = nlohmann::json::array();
  for (const Beam& b : beams) {
    const TetMesh linear = MakeBoxTetMesh(Eigen::Vector3d(100, 30, 20), b.cells, BoxTetSplit::kSix);
    const mechanics::HighOrderTetMesh beam = mechanics::RaiseTetMesh(linear, 2);
    const int nv = CrossedByThePlane(linear);
    for (RemeshMethod method : {RemeshMethod::kFlips, RemeshMethod::kBielser})
      for (double eps : {0.0, 0.1, 0.2, 0.3}) {
        cutting::QuadraticCuttableMesh mesh(beam);
        CutOptions o;
        o.method = method;
        o.snap_epsilon = eps;
        const CutSummary s = mesh.Cut(PlaneUpTo(40), o);
        ARREG_ASSERT(s.status == CutStatus::kCut, s.message);
        const int added = mesh.num_nodes() - beam.num_nodes();
        const char* name = method == RemeshMethod::kFlips ? "ours" : "bielser";
        std::printf("%8d %6d %6d | %-8s %4.1f | %8d %8.2f %9.1f\n", linear.num_tetrahedra(),
                    beam.num_nodes(), nv, name, eps, added, static_cast<double>(added) / nv,
                    b.thesis_nodes_per_nv);
        rows.push_back({{"elements", linear.num_tetrahedra()},
                        {"nodes", beam.num_nodes()},
                        {"nv", nv},
                        {"method", name},
                        {"eps", eps},
                        {"nodes_added", added},
                        {"nodes_added_per_nv", static_cast<double>(added) / nv},
                        {"thesis_elements", b.thesis_elements},
                        {"thesis_nodes_added_per_nv", b.thesis_nodes_per_nv}});
      }
  }
  if (!json_path.empty())
    WriteFileAtomic(json_path, [&](std::ostream& out) {
      out << nlohmann::json{{"degree", 2}, {"quadratic_beam", rows}}.dump(2) << "\n";
    });
  return 0;
}

}  // namespace

int RunBenchCutting(int argc, char** argv) {
  std::string json_path, svg_path, failures_dir;
  std::string shared_data =
      std::getenv("ARREG_SHARED_DATA") ? std::getenv("ARREG_SHARED_DATA") : "../shared/data";
  int steps = 10, repeats = 21, structure_rings = 24, random = 0, seed = 1, threads = 1, degree = 1;
  OptionParser parser(
      "arreg bench cutting [--steps N] [--repeats N] [--structure-rings N] [--json OUT] "
      "[--svg OUT] | --degree 2 [--json OUT] | --random N [--degree 1|2] [--seed S] [--threads N] "
      "[--json OUT] [--save-failures DIR] [--shared-data DIR]",
      "Cuts the thesis beam progressively with our remesher and the Bielser-style "
      "baseline at snapping thresholds 0, 0.1, 0.2, 0.3 (vertex/element growth, "
      "minimum dihedral angle, condition number of M + dt^2 K per step), and "
      "times one remeshing event crossing about 100 tetrahedra and the split of an "
      "internal structure (a sphere, 2,208 triangles by default) along its crack. "
      "With --random N: N random cuts drawn in sequences of up to 20 on the SOFA livers, "
      "the kidney and the beam (a sequence ends early once its mesh has 10,000 elements), "
      "every cut checked (docs/cutting.md); exit status 1 when a check failed. With --degree 2: "
      "the quadratic remesher, on beams of three resolutions (thesis table 6.4) or, with "
      "--random, in the sweep (with a fifth mesh, the beam with curved faces).");
  parser.AddInt("degree", &degree, "K", "element degree: 1 (default) or 2 (quadratic remesher)");
  parser.AddInt("random", &random, "N", "run the random-cut sweep of N cuts instead");
  parser.AddInt("seed", &seed, "S", "seed of the random-cut sweep (default 1)");
  parser.AddInt("threads", &threads, "N",
                "random sweep: sequences cut in parallel (default 1; same result)");
  parser.AddString("save-failures", &failures_dir, "DIR",
                   "random sweep: write each offending case to a folder under DIR");
  parser.AddString("shared-data", &shared_data, "DIR",
                   "where meshes/sofa/liver*.msh are (default $ARREG_SHARED_DATA or "
                   "../shared/data)");
  parser.AddInt("steps", &steps, "N", "cut steps of the advancing plane");
  parser.AddInt("repeats", &repeats, "N", "timed repetitions of the speed event and the split");
  parser.AddInt("structure-rings", &structure_rings, "N",
                "rings of the split sphere (2 N segments: 4 N^2 - 4 N triangles)");
  parser.AddString("json", &json_path, "OUT", "write all figures as JSON");
  parser.AddString("svg", &svg_path, "OUT", "write the vertex-count / condition-number plot");
  if (!parser.Parse(argc, argv)) return 0;
  ARREG_CHECK_INPUT(steps >= 1, "", "--steps", "must be >= 1");
  ARREG_CHECK_INPUT(repeats >= 1, "", "--repeats", "must be >= 1");
  ARREG_CHECK_INPUT(structure_rings >= 2, "", "--structure-rings", "must be >= 2");
  ARREG_CHECK_INPUT(random >= 0, "", "--random", "must be >= 0");
  ARREG_CHECK_INPUT(seed >= 0, "", "--seed", "must be >= 0");
  ARREG_CHECK_INPUT(threads >= 1, "", "--threads", "must be >= 1");
  ARREG_CHECK_INPUT(degree == 1 || degree == 2, "", "--degree", "must be 1 or 2, got ", degree);
  if (random > 0)
    return RunRandomSweep(random, seed, threads, degree, shared_data, json_path, failures_dir);
  if (degree == 2) return RunQuadraticBeams(json_path);

  const TetMesh beam = MakeBeam();
  cutting::ConditioningOptions cond;
  const int nv_crossed = CrossedByThePlane(beam);
  std::printf("beam: %d vertices, %d tetrahedra; the plane crosses n(v) = %d of them\n",
              beam.num_vertices(), beam.num_tetrahedra(), nv_crossed);
  std::printf("%-8s %4s | %8s %8s | %8s %8s %10s %12s | %s\n", "method", "eps", "dV/n(v)",
              "dT/n(v)", "vertices", "tets", "min dih.", "cond. final", "cond. max over steps");
  std::vector<Run> runs;
  for (RemeshMethod method : {RemeshMethod::kFlips, RemeshMethod::kBielser})
    for (double eps : {0.0, 0.1, 0.2, 0.3}) {
      Run run = RunBeam(method, eps, steps, nv_crossed, cond);
      double worst = 0, min_dih = 180;
      for (const StepRecord& r : run.steps) {
        worst = std::max(worst, r.condition_number);
        min_dih = std::min(min_dih, r.min_dihedral_deg);
      }
      std::printf("%-8s %4.1f | %8.2f %8.2f | %8d %8d %10.3f %12.4g | %.4g\n", run.method.c_str(),
                  eps, run.vertices_per_nv, run.tetrahedra_per_nv, run.steps.back().num_vertices,
                  run.steps.back().num_tetrahedra, min_dih, run.steps.back().condition_number,
                  worst);
      runs.push_back(std::move(run));
    }
  std::printf("(cond. of the uncut beam: %.4g)\n", runs[0].steps[0].condition_number);

  // Growth when the whole plane is inserted in one event (thesis 5.2.1 counts).
  nlohmann::json single;
  std::printf("\none event, whole plane: added vertices / tetrahedra per n(v)\n");
  std::printf("%-8s %4s | %10s %10s | %10s %10s\n", "method", "eps", "dV remesh", "dT remesh",
              "dV sep.", "dT sep.");
  for (RemeshMethod method : {RemeshMethod::kFlips, RemeshMethod::kBielser})
    for (double eps : {0.0, 0.1, 0.2, 0.3}) {
      double dv[2], dt[2];
      for (int separate = 0; separate < 2; ++separate) {
        CuttableMesh mesh(beam);
        CutOptions o;
        o.method = method;
        o.snap_epsilon = eps;
        o.separate = separate == 1;
        mesh.Cut(PlaneUpTo(40), o);
        dv[separate] = static_cast<double>(mesh.num_vertices() - beam.num_vertices()) / nv_crossed;
        dt[separate] =
            static_cast<double>(mesh.num_tetrahedra() - beam.num_tetrahedra()) / nv_crossed;
      }
      const char* name = method == RemeshMethod::kFlips ? "ours" : "bielser";
      std::printf("%-8s %4.1f | %10.2f %10.2f | %10.2f %10.2f\n", name, eps, dv[0], dt[0], dv[1],
                  dt[1]);
      single.push_back({{"method", name},
                        {"eps", eps},
                        {"vertices_per_nv_remesh", dv[0]},
                        {"tetrahedra_per_nv_remesh", dt[0]},
                        {"vertices_per_nv_separated", dv[1]},
                        {"tetrahedra_per_nv_separated", dt[1]}});
    }

  // Speed: one event through a 5 x 5 x 4 cell box (100-140 crossed elements), with the
  // update of a mechanics::MechanicalState (new vertices, replaced elements).
  const TetMesh box =
      MakeBoxTetMesh(Eigen::Vector3d(50, 50, 40), Eigen::Vector3i(5, 5, 4), BoxTetSplit::kSix);
  const cutting::CutSurface plane = cutting::MakePlaneSurface(
      {25.4, 25, 20}, Eigen::Vector3d(1, 0.15, 0.1).normalized(), 100, 100, {0, 1, 0});
  std::vector<double> ms, cpu_ms;
  int crossed = 0;
  for (int r = 0; r < repeats; ++r) {
    CuttableMesh mesh(box);
    mechanics::MechanicalState state(box, mechanics::Material());
    CutOptions o;
    o.snap_epsilon = 0;  // the mechanical state keeps its rest positions
    cutting::CutChange change;
    const double c0 = ThreadCpuMs();
    const auto t0 = Clock::now();
    const CutSummary s = mesh.Cut(plane, o, &change);
    cutting::ApplyCutChange(change, &state);
    ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
    cpu_ms.push_back(ThreadCpuMs() - c0);
    crossed = s.num_crossed_tetrahedra;
  }
  const double median_ms = Median(ms), median_cpu_ms = Median(cpu_ms);
  std::printf(
      "remeshing event crossing %d tetrahedra (box of %d), mechanics update included: median "
      "%.3f ms wall, %.3f ms thread CPU over %d runs\n",
      crossed, box.num_tetrahedra(), median_ms, median_cpu_ms, repeats);

  // The same event's crack through an internal structure: the crack extracted from the cut
  // mesh, the sphere split and capped along it (CGAL corefinement), and embedded again.
  CuttableMesh cut_box(box);
  {
    CutOptions o;
    o.snap_epsilon = 0;
    cut_box.Cut(plane, o);
  }
  const TetMesh cut_rest = cut_box.RestMesh();
  const SurfaceMesh sphere =
      MakeUvSphere(Eigen::Vector3d(25, 25, 20), 12, structure_rings, 2 * structure_rings);
  // As in the pipeline, vertices off the crack in unchanged elements keep their embedding.
  const mechanics::EmbeddedPoints sphere_embedding =
      mechanics::EmbeddedPoints::Embed(sphere.vertices, box.vertices, box.tetrahedra);
  std::vector<double> split_ms;
  cutting::SplitStructure split;
  for (int r = 0; r < repeats; ++r) {
    const auto t0 = Clock::now();
    const SurfaceMesh crack = cutting::CrackSurface(cut_rest);
    split = cutting::SplitAlongCrack(sphere, crack, 1e-4 * cut_box.mean_rest_edge_length());
    const mechanics::EmbeddedPoints embedded =
        cutting::EmbedSplitStructure(split, cut_rest, {&sphere_embedding, &sphere.vertices});
    split_ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
  }
  const double split_median_ms = Median(split_ms);
  std::printf(
      "internal structure split along that crack (sphere of %d triangles; %d added by the "
      "subdivision, %d cap triangles), crack extraction and local re-embedding included: "
      "median %.3f ms wall over %d runs\n",
      sphere.num_faces(), split.added_faces, split.cap_faces, split_median_ms, repeats);

  if (!json_path.empty()) {
    nlohmann::json j;
    j["beam"] = {{"vertices", beam.num_vertices()},
                 {"tetrahedra", beam.num_tetrahedra()},
                 {"n_v", nv_crossed},
                 {"conditioning",
                  {{"youngs_modulus_pa", cond.youngs_modulus_pa},
                   {"poisson_ratio", cond.poisson_ratio},
                   {"density_kg_per_m3", cond.density_kg_per_m3},
                   {"dt_s", cond.dt_s}}}};
    for (const Run& run : runs) {
      nlohmann::json jr = {{"method", run.method},
                           {"eps", run.eps},
                           {"vertices_per_nv", run.vertices_per_nv},
                           {"tetrahedra_per_nv", run.tetrahedra_per_nv}};
      for (const StepRecord& r : run.steps)
        jr["steps"].push_back({{"step", r.step},
                               {"vertices", r.num_vertices},
                               {"tetrahedra", r.num_tetrahedra},
                               {"crossed", r.crossed},
                               {"rejected", r.rejected},
                               {"min_dihedral_deg", r.min_dihedral_deg},
                               {"condition_number", r.condition_number}});
      j["runs"].push_back(jr);
    }
    j["single_event"] = single;
    j["speed"] = {{"crossed_tetrahedra", crossed},
                  {"mesh_tetrahedra", box.num_tetrahedra()},
                  {"median_ms", median_ms},
                  {"median_thread_cpu_ms", median_cpu_ms},
                  {"repeats", repeats}};
    j["structure_split"] = {{"triangles", sphere.num_faces()},
                            {"added_triangles", split.added_faces},
                            {"cap_triangles", split.cap_faces},
                            {"median_ms", split_median_ms},
                            {"repeats", repeats}};
    WriteFileAtomic(json_path, [&](std::ostream& out) { out << j.dump(2) << "\n"; });
  }
  if (!svg_path.empty()) {
    const std::string svg = Plot(runs);
    WriteFileAtomic(svg_path, [&](std::ostream& out) { out << svg; });
  }
  return 0;
}

}  // namespace arreg::cli
