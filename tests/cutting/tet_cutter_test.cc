#include "cutting/tet_cutter.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <random>

#include "core/error.h"
#include "core/mesh_generators.h"
#include "core/mesh_io.h"
#include "core/mesh_ops.h"
#include "cutting/mesh_checks.h"
#include "cutting/predicates.h"
#include "test_util.h"

namespace arreg::cutting {
namespace {

// The method names are the scene and record spelling; any other name is refused naming the field.
TEST(RemeshMethodTest, NamesRoundTripAndUnknownNamesAreRefused) {
  for (RemeshMethod method : {RemeshMethod::kFlips, RemeshMethod::kBielser})
    EXPECT_EQ(ParseRemeshMethod(RemeshMethodName(method), "", "method"), method);
  EXPECT_STREQ(RemeshMethodName(RemeshMethod::kBielser), "bielser");
  try {
    ParseRemeshMethod("subdivide", "cuts.json", "cuts[].options.method");
    FAIL() << "an unknown method was accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.file(), "cuts.json");
    EXPECT_EQ(e.where(), "cuts[].options.method");
  }
}

TetMesh Box() {
  return MakeBoxTetMesh(Eigen::Vector3d(30, 20, 10), Eigen::Vector3i(3, 2, 2), BoxTetSplit::kSix);
}

// Component count with elements connected when they share a vertex: the
// mechanical notion of "still attached".
int NumPieces(const TetMesh& m) {
  int n = 0;
  ConnectedComponents(m, Adjacency::kVertex, &n);
  return n;
}

// Every element of `m` lies on one side of the plane (within tol).
bool ElementsOnOneSide(const TetMesh& m, const Eigen::Vector3d& p, const Eigen::Vector3d& n,
                       double tol) {
  for (int t = 0; t < m.num_tetrahedra(); ++t) {
    double lo = 1e300, hi = -1e300;
    for (int k = 0; k < 4; ++k) {
      const double d = n.dot(m.vertices.row(m.tetrahedra(t, k)).transpose() - p);
      lo = std::min(lo, d);
      hi = std::max(hi, d);
    }
    if (lo < -tol && hi > tol) return false;
  }
  return true;
}

TEST(Predicates, OrientationMatchesSignedVolume) {
  const Eigen::Vector3d a(0, 0, 0), b(1, 0, 0), c(0, 1, 0), d(0, 0, 1);
  EXPECT_EQ(Orient3d(a, b, c, d), 1);
  EXPECT_EQ(Orient3d(a, c, b, d), -1);
  EXPECT_EQ(Orient3d(a, b, c, Eigen::Vector3d(0.3, 0.2, 0)), 0);
  EXPECT_NEAR(TetVolume(a, b, c, d), 1.0 / 6.0, 1e-15);
  // The regular tetrahedron has quality 1 (sign from its orientation).
  EXPECT_NEAR(std::abs(TetQuality(Eigen::Vector3d(1, 1, 1), Eigen::Vector3d(1, -1, -1),
                                  Eigen::Vector3d(-1, 1, -1), Eigen::Vector3d(-1, -1, 1))),
              1.0, 1e-12);
}

TEST(CutOptions, CheckNamesTheField) {
  CutOptions o;
  o.snap_epsilon = -1;
  try {
    o.Check();
    FAIL() << "no throw";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("snap_epsilon"), std::string::npos);
  }
}

struct PlaneCase {
  RemeshMethod method;
  double eps;
  unsigned seed;
};

class RandomPlanes : public ::testing::TestWithParam<PlaneCase> {};

// Random planes through a box: each cut keeps the mesh conforming and positive,
// keeps the volume, and separates it into pieces lying on either side of the plane.
TEST_P(RandomPlanes, KeepInvariantsAndSeparate) {
  const TetMesh box = Box();
  std::mt19937 rng(GetParam().seed);
  std::uniform_real_distribution<double> u(-1, 1);
  int num_cut = 0;
  const int kCases = 400;
  for (int i = 0; i < kCases; ++i) {
    CuttableMesh m(box);
    Eigen::Vector3d n(u(rng), u(rng), u(rng));
    n.normalize();
    const Eigen::Vector3d p(15 + 12 * u(rng), 10 + 8 * u(rng), 5 + 4 * u(rng));
    CutOptions opt;
    opt.method = GetParam().method;
    opt.snap_epsilon = GetParam().eps;
    const double v0 = CheckMeshInvariants(m.RestMesh()).total_volume;
    const CutSummary s = m.Cut(MakePlaneSurface(p, n, 100, 100, Eigen::Vector3d::UnitX()), opt);
    ASSERT_NE(s.status, CutStatus::kRejected) << "case " << i << ": " << s.message;
    const TetMesh rest = m.RestMesh();
    const MeshInvariants inv = CheckMeshInvariants(rest);
    ASSERT_TRUE(inv.ok()) << "case " << i << ": " << inv.ToString();
    ASSERT_NEAR(inv.total_volume, v0, 1e-9 * v0) << "case " << i;
    ASSERT_EQ(inv.num_unreferenced_vertices, 0) << "case " << i;
    if (s.status != CutStatus::kCut) continue;
    ++num_cut;
    // The plane passes through the box: two pieces, each on one side.
    EXPECT_TRUE(ElementsOnOneSide(rest, p, n, 1e-6 * m.mean_rest_edge_length())) << "case " << i;
    EXPECT_EQ(NumPieces(rest), 2) << "case " << i;
  }
  EXPECT_GT(num_cut, kCases / 3);
}

INSTANTIATE_TEST_SUITE_P(Methods, RandomPlanes,
                         ::testing::Values(PlaneCase{RemeshMethod::kFlips, 0.0, 1},
                                           PlaneCase{RemeshMethod::kFlips, 0.2, 2},
                                           PlaneCase{RemeshMethod::kBielser, 0.0, 3},
                                           PlaneCase{RemeshMethod::kBielser, 0.2, 4}),
                         [](const ::testing::TestParamInfo<PlaneCase>& info) {
                           return std::string(info.param.method == RemeshMethod::kFlips
                                                  ? "Flips"
                                                  : "Bielser") +
                                  "Eps" +
                                  std::to_string(static_cast<int>(info.param.eps * 10 + 0.5));
                         });

// Curved surfaces (cylinders and spheres of random radius) through the box.
TEST(TetCutter, RandomCurvedSurfacesKeepInvariants) {
  const TetMesh box = Box();
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(0, 1);
  int separated = 0, rejected = 0;
  for (int i = 0; i < 300; ++i) {
    CuttableMesh m(box);
    const double v0 = CheckMeshInvariants(m.RestMesh()).total_volume;
    const Eigen::Vector3d c(30 * u(rng), 20 * u(rng), -5 + 20 * u(rng));
    const double r = 4 + 20 * u(rng);
    CutSurface s;
    if (i % 2 == 0) {
      // Cylinder along z through the whole box thickness.
      s = MakeGridSurface(
          [&](double a, double h) {
            const double phi = 2 * M_PI * a;
            return Eigen::Vector3d(c.x() + r * std::cos(phi), c.y() + r * std::sin(phi),
                                   -1 + 12 * h);
          },
          48, 3);
    } else {
      s = MakeGridSurface(
          [&](double a, double b) {
            const double phi = 2 * M_PI * a, theta = M_PI * b;
            return Eigen::Vector3d(c.x() + r * std::sin(theta) * std::cos(phi),
                                   c.y() + r * std::sin(theta) * std::sin(phi),
                                   c.z() + r * std::cos(theta));
          },
          32, 16);
    }
    CutOptions opt;
    opt.snap_epsilon = (i % 3) * 0.1;
    const CutSummary sum = m.Cut(s, opt);
    // Surfaces curved on the scale of the elements may be refused (mesh unchanged).
    rejected += sum.status == CutStatus::kRejected;
    const MeshInvariants inv = CheckMeshInvariants(m.RestMesh());
    ASSERT_TRUE(inv.ok()) << "case " << i << ": " << inv.ToString();
    ASSERT_NEAR(inv.total_volume, v0, 1e-9 * v0) << "case " << i;
    if (NumPieces(m.RestMesh()) >= 2) ++separated;
  }
  EXPECT_GT(separated, 50);
  EXPECT_LT(rejected, 15);
}

// A partial cut (S ends inside the mesh) opens a crack but leaves one piece;
// continuing it in steps separates the mesh when S finally crosses it.
TEST(TetCutter, ProgressivePartialCutsSeparateAtTheEnd) {
  for (RemeshMethod method : {RemeshMethod::kFlips, RemeshMethod::kBielser}) {
    for (double eps : {0.0, 0.1, 0.3}) {
      CuttableMesh m(
          MakeBoxTetMesh(Eigen::Vector3d(40, 12, 8), Eigen::Vector3i(10, 3, 2), BoxTetSplit::kSix));
      const double v0 = CheckMeshInvariants(m.RestMesh()).total_volume;
      const Eigen::Vector3d n = Eigen::Vector3d(1, 0.07, 0.04).normalized();
      const Eigen::Vector3d p(20.3, 6, 4);
      CutOptions opt;
      opt.method = method;
      opt.snap_epsilon = eps;
      int duplicated = 0;
      for (int step = 1; step <= 8; ++step) {
        // The cut advances along y: S covers y < front.
        const double front = -1 + 14.0 * step / 8;
        const Eigen::Vector3d u = n.cross(Eigen::Vector3d::UnitZ()).normalized();
        const Eigen::Vector3d w = n.cross(u);
        CutSurface s = MakeGridSurface(
            [&](double a, double b) {
              Eigen::Vector3d q = p + (-20 + 40 * a) * w;
              const double t0 = (-2 - p.y()) / u.y(), t1 = (front - p.y()) / u.y();
              return Eigen::Vector3d(q + (t0 + (t1 - t0) * b) * u);
            },
            2, 2);
        const CutSummary sum = m.Cut(s, opt);
        ASSERT_NE(sum.status, CutStatus::kRejected) << sum.message;
        duplicated += sum.num_duplicated_vertices;
        const TetMesh rest = m.RestMesh();
        const MeshInvariants inv = CheckMeshInvariants(rest);
        ASSERT_TRUE(inv.ok()) << "step " << step << ": " << inv.ToString();
        ASSERT_NEAR(inv.total_volume, v0, 1e-9 * v0);
        if (step < 7) {
          EXPECT_EQ(NumPieces(rest), 1) << "step " << step;
        }
        if (step >= 3 && step < 7) {
          EXPECT_GT(duplicated, 0) << "step " << step;
        }
      }
      EXPECT_EQ(NumPieces(m.RestMesh()), 2) << "eps " << eps;
    }
  }
}

// S ends inside the element, crossing two of its edges: the 1-4 vertex goes to the centroid of
// the element's section by S's tangent plane, which here lies inside S. It is then on S like a
// crossing, and the face it makes with the two crossings is on S and unsewn (taken as off S,
// the strip of a growing cut stayed sewn in every element where it ended).
TEST(TetCutter, SplitVertexInsideAPartialSIsOnIt) {
  TetMesh tet;
  tet.vertices.resize(4, 3);
  tet.vertices << 0, 0, 0, 10, 0, 0, 0, 10, 0, 0, 0, 10;
  tet.tetrahedra.resize(1, 4);
  tet.tetrahedra << 0, 1, 2, 3;
  // The plane x = 2 cuts edges 0-1, 1-2 and 1-3 at (2, 0, 0), (2, 8, 0) and (2, 0, 8); S is
  // its part with z <= 3, so it crosses the first two. The section's centroid (2, 8/3, 8/3)
  // is inside S.
  const CutSurface s = MakeGridSurface(
      [](double a, double b) { return Eigen::Vector3d(2, -5 + 20 * a, -5 + 8 * b); }, 2, 2);
  for (RemeshMethod method : {RemeshMethod::kFlips, RemeshMethod::kBielser}) {
    CuttableMesh m(tet);
    CutOptions opt;
    opt.method = method;
    opt.snap_epsilon = 0;
    CutChange change;
    const CutSummary sum = m.Cut(s, opt, &change);
    ASSERT_EQ(sum.status, CutStatus::kCut) << sum.message;
    const MeshInvariants inv = CheckMeshInvariants(m.RestMesh());
    ASSERT_TRUE(inv.ok()) << inv.ToString();
    EXPECT_NEAR(inv.total_volume, 1000.0 / 6.0, 1e-9);
    // Every unsewn face lies in S, and the section's part inside S has at least one.
    EXPECT_GE(change.separated_faces.size(), 1u) << "method " << static_cast<int>(method);
    for (const auto& f : change.separated_faces)
      for (int v : f) {
        const Eigen::Vector3d x = m.rest_positions()[v];
        EXPECT_NEAR(x.x(), 2.0, 1e-9);
        EXPECT_LE(x.z(), 3.0 + 1e-9);
      }
    EXPECT_EQ(NumPieces(m.RestMesh()), 1);  // a partial cut leaves one piece
  }
}

// Two crossing planes give four pieces, whichever is cut first.
TEST(TetCutter, CrossingCutsGiveFourPieces) {
  for (RemeshMethod method : {RemeshMethod::kFlips, RemeshMethod::kBielser}) {
    for (double eps : {0.0, 0.2}) {
      CuttableMesh m(Box());
      const double v0 = CheckMeshInvariants(m.RestMesh()).total_volume;
      CutOptions opt;
      opt.method = method;
      opt.snap_epsilon = eps;
      ASSERT_EQ(
          m.Cut(MakePlaneSurface({14.1, 10, 5}, {1, 0.1, 0.05}, 60, 60, {0, 1, 0}), opt).status,
          CutStatus::kCut);
      ASSERT_EQ(
          m.Cut(MakePlaneSurface({15, 9.3, 5}, {0.08, 1, -0.1}, 60, 60, {1, 0, 0}), opt).status,
          CutStatus::kCut);
      const MeshInvariants inv = CheckMeshInvariants(m.RestMesh());
      ASSERT_TRUE(inv.ok()) << inv.ToString();
      EXPECT_NEAR(inv.total_volume, v0, 1e-9 * v0);
      EXPECT_EQ(NumPieces(m.RestMesh()), 4);
    }
  }
}

// Mechanics follow the change: under an affine current configuration new and
// duplicated vertices (and snapped ones) stay on the same affine map, so the
// piecewise-linear deformation (and with it the elastic force of every
// element) is that of the uncut body; the change description rebuilds the mesh.
TEST(TetCutter, ChangeDescriptionRebuildsTheMeshAndKeepsTheAffineState) {
  const TetMesh box = Box();
  Eigen::Matrix3d A;
  A << 1.1, 0.05, 0, -0.02, 0.95, 0.1, 0.03, 0, 1.02;
  const Eigen::Vector3d b(1, -2, 0.5), velocity(0.3, -0.1, 0.2);
  RowMatX3d current(box.num_vertices(), 3), vel(box.num_vertices(), 3);
  for (int i = 0; i < box.num_vertices(); ++i) {
    current.row(i) = (A * box.vertices.row(i).transpose() + b).transpose();
    vel.row(i) = velocity.transpose();
  }
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int i = 0; i < 100; ++i) {
    CuttableMesh m(box, current, vel);
    CutOptions opt;
    opt.method = i % 2 ? RemeshMethod::kBielser : RemeshMethod::kFlips;
    opt.snap_epsilon = 0.15 * (i % 3);
    const Eigen::Vector3d n = Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized();
    const Eigen::Vector3d p = A * Eigen::Vector3d(15 + 10 * u(rng), 10 + 7 * u(rng), 5) + b;
    // Keep the old state to replay the change on.
    std::vector<Eigen::Vector3d> rest = m.rest_positions(), cur = m.positions(), v = m.velocities();
    std::vector<std::array<int, 4>> tets = m.tetrahedra();
    CutChange change;
    const CutSummary s = m.Cut(MakePlaneSurface(p, n, 100, 100, {1, 0, 0}), opt, &change);
    ASSERT_NE(s.status, CutStatus::kRejected) << s.message;
    if (s.status != CutStatus::kCut) continue;
    for (const SnappedVertex& sv : change.snapped) {
      rest[sv.index] = (1 - sv.t) * rest[sv.a] + sv.t * rest[sv.b];
      cur[sv.index] = (1 - sv.t) * cur[sv.a] + sv.t * cur[sv.b];
      v[sv.index] = (1 - sv.t) * v[sv.a] + sv.t * v[sv.b];
    }
    for (const NewVertex& nv : change.new_vertices) {
      ASSERT_EQ(nv.index, static_cast<int>(rest.size()));
      Eigen::Vector3d r = Eigen::Vector3d::Zero(), c = r, w = r;
      double sum = 0;
      for (size_t k = 0; k < nv.parents.size(); ++k) {
        ASSERT_GE(nv.weights[k], 0);
        sum += nv.weights[k];
        r += nv.weights[k] * rest[nv.parents[k]];
        c += nv.weights[k] * cur[nv.parents[k]];
        w += nv.weights[k] * v[nv.parents[k]];
      }
      ASSERT_NEAR(sum, 1, 1e-12);
      rest.push_back(r);
      cur.push_back(c);
      v.push_back(w);
    }
    for (const DuplicatedVertex& d : change.duplicated) {
      ASSERT_EQ(d.index, static_cast<int>(rest.size()));
      ASSERT_TRUE(d.side == 1 || d.side == -1);
      rest.push_back(rest[d.original]);
      cur.push_back(cur[d.original]);
      v.push_back(v[d.original]);
    }
    ASSERT_EQ(static_cast<int>(rest.size()), m.num_vertices());
    ASSERT_GE(change.new_tetrahedra.rows(), static_cast<int>(change.removed_tetrahedra.size()));
    for (size_t k = 0; k < change.removed_tetrahedra.size(); ++k)
      for (int j = 0; j < 4; ++j)
        tets[change.removed_tetrahedra[k]][j] = change.new_tetrahedra(k, j);
    for (int k = static_cast<int>(change.removed_tetrahedra.size());
         k < change.new_tetrahedra.rows(); ++k)
      tets.push_back({change.new_tetrahedra(k, 0), change.new_tetrahedra(k, 1),
                      change.new_tetrahedra(k, 2), change.new_tetrahedra(k, 3)});
    ASSERT_EQ(tets, m.tetrahedra());
    for (int k = 0; k < m.num_vertices(); ++k) {
      ASSERT_LT((rest[k] - m.rest_positions()[k]).norm(), 1e-12);
      ASSERT_LT((cur[k] - m.positions()[k]).norm(), 1e-12);
      ASSERT_LT((v[k] - velocity).norm(), 1e-12);
      ASSERT_LT((m.positions()[k] - (A * m.rest_positions()[k] + b)).norm(), 1e-9) << k;
    }
  }
}

