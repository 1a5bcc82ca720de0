// Bezier triangle shell (seed 000): derivatives against finite differences,
// rigid motions, element spectrum, patch tests, and the fine-surface mapping.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <random>

#include "core/error.h"
#include "dense_hessian_sink.h"
#include "mechanics/bezier_shell.h"
#include "mechanics/shell_mapping.h"
#include "mechanics/so3.h"

namespace arreg::mechanics {
namespace {

Eigen::MatrixXd DenseHessian(const BezierShell& shell, const GeneralisedState& state) {
  testing::DenseHessianSink sink(state);
  shell.AddHessian(state, 1.0, &sink);
  return sink.matrix();
}

Eigen::VectorXd Gradient(const BezierShell& shell, const GeneralisedState& state) {
  Eigen::VectorXd g = Eigen::VectorXd::Zero(state.num_dofs());
  shell.AddGradient(state, &g);
  return g;
}

// A state with frame nodes at `positions` and the given rest rotations.
GeneralisedState MakeState(const RowMatX3d& positions, const std::vector<Eigen::Matrix3d>& rot) {
  GeneralisedState state;
  for (int v = 0; v < positions.rows(); ++v)
    state.AddFrameNode(positions.row(v).transpose(), rot[v]);
  return state;
}

// A curved patch (part of a cylinder of radius 3) of 2 x 2 squares split into
// 8 triangles; node frames turned about their normals by different angles.
struct Patch {
  RowMatX3d positions;
  std::vector<Eigen::Vector3i> triangles;
  std::vector<Eigen::Matrix3d> rotations;
};
Patch CurvedPatch() {
  Patch p;
  p.positions.resize(9, 3);
  for (int j = 0; j < 3; ++j)
    for (int i = 0; i < 3; ++i) {
      const double s = 0.4 * (i - 1), y = 0.5 * j + 0.1 * (i == 1 && j == 1);
      p.positions.row(3 * j + i) << 3 * std::sin(s), y, 3 * std::cos(s) - 3;
    }
  for (int j = 0; j < 2; ++j)
    for (int i = 0; i < 2; ++i) {
      const int a = 3 * j + i;
      // Counter-clockwise seen from +z (the cylinder's outside).
      p.triangles.push_back({a, a + 1, a + 4});
      p.triangles.push_back({a, a + 4, a + 3});
    }
  p.rotations = ShellVertexRotations(p.positions, p.triangles);
  for (int v = 0; v < 9; ++v)
    p.rotations[v] = p.rotations[v] * ExpSO3(Eigen::Vector3d(0, 0, 0.7 * v - 2.0));
  return p;
}

BezierShellOptions Material(ShellHessian hessian = ShellHessian::kGaussNewton) {
  BezierShellOptions o;
  o.material.youngs_modulus_kpa = 50.0;
  o.material.poisson_ratio = 0.3;
  o.material.thickness_mm = 0.2;
  o.hessian = hessian;
  return o;
}

// Plane-stress elasticity matrix (Voigt, engineering shear) of the material.
Eigen::Matrix3d PlaneStress(const BezierShellOptions& o) {
  const double e = o.material.youngs_modulus_kpa, nu = o.material.poisson_ratio;
  Eigen::Matrix3d d;
  d << 1, nu, 0, nu, 1, 0, 0, 0, 0.5 * (1 - nu);
  return d * e / (1 - nu * nu);
}

// Deforms the state (positions and rotations) and then moves it rigidly by
// `rigid` (a rotation far from identity) and a translation.
void DeformAndMove(GeneralisedState* state, double amount, const Eigen::Matrix3d& rigid,
                   const Eigen::Vector3d& shift, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int n = 0; n < state->num_nodes(); ++n) {
    const Eigen::Vector3d d(u(rng), u(rng), u(rng));
    const Eigen::Vector3d w(u(rng), u(rng), u(rng));
    state->mutable_positions().row(n) =
        (rigid * (state->position(n) + amount * d) + shift).transpose();
    state->mutable_rotation(n) = rigid * ExpSO3(3 * amount * w) * state->rotation(n);
  }
}

// Value at the state moved by a DOF increment (phi as Exp(phi) R, not a sequence).
double ValueAt(const BezierShell& shell, const GeneralisedState& state, const Eigen::VectorXd& dq) {
  GeneralisedState moved = state;
  for (int n = 0; n < state.num_nodes(); ++n) {
    const int o = state.dof_offset(n);
    moved.mutable_positions().row(n) += dq.segment<3>(o).transpose();
    moved.mutable_rotation(n) = ExpSO3(dq.segment<3>(o + 3)) * state.rotation(n);
  }
  return shell.Value(moved);
}

const Eigen::Matrix3d kRot170 =
    ExpSO3(170.0 * M_PI / 180.0 * Eigen::Vector3d(1, 2, -0.5).normalized());
const Eigen::Matrix3d kRot90 = ExpSO3(0.5 * M_PI * Eigen::Vector3d(0, 0.6, 0.8));

TEST(BezierShell, GradientMatchesFiniteDifferencesFarFromIdentity) {
  const Patch p = CurvedPatch();
  for (const Eigen::Matrix3d& rigid : {kRot90, kRot170}) {
    GeneralisedState state = MakeState(p.positions, p.rotations);
    const BezierShell shell(state, p.triangles, Material());
    DeformAndMove(&state, 0.06, rigid, Eigen::Vector3d(4, -2, 7), 11);
    const Eigen::VectorXd g = Gradient(shell, state);
    ASSERT_GT(shell.Value(state), 1e-3);
    const double h = 1e-6;
    double max_err = 0;
    for (int k = 0; k < state.num_dofs(); ++k) {
      Eigen::VectorXd dq = Eigen::VectorXd::Zero(state.num_dofs());
      dq(k) = h;
      const double fd = (ValueAt(shell, state, dq) - ValueAt(shell, state, -dq)) / (2 * h);
      max_err = std::max(max_err, std::abs(fd - g(k)));
    }
    // Central differences: truncation ~h^2 |E'''|, rounding ~1e-16 E / h.
    EXPECT_LT(max_err, 1e-6 * g.cwiseAbs().maxCoeff()) << max_err;
  }
}

// Value reuses the energy computed with the cached derivatives only at the
// cached state: the same sum of element energies there, a fresh one elsewhere.
TEST(BezierShell, ValueUsesTheDerivativeCacheOnlyAtItsState) {
  const Patch p = CurvedPatch();
  GeneralisedState state = MakeState(p.positions, p.rotations);
  const BezierShell shell(state, p.triangles, Material());
  DeformAndMove(&state, 0.06, kRot90, Eigen::Vector3d(1, 2, 3), 5);
  double sum = 0;
  for (int e = 0; e < shell.num_elements(); ++e) sum += shell.ElementEnergy(state, e);
  Gradient(shell, state);  // fills the cache
  EXPECT_EQ(shell.Value(state), sum);
  GeneralisedState moved = state;
  moved.mutable_rotation(4) = ExpSO3(Eigen::Vector3d(0, 0.01, 0)) * moved.rotation(4);
  double moved_sum = 0;
  for (int e = 0; e < shell.num_elements(); ++e) moved_sum += shell.ElementEnergy(moved, e);
  EXPECT_NE(moved_sum, sum);
  EXPECT_EQ(shell.Value(moved), moved_sum);
  EXPECT_EQ(shell.Value(state), sum);
}

TEST(BezierShell, ExactHessianMatchesFiniteDifferencesAndIsSymmetric) {
  const Patch p = CurvedPatch();
  GeneralisedState state = MakeState(p.positions, p.rotations);
  const BezierShell exact(state, p.triangles, Material(ShellHessian::kExact));
  DeformAndMove(&state, 0.06, kRot170, Eigen::Vector3d(1, 2, 3), 5);
  const Eigen::MatrixXd h = DenseHessian(exact, state);
  EXPECT_LT((h - h.transpose()).norm(), 1e-12 * h.norm());
  const Eigen::VectorXd g0 = Gradient(exact, state);
  // Second differences of the value with phi summed inside one Exp (the
  // Hessian of E(Exp(phi) R) at phi = 0, second-order part of Exp included).
  const double step = 1e-4;
  const int n = state.num_dofs();
  double max_err = 0;
  for (int a = 0; a < n; a += 1)
    for (int b = a; b < n; b += 5) {
      Eigen::VectorXd ea = Eigen::VectorXd::Zero(n), eb = Eigen::VectorXd::Zero(n);
      ea(a) = step;
      eb(b) = step;
      const double fd = (ValueAt(exact, state, ea + eb) - ValueAt(exact, state, ea - eb) -
                         ValueAt(exact, state, eb - ea) + ValueAt(exact, state, -ea - eb)) /
                        (4 * step * step);
      max_err = std::max(max_err, std::abs(fd - h(a, b)));
    }
  EXPECT_LT(max_err, 1e-5 * h.cwiseAbs().maxCoeff()) << max_err;
  // The geometric part is present: Gauss-Newton differs away from rest.
  const BezierShell gn(MakeState(p.positions, p.rotations), p.triangles, Material());
  EXPECT_GT((DenseHessian(gn, state) - h).norm(), 1e-4 * h.norm());
  (void)g0;
}

TEST(BezierShell, GaussNewtonIsExactAtRigidStatesAndPositiveSemiDefinite) {
  const Patch p = CurvedPatch();
  GeneralisedState state = MakeState(p.positions, p.rotations);
  const BezierShell gn(state, p.triangles, Material());
  const BezierShell exact(state, p.triangles, Material(ShellHessian::kExact));
  const BezierShell projected(state, p.triangles, Material(ShellHessian::kExactProjected));
  DeformAndMove(&state, 0.0, kRot170, Eigen::Vector3d(1, 2, 3), 5);
  const Eigen::MatrixXd hg = DenseHessian(gn, state), he = DenseHessian(exact, state);
  EXPECT_LT((hg - he).norm(), 1e-9 * he.norm());
  DeformAndMove(&state, 0.08, kRot90, Eigen::Vector3d::Zero(), 9);
  for (const BezierShell* s : {&gn, &projected}) {
    for (int e = 0; e < s->num_elements(); ++e) {
      Eigen::Matrix<double, 18, 18> he18;
      s->ElementEnergy(state, e, nullptr, &he18);
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 18, 18>> eig(he18);
      EXPECT_GT(eig.eigenvalues().minCoeff(), -1e-10 * eig.eigenvalues().maxCoeff());
    }
  }
}

TEST(BezierShell, RigidMotionsGiveZeroEnergyForceAndTorque) {
  const Patch p = CurvedPatch();
  for (const Eigen::Matrix3d& rigid : {kRot90, kRot170}) {
    GeneralisedState state = MakeState(p.positions, p.rotations);
    const BezierShell shell(state, p.triangles, Material());
    // Reference: the energy of a small real deformation.
    GeneralisedState deformed = state;
    DeformAndMove(&deformed, 0.01, Eigen::Matrix3d::Identity(), Eigen::Vector3d::Zero(), 3);
    const double scale = shell.Value(deformed);
    const double gscale = Gradient(shell, deformed).cwiseAbs().maxCoeff();
    DeformAndMove(&state, 0.0, rigid, Eigen::Vector3d(30, -12, 5), 1);
    EXPECT_LT(shell.Value(state), 1e-20 * scale + 1e-25);
    EXPECT_LT(Gradient(shell, state).cwiseAbs().maxCoeff(), 1e-10 * gscale);
    for (int e = 0; e < shell.num_elements(); ++e)
      EXPECT_LT(shell.DeformationalCoordinates(state, e).norm(), 1e-12);
  }
}

TEST(BezierShell, ElementStiffnessHasExactlySixZeroModes) {
  const Patch p = CurvedPatch();
  GeneralisedState state = MakeState(p.positions, p.rotations);
  const BezierShell shell(state, p.triangles, Material());
  for (int pass = 0; pass < 2; ++pass) {
    if (pass == 1) DeformAndMove(&state, 0.0, kRot170, Eigen::Vector3d(2, 2, 2), 1);
    for (int e = 0; e < shell.num_elements(); ++e) {
      Eigen::Matrix<double, 18, 18> k;
      shell.ElementEnergy(state, e, nullptr, &k);
      // Rotations contribute lever arms: compare in consistent units by
      // scaling the rotation DOFs with the element size.
      const double size = std::sqrt(shell.rest_area(e));
      Eigen::Matrix<double, 18, 1> sc;
      for (int i = 0; i < 18; ++i) sc(i) = (i % 6) < 3 ? 1.0 : size;
      const Eigen::Matrix<double, 18, 18> ks = sc.asDiagonal() * k * sc.asDiagonal();
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 18, 18>> eig(ks);
      const Eigen::Matrix<double, 18, 1> ev = eig.eigenvalues();
      const double top = ev.maxCoeff();
      int zeros = 0;
      for (int i = 0; i < 18; ++i) zeros += std::abs(ev(i)) < 1e-10 * top;
      EXPECT_EQ(zeros, 6) << "element " << e;
      EXPECT_GT(ev(6), 1e-6 * top) << "element " << e;  // a clear gap to the 7th
    }
  }
}

// Flat irregular patch with one interior node (node 8).
Patch FlatPatch() {
  Patch p;
  p.positions.resize(9, 3);
  p.positions << 0, 0, 0, 1.1, 0, 0, 2, 0, 0, 2, 0.8, 0, 2, 1.5, 0, 0.8, 1.5, 0, 0, 1.5, 0, 0, 0.6,
      0, 0.9, 0.7, 0;
  for (int k = 0; k < 8; ++k) p.triangles.push_back({k, (k + 1) % 8, 8});
  p.rotations.assign(9, Eigen::Matrix3d::Identity());
  return p;
}

TEST(BezierShell, MembraneConstantStrainPatchTestIsExact) {
  const Patch p = FlatPatch();
  GeneralisedState state = MakeState(p.positions, p.rotations);
  BezierShellOptions o = Material();
  const BezierShell shell(state, p.triangles, o);
  const Eigen::MatrixXd k = DenseHessian(shell, state);
  Eigen::Matrix2d eps;
  eps << 0.013, -0.004, -0.004, 0.021;
  Eigen::VectorXd q = Eigen::VectorXd::Zero(state.num_dofs());
  for (int n = 0; n < 9; ++n) q.segment<2>(6 * n) = eps * p.positions.row(n).head<2>().transpose();
  const Eigen::VectorXd f = k * q;
  // Interior node in equilibrium (all 6 DOFs); energy = 1/2 t eps:D:eps area.
  EXPECT_LT(f.segment<6>(48).norm(), 1e-12 * f.norm());
  const Eigen::Vector3d ev(eps(0, 0), eps(1, 1), 2 * eps(0, 1));
  const Eigen::Matrix3d d = PlaneStress(o);
  const double exact = 0.5 * o.material.thickness_mm * ev.dot(d * ev) * 3.0;  // area 2 x 1.5
  EXPECT_NEAR(0.5 * q.dot(f), exact, 1e-12 * exact);
  // The same holds for the nonlinear energy at a finite uniform stretch with a
  // rigid rotation on top: E = 1/2 t (S - I):D:(S - I) area exactly.
  GeneralisedState moved = state;
  for (int n = 0; n < 9; ++n) {
    const Eigen::Vector3d x = p.positions.row(n).transpose();
    Eigen::Vector3d y = x;
    y.head<2>() += eps * x.head<2>();
    moved.mutable_positions().row(n) = (kRot170 * y).transpose();
    moved.mutable_rotation(n) = kRot170;
  }
  EXPECT_NEAR(shell.Value(moved), exact, 1e-12 * exact);
}

TEST(BezierShell, BendingConstantCurvaturePatchTestIsExact) {
  const Patch p = FlatPatch();
  GeneralisedState state = MakeState(p.positions, p.rotations);
  BezierShellOptions o = Material();
  const BezierShell shell(state, p.triangles, o);
  const Eigen::MatrixXd k = DenseHessian(shell, state);
  const double kxx = 0.03, kyy = -0.02, kxy = 0.011;  // w = 1/2 kxx x^2 + kxy x y + 1/2 kyy y^2
  Eigen::VectorXd q = Eigen::VectorXd::Zero(state.num_dofs());
  for (int n = 0; n < 9; ++n) {
    const double x = p.positions(n, 0), y = p.positions(n, 1);
    const double wx = kxx * x + kxy * y, wy = kxy * x + kyy * y;
    q(6 * n + 2) = 0.5 * kxx * x * x + kxy * x * y + 0.5 * kyy * y * y;
    q(6 * n + 3) = wy;  // theta x d gives dz = theta_x dy - theta_y dx
    q(6 * n + 4) = -wx;
  }
  const Eigen::VectorXd f = k * q;
  // Interior node in equilibrium (the boundary-integral curvature is shared
  // by neighbours), and each element's energy is the exact one.
  EXPECT_LT(f.segment<6>(48).norm(), 1e-12 * f.norm());
  const double t = o.material.thickness_mm;
  const Eigen::Vector3d kv(kxx, kyy, 2 * kxy);
  const Eigen::Matrix3d d = PlaneStress(o);
  const double exact = 0.5 * t * t * t / 12.0 * kv.dot(d * kv) * 3.0;
  EXPECT_NEAR(0.5 * q.dot(f), exact, 1e-12 * exact);
  for (int el = 0; el < shell.num_elements(); ++el) {
    Eigen::Matrix<double, 18, 18> ke;
    shell.ElementEnergy(state, el, nullptr, &ke);
    Eigen::Matrix<double, 18, 1> qe;
    for (int c = 0; c < 3; ++c) qe.segment<6>(6 * c) = q.segment<6>(6 * p.triangles[el][c]);
    const double expected = exact / 3.0 * shell.rest_area(el);
    EXPECT_NEAR(0.5 * qe.dot(ke * qe), expected, 1e-12 * expected) << "element " << el;
  }
}

TEST(BezierShell, MassAndInertiaAreTheElementsTotals) {
  const Patch p = FlatPatch();
  GeneralisedState state = MakeState(p.positions, p.rotations);
  BezierShellOptions o = Material();
  o.material.density_kg_per_mm3 = 2e-6;
  const BezierShell shell(state, p.triangles, o);
  std::vector<NodeInertia> inertia(9);
  shell.AddNodeInertia(state, &inertia);
  double mass = 0;
  for (const NodeInertia& ni : inertia) {
    mass += ni.mass_kg;
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(ni.body_inertia);
    EXPECT_GT(eig.eigenvalues().minCoeff(), 0.0);
  }
  EXPECT_NEAR(mass, 2e-6 * 0.2 * 3.0, 1e-15);
}

TEST(BezierShell, BadInputThrows) {
  const Patch p = FlatPatch();
  const GeneralisedState state = MakeState(p.positions, p.rotations);
  BezierShellOptions o = Material();
  o.material.poisson_ratio = 0.5;
  EXPECT_THROW(BezierShell(state, p.triangles, o), Error);
  std::vector<Eigen::Vector3i> flipped = {{0, 8, 1}};  // clockwise: normal against node z axes
  EXPECT_THROW(BezierShell(state, flipped, Material()), Error);
  std::vector<Eigen::Vector3i> out_of_range = {{0, 1, 42}};
  EXPECT_THROW(BezierShell(state, out_of_range, Material()), Error);
}

// Fine points on a deformed, rotated curved patch: the velocities are the time
// derivative of the positions, and the projected forces and torques do the
// fine forces' virtual power (seed section 4.3).
TEST(ShellMapping, VelocitiesDifferentiatePositionsAndForcesKeepVirtualPower) {
  const Patch p = CurvedPatch();
  GeneralisedState state = MakeState(p.positions, p.rotations);
  const BezierShell shell(state, p.triangles, Material());
  // Fine vertices: a 5 x 5 sample per element, and projected points.
  std::vector<ShellSurfacePoint> points;
  for (int e = 0; e < shell.num_elements(); ++e)
    for (int i = 0; i <= 4; ++i)
      for (int j = 0; i + j <= 4; ++j) points.push_back({e, i / 4.0, j / 4.0});
  const ShellMapping mapping(shell, points);
  DeformAndMove(&state, 0.05, kRot170, Eigen::Vector3d(1, -1, 2), 21);
  std::mt19937 rng(4);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int n = 0; n < state.num_nodes(); ++n) {
    state.mutable_velocities().row(n) << u(rng), u(rng), u(rng);
    state.mutable_angular_velocities().row(n) << u(rng), u(rng), u(rng);
  }
  RowMatX3d x0, v;
  mapping.Positions(state, &x0);
  mapping.Velocities(state, &v);
  // Corners map onto the nodes exactly.
  EXPECT_LT((x0.row(0) - state.positions().row(p.triangles[0][2])).norm(), 1e-12);
  const double h = 1e-6;
  RowMatX3d xp, xm;
  for (int sign : {1, -1}) {
    GeneralisedState moved = state;
    for (int n = 0; n < state.num_nodes(); ++n) {
      moved.mutable_positions().row(n) += sign * h * state.velocities().row(n);
      moved.mutable_rotation(n) =
          ExpSO3(sign * h * state.angular_velocities().row(n).transpose()) * state.rotation(n);
    }
    mapping.Positions(moved, sign > 0 ? &xp : &xm);
  }
  EXPECT_LT(((xp - xm) / (2 * h) - v).cwiseAbs().maxCoeff(), 1e-7 * v.cwiseAbs().maxCoeff());
  // Virtual power: sum_p v_p . f_p = sum_n (V_n . F_n + omega_n . tau_n).
  RowMatX3d f(mapping.size(), 3);
  for (int k = 0; k < mapping.size(); ++k) f.row(k) << u(rng), u(rng), u(rng);
  Eigen::VectorXd generalised = Eigen::VectorXd::Zero(state.num_dofs());
  mapping.AddForces(state, f, &generalised);
  double fine = 0, coarse = 0, scale = 0;
  for (int k = 0; k < mapping.size(); ++k) {
    fine += v.row(k).dot(f.row(k));
    scale += v.row(k).norm() * f.row(k).norm();
  }
  for (int n = 0; n < state.num_nodes(); ++n)
    coarse += state.velocities().row(n).dot(generalised.segment<3>(6 * n)) +
              state.angular_velocities().row(n).dot(generalised.segment<3>(6 * n + 3));
  EXPECT_LT(std::abs(fine - coarse), 1e-12 * scale);
  // Projection onto the closest element reproduces the points it was given.
  const ShellMapping projected =
      ShellMapping::Project(shell, MakeState(p.positions, p.rotations), p.positions);
  for (int k = 0; k < projected.size(); ++k) {
    const ShellSurfacePoint& s = projected.point(k);
    const double w[3] = {s.xi1, s.xi2, 1 - s.xi1 - s.xi2};
    Eigen::Vector3d y = Eigen::Vector3d::Zero();
    for (int c = 0; c < 3; ++c)
      y += w[c] * p.positions.row(shell.triangle(s.element)[c]).transpose();
    EXPECT_LT((y - p.positions.row(k).transpose()).norm(), 1e-12);
  }
}

