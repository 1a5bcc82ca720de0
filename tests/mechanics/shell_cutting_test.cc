// Cuts and tears of Bezier shells (docs/shell-cutting.md): mesh invariants
// after many random cuts, separation under a static solve, crossing cuts,
// re-anchored surface points, and stress-driven tearing of the thesis's
// L-shaped membrane and precut sheet (thesis section 6.2, figs. 6.12-6.16).
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <map>
#include <numeric>
#include <random>
#include <set>

#include "core/error.h"
#include "mechanics/bezier_shell.h"
#include "mechanics/generalised_solver.h"
#include "mechanics/shell_cutting.h"
#include "mechanics/shell_mapping.h"
#include "mechanics/so3.h"

namespace arreg::mechanics {
namespace {

using Triangles = std::vector<Eigen::Vector3i>;

// A flat sheet in the plane z = 0: nx x ny square cells of `cell` mm, each
// split by its (1, 1) diagonal; nodes with identity rest rotations (z up).
// Cells for which `keep(i, j)` is false are left out (nodes of no cell too).
template <class Keep>
void MakeSheet(int nx, int ny, double cell, Keep keep, GeneralisedState* state, Triangles* tris) {
  std::vector<int> id((nx + 1) * (ny + 1), -1);
  auto node = [&](int i, int j) {
    int& n = id[j * (nx + 1) + i];
    if (n < 0) n = state->AddFrameNode({cell * i, cell * j, 0}, Eigen::Matrix3d::Identity());
    return n;
  };
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      if (!keep(i, j)) continue;
      const int a = node(i, j), b = node(i + 1, j), c = node(i + 1, j + 1), d = node(i, j + 1);
      tris->push_back({a, b, c});
      tris->push_back({a, c, d});
    }
}
void MakeSheet(int nx, int ny, double cell, GeneralisedState* state, Triangles* tris) {
  MakeSheet(nx, ny, cell, [](int, int) { return true; }, state, tris);
}

Eigen::Vector3d Rest(const GeneralisedState& s, int n) {
  return s.rest_positions().row(n).transpose();
}

double RestArea(const GeneralisedState& s, const Eigen::Vector3i& t) {
  return 0.5 * (Rest(s, t[1]) - Rest(s, t[0])).cross(Rest(s, t[2]) - Rest(s, t[0])).norm();
}
double TotalRestArea(const GeneralisedState& s, const Triangles& tris) {
  double a = 0;
  for (const auto& t : tris) a += RestArea(s, t);
  return a;
}

// Smallest angle (rad) and smallest area of the rest triangles.
void Quality(const GeneralisedState& s, const Triangles& tris, double* min_angle,
             double* min_area) {
  *min_angle = M_PI;
  *min_area = INFINITY;
  for (const auto& t : tris) {
    for (int i = 0; i < 3; ++i) {
      const Eigen::Vector3d u = Rest(s, t[(i + 1) % 3]) - Rest(s, t[i]);
      const Eigen::Vector3d v = Rest(s, t[(i + 2) % 3]) - Rest(s, t[i]);
      *min_angle = std::min(*min_angle, std::atan2(u.cross(v).norm(), u.dot(v)));
    }
    *min_area = std::min(*min_area, RestArea(s, t));
  }
}

// A manifold with boundary, consistently oriented: no repeated node in a
// triangle, each directed edge once, each undirected edge in one or two
// triangles, and the triangles around each node connected across shared edges
// (one fan: no two sheets touching at a node). Returns "" or what failed.
std::string ManifoldProblem(const Triangles& tris) {
  std::set<std::pair<int, int>> directed;
  std::map<int, std::vector<int>> around;
  for (size_t t = 0; t < tris.size(); ++t) {
    const auto& tri = tris[t];
    if (tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2])
      return "triangle " + std::to_string(t) + " repeats a node";
    for (int i = 0; i < 3; ++i) {
      if (!directed.insert({tri[i], tri[(i + 1) % 3]}).second)
        return "directed edge twice (non-manifold or flipped) at triangle " + std::to_string(t);
      around[tri[i]].push_back(int(t));
    }
  }
  for (const auto& [v, ts] : around) {
    std::vector<int> parent(ts.size());
    std::iota(parent.begin(), parent.end(), 0);
    auto find = [&](int i) {
      while (parent[i] != i) i = parent[i] = parent[parent[i]];
      return i;
    };
    std::map<int, int> with;
    for (size_t i = 0; i < ts.size(); ++i)
      for (int c = 0; c < 3; ++c) {
        const int w = tris[ts[i]][c];
        if (w == v) continue;
        auto [it, inserted] = with.emplace(w, int(i));
        if (!inserted) parent[find(int(i))] = find(it->second);
      }
    for (size_t i = 0; i < ts.size(); ++i)
      if (find(int(i)) != find(0)) return "node " + std::to_string(v) + " has two fans";
  }
  return "";
}

