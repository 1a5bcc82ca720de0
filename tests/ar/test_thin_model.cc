// ThinSystem (src/ar/pipeline/thin_model.h): loading, a sheet pulled by feature springs, cuts.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <set>

#include "ar/pipeline/thin_model.h"
#include "core/error.h"
#include "core/mesh_io.h"
#include "test_util.h"

namespace arreg::pipeline {
namespace {

namespace fs = std::filesystem;

// A flat square sheet in the z = 0 plane, centred at the origin, n x n cells of two triangles.
SurfaceMesh Sheet(double size_mm, int n) {
  SurfaceMesh m;
  m.vertices.resize((n + 1) * (n + 1), 3);
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i)
      m.vertices.row(j * (n + 1) + i) << size_mm * (double(i) / n - 0.5),
          size_mm * (double(j) / n - 0.5), 0.0;
  m.faces.resize(2 * n * n, 3);
  int f = 0;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int a = j * (n + 1) + i, b = a + 1, c = a + n + 1, d = c + 1;
      m.faces.row(f++) << a, b, d;
      m.faces.row(f++) << a, d, c;
    }
  return m;
}

LoadedThin ShellOf(const SurfaceMesh& m) {
  LoadedThin l;
  l.spec.name = "membrane";
  l.spec.type = ThinStructureType::kShell;
  l.spec.thickness_mm = 0.5;
  l.spec.material.youngs_modulus_pa = 20000;
  l.spec.material.poisson_ratio = 0.3;
  l.vertices = m.vertices;
  l.triangles = m.faces;
  return l;
}

ThinSystemOptions StepOptions() {
  ThinSystemOptions o;
  o.integrator.dt_s = 1.0 / 30.0;
  o.integrator.newton_mode = mechanics::NewtonMode::kFixedIterations;
  o.integrator.max_newton_iterations = 2;
  o.integrator.newton_tolerance_mm = 1e-6;
  o.integrator.rayleigh_mass_alpha = 0.1;
  o.integrator.rayleigh_stiffness_beta = 0.01;
  o.integrator.linear_solver.type = mechanics::LinearSolverType::kCholmod;
  return o;
}

// The lift triangle (of the frame-0 mid-surface) that holds point p of the flat sheet.
int TriangleAt(const ThinSystem& thin, const Eigen::Vector3d& p) {
  const RowMatX3d v = thin.LiftVertices();
  const RowMatX3i& t = thin.lift_triangles();
  for (int f = 0; f < t.rows(); ++f) {
    const Eigen::Vector2d a = v.row(t(f, 0)).head<2>(), b = v.row(t(f, 1)).head<2>(),
                          c = v.row(t(f, 2)).head<2>();
    Eigen::Matrix2d m;
    m << b - a, c - a;
    const Eigen::Vector2d uv = m.inverse() * (p.head<2>() - a);
    if (uv.x() >= -1e-12 && uv.y() >= -1e-12 && uv.sum() <= 1 + 1e-12) return f;
  }
  ADD_FAILURE() << "no triangle at " << p.transpose();
  return 0;
}

// Feature springs (5 mN/mm) at 12 points spread over the 40 mm sheet, at their own positions.
std::vector<int> TwelveFeatures(ThinSystem* thin, std::vector<Eigen::Vector3d>* points) {
  for (double x : {-15.0, -5.0, 5.0, 15.0})
    for (double y : {-12.0, 3.0, 14.0}) points->emplace_back(x + 0.3, y + 0.2, 0.0);
  std::vector<int> ids;
  for (const Eigen::Vector3d& p : *points)
    ids.push_back(thin->AddFeatureSpring(TriangleAt(*thin, p), p, p, 5.0));
  return ids;
}

// Connected components of a triangle list by shared vertices.
int Components(const SurfaceMesh& m) {
  std::vector<int> parent(m.num_vertices());
  for (size_t i = 0; i < parent.size(); ++i) parent[i] = static_cast<int>(i);
  std::function<int(int)> find = [&](int x) {
    return parent[x] == x ? x : parent[x] = find(parent[x]);
  };
  for (int f = 0; f < m.num_faces(); ++f) {
    parent[find(m.faces(f, 1))] = find(m.faces(f, 0));
    parent[find(m.faces(f, 2))] = find(m.faces(f, 0));
  }
  std::set<int> roots;
  for (int f = 0; f < m.num_faces(); ++f) roots.insert(find(m.faces(f, 0)));
  return static_cast<int>(roots.size());
}