// Growth per crossed element (thesis 5.2.1): ours adds about n(v) vertices before
// separation and 6.4-7.2 n(v) elements; the Bielser-style baseline adds more of both.
TEST(TetCutter, GrowthMatchesTheTheoreticalAnalysis) {
  const TetMesh mesh =
      MakeBoxTetMesh(Eigen::Vector3d(40, 40, 40), Eigen::Vector3i(8, 8, 8), BoxTetSplit::kSix);
  double ours_v = 0, ours_t = 0, bielser_v = 0, bielser_t = 0, crossed = 0;
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int i = 0; i < 10; ++i) {
    // Planes through the interior that avoid the boundary (interior growth only).
    const Eigen::Vector3d n = Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized();
    const Eigen::Vector3d p(20 + 2 * u(rng), 20 + 2 * u(rng), 20 + 2 * u(rng));
    const CutSurface s = MakePlaneSurface(p, n, 100, 100, {1, 0, 0});
    CutOptions opt;
    opt.snap_epsilon = 0;
    opt.separate = false;
    CuttableMesh a(mesh), b(mesh);
    const CutSummary sa = a.Cut(s, opt);
    opt.method = RemeshMethod::kBielser;
    const CutSummary sb = b.Cut(s, opt);
    crossed += sa.num_crossed_tetrahedra;
    ours_v += sa.num_new_vertices;
    ours_t += sa.num_tetrahedra_added + sa.num_crossed_tetrahedra;
    bielser_v += sb.num_new_vertices;
    bielser_t += sb.num_tetrahedra_added + sb.num_crossed_tetrahedra;
  }
  // Vertices: n(v) plus the boundary face/edge vertices (a fraction of n(v)).
  EXPECT_GT(ours_v / crossed, 1.0);
  EXPECT_LT(ours_v / crossed, 1.6);
  EXPECT_GT(ours_t / crossed, 5.0);
  EXPECT_LT(ours_t / crossed, 8.0);
  EXPECT_GT(bielser_v / crossed, 2.0);
  EXPECT_GT(bielser_t / crossed, ours_t / crossed * 1.5);
}

