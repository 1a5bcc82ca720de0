#include "cutting/random_cuts.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <filesystem>
#include <limits>
#include <nlohmann/json.hpp>
#include <set>

#include "core/error.h"
#include "core/file_util.h"
#include "core/mesh_generators.h"
#include "core/mesh_io.h"
#include "core/mesh_ops.h"
#include "cutting/mesh_checks.h"
#include "cutting/quadratic_cutter.h"
#include "mechanics/high_order_mesh.h"
#include "test_util.h"

namespace arreg::cutting {
namespace {

TetMesh Beam() {
  return MakeBoxTetMesh(Eigen::Vector3d(100, 30, 20), Eigen::Vector3i(10, 3, 2), BoxTetSplit::kSix);
}

// Distance of point p to the plane of triangle f of S.
double PlaneDistance(const CutSurface& s, int f, const Eigen::Vector3d& p) {
  const Eigen::Vector3d a = s.vertices.row(s.triangles(f, 0)).transpose();
  const Eigen::Vector3d b = s.vertices.row(s.triangles(f, 1)).transpose();
  const Eigen::Vector3d c = s.vertices.row(s.triangles(f, 2)).transpose();
  return std::abs((b - a).cross(c - a).normalized().dot(p - a));
}

// Distance of p to the segment [a, b].
double SegmentDistance(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                       const Eigen::Vector3d& b) {
  const double t = std::clamp((p - a).dot(b - a) / (b - a).squaredNorm(), 0.0, 1.0);
  return (p - (a + t * (b - a))).norm();
}

// Grazing cuts pass their vertex, edge or face at 1e-9..1e-3 of the reference edge length: every
// grazed vertex is at the drawn distance from the plane of every triangle of S (to 1e-3 of it; a
// face's three vertices to within a factor 2, as the normal of a sliver face left by earlier cuts
// is rounded), on the uncut beam and on the beam after earlier cuts (whose edges can be short:
// 1e-9 of such an edge is below the rounding of the beam's coordinates, up to 100 mm, which the
// test allows).
TEST(RandomCuts, GrazingCutsAreWithinTheStatedDistance) {
  const double kRounding = 8 * std::numeric_limits<double>::epsilon() * 100;
  RandomCutOptions options;
  double smallest = 1, largest = 0;
  for (std::uint64_t seed = 1; seed <= 12; ++seed) {
    RandomCutGenerator generator(seed, options);
    CuttableMesh mesh(Beam());
    for (int i = 0; i < 12; ++i) {
      const RandomCutKind kind =
          i % 4 == 3
              ? RandomCutKind::kPlane
              : static_cast<RandomCutKind>(static_cast<int>(RandomCutKind::kGrazeVertex) + i % 4);
      const RandomCut cut = generator.Next(mesh, kind);
      if (kind != RandomCutKind::kPlane) {
        ASSERT_EQ(cut.kind, kind);
        ASSERT_EQ(static_cast<int>(cut.grazed.size()), i % 4 + 1);
        const double fraction = cut.graze_distance_mm / cut.graze_reference_mm;
        EXPECT_GE(fraction, options.min_graze_fraction * (1 - 1e-12));
        EXPECT_LE(fraction, options.max_graze_fraction * (1 + 1e-12));
        smallest = std::min(smallest, fraction);
        largest = std::max(largest, fraction);
        for (int v : cut.grazed)
          for (int f = 0; f < cut.surface.num_triangles(); ++f)
            EXPECT_NEAR(PlaneDistance(cut.surface, f, mesh.positions()[v]), cut.graze_distance_mm,
                        (kind == RandomCutKind::kGrazeFace ? 0.5 : 1e-3) * cut.graze_distance_mm +
                            kRounding)
                << RandomCutKindName(kind) << " seed " << seed << " cut " << i;
        // The reference length of an edge is its length.
        if (kind == RandomCutKind::kGrazeEdge) {
          EXPECT_NEAR(cut.graze_reference_mm,
                      (mesh.positions()[cut.grazed[0]] - mesh.positions()[cut.grazed[1]]).norm(),
                      1e-12 * cut.graze_reference_mm);
        }
        EXPECT_GT(cut.graze_reference_mm, 0);
      }
      // Cuts refine the mesh: keep it small (the sweep tests the cuts themselves).
      if (mesh.num_tetrahedra() > 3000) continue;
      const CutSummary s = mesh.Cut(cut.surface, cut.options);
      generator.Record(cut, s.status);
    }
  }
  // The log-uniform draw covers the range.
  EXPECT_LT(smallest, 1e-8);
  EXPECT_GT(largest, 1e-4);
}

// A crack-front cut starts on the free edge of an earlier partial cut of its sequence: the
// segment it starts on lies on that front, and so does a row of S's vertices. Without an earlier
// partial cut the generator makes a partial cut instead.
TEST(RandomCuts, CrackFrontCutsStartOnAnEarlierFront) {
  int checked = 0;
  for (std::uint64_t seed = 1; seed <= 15; ++seed) {
    RandomCutGenerator generator(seed);
    CuttableMesh mesh(Beam());
    EXPECT_EQ(generator.Next(mesh, RandomCutKind::kCrackFront).kind, RandomCutKind::kPartial);
    std::vector<RandomCut> fronts;
    for (int i = 0; i < 8; ++i) {
      const RandomCut cut =
          generator.Next(mesh, i % 2 ? RandomCutKind::kCrackFront : RandomCutKind::kPartial);
      if (cut.kind == RandomCutKind::kCrackFront) {
        ASSERT_FALSE(fronts.empty());
        bool on_a_front = false;
        for (const RandomCut& f : fronts) {
          const double tol = 1e-9 * (f.front[1] - f.front[0]).norm();
          if (SegmentDistance(cut.start[0], f.front[0], f.front[1]) > tol ||
              SegmentDistance(cut.start[1], f.front[0], f.front[1]) > tol)
            continue;
          on_a_front = true;
          int on_segment = 0;
          for (int v = 0; v < cut.surface.vertices.rows(); ++v)
            on_segment += SegmentDistance(cut.surface.vertices.row(v).transpose(), f.front[0],
                                          f.front[1]) <= tol;
          EXPECT_GE(on_segment, 5);  // the strip's first row of 5 grid vertices
          // It starts on at least the middle fifth of that front.
          EXPECT_GE((cut.start[1] - cut.start[0]).norm(),
                    0.2 * (f.front[1] - f.front[0]).norm() * (1 - 1e-9));
        }
        EXPECT_TRUE(on_a_front) << "seed " << seed << " cut " << i;
        ++checked;
      }
      const CutSummary s = mesh.Cut(cut.surface, cut.options);
      generator.Record(cut, s.status);
      if (s.status == CutStatus::kCut && cut.has_front) fronts.push_back(cut);
      EXPECT_EQ(generator.num_fronts(), static_cast<int>(fronts.size()));
    }
  }
  EXPECT_GT(checked, 30);
}

// The same seed gives the same cuts.
TEST(RandomCuts, GeneratorIsDeterministic) {
  CuttableMesh mesh(Beam());
  RandomCutGenerator a(42), b(42);
  for (int i = 0; i < 20; ++i) {
    const RandomCut ca = a.Next(mesh), cb = b.Next(mesh);
    ASSERT_EQ(ca.kind, cb.kind);
    ASSERT_TRUE(ca.surface.vertices == cb.surface.vertices);
    ASSERT_TRUE(ca.surface.triangles == cb.surface.triangles);
    ASSERT_EQ(ca.options.snap_epsilon, cb.options.snap_epsilon);
  }
}

// 150 cuts drawn in sequences on the beam and, when ../shared/data has it, the SOFA liver (a
// sequence ends once its mesh has 5,000 elements): no check fails, every kind is drawn, and most
// cuts cross the mesh.
TEST(RandomCuts, SweepOfAHundredAndFiftyCutsKeepsEveryCheck) {
  std::vector<SweepMesh> meshes;
  meshes.push_back({"beam", Beam(), {}, {}});
  const std::string liver = testing::SharedDataPath("meshes/sofa/liver.msh");
  if (!liver.empty()) {
    SweepMesh m{"liver", ReadTetMesh(liver), {}, {}};
    m.mesh.triangles.resize(0, 3);
    FixOrientation(&m.mesh);
    meshes.push_back(std::move(m));
  }
  SweepOptions options;
  options.num_cuts = 150;
  options.seed = 7;
  options.max_tetrahedra = 5000;  // fast: sequences end once cuts refined the mesh that far
  const SweepResult r = RunRandomCutSweep(meshes, options);
  EXPECT_LE(r.cuts, 150);
  EXPECT_GE(r.cuts, 50);
  for (const Violation& v : r.violations)
    ADD_FAILURE() << v.mesh << " sequence " << v.sequence << " cut " << v.index << " ("
                  << RandomCutKindName(v.kind) << "): " << v.check << ": " << v.detail;
  int crossed = 0, cuts = 0;
  std::set<std::string> kinds;
  for (const auto& [mesh, per_kind] : r.counts)
    for (const auto& [kind, c] : per_kind) {
      crossed += c.crossed;
      cuts += c.cuts;
      kinds.insert(kind);
    }
  EXPECT_EQ(cuts, r.cuts);
  EXPECT_GT(crossed, 0.6 * cuts);
  EXPECT_EQ(static_cast<int>(kinds.size()), kNumRandomCutKinds);
}

// Draws `n` random cuts (seed `seed`) on `mesh` in turn, each made; returns how many crossed it.
template <class Mesh, class Corners>
int DrawAndCut(int seed, int n, Mesh* mesh, Corners corners, std::vector<RandomCut>* cuts) {
  RandomCutGenerator generator(seed);
  int made = 0;
  for (int i = 0; i < n; ++i) {
    RandomCut cut = generator.Next(corners(*mesh));
    const CutSummary s = mesh->Cut(cut.surface, cut.options);
    made += s.status == CutStatus::kCut;
    generator.Record(cut, s.status);
    cuts->push_back(std::move(cut));
  }
  return made;
}

// A saved case replays: the cuts of a sequence written by SaveCase, run again from initial.vtk,
// pass every check (the files hold the surfaces to the bit). A case with a missing file is an
// error naming it.
TEST(RandomCuts, SavedCaseReplays) {
  const std::string dir = testing::ScratchDir("random_cuts_replay");
  SweepMesh mesh{"beam", Beam(), {}, {}};
  CuttableMesh cutter(mesh.mesh);
  std::vector<RandomCut> cuts;
  ASSERT_GT(
      DrawAndCut(
          3, 6, &cutter, [](const CuttableMesh& m) -> const CuttableMesh& { return m; }, &cuts),
      2);
  Violation v;
  v.mesh = "beam";
  v.index = 5;
  v.check = "volume";
  SaveCase(dir + "/case", mesh, cuts, v);
  EXPECT_TRUE(ReplayCase(dir + "/case").empty());
  std::filesystem::remove(dir + "/case/cut_002.obj");
  try {
    ReplayCase(dir + "/case");
    FAIL() << "no throw";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("cut_002.obj"), std::string::npos) << e.what();
  }
}

// A degree-2 case keeps its degree and its curved control points: it replays clean, and with one
// control point moved through its element the replay reports the inverted element.
TEST(RandomCuts, SavedQuadraticCaseReplays) {
  const std::string dir = testing::ScratchDir("random_cuts_replay_p2");
  const Eigen::Vector3d size(60, 20, 16);
  SweepMesh mesh{"beam-curved", MakeBoxTetMesh(size, Eigen::Vector3i(6, 2, 2)), {}, {}};
  mesh.quadratic_nodes = BulgedBoxQuadraticNodes(mesh.mesh, size, 1.5);
  mechanics::HighOrderTetMesh raised = mechanics::RaiseTetMesh(mesh.mesh, 2);
  raised.nodes = mesh.quadratic_nodes;
  QuadraticCuttableMesh cutter(raised);
  std::vector<RandomCut> cuts;
  ASSERT_GT(DrawAndCut(
                5, 5, &cutter,
                [](const QuadraticCuttableMesh& m) -> const CuttableMesh& { return m.skeleton(); },
                &cuts),
            1);
  Violation v;
  v.mesh = mesh.name;
  SaveCase(dir + "/case", mesh, cuts, v, 2);
  const nlohmann::json c = nlohmann::json::parse(ReadFileToString(dir + "/case/case.json"));
  EXPECT_EQ(c.at("degree").get<int>(), 2);
  EXPECT_EQ(c.at("quadratic_nodes").size(), static_cast<size_t>(raised.num_nodes()));
  EXPECT_TRUE(ReplayCase(dir + "/case").empty());
  // The control point of element 0's edge (0, 1) (BernsteinIndices(2): corners first, then
  // (1,1,0,0)) moved 40 mm along that edge: det J < 0 near corner 1.
  SweepMesh broken = mesh;
  const int node = raised.elements(0, 4);
  ASSERT_GE(node, raised.num_vertices);
  broken.quadratic_nodes.row(node) +=
      40 * (raised.nodes.row(raised.elements(0, 1)) - raised.nodes.row(raised.elements(0, 0)))
               .normalized();
  SaveCase(dir + "/broken", broken, cuts, v, 2);
  const std::vector<Violation> found = ReplayCase(dir + "/broken");
  ASSERT_EQ(found.size(), 1u);
  EXPECT_EQ(found[0].check, "jacobian");
}

// Saved sweep cases that failed a check before the remesher was fixed replay without violation.
// beam_partial_zero_volume (a graze-edge, a graze-face, a plane and a partial cut on the beam):
// the partial cut made an element whose exact orientation is positive but whose rest volume in
// floating point, as the mechanics compute it, is -5.6e-15 mm^3 (ApplyCutChange refused it); the
// cutter now refuses such elements in its check of the new elements.
// beam_graze_face_indefinite (a plane, then a graze-face cut): the grazing cut left elements of
// normalised volume 9.5e-13 and the implicit step's matrix was not positive definite to CHOLMOD;
// vertices nearer to S than min_barycentric of their shortest edge now count as on S.
TEST(RandomCuts, SavedFailuresReplayWithoutViolation) {
  for (const char* name : {"beam_partial_zero_volume", "beam_graze_face_indefinite",
                           "beam_graze_face_sliver", "kidney_graze_face_corefinement"}) {
    const std::vector<Violation> v =
        ReplayCase(std::string(ARREG_SOURCE_DIR) + "/tests/data/random_cuts/" + name);
    EXPECT_TRUE(v.empty()) << name << ": " << v[0].check << ": " << v[0].detail;
  }
}

// The floor on inserted elements' quality is what keeps this sequence solvable: without it
// (min_element_quality 0) a grazing cut leaves a sliver on which the implicit step's Cholesky
// factorisation fails; with the default the event is remade with a wider on-surface tolerance.
TEST(RandomCuts, SliverFloorKeepsTheStepSolvable) {
  const std::string saved = std::string(ARREG_SOURCE_DIR) +
                            "/tests/data/random_cuts/"
                            "beam_graze_face_sliver";
  const std::string dir = testing::ScratchDir("sliver_floor_off");
  for (const char* file : {"initial.vtk", "cut_000.obj", "cut_001.obj", "cut_002.obj",
                           "cut_003.obj", "cut_004.obj", "cut_005.obj"})
    std::filesystem::copy_file(saved + "/" + file, dir + "/" + file,
                               std::filesystem::copy_options::overwrite_existing);
  nlohmann::json c = nlohmann::json::parse(ReadFileToString(saved + "/case.json"));
  for (auto& cut : c.at("cuts")) cut.at("options")["min_element_quality"] = 0.0;
  WriteFileAtomic(dir + "/case.json", [&](std::ostream& out) { out << c.dump(1); });
  const std::vector<Violation> without = ReplayCase(dir);
  ASSERT_EQ(without.size(), 1u);
  EXPECT_EQ(without[0].check, "mechanics");
  EXPECT_NE(without[0].detail.find("smallest normalised volume"), std::string::npos);
  EXPECT_TRUE(ReplayCase(saved).empty());
}

TEST(RandomCuts, OptionsCheckNamesTheField) {
  SweepOptions o;
  o.cuts.min_graze_fraction = 0;
  try {
    o.Check();
    FAIL() << "no throw";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("min_graze_fraction"), std::string::npos);
  }
  EXPECT_THROW(RandomCutKindFromName("cone", "kind"), Error);
  SweepOptions cubic;
  cubic.degree = 3;
  EXPECT_THROW(cubic.Check(), Error);
  EXPECT_EQ(RandomCutKindFromName("graze-edge", "kind"), RandomCutKind::kGrazeEdge);
}

}  // namespace
}  // namespace arreg::cutting