// A scene (in `dir`) of one vessel of radius 1.5 mm along the centreline file `name`.
Scene VesselScene(const std::string& dir, const std::string& name) {
  Scene scene;
  scene.path = dir + "/scene.json";
  ThinStructure t;
  t.name = "vessel";
  t.type = ThinStructureType::kVessel;
  t.centreline_path = dir + "/" + name;
  t.radius_mm = 1.5;
  scene.thin_structures = {t};
  return scene;
}

TEST(ThinModel, CentrelineReaderNamesBadInput) {
  const std::string dir = testing::ScratchDir("thin_centreline");
  const std::string path = dir + "/c.obj";
  std::ofstream(path) << "v 0 0 0\nv 1 0 0\nv 2 0 0\nv 1 1 0\nl 1 2 3\nl 2 4\n";
  RowMatX3d v;
  std::vector<Eigen::Vector2i> seg;
  ReadCentreline(path, &v, &seg);
  EXPECT_EQ(v.rows(), 4);
  EXPECT_EQ(seg.size(), 3u);
  std::ofstream(path) << "v 0 0 0\nv 1 0 0\nl 1 3\n";
  try {
    ReadCentreline(path, &v, &seg);
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("line 3"), std::string::npos) << e.what();
  }
}

TEST(ThinModel, LoadingRejectsLoopsAndBadFixedVertices) {
  const std::string dir = testing::ScratchDir("thin_load");
  std::ofstream(dir + "/loop.obj") << "v 0 0 0\nv 1 0 0\nv 0 1 0\nl 1 2 3 1\n";
  Scene scene = VesselScene(dir, "loop.obj");
  EXPECT_THROW(LoadThinStructures(scene), Error);
  WriteSurfaceMesh(dir + "/sheet.obj", Sheet(10, 2));
  ThinStructure shell;
  shell.name = "s";
  shell.type = ThinStructureType::kShell;
  shell.mesh_path = dir + "/sheet.obj";
  shell.thickness_mm = 0.5;
  shell.fixed_vertices = {9};  // 3 x 3 vertices
  scene.thin_structures = {shell};
  try {
    LoadThinStructures(scene);
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("thin_structures[0].fixed_vertices"), std::string::npos)
        << e.what();
  }
  scene.thin_structures[0].fixed_vertices = {8};
  const std::vector<LoadedThin> loaded = LoadThinStructures(scene);
  ASSERT_EQ(loaded.size(), 1u);
  EXPECT_EQ(loaded[0].triangles.rows(), 8);
}