TEST(ShellMapping, BadInputThrows) {
  const Patch p = FlatPatch();
  const GeneralisedState state = MakeState(p.positions, p.rotations);
  const BezierShell shell(state, p.triangles, Material());
  EXPECT_THROW(ShellMapping(shell, {{8, 0.2, 0.2}}), Error);  // no element 8
  EXPECT_THROW(ShellMapping(shell, {{0, 0.7, 0.5}}), Error);  // outside the triangle
  const ShellMapping mapping(shell, {{0, 0.2, 0.2}});
  Eigen::VectorXd g = Eigen::VectorXd::Zero(state.num_dofs());
  EXPECT_THROW(mapping.AddForces(state, RowMatX3d::Zero(2, 3), &g), Error);
}

TEST(ShellVertexRotations, NormalsFollowTheSurfaceAndBadIndicesThrow) {
  const Patch p = CurvedPatch();
  const std::vector<Eigen::Matrix3d> r = ShellVertexRotations(p.positions, p.triangles);
  for (int v = 0; v < 9; ++v) {
    EXPECT_LT((r[v].transpose() * r[v] - Eigen::Matrix3d::Identity()).norm(), 1e-12);
    EXPECT_NEAR(r[v].determinant(), 1.0, 1e-12);
    // The cylinder's outward normal (sin s, 0, cos s) within the facets' spread.
    const double s = std::atan2(p.positions(v, 0), p.positions(v, 2) + 3);
    EXPECT_GT(r[v].col(2).dot(Eigen::Vector3d(std::sin(s), 0, std::cos(s))), 0.98) << v;
  }
  EXPECT_THROW(ShellVertexRotations(p.positions, {{0, 1, 9}}), Error);
}

TEST(ShellSupportTerm, GradientMatchesFiniteDifferences) {
  const Patch p = CurvedPatch();
  GeneralisedState state = MakeState(p.positions, p.rotations);
  ShellSupportTerm term;
  term.HoldTranslation(1, Eigen::Vector3d(1, 2, 0), 3.0);
  term.HoldRotation(2, Eigen::Vector3d(0, 1, 1), 5.0);
  term.AddForce(4, Eigen::Vector3d(0.3, -0.2, 1.0));
  DeformAndMove(&state, 0.1, kRot90, Eigen::Vector3d(1, 0, 0), 2);
  Eigen::VectorXd g = Eigen::VectorXd::Zero(state.num_dofs());
  term.AddGradient(state, &g);
  const double h = 1e-6;
  for (int k = 0; k < state.num_dofs(); ++k) {
    GeneralisedState a = state, b = state;
    Eigen::VectorXd dq = Eigen::VectorXd::Zero(state.num_dofs());
    dq(k) = h;
    a.ApplyIncrement(dq);
    b.ApplyIncrement(-dq);
    EXPECT_NEAR((term.Value(a) - term.Value(b)) / (2 * h), g(k), 1e-6) << k;
  }
}

}  // namespace
}  // namespace arreg::mechanics