// Connected pieces of the mesh (across shared edges): piece index per node (-1: unused).
std::vector<int> Pieces(const GeneralisedState& s, const Triangles& tris, int* count) {
  std::vector<int> parent(s.num_nodes());
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
  };
  std::vector<char> used(s.num_nodes(), 0);
  for (const auto& t : tris)
    for (int i = 0; i < 3; ++i) {
      parent[find(t[i])] = find(t[(i + 1) % 3]);
      used[t[i]] = 1;
    }
  std::map<int, int> index;
  std::vector<int> piece(s.num_nodes(), -1);
  for (int n = 0; n < s.num_nodes(); ++n)
    if (used[n]) piece[n] = index.emplace(find(n), int(index.size())).first->second;
  *count = int(index.size());
  return piece;
}

BezierShellOptions ShellOptions() {
  BezierShellOptions o;
  o.material.youngs_modulus_kpa = 10;
  o.material.poisson_ratio = 0.3;
  o.material.thickness_mm = 0.5;
  return o;
}

// Moves the current state rigidly: x -> r x + c, R -> r R.
void MoveRigidly(const Eigen::Matrix3d& r, const Eigen::Vector3d& c, GeneralisedState* s) {
  for (int n = 0; n < s->num_nodes(); ++n) {
    s->mutable_positions().row(n) = (r * Rest(*s, n) + c).transpose();
    s->mutable_rotation(n) = r * s->rest_rotation(n);
  }
}

TEST(ShellCutting, OptionsNameTheirField) {
  ShellCutOptions cut;
  cut.snap_fraction = 0.5;
  try {
    cut.Check();
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.where(), "shell_cut.snap_fraction");
  }
  ShellTearOptions tear;
  tear.strength_kpa = 0;
  EXPECT_THROW(tear.Check(), Error);
  GeneralisedState s;
  Triangles t;
  MakeSheet(2, 2, 1.0, &s, &t);
  EXPECT_THROW(CutShell(&s, &t, {{0, 0, 0}}, {0, 0, 1}, cut = {}), Error);
  EXPECT_THROW(CutShell(&s, &t, {{0, 0, 0}, {1, 1, 0}}, {0, 0, 0}, {}), Error);
}

// A straight cut across a 30 x 20 mm sheet (6 x 4 cells of 5 mm) at x = 13,
// through cells (splits), leaves two pieces; pulled apart (left edge clamped,
// right edge moved 5 mm), the right piece translates rigidly: zero energy,
// where the uncut sheet stores energy.
TEST(ShellCutting, StraightCutSeparatesAndPiecesMoveIndependently) {
  for (const bool cut : {false, true}) {
    GeneralisedState s;
    Triangles tris;
    MakeSheet(6, 4, 5.0, &s, &tris);
    const double area = TotalRestArea(s, tris);
    const int nodes_before = s.num_nodes();
    ShellCutResult result;
    if (cut) {
      result = CutShell(&s, &tris, {{13, -1, 0}, {13, 21, 0}}, {0, 0, 1}, {});
      EXPECT_EQ(ManifoldProblem(tris), "");
      EXPECT_NEAR(TotalRestArea(s, tris), area, 1e-12 * area);
      int pieces = 0;
      const std::vector<int> piece = Pieces(s, tris, &pieces);
      EXPECT_EQ(pieces, 2);
      // Every node is on the side of x = 13 its piece is; 9 nodes inserted on
      // the crossed horizontal and diagonal edges, each duplicated.
      for (int n = 0; n < s.num_nodes(); ++n) {
        const double x = s.rest_positions()(n, 0);
        if (piece[n] < 0 || std::abs(x - 13) < 1e-9) continue;
        EXPECT_EQ(piece[n], x < 13 ? piece[0] : 1 - piece[0]) << n;
      }
      EXPECT_EQ(result.inserted_nodes.size(), 9u);
      EXPECT_EQ(result.duplicated_nodes, 9);
      EXPECT_EQ(s.num_nodes(), nodes_before + 18);
      EXPECT_EQ(result.element_children.size(), 48u);
    }
    BezierShell shell(s, tris, ShellOptions());
    for (int e = 0; e < shell.num_elements(); ++e)
      EXPECT_LT(shell.ElementEnergy(s, e), 1e-20) << e;
    for (int n = 0; n < s.num_nodes(); ++n) {
      const double x = s.rest_positions()(n, 0);
      if (x < 1e-9) {
        s.SetFixedTranslation(n, true);
        s.SetFixedRotation(n, true);
      } else if (x > 30 - 1e-9) {
        s.SetFixedTranslation(n, true);
        s.SetFixedRotation(n, true);
        s.mutable_positions()(n, 0) += 5;
      }
    }
    GeneralisedStaticSolver solver({});
    const GeneralisedSummary summary = solver.Solve(&s, {&shell});
    ASSERT_EQ(summary.status, StepStatus::kConverged) << summary.message;
    if (!cut) {
      // Uncut: 5 mm on 30 mm stretches the sheet (order E t A eps^2 / 2 ~ 10 uJ).
      EXPECT_GT(summary.energy, 1.0);
      continue;
    }
    EXPECT_LT(summary.energy, 1e-12);
    for (int n = 0; n < s.num_nodes(); ++n) {
      const double x = s.rest_positions()(n, 0);
      const double dx = s.positions()(n, 0) - x;
      if (x < 13 - 1e-9) EXPECT_NEAR(dx, 0, 1e-6) << n;
      if (x > 13 + 1e-9) EXPECT_NEAR(dx, 5, 1e-6) << n;
    }
  }
}