// Feature springs whose targets move the sheet rigidly (a translation and a turn about the
// normal): a rigid motion costs no elastic energy (BezierShell's coordinates are zero for
// it), so the damped system settles with every spring at zero length. The motion ends at frame
// 20; 40 damped frames later 0.01 mm (0.1 % of the 8 mm motion) is left at most.
TEST(ThinModel, SheetFollowsFeatureTargets) {
  mechanics::MechanicalState body{TetMesh(), mechanics::Material()};
  mechanics::SpringEnergy springs;
  const SurfaceMesh sheet = Sheet(40, 8);
  ThinSystem thin({ShellOf(sheet)}, Scene(), &body, &springs, StepOptions());
  EXPECT_EQ(thin.num_shell_elements(), 128);
  std::vector<Eigen::Vector3d> points;
  const std::vector<int> ids = TwelveFeatures(&thin, &points);
  for (size_t i = 0; i < ids.size(); ++i)
    EXPECT_LT((thin.FeatureAnchor(ids[i]) - points[i]).norm(), 1e-9);
  const Eigen::Matrix3d turn = Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const Eigen::Vector3d shift(3, -2, 7);
  const int frames = 60;
  for (int frame = 1; frame <= frames; ++frame) {
    const double s = std::min(1.0, frame / 20.0);  // the motion over 20 frames, then held
    const Eigen::Matrix3d r =
        Eigen::AngleAxisd(0.1 * s, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    for (size_t i = 0; i < ids.size(); ++i)
      thin.SetFeatureTarget(ids[i], r * points[i] + s * shift);
    const mechanics::GeneralisedSummary step = thin.Step(&body);
    ASSERT_NE(step.status, mechanics::StepStatus::kLinearSolveFailed);
  }
  double max_error = 0;
  for (size_t i = 0; i < ids.size(); ++i)
    max_error =
        std::max(max_error, (thin.FeatureAnchor(ids[i]) - (turn * points[i] + shift)).norm());
  std::cout << "features: max error " << max_error << " mm\n";
  EXPECT_LT(max_error, 0.01);
  // The whole sheet moved with it (not only the feature points).
  const SurfaceMesh now = thin.Surfaces()[0];
  ASSERT_EQ(now.num_vertices(), sheet.num_vertices());
  double max_vertex = 0;
  for (int v = 0; v < sheet.num_vertices(); ++v) {
    double best = 1e9;  // the Surfaces() order is by node, the same as the sheet's vertices
    best = (now.vertices.row(v).transpose() - (turn * sheet.vertices.row(v).transpose() + shift))
               .norm();
    max_vertex = std::max(max_vertex, best);
  }
  std::cout << "sheet vertices: max error " << max_vertex << " mm\n";
  EXPECT_LT(max_vertex, 0.01);
}

// Largest node distance (mm) between two runs of a sheet pulled by 12 features, 4 of which are
// lost at frame 10: removing a spring keeps the system's pattern and the solver's factor, while
// `force_rebuild` adds a zero-stiffness spring there, which collects the terms again and
// rebuilds the pattern, the symbolic analysis and the factor (what a removal did before).
double LostFeaturesDifference(mechanics::LinearSolverType solver) {
  std::vector<std::vector<Eigen::Vector3d>> finals;
  for (const bool force_rebuild : {false, true}) {
    mechanics::MechanicalState body{TetMesh(), mechanics::Material()};
    mechanics::SpringEnergy springs;
    ThinSystemOptions o = StepOptions();
    o.integrator.linear_solver.type = solver;
    ThinSystem thin({ShellOf(Sheet(40, 8))}, Scene(), &body, &springs, o);
    std::vector<Eigen::Vector3d> points;
    const std::vector<int> ids = TwelveFeatures(&thin, &points);
    for (int frame = 1; frame <= 30; ++frame) {
      const double s = std::min(1.0, frame / 20.0);
      if (frame == 10) {
        for (int i = 0; i < 4; ++i) thin.RemoveFeatureSpring(ids[3 * i]);
        if (force_rebuild)
          thin.AddFeatureSpring(TriangleAt(thin, points[1]), points[1], points[1], 0.0);
      }
      for (size_t i = 0; i < ids.size(); ++i)
        thin.SetFeatureTarget(ids[i],
                              points[i] + s * Eigen::Vector3d(2 * points[i].x() / 15, 0, 6));
      EXPECT_NE(thin.Step(&body).status, mechanics::StepStatus::kLinearSolveFailed);
    }
    std::vector<Eigen::Vector3d> x;
    for (int n = 0; n < thin.state().num_nodes(); ++n) x.push_back(thin.state().position(n));
    finals.push_back(x);
  }
  double d = 0;
  for (size_t n = 0; n < finals[0].size(); ++n)
    d = std::max(d, (finals[0][n] - finals[1][n]).norm());
  return d;
}

// Lost features do not rebuild the system: with a direct solve the state is the one of a
// rebuilt system to round-off (the pattern is the same: a feature's stencil is its element's);
// with cholmod-pcg (the run's default) the kept factor preconditions CG to the same relative
// tolerance (1e-3 of the increment) where the rebuilt one is exact.
TEST(ThinModel, LostFeaturesKeepTheFactorAndTheState) {
  const double direct = LostFeaturesDifference(mechanics::LinearSolverType::kCholmod);
  const double pcg = LostFeaturesDifference(mechanics::LinearSolverType::kCholmodPcg);
  std::cout << "lost features, kept pattern vs rebuilt: cholmod " << direct << " mm, cholmod-pcg "
            << pcg << " mm\n";
  EXPECT_LT(direct, 1e-9);
  EXPECT_LT(pcg, 1e-3);
}

// A cut across the sheet separates it: afterwards features on the two halves pulled 5 mm
// apart reach their targets, while on the uncut sheet the membrane (E t = 10 N/m, 25 % strain
// over the gap) holds them back by millimetres.
double PullApartError(bool cut, int* components) {
  mechanics::MechanicalState body{TetMesh(), mechanics::Material()};
  mechanics::SpringEnergy springs;
  ThinSystem thin({ShellOf(Sheet(40, 8))}, Scene(), &body, &springs, StepOptions());
  std::vector<Eigen::Vector3d> points;
  for (double x : {-15.0, -5.0, 5.0, 15.0})
    for (double y : {-12.0, -6.0, 6.0, 12.0}) points.emplace_back(x + 0.3, y + 0.2, 0.0);
  std::vector<int> ids;
  for (const Eigen::Vector3d& p : points)
    ids.push_back(thin.AddFeatureSpring(TriangleAt(thin, p), p, p, 1.0));
  if (cut) {
    const ThinCutEvent ev = thin.Cut({Eigen::Vector3d(-25, 0.7, 0), Eigen::Vector3d(25, 0.7, 0)},
                                     {}, Eigen::Vector3d(0, 0, -1));
    EXPECT_EQ(ev.shells_cut, 1);
    EXPECT_GT(ev.shell_nodes_added, 8);
  }
  for (int frame = 1; frame <= 60; ++frame) {
    const double s = std::min(1.0, frame / 20.0);
    for (size_t i = 0; i < ids.size(); ++i)
      thin.SetFeatureTarget(ids[i],
                            points[i] + Eigen::Vector3d(0, points[i].y() > 0 ? 5 * s : -5 * s, 0));
    thin.Step(&body);
  }
  *components = Components(thin.Surfaces()[0]);
  double sum = 0;
  for (size_t i = 0; i < ids.size(); ++i)
    sum += (thin.FeatureAnchor(ids[i]) -
            (points[i] + Eigen::Vector3d(0, points[i].y() > 0 ? 5 : -5, 0)))
               .norm();
  return sum / ids.size();
}

TEST(ThinModel, CutSeparatesTheSheet) {
  int uncut_components = 0, cut_components = 0;
  const double uncut = PullApartError(false, &uncut_components);
  const double cut = PullApartError(true, &cut_components);
  std::cout << "mean feature error: uncut " << uncut << " mm, cut " << cut << " mm\n";
  EXPECT_EQ(uncut_components, 1);
  EXPECT_EQ(cut_components, 2);
  EXPECT_GT(uncut, 2.0);
  EXPECT_LT(cut, 0.1);
}

// A Y-shaped vessel tree (three branches meeting at one centreline vertex, tied there) cut
// across its trunk by a plane: the trunk separates (its tube falls into two pieces, one frame
// duplicated), a plane beyond the tree changes nothing, and the system still steps.
TEST(ThinModel, VesselTreeIsCutAcrossOneBranch) {
  const std::string dir = testing::ScratchDir("thin_vessel");
  std::ofstream(dir + "/tree.obj") << "v 0 0 0\nv 20 0 0\nv 40 0 0\nv 60 10 0\nv 60 -10 0\n"
                                      "l 1 2 3\nl 3 4\nl 3 5\n";
  Scene scene = VesselScene(dir, "tree.obj");
  scene.thin_structures[0].material.poisson_ratio = 0.0;
  scene.thin_structures[0].fixed_vertices = {0};
  const std::vector<LoadedThin> loaded = LoadThinStructures(scene);
  mechanics::MechanicalState body{TetMesh(), mechanics::Material()};
  mechanics::SpringEnergy springs;
  ThinSystem thin(loaded, scene, &body, &springs, StepOptions());
  EXPECT_EQ(thin.num_vessels(), 1);
  const SurfaceMesh before = thin.Surfaces()[0];
  EXPECT_EQ(before.num_vertices() % ThinSystem::kTubeSides, 0);
  EXPECT_EQ(Components(before), 3);  // one tube per branch
  // The plane x = 20 through the trunk (the polyline across it, seen along -z).
  const ThinCutEvent ev = thin.Cut(
      {}, {Eigen::Vector3d(20.3, -10, 0), Eigen::Vector3d(20.3, 10, 0)}, Eigen::Vector3d(0, 0, -1));
  EXPECT_EQ(ev.vessels_cut, 1);
  EXPECT_EQ(ev.vessel_frames_added, 1);
  const SurfaceMesh after = thin.Surfaces()[0];
  EXPECT_EQ(Components(after), 4);
  EXPECT_EQ(after.num_vertices(), before.num_vertices() + ThinSystem::kTubeSides);
  // A plane that misses every chord (beyond the tree's end) changes nothing.
  const ThinCutEvent none = thin.Cut({}, {Eigen::Vector3d(80, -10, 0), Eigen::Vector3d(80, 10, 0)},
                                     Eigen::Vector3d(0, 0, -1));
  EXPECT_EQ(none.vessels_cut, 0);
  for (int frame = 0; frame < 5; ++frame)
    EXPECT_NE(thin.Step(&body).status, mechanics::StepStatus::kLinearSolveFailed);
}

// A shell tied to a tetrahedral block follows the block when the block's own feature springs
// move it: one system, the ties carry the motion.
TEST(ThinModel, ShellTiedToTheOrganFollowsIt) {
  TetMesh cube;  // a 20 mm cube of 5 tetrahedra, z in [-20, 0]
  cube.vertices.resize(8, 3);
  for (int i = 0; i < 8; ++i)
    cube.vertices.row(i) << ((i & 1) ? 10 : -10), ((i & 2) ? 10 : -10), ((i & 4) ? 0 : -20);
  cube.tetrahedra.resize(5, 4);
  cube.tetrahedra << 0, 1, 2, 4, 1, 3, 2, 7, 1, 4, 5, 7, 2, 4, 7, 6, 1, 2, 4, 7;
  for (int t = 0; t < 5; ++t) {
    const Eigen::Vector3d a = cube.vertices.row(cube.tetrahedra(t, 0)),
                          b = cube.vertices.row(cube.tetrahedra(t, 1)),
                          c = cube.vertices.row(cube.tetrahedra(t, 2)),
                          d = cube.vertices.row(cube.tetrahedra(t, 3));
    if ((b - a).cross(c - a).dot(d - a) < 0)
      std::swap(cube.tetrahedra(t, 2), cube.tetrahedra(t, 3));
  }
  mechanics::Material material;
  material.youngs_modulus_pa = 5000;
  mechanics::MechanicalState body(cube, material);
  mechanics::SpringEnergy springs;
  LoadedThin shell = ShellOf(Sheet(16, 4));  // on the top face z = 0, inside the cube's outline
  shell.spec.attach = ThinAttachment::kModel;
  shell.spec.attach_distance_mm = 0.5;
  ThinSystem thin({shell}, Scene(), &body, &springs, StepOptions());
  const Eigen::Vector3d shift(0, 0, 4);
  std::vector<int> spring_ids;
  for (int v = 0; v < 8; ++v) {
    mechanics::EmbeddedPoint e;
    // Each cube vertex pulled by a spring on itself (weight 1 on one tetrahedron's corner).
    for (int t = 0; t < 5 && e.tet < 0; ++t)
      for (int a = 0; a < 4; ++a)
        if (cube.tetrahedra(t, a) == v) {
          e.tet = t;
          e.barycentric.setZero();
          e.barycentric[a] = 1;
          break;
        }
    spring_ids.push_back(springs.Add(e, cube.vertices.row(v).transpose() + shift, 50.0));
  }
  for (int frame = 0; frame < 60; ++frame) thin.Step(&body);
  // The block translated (its springs agree with a rigid shift) and the sheet with it.
  for (int v = 0; v < 8; ++v)
    EXPECT_LT((body.position(v) - cube.vertices.row(v).transpose() - shift).norm(), 0.05);
  const SurfaceMesh now = thin.Surfaces()[0];
  const SurfaceMesh rest = Sheet(16, 4);
  for (int v = 0; v < rest.num_vertices(); ++v)
    EXPECT_LT((now.vertices.row(v) - rest.vertices.row(v) - shift.transpose()).norm(), 0.05) << v;
}

}  // namespace
}  // namespace arreg::pipeline
