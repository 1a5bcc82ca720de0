// Convergence of Bernstein-Bezier tetrahedra (P1, P2, P3) on two bending problems:
// a clamped cantilever under a tip shear load and Cook's membrane. Prints the
// tables of docs/higher-order-verification.md. Slow (a few fine meshes).
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "core/mesh_generators.h"
#include "mechanics/bernstein_tet.h"
#include "mechanics/generalised_solver.h"

namespace arreg::mechanics {
namespace {

struct Result {
  int degree = 1;
  int pressure_degree = -1;  // -1: displacement formulation
  int cells = 0;             // refinement parameter n
  int free_dofs = 0;
  double tip = 0;  // mean tip displacement (mm) along the load, scaled back to the nominal load
  double ms = 0;
};

// Clamps every control point with x = 0, loads the boundary faces with x = x_load by
// a uniform traction along y, solves statically and returns the mean y displacement
// of the linear mesh's vertices `tip` (Bernstein vertex control points lie on the field).
Result Solve(const TetMesh& tets, int degree, const Material& material, double x_load,
             const Eigen::Vector3d& traction_kpa, const std::vector<int>& tip, double scale,
             int axis = 0, int component = 1, int pressure_degree = -1) {
  const auto start = std::chrono::steady_clock::now();
  const HighOrderTetMesh mesh = RaiseTetMesh(tets, degree);
  GeneralisedState state;
  const std::vector<int> node = AddHighOrderNodes(mesh, &state);
  BernsteinTetOptions options;
  options.material = material;
  options.pressure_degree = pressure_degree;
  BernsteinTetTerm elastic(&mesh, node, options);
  const auto on_load_face = [x_load, axis](const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                           const Eigen::Vector3d& c) {
    return std::abs(a[axis] - x_load) < 1e-9 && std::abs(b[axis] - x_load) < 1e-9 &&
           std::abs(c[axis] - x_load) < 1e-9;
  };
  NodalForceTerm load(UniformTractionLoads(mesh, on_load_face, traction_kpa));
  int fixed = 0;
  for (int i = 0; i < state.num_nodes(); ++i)
    if (std::abs(state.rest_positions()(i, axis)) < 1e-9) {
      state.SetFixedTranslation(node[i], true);
      ++fixed;
    }
  GeneralisedStaticSolver solver({});
  const GeneralisedSummary summary = solver.Solve(&state, {&elastic, &load});
  EXPECT_EQ(summary.status, StepStatus::kConverged) << summary.message;
  Result r;
  r.degree = degree;
  r.pressure_degree = pressure_degree;
  r.free_dofs = 3 * (state.num_nodes() - fixed);
  for (int v : tip)
    r.tip += state.positions()(node[v], component) - state.rest_positions()(node[v], component);
  r.tip *= scale / tip.size();
  r.ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return r;
}

void Print(const char* title, const std::vector<Result>& results, double reference) {
  std::printf("%s (reference %.5f)\n  degree  n  free DOFs  tip (mm)   error %%   solve ms\n",
              title, reference);
  for (const Result& r : results)
    std::printf("  P%d%s%-2s %2d  %9d  %9.5f  %7.3f  %9.1f\n", r.degree,
                r.pressure_degree < 0 ? "  " : "/P",
                r.pressure_degree < 0 ? "" : std::to_string(r.pressure_degree).c_str(), r.cells,
                r.free_dofs, r.tip, 100.0 * std::abs(r.tip - reference) / std::abs(reference),
                r.ms);
}

// The fewest free DOFs with which `degree` gets within `tolerance` of the reference.
int DofsToReach(const std::vector<Result>& results, int degree, double reference,
                double tolerance) {
  int best = -1;
  for (const Result& r : results)
    if (r.degree == degree && std::abs(r.tip - reference) <= tolerance * std::abs(reference) &&
        (best < 0 || r.free_dofs < best))
      best = r.free_dofs;
  return best;
}

// P2 and P3 get within `tolerance` of the reference with under a third of the free DOFs
// P1 needs (P1 must get there when `p1_reaches`).
void ExpectFewerDofs(const std::vector<Result>& results, double reference, double tolerance,
                     bool p1_reaches) {
  const int p1 = DofsToReach(results, 1, reference, tolerance);
  const int p2 = DofsToReach(results, 2, reference, tolerance);
  const int p3 = DofsToReach(results, 3, reference, tolerance);
  std::printf("free DOFs to reach %g %%: P1 %d, P2 %d, P3 %d\n", 100 * tolerance, p1, p2, p3);
  ASSERT_GT(p2, 0);
  ASSERT_GT(p3, 0);
  if (p1_reaches) {
    ASSERT_GT(p1, 0);
  }
  if (p1 > 0) {
    EXPECT_LT(p2 * 3, p1);
    EXPECT_LT(p3 * 3, p1);
  }
}

// Each family converges: the error falls with every refinement.
void ExpectConverging(const std::vector<Result>& results, double reference) {
  for (size_t i = 1; i < results.size(); ++i) {
    if (results[i].degree == results[i - 1].degree) {
      EXPECT_LT(std::abs(results[i].tip - reference), std::abs(results[i - 1].tip - reference))
          << "P" << results[i].degree << " n = " << results[i].cells;
    }
  }
}

// Cantilever 40 x 4 x 4 mm, clamped at x = 0, shear traction on x = 40 (total P),
// E = 3 kPa, nu = 0.3; meshes of 10n x n x n cells (6 tets each). The load is small
// (deflection ~1e-4 of the length) so the corotational solve is the linear one; tip
// values are scaled to P = 1 mN. Reference: the finest P3 solution; Timoshenko beam
// theory for comparison.
TEST(BernsteinConvergence, CantileverInBending) {
  const double length = 40, side = 4, load_mn = 1.0, scale = 1e4;
  Material material;
  material.youngs_modulus_pa = 3000;
  material.poisson_ratio = 0.3;
  const Eigen::Vector3d traction(0, load_mn / (side * side) / scale, 0);
  std::vector<Result> results;
  const std::vector<std::pair<int, std::vector<int>>> runs = {
      {1, {1, 2, 4, 8}}, {2, {1, 2, 4}}, {3, {1, 2, 3}}};
  for (const auto& [degree, ns] : runs)
    for (int n : ns) {
      const TetMesh tets = MakeBoxTetMesh({length, side, side}, {10 * n, n, n});
      std::vector<int> tip;
      for (int v = 0; v < tets.num_vertices(); ++v)
        if (std::abs(tets.vertices(v, 0) - length) < 1e-9 &&
            (tets.vertices.row(v).tail<2>().array().abs() < 1e-9 ||
             (tets.vertices.row(v).tail<2>().array() - side).abs() < 1e-9)
                .all())
          tip.push_back(v);  // the four tip corners
      ASSERT_EQ(tip.size(), 4u);
      results.push_back(Solve(tets, degree, material, length, traction, tip, scale));
      results.back().cells = n;
    }
  const double reference = results.back().tip;
  const double E = material.youngs_modulus_pa * 1e-3, G = E / (2 * (1 + material.poisson_ratio));
  const double I = std::pow(side, 4) / 12, A = side * side;
  const double timoshenko =
      load_mn * std::pow(length, 3) / (3 * E * I) + load_mn * length / (5.0 / 6.0 * G * A);
  std::printf("Timoshenko beam tip %.5f mm (Euler-Bernoulli %.5f)\n", timoshenko,
              load_mn * std::pow(length, 3) / (3 * E * I));
  Print("Cantilever 40 x 4 x 4, tip shear", results, reference);
  ExpectConverging(results, reference);
  EXPECT_NEAR(reference / timoshenko, 1.0, 0.02);  // beam theory within 2 %
  // P2 and P3 reach 1 % with far fewer DOFs than P1 (which does not reach it here).
  ExpectFewerDofs(results, reference, 0.01, false);
}

// Cook's membrane: the trapezoid (0,0), (48,44), (48,60), (0,44) mm extruded 1 mm
// (one layer, free faces: the plane-stress setup), clamped at x = 0, a shear load of
// total F = 1 mN per mm of thickness on x = 48, E = 1 kPa, nu = 1/3. Meshes of n x n x 1
// cells mapped bilinearly. Measured: the vertical displacement of the top corner
// (48, 60); the load is scaled down by 1e4 (small displacement) and the result back up.
// The 2D plane-stress literature value is 23.96; this 3D slab passes it (conforming
// displacement elements approach the exact compliance from below, and P1 at n = 64 is
// above it too), so the reference here is the finest P3 solution; see
// docs/higher-order-verification.md.
TEST(BernsteinConvergence, CooksMembrane) {
  const double thickness = 1, scale = 1e4;
  Material material;
  material.youngs_modulus_pa = 1000;
  material.poisson_ratio = 1.0 / 3.0;
  const Eigen::Vector3d traction(0, 1.0 / 16.0 / scale, 0);
  std::vector<Result> results;
  const std::vector<std::pair<int, std::vector<int>>> runs = {
      {1, {2, 4, 8, 16, 32, 64}}, {2, {1, 2, 4, 8, 16}}, {3, {1, 2, 4, 8}}};
  const auto solve = [&](int degree, int n, const Material& m, int pressure_degree) {
    TetMesh tets = MakeBoxTetMesh({1, 1, thickness}, {n, n, 1});
    std::vector<int> tip;
    for (int v = 0; v < tets.num_vertices(); ++v) {
      const double s = tets.vertices(v, 0), r = tets.vertices(v, 1);
      tets.vertices(v, 0) = 48 * s;
      tets.vertices(v, 1) = 44 * s + r * (44 - 28 * s);
      if (std::abs(s - 1) < 1e-12 && std::abs(r - 1) < 1e-12) tip.push_back(v);
    }
    EXPECT_EQ(tip.size(), 2u);
    Result r = Solve(tets, degree, m, 48, traction, tip, scale, 0, 1, pressure_degree);
    r.cells = n;
    return r;
  };
  for (const auto& [degree, ns] : runs)
    for (int n : ns) results.push_back(solve(degree, n, material, -1));
  const double reference = results.back().tip;
  Print("Cook's membrane, 3D slab (plane stress setup), top corner", results, reference);
  ExpectConverging(results, reference);
  ExpectFewerDofs(results, reference, 0.05, true);
  // Cross-check against other codes: plane strain with (E, nu) is plane stress with
  // E / (1 - nu^2) and nu / (1 - nu) = 0.5 (0.4999 here, P2/P0 against locking). The
  // CoFEA comparison of CalculiX, Code_Aster and Elmer (quoted by the solids4foam
  // cooksMembrane tutorial: 32.20-32.28 mm for E = 70, F = 100 in plane strain) scales
  // linearly to 22.59 mm.
  Material strain = material;
  strain.youngs_modulus_pa = 1000.0 / (1.0 - 1.0 / 9.0);
  strain.poisson_ratio = 0.4999;
  std::vector<Result> plane_strain = {solve(2, 8, strain, 0), solve(2, 16, strain, 0)};
  Print("Cook's membrane, plane strain by the plane-stress equivalence", plane_strain, 22.59);
  EXPECT_NEAR(plane_strain.back().tip / 22.59, 1.0, 0.01);
}

// A nearly incompressible block (nu = 0.499): a 10 mm cube of E = 3 kPa clamped at
// z = 0 and pressed by a uniform traction on its top face; the top centre's vertical
// displacement, scaled to 1 kPa. The material has to bulge out at the free sides: a
// locking element cannot. Families: displacement P1, P2, P3 and mixed u-p with a
// discontinuous pressure of degree m (Pk/Pm; Pk/P(k-1) is the displacement element, since
// div u is already of degree k - 1). Reference: the finest P2/P0; the finest P2, P3/P1 and
// P3/P0 solutions lie within 1 % of it.
TEST(BernsteinConvergence, NearlyIncompressibleBlock) {
  const double side = 10, scale = 1e4;
  Material material;
  material.youngs_modulus_pa = 3000;
  material.poisson_ratio = 0.499;
  const Eigen::Vector3d traction(0, 0, -1.0 / scale);
  struct Run {
    int degree, pressure_degree;
    std::vector<int> ns;
  };
  const std::vector<Run> runs = {{1, -1, {2, 4, 8, 16}}, {2, -1, {2, 4, 8}}, {2, 0, {2, 4, 8}},
                                 {2, 1, {2, 4, 8}},      {3, -1, {2, 4}},    {3, 1, {2, 4}},
                                 {3, 0, {2, 4, 6}}};
  std::vector<Result> results;
  const auto find = [&results](int degree, int pressure_degree, int n) {
    for (const Result& r : results)
      if (r.degree == degree && r.pressure_degree == pressure_degree && r.cells == n) return r;
    ADD_FAILURE() << "no run P" << degree << "/" << pressure_degree << " n = " << n;
    return Result{};
  };
  for (const Run& run : runs)
    for (int n : run.ns) {
      const TetMesh tets = MakeBoxTetMesh({side, side, side}, {n, n, n});
      std::vector<int> tip;
      for (int v = 0; v < tets.num_vertices(); ++v)
        if ((tets.vertices.row(v) - Eigen::RowVector3d(side / 2, side / 2, side)).norm() < 1e-9)
          tip.push_back(v);
      ASSERT_EQ(tip.size(), 1u);
      results.push_back(
          Solve(tets, run.degree, material, side, traction, tip, scale, 2, 2, run.pressure_degree));
      results.back().cells = n;
    }
  const double reference = find(2, 0, 8).tip;
  Print("Block, nu = 0.499, top centre under 1 kPa", results, reference);
  const auto error = [&](const Result& r) { return std::abs(r.tip / reference - 1.0); };
  for (const Result& r : {find(2, -1, 8), find(3, 1, 4), find(3, 0, 6)})
    EXPECT_LT(error(r), 0.01) << "P" << r.degree << "/" << r.pressure_degree;
  // P1 locks: 18 % short with 13,872 DOFs, where P2/P0 is within 2 % with 300.
  EXPECT_GT(error(find(1, -1, 16)), 0.1);
  EXPECT_LT(error(find(2, 0, 2)), 0.02);
  EXPECT_LT(error(find(3, 1, 2)), 0.02);
  // Pk/P(k-1) with a discontinuous pressure is the displacement element.
  EXPECT_NEAR(find(2, 1, 4).tip, find(2, -1, 4).tip, 1e-9 * std::abs(reference));
}

}  // namespace
}  // namespace arreg::mechanics