// Two cuts crossing inside the sheet (neither reaches the boundary): the
// crossing point gets four nodes (one per quadrant), the mesh stays manifold.
TEST(ShellCutting, CrossingCutsMakeFourCornersAtTheCrossing) {
  GeneralisedState s;
  Triangles tris;
  MakeSheet(6, 4, 5.0, &s, &tris);
  const double area = TotalRestArea(s, tris);
  CutShell(&s, &tris, {{4, 10, 0}, {26, 10, 0}}, {0, 0, 1}, {});
  ASSERT_EQ(ManifoldProblem(tris), "");
  const ShellCutResult second = CutShell(&s, &tris, {{13, 3, 0}, {13, 17, 0}}, {0, 0, 1}, {});
  ASSERT_EQ(ManifoldProblem(tris), "");
  EXPECT_NEAR(TotalRestArea(s, tris), area, 1e-12 * area);
  std::set<int> at_crossing;
  for (const auto& t : tris)
    for (int i = 0; i < 3; ++i)
      if ((Rest(s, t[i]) - Eigen::Vector3d(13, 10, 0)).norm() < 1e-9) at_crossing.insert(t[i]);
  EXPECT_EQ(at_crossing.size(), 4u);
  int pieces = 0;
  Pieces(s, tris, &pieces);
  EXPECT_EQ(pieces, 1);  // the cuts end inside the sheet
  EXPECT_GT(second.duplicated_nodes, 0);
}

// Fine points mapped before a cut keep their rest positions after
// RemapShellMapping, each on its own side; the cut of a rigidly moved sheet
// leaves every element at zero energy (inserted nodes' rotations interpolated).
TEST(ShellCutting, RemappedPointsKeepTheirPlaceAndSide) {
  GeneralisedState s;
  Triangles tris;
  MakeSheet(6, 4, 5.0, &s, &tris);
  const Eigen::Matrix3d r = ExpSO3({0.3, -1.1, 0.7});
  MoveRigidly(r, {4, -2, 9}, &s);
  BezierShell before(s, tris, ShellOptions());
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> ux(0.2, 29.8), uy(0.2, 19.8);
  RowMatX3d fine(300, 3);
  for (int p = 0; p < fine.rows(); ++p) fine.row(p) << ux(rng), uy(rng), 0;
  const ShellMapping mapping = ShellMapping::Project(before, s, fine);
  const ShellCutResult cut =
      CutShell(&s, &tris, {{-1, 3, 0}, {12, 9, 0}, {22, 8, 0}, {31, 16, 0}}, {0, 0, 1}, {});
  ASSERT_TRUE(cut.changed());
  BezierShell after(s, tris, ShellOptions());
  for (int e = 0; e < after.num_elements(); ++e) EXPECT_LT(after.ElementEnergy(s, e), 1e-18) << e;
  const ShellMapping moved = RemapShellMapping(mapping, cut, after, s);
  RowMatX3d x_before, x_after;
  mapping.Positions(s, &x_before);  // old elements' nodes are still in the state
  moved.Positions(s, &x_after);
  EXPECT_LT((x_before - x_after).cwiseAbs().maxCoeff(), 1e-9);
  // Side: the element a point lands in lies on the same side of the cut as the point.
  int pieces = 0;
  const std::vector<int> piece = Pieces(s, tris, &pieces);
  EXPECT_EQ(pieces, 2);
  std::map<int, int> piece_of_side;  // above/below the polyline -> piece
  for (int p = 0; p < moved.size(); ++p) {
    const Eigen::Vector3i t = tris[moved.point(p).element];
    const double x = fine(p, 0);
    const double line_y = x < 12 ? 3 + 6 * (x + 1) / 13 : x < 22 ? 9 - (x - 12) / 10 : 8 + 8 * (x - 22) / 9;
    // Snapping moves the crack up to snap_fraction x 5 mm (diagonals 7 mm) from the line.
    if (std::abs(fine(p, 1) - line_y) < 1.5) continue;
    const int side = fine(p, 1) > line_y;
    auto [it, inserted] = piece_of_side.emplace(side, piece[t[0]]);
    EXPECT_EQ(it->second, piece[t[0]]) << p;
  }
}