// Random planes (full and partial) and spheres through the SOFA liver (curved
// boundary: boundary edges are bisected, never flipped, so the volume is kept).
TEST(TetCutter, LiverRandomSurfacesKeepInvariants) {
  ARREG_REQUIRE_SHARED(path, "meshes/sofa/liver.msh");
  TetMesh liver = ReadTetMesh(path);
  FixOrientation(&liver);
  const BoundingBox box = ComputeBoundingBox(liver.vertices);
  std::mt19937 rng(21);
  std::uniform_real_distribution<double> u(0, 1);
  int cut = 0, rejected = 0;
  for (int i = 0; i < 150; ++i) {
    CuttableMesh m(liver);
    const double v0 = CheckMeshInvariants(m.RestMesh()).total_volume;
    const Eigen::Vector3d p =
        box.min + box.size().cwiseProduct(Eigen::Vector3d(u(rng), u(rng), u(rng)));
    const Eigen::Vector3d n =
        Eigen::Vector3d(u(rng) - 0.5, u(rng) - 0.5, u(rng) - 0.5).normalized();
    CutOptions opt;
    opt.method = i % 3 == 2 ? RemeshMethod::kBielser : RemeshMethod::kFlips;
    opt.snap_epsilon = 0.1 * (i % 4);
    // Half of the cases are partial: S covers only half of the plane.
    const double half = box.size().norm();
    // Every fifth case is a sphere (curved S) through the liver.
    const double radius = (0.2 + 0.5 * u(rng)) * half;
    const auto sphere = [&](double a, double b) {
      const double phi = 2 * M_PI * a, theta = M_PI * b;
      return Eigen::Vector3d(p + radius * Eigen::Vector3d(std::sin(theta) * std::cos(phi),
                                                          std::sin(theta) * std::sin(phi),
                                                          std::cos(theta)));
    };
    const CutSurface s =
        i % 5 == 4 ? MakeGridSurface(sphere, 24, 12)
        : i % 2    ? MakePlaneSurface(p, n, half, half, {1, 0, 0})
                   : MakeGridSurface(
                      [&](double a, double b) {
                        const Eigen::Vector3d e1 = n.unitOrthogonal(), e2 = n.cross(e1);
                        return Eigen::Vector3d(p + (2 * a - 1) * half * e1 + b * half * e2);
                      },
                      4, 4);
    const CutSummary sum = m.Cut(s, opt);
    rejected += sum.status == CutStatus::kRejected;
    cut += sum.status == CutStatus::kCut;
    const MeshInvariants inv = CheckMeshInvariants(m.RestMesh());
    ASSERT_TRUE(inv.ok()) << "case " << i << ": " << inv.ToString();
    ASSERT_NEAR(inv.total_volume, v0, 1e-9 * std::abs(v0)) << "case " << i;
  }
  EXPECT_GT(cut, 50);
  EXPECT_LT(rejected, 8);
}

// With an on-surface tolerance wider than a layer of thin elements, all four vertices of the
// elements between two vertex layers count as on S. A plane across the whole block must still
// separate it, and no element may straddle the plane by more than the tolerance.
TEST(TetCutter, ToleranceSlabOfThinElementsStillSeparates) {
  // Cells 4 mm thick along x, 10 mm across: vertex layers at x = 0, 4, ..., 40.
  CuttableMesh m(
      MakeBoxTetMesh(Eigen::Vector3d(40, 20, 20), Eigen::Vector3i(10, 2, 2), BoxTetSplit::kSix));
  const double v0 = CheckMeshInvariants(m.RestMesh()).total_volume;
  CutOptions opt;
  opt.snap_epsilon = 0.0;
  // 2.5 mm: the layers x = 20 (2.1 mm from the plane) and x = 24 (1.9 mm) are both within.
  opt.on_surface_tolerance = 2.5 / m.mean_rest_edge_length();
  const CutSummary s = m.Cut(MakePlaneSurface({22.1, 10, 10}, {1, 0, 0}, 60, 60, {0, 1, 0}), opt);
  ASSERT_EQ(s.status, CutStatus::kCut) << s.message;
  const TetMesh rest = m.RestMesh();
  const MeshInvariants inv = CheckMeshInvariants(rest);
  ASSERT_TRUE(inv.ok()) << inv.ToString();
  EXPECT_NEAR(inv.total_volume, v0, 1e-9 * v0);
  EXPECT_EQ(NumPieces(rest), 2);
  EXPECT_TRUE(ElementsOnOneSide(rest, {22.1, 10, 10}, {1, 0, 0}, 2.5));
}

}  // namespace
}  // namespace arreg::cutting