// Thousands of random cuts (100 sheets of 4 x 4 cells of 5 mm, 20 cuts each,
// straight or curved, projected along directions up to ~8 deg off the normal,
// on sheets moved rigidly): after every cut the mesh is a consistently
// oriented manifold with boundary, the rest area is kept to 1e-9, every
// triangle keeps its orientation and its smallest angle above 0.5 deg; each cut sheet builds a BezierShell with zero energy
// in every element.
TEST(ShellCutting, RandomCutsKeepTheShellValid) {
  std::mt19937 rng(35);
  std::uniform_real_distribution<double> u(0, 1);
  double worst_angle = M_PI, worst_area = INFINITY, worst_area_error = 0, worst_energy = 0;
  int cuts = 0, max_triangles = 0;
  for (int sheet = 0; sheet < 100; ++sheet) {
    GeneralisedState s;
    Triangles tris;
    MakeSheet(4, 4, 5.0, &s, &tris);
    MoveRigidly(ExpSO3({3 * u(rng) - 1.5, 3 * u(rng) - 1.5, 3 * u(rng) - 1.5}),
                {u(rng), u(rng), u(rng)}, &s);
    const double area = TotalRestArea(s, tris);
    for (int c = 0; c < 20; ++c, ++cuts) {
      // A random chord or arc over (and beyond) the 20 x 20 mm sheet.
      const Eigen::Vector2d a(-5 + 30 * u(rng), -5 + 30 * u(rng));
      const Eigen::Vector2d b(-5 + 30 * u(rng), -5 + 30 * u(rng));
      const double bow = u(rng) < 0.5 ? 0 : (u(rng) - 0.5) * 0.8;
      const Eigen::Vector2d normal = Eigen::Vector2d(a.y() - b.y(), b.x() - a.x());
      std::vector<Eigen::Vector3d> line;
      const int points = bow == 0 ? 2 : 7;
      for (int k = 0; k < points; ++k) {
        const double t = double(k) / (points - 1);
        const Eigen::Vector2d p = (1 - t) * a + t * b + bow * 4 * t * (1 - t) * normal;
        line.push_back({p.x(), p.y(), 0.3 * (u(rng) - 0.5)});
      }
      const Eigen::Vector3d dir(0.15 * (u(rng) - 0.5), 0.15 * (u(rng) - 0.5), 1);
      CutShell(&s, &tris, line, dir, {});
      const std::string problem = ManifoldProblem(tris);
      ASSERT_EQ(problem, "") << "sheet " << sheet << " cut " << c;
      for (size_t t = 0; t < tris.size(); ++t) {
        const Eigen::Vector3i& tri = tris[t];
        const Eigen::Vector3d n =
            (Rest(s, tri[1]) - Rest(s, tri[0])).cross(Rest(s, tri[2]) - Rest(s, tri[0]));
        ASSERT_GT(n.z(), 0) << "sheet " << sheet << " cut " << c << ": triangle " << t
                            << " flipped or degenerate";
      }
      double angle = 0, min_area = 0;
      Quality(s, tris, &angle, &min_area);
      worst_angle = std::min(worst_angle, angle);
      worst_area = std::min(worst_area, min_area);
      worst_area_error = std::max(worst_area_error, std::abs(TotalRestArea(s, tris) / area - 1));
    }
    max_triangles = std::max(max_triangles, int(tris.size()));
    BezierShell shell(s, tris, ShellOptions());
    for (int e = 0; e < shell.num_elements(); ++e)
      worst_energy = std::max(worst_energy, shell.ElementEnergy(s, e));
  }
  std::printf("%d cuts: smallest angle %.2f deg, smallest area %.3g mm^2 (cell triangle 12.5), "
              "area error %.2g, largest element energy at rest %.2g uJ, up to %d triangles\n",
              cuts, worst_angle * 180 / M_PI, worst_area, worst_area_error, worst_energy,
              max_triangles);
  EXPECT_LT(worst_area_error, 1e-9);
  EXPECT_LT(worst_energy, 1e-18);
  // Each split keeps angles above ~asin(snap_fraction) of its parent's, but
  // 20 cuts through a 20 mm sheet split the same places repeatedly: the
  // smallest angle measured over random seeds 1-6 is 0.65-1.46 deg; the bound
  // asserts the shape (not the size: pieces of cut pieces are small).
  EXPECT_GT(worst_angle * 180 / M_PI, 0.5);
}

}  // namespace
}  // namespace arreg::mechanics
