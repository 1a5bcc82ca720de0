// Generalised DOFs: the system matrix over 3- and 6-DOF nodes, the shared
// terms (tets on point nodes, zero-length springs with frame offsets, gravity)
// against finite differences, the static and implicit-Euler solvers against the
// tet-only solvers, rigid-body rotation and boundary masks.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <cmath>
#include <numeric>
#include <random>

#include "core/error.h"
#include "mechanics/generalised_solver.h"
#include "mechanics/generalised_terms.h"
#include "mechanics/integrator.h"
#include "mechanics/so3.h"
#include "mechanics/spring_energy.h"
#include "mechanics/units.h"
#include "mechanics_test_util.h"

namespace arreg::mechanics {
namespace {

using testing::SmallBox;

Eigen::Matrix3d AxisAngle(const Eigen::Vector3d& axis, double degrees) {
  return ExpSO3(axis.normalized() * degrees * M_PI / 180.0);
}

// The state after the increment dq from `base` (x += dx, R <- Exp(dphi) R).
GeneralisedState Moved(const GeneralisedState& base, const Eigen::VectorXd& dq) {
  GeneralisedState s = base;
  s.ApplyIncrement(dq);
  return s;
}

double ValueAt(GeneralisedEnergyTerm* term, const GeneralisedState& s) {
  term->Update(s);
  return term->Value(s);
}

Eigen::VectorXd GradientAt(GeneralisedEnergyTerm* term, const GeneralisedState& s) {
  term->Update(s);
  Eigen::VectorXd g = Eigen::VectorXd::Zero(s.num_dofs());
  term->AddGradient(s, &g);
  return g;
}

Eigen::MatrixXd HessianAt(GeneralisedEnergyTerm* term, const GeneralisedState& s) {
  term->Update(s);
  GeneralisedSystem system;
  system.Build(s, {term});
  term->AddHessian(s, 1.0, &system);
  return Eigen::MatrixXd(system.matrix());
}

// Gradient of f(dq) = E(Moved(base, dq)) at dq = eps e_k, from the term's
// gradient at that state (left increments there): rotation rows J_l(phi)^T g.
Eigen::VectorXd CoordinateGradient(GeneralisedEnergyTerm* term, const GeneralisedState& base,
                                   const Eigen::VectorXd& dq) {
  const GeneralisedState s = Moved(base, dq);
  Eigen::VectorXd g = GradientAt(term, s);
  for (int n = 0; n < s.num_nodes(); ++n)
    if (s.is_frame(n)) {
      const int o = s.dof_offset(n) + 3;
      g.segment<3>(o) = LeftJacobianSO3(dq.segment<3>(o)).transpose() * g.segment<3>(o);
    }
  return g;
}

// Central differences of the value (gradient) and of the coordinate gradient
// (Hessian) along every DOF, against the term's own; tolerances relative to the
// largest entry (the truncation error of h = 1e-6 steps is ~1e-12 of it, round-off
// of the value differences ~1e-10).
void CheckDerivatives(GeneralisedEnergyTerm* term, const GeneralisedState& state,
                      bool check_hessian, double tolerance = 1e-6) {
  const int n = state.num_dofs();
  const double eps = 1e-6;
  const Eigen::VectorXd g = GradientAt(term, state);
  Eigen::VectorXd g_fd(n);
  Eigen::MatrixXd h_fd(n, n);
  for (int k = 0; k < n; ++k) {
    Eigen::VectorXd dq = Eigen::VectorXd::Zero(n);
    dq[k] = eps;
    g_fd[k] = (ValueAt(term, Moved(state, dq)) - ValueAt(term, Moved(state, -dq))) / (2 * eps);
    if (check_hessian)
      h_fd.col(k) =
          (CoordinateGradient(term, state, dq) - CoordinateGradient(term, state, -dq)) / (2 * eps);
  }
  const double gscale = std::max(1.0, g.cwiseAbs().maxCoeff());
  EXPECT_LT((g - g_fd).cwiseAbs().maxCoeff(), tolerance * gscale) << term->name() << "\n"
                                                                  << g.transpose() << "\n"
                                                                  << g_fd.transpose();
  if (!check_hessian) return;
  const Eigen::MatrixXd h = HessianAt(term, state);
  const double hscale = std::max(1.0, h.cwiseAbs().maxCoeff());
  EXPECT_LT((h - h.transpose()).cwiseAbs().maxCoeff(), 1e-12 * hscale) << term->name();
  EXPECT_LT((h - h_fd).cwiseAbs().maxCoeff(), tolerance * hscale) << term->name() << "\n"
                                                                  << h << "\n\n"
                                                                  << h_fd;
}

// A scene with frame nodes far from identity (90 and 170 degrees about
// different axes), a point node, and springs between all kinds of anchors.
struct MixedScene {
  GeneralisedState state;
  int f0, f1, p0;
  MixedScene() {
    f0 = state.AddFrameNode({0, 0, 0}, AxisAngle({1, 2, 3}, 90));
    p0 = state.AddPointNode({10, 1, -2});
    f1 = state.AddFrameNode({4, 8, 1}, AxisAngle({-2, 1, 0.5}, 170));
    // Move away from the rest so that the springs are stretched in every direction.
    state.mutable_positions() = testing::Perturbed(state.positions(), 2.0, 7);
    state.mutable_rotation(f0) = AxisAngle({0, 1, 1}, 20) * state.rotation(f0);
  }
  void AddSprings(ZeroLengthSpringTerm* springs) const {
    springs->Add(SpringAnchor::AtOffset(f0, {3, -1, 2}), SpringAnchor::Fixed({5, 6, -3}), 2.0);
    springs->Add(SpringAnchor::AtOffset(f0, {-2, 4, 1}), SpringAnchor::AtOffset(f1, {1, 2, -5}),
                 1.5);
    springs->Add(SpringAnchor::AtOffset(f1, {0, 3, 3}), SpringAnchor::AtNode(p0), 3.0);
    springs->Add(SpringAnchor::AtNode(p0), SpringAnchor::Fixed({-4, 2, 9}), 0.7);
    springs->Add(SpringAnchor::AtNode(f1), SpringAnchor::AtNode(p0), 1.1);
  }
};

TEST(GeneralisedSystem, PatternOfMixedBlocksAndDirichletIdentity) {
  MixedScene scene;
  ZeroLengthSpringTerm springs;
  // Only f0 - f1 coupled: (f0, p0) is outside the pattern.
  springs.Add(SpringAnchor::AtOffset(scene.f0, {1, 0, 0}), SpringAnchor::AtNode(scene.f1), 1.0);
  GeneralisedSystem system;
  system.Build(scene.state, {&springs});
  EXPECT_EQ(system.num_dofs(), 15);
  // Diagonal blocks 36 + 9 + 36, the f0-f1 pair twice 36.
  EXPECT_EQ(system.nonzeros(), 36 + 9 + 36 + 2 * 36);
  EXPECT_GE(system.BlockSlot(scene.f1, scene.f0), 0);
  EXPECT_EQ(system.BlockSlot(scene.p0, scene.f0), -1);
  EXPECT_THROW(system.AddBlock(scene.p0, scene.f0, Eigen::MatrixXd::Ones(3, 6), 1.0), Error);
  EXPECT_THROW(system.AddBlock(scene.f0, scene.f0, Eigen::MatrixXd::Ones(3, 3), 1.0), Error);
  // A block (a, b) lands at (a, b) and transposed at (b, a).
  Eigen::MatrixXd block(6, 6);
  for (int i = 0; i < 36; ++i) block(i % 6, i / 6) = i + 1;
  system.AddBlock(scene.f0, scene.f1, block, 2.0);
  const Eigen::MatrixXd dense(system.matrix());
  const int o0 = scene.state.dof_offset(scene.f0), o1 = scene.state.dof_offset(scene.f1);
  EXPECT_EQ((dense.block(o0, o1, 6, 6) - 2 * block).norm(), 0.0);
  EXPECT_EQ((dense.block(o1, o0, 6, 6) - 2 * block.transpose()).norm(), 0.0);
  // Simply supported f1 (translation fixed): its 3 translation rows/columns become identity.
  scene.state.SetFixedTranslation(scene.f1, true);
  system.ApplyDirichlet(scene.state.FixedDofMask());
  const Eigen::MatrixXd fixed(system.matrix());
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(fixed.row(o1 + k).cwiseAbs().sum(), 1.0);
    EXPECT_EQ(fixed.col(o1 + k).cwiseAbs().sum(), 1.0);
    EXPECT_EQ(fixed(o1 + k, o1 + k), 1.0);
  }
  EXPECT_EQ((fixed.block(o0, o1 + 3, 6, 3) - 2 * block.rightCols<3>()).norm(), 0.0);
}

TEST(GeneralisedSystem, ProjectToPsdKeepsPsdAndClampsNegativeEigenvalues) {
  Eigen::MatrixXd a = Eigen::MatrixXd::Random(6, 6);
  a = (a * a.transpose()).eval();
  Eigen::MatrixXd b = a;
  ProjectToPsd(b);
  EXPECT_LT((a - b).cwiseAbs().maxCoeff(), 1e-12 * a.cwiseAbs().maxCoeff());
  Eigen::MatrixXd c = Eigen::MatrixXd::Random(6, 6);
  c = (0.5 * (c + c.transpose())).eval();
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> before(c);
  ASSERT_LT(before.eigenvalues().minCoeff(), 0.0);
  ProjectToPsd(c);
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> after(c);
  EXPECT_GT(after.eigenvalues().minCoeff(), -1e-12);
  // Positive eigenvalues kept (sorted ascending in both).
  for (int k = 0; k < 6; ++k) {
    if (before.eigenvalues()[k] > 0) {
      EXPECT_NEAR(after.eigenvalues()[k], before.eigenvalues()[k], 1e-12);
    }
  }
}

TEST(GeneralisedTerms, SpringGradientAndHessianMatchFiniteDifferencesAtLargeRotations) {
  MixedScene scene;
  ZeroLengthSpringTerm springs(/*project_psd=*/false);
  scene.AddSprings(&springs);
  CheckDerivatives(&springs, scene.state, /*check_hessian=*/true);
  // The frame-offset spring alone, at stored rotations of 90 and 170 degrees.
  for (const double degrees : {90.0, 170.0}) {
    GeneralisedState s;
    const int f = s.AddFrameNode({1, 2, 3}, AxisAngle({1, -1, 2}, degrees));
    ZeroLengthSpringTerm one(false);
    one.Add(SpringAnchor::AtOffset(f, {4, 1, -2}), SpringAnchor::Fixed({-3, 5, 2}), 5.0);
    CheckDerivatives(&one, s, true);
  }
}

TEST(GeneralisedTerms, ProjectedSpringHessianIsPsdAndExactWherePsd) {
  MixedScene scene;
  ZeroLengthSpringTerm exact(false), projected(true);
  scene.AddSprings(&exact);
  scene.AddSprings(&projected);
  const Eigen::MatrixXd he = HessianAt(&exact, scene.state);
  const Eigen::MatrixXd hp = HessianAt(&projected, scene.state);
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> ee(he), ep(hp);
  EXPECT_LT(ee.eigenvalues().minCoeff(), -1e-3);  // the exact one is indefinite here
  EXPECT_GT(ep.eigenvalues().minCoeff(), -1e-10 * hp.norm());
  // Only the rotation-rotation blocks of a node differ (the translation rows are exact).
  const GeneralisedState& st = scene.state;
  for (int i = 0; i < st.num_dofs(); ++i)
    for (int j = 0; j < st.num_dofs(); ++j) {
      bool same_rotation_block = false;
      for (const int f : {scene.f0, scene.f1}) {
        const int o = st.dof_offset(f) + 3;
        same_rotation_block |= i >= o && i < o + 3 && j >= o && j < o + 3;
      }
      if (!same_rotation_block) {
        EXPECT_EQ(he(i, j), hp(i, j)) << i << " " << j;
      }
    }
  // A hanging pendulum at rest (d antiparallel to the offset): the exact block is PSD
  // and the projection leaves it unchanged.
  GeneralisedState s;
  const int f = s.AddFrameNode({0, 0, -12}, Eigen::Matrix3d::Identity());
  ZeroLengthSpringTerm a(false), b(true);
  for (ZeroLengthSpringTerm* t : {&a, &b})
    t->Add(SpringAnchor::AtOffset(f, {0, 0, 10}), SpringAnchor::Fixed({0, 0, 0}), 4.0);
  EXPECT_LT((HessianAt(&a, s) - HessianAt(&b, s)).cwiseAbs().maxCoeff(), 1e-12);
}

// The projection of the rotational curvature is the eigen-clamp (ProjectToPsd) of it, also
// where d and s are parallel or antiparallel.
TEST(GeneralisedTerms, ProjectedSpringCurvatureIsItsNearestPsdMatrix) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  const double k = 3.0;
  for (int trial = 0; trial < 40; ++trial) {
    const Eigen::Vector3d offset(u(rng), u(rng), u(rng));
    GeneralisedState s;
    const int f = s.AddFrameNode({0, 0, 0}, AxisAngle({u(rng), u(rng), u(rng)}, 150 * u(rng)));
    const Eigen::Vector3d arm = s.rotation(f) * offset;
    // Targets in general position, and along the arm (d parallel / antiparallel to s).
    Eigen::Vector3d target(u(rng), u(rng), u(rng));
    if (trial % 4 == 1) target = 3.0 * arm;
    if (trial % 4 == 2) target = -2.0 * arm;
    ZeroLengthSpringTerm exact(false), projected(true);
    for (ZeroLengthSpringTerm* t : {&exact, &projected})
      t->Add(SpringAnchor::AtOffset(f, offset), SpringAnchor::Fixed(target), k);
    const Eigen::MatrixXd he = HessianAt(&exact, s), hp = HessianAt(&projected, s);
    // G = exact rotation block - k [s]x^T [s]x.
    const Eigen::Matrix3d sx = Skew(arm);
    Eigen::MatrixXd g = he.bottomRightCorner<3, 3>() - k * sx.transpose() * sx;
    const Eigen::Matrix3d g_exact = g;
    ProjectToPsd(g);
    EXPECT_LT((hp.bottomRightCorner<3, 3>() - he.bottomRightCorner<3, 3>() - (g - g_exact))
                  .cwiseAbs()
                  .maxCoeff(),
              1e-12 * std::max(1.0, he.norm()))
        << "trial " << trial;
  }
}

TEST(GeneralisedTerms, GravityGradientMatchesFiniteDifferences) {
  MixedScene scene;
  std::vector<NodeInertia> inertia(scene.state.num_nodes());
  for (int n = 0; n < scene.state.num_nodes(); ++n) inertia[n].mass_kg = 0.01 * (n + 1);
  GravityTerm gravity(inertia, {0, 0, -kStandardGravityMmPerS2});
  CheckDerivatives(&gravity, scene.state, true);
}

// A tet body whose vertices sit on nodes in a shuffled order between frame nodes.
struct ShuffledTets {
  MechanicalState body{SmallBox({3, 2, 2}, {30, 20, 20}), Material{3000, 0.45, 1000}};
  GeneralisedState state;
  std::vector<int> vertex_node;
  ShuffledTets() {
    std::vector<int> order(body.num_vertices());
    std::iota(order.begin(), order.end(), 0);
    std::shuffle(order.begin(), order.end(), std::mt19937(3));
    vertex_node.resize(body.num_vertices());
    state.AddFrameNode({50, 0, 0}, AxisAngle({1, 0, 0}, 90));
    for (int k = 0; k < body.num_vertices(); ++k) {
      vertex_node[order[k]] = state.AddPointNode(body.rest_position(order[k]));
      if (k == 5) state.AddFrameNode({60, 0, 0}, Eigen::Matrix3d::Identity());
    }
    const RowMatX3d x = testing::Perturbed(body.rest_positions(), 1.5, 11);
    for (int v = 0; v < body.num_vertices(); ++v)
      state.mutable_positions().row(vertex_node[v]) = x.row(v);
  }
};

TEST(GeneralisedTerms, TetTermIsTheCorotationalElasticityOnItsNodes) {
  ShuffledTets scene;
  TetElasticityTerm term(&scene.body, scene.vertex_node);
  // Its gradient is the exact gradient of its energy (polar rotations, elastic_energy.h).
  CheckDerivatives(&term, scene.state, /*check_hessian=*/false, 1e-6);
  // Energy, gradient and Hessian are the ones of CorotationalElasticity at the same x.
  const RowMatX3d x = term.VertexPositions(scene.state);
  CorotationalElasticity reference;
  reference.Update(scene.body, x);
  term.Update(scene.state);
  // The same to the polar iteration's tolerance (warm-started from other rotations).
  EXPECT_NEAR(term.Value(scene.state), reference.Value(scene.body, x),
              1e-12 * reference.Value(scene.body, x));
  RowMatX3d g_ref = RowMatX3d::Zero(x.rows(), 3);
  reference.AddGradient(scene.body, x, &g_ref);
  const Eigen::VectorXd g = GradientAt(&term, scene.state);
  SystemMatrix k_ref(scene.body.num_vertices(), scene.body.tetrahedra());
  reference.AddHessian(scene.body, x, 1.0, &k_ref);
  const Eigen::MatrixXd kr(k_ref.matrix());
  const Eigen::MatrixXd h = HessianAt(&term, scene.state);
  for (int a = 0; a < x.rows(); ++a) {
    const int oa = scene.state.dof_offset(scene.vertex_node[a]);
    EXPECT_LT((g.segment<3>(oa) - g_ref.row(a).transpose()).norm(), 1e-12 * g_ref.norm());
    for (int b = 0; b < x.rows(); ++b) {
      const int ob = scene.state.dof_offset(scene.vertex_node[b]);
      EXPECT_LT((h.block<3, 3>(oa, ob) - kr.block<3, 3>(3 * a, 3 * b)).norm(), 1e-12 * kr.norm());
    }
  }
  // Frame nodes untouched by the term; lumped masses as the body's.
  EXPECT_EQ(g.segment<6>(0).norm(), 0.0);
  const std::vector<NodeInertia> inertia = CollectNodeInertia(scene.state, {&term});
  const Eigen::VectorXd m = scene.body.LumpedVertexMasses();
  for (int v = 0; v < m.size(); ++v) EXPECT_DOUBLE_EQ(inertia[scene.vertex_node[v]].mass_kg, m[v]);
  EXPECT_EQ(inertia[0].mass_kg, 0.0);
}

// A cantilever under gravity, fixed at x = 0, on both paths.
struct Cantilever {
  MechanicalState body{SmallBox({6, 2, 2}, {60, 20, 20}), Material{30000, 0.45, 1000}};
  CorotationalElasticity elastic;
  GravityEnergy gravity{{0, 0, -kStandardGravityMmPerS2}};
  GeneralisedState state;
  std::unique_ptr<TetElasticityTerm> tets;
  std::unique_ptr<GravityTerm> gterm;
  Cantilever() {
    for (int v = 0; v < body.num_vertices(); ++v)
      if (body.rest_positions()(v, 0) == 0.0) body.SetFixed(v, true);
    tets = std::make_unique<TetElasticityTerm>(&body, AddTetVertexNodes(body, &state));
    gterm = std::make_unique<GravityTerm>(CollectNodeInertia(state, {tets.get()}),
                                          Eigen::Vector3d(0, 0, -kStandardGravityMmPerS2));
  }
  RowMatX3d GeneralisedPositions() const { return tets->VertexPositions(state); }
  RowMatX3d GeneralisedVelocities() const {
    RowMatX3d v(body.num_vertices(), 3);
    for (int i = 0; i < v.rows(); ++i) v.row(i) = state.velocities().row(tets->vertex_node()[i]);
    return v;
  }
};

TEST(GeneralisedStaticSolver, TetCantileverEqualsTheStaticSolver) {
  Cantilever c;
  StaticSolver reference(StaticSolverOptions{});
  const StepSummary sr = reference.Solve(&c.body, &c.elastic, {&c.gravity});
  ASSERT_EQ(sr.status, StepStatus::kConverged)
      << sr.message << " " << sr.newton_iterations << " " << sr.last_increment_mm;
  GeneralisedStaticSolver solver(GeneralisedStaticOptions{});
  const GeneralisedSummary sg = solver.Solve(&c.state, {c.tets.get(), c.gterm.get()});
  ASSERT_EQ(sg.status, StepStatus::kConverged) << sg.message;
  const RowMatX3d u_ref = c.body.positions() - c.body.rest_positions();
  const double scale = u_ref.cwiseAbs().maxCoeff();
  EXPECT_GT(scale, 1.0);  // a real deflection (mm)
  EXPECT_LT((c.GeneralisedPositions() - c.body.positions()).cwiseAbs().maxCoeff(), 1e-8 * scale);
  EXPECT_EQ(sg.newton_iterations, sr.newton_iterations);
}

// The tet body's other EnergyTerms (embedded springs, point forces) through TetBodyTerm.
TEST(GeneralisedStaticSolver, TetBodyTermsEqualTheStaticSolverWithSpringsAndForces) {
  Cantilever c;
  const RowMatX3d anchors = (RowMatX3d(3, 3) << 59, 10, 10, 59, 2, 18, 35, 18, 2).finished();
  const EmbeddedPoints e =
      EmbeddedPoints::Embed(anchors, c.body.rest_positions(), c.body.tetrahedra());
  SpringEnergy springs;
  for (int i = 0; i < e.size(); ++i)
    springs.Add(e[i], anchors.row(i).transpose() + Eigen::Vector3d(4, 3, 6), 2.0);
  PointForceEnergy forces;
  forces.AddForce(c.body.num_vertices() - 1, {0, 5, 0});
  TetBodyTerm gspring(&c.body, c.tets->vertex_node(), &springs);
  TetBodyTerm gforce(&c.body, c.tets->vertex_node(), &forces);
  // The adapter's derivatives are the wrapped term's: exact for springs (constant Hessian).
  GeneralisedState perturbed = c.state;
  perturbed.mutable_positions() = testing::Perturbed(c.state.positions(), 1.0, 4);
  CheckDerivatives(&gspring, perturbed, /*check_hessian=*/true);
  EXPECT_EQ(gspring.name(), "springs");

  StaticSolver reference(StaticSolverOptions{});
  const StepSummary sr = reference.Solve(&c.body, &c.elastic, {&c.gravity, &springs, &forces});
  ASSERT_EQ(sr.status, StepStatus::kConverged) << sr.message;
  GeneralisedStaticSolver solver(GeneralisedStaticOptions{});
  const GeneralisedSummary sg =
      solver.Solve(&c.state, {c.tets.get(), c.gterm.get(), &gspring, &gforce});
  ASSERT_EQ(sg.status, StepStatus::kConverged) << sg.message;
  const double scale = (c.body.positions() - c.body.rest_positions()).cwiseAbs().maxCoeff();
  EXPECT_LT((c.GeneralisedPositions() - c.body.positions()).cwiseAbs().maxCoeff(), 1e-8 * scale);
}

class ImplicitStepsAgree : public ::testing::TestWithParam<NewtonMode> {};

TEST_P(ImplicitStepsAgree, TetCantileverEqualsTheImplicitEulerIntegrator) {
  Cantilever c;
  ImplicitEulerOptions o;
  o.dt_s = 0.02;
  o.newton_mode = GetParam();
  o.max_newton_iterations = GetParam() == NewtonMode::kFixedIterations ? 2 : 20;
  o.rayleigh_mass_alpha = 0.5;
  o.rayleigh_stiffness_beta = 0.01;
  o.substeps = GetParam() == NewtonMode::kOneStep ? 1 : 2;  // sub-steps covered too
  GeneralisedImplicitEulerOptions g;
  g.dt_s = o.dt_s;
  g.substeps = o.substeps;
  g.newton_mode = o.newton_mode;
  g.max_newton_iterations = o.max_newton_iterations;
  g.rayleigh_mass_alpha = o.rayleigh_mass_alpha;
  g.rayleigh_stiffness_beta = o.rayleigh_stiffness_beta;
  ImplicitEulerIntegrator reference(o);
  GeneralisedImplicitEuler euler(g);
  const std::vector<NodeInertia> inertia = CollectNodeInertia(c.state, {c.tets.get()});
  for (int step = 0; step < 8; ++step) {
    const StepSummary sr = reference.Step(&c.body, &c.elastic, {&c.gravity});
    const GeneralisedSummary sg = euler.Step(&c.state, {c.tets.get()}, {c.gterm.get()}, inertia);
    ASSERT_EQ(sr.status, StepStatus::kConverged)
        << sr.message << " " << sr.newton_iterations << " " << sr.last_increment_mm;
    ASSERT_EQ(sg.status, StepStatus::kConverged) << sg.message;
    EXPECT_EQ(sg.newton_iterations, sr.newton_iterations);
    const double xs = (c.body.positions() - c.body.rest_positions()).cwiseAbs().maxCoeff();
    const double vs = c.body.velocities().cwiseAbs().maxCoeff();
    ASSERT_GT(xs, 0.0);
    EXPECT_LT((c.GeneralisedPositions() - c.body.positions()).cwiseAbs().maxCoeff(), 1e-8 * xs)
        << "step " << step;
    EXPECT_LT((c.GeneralisedVelocities() - c.body.velocities()).cwiseAbs().maxCoeff(), 1e-8 * vs)
        << "step " << step;
  }
}

INSTANTIATE_TEST_SUITE_P(Modes, ImplicitStepsAgree,
                         ::testing::Values(NewtonMode::kOneStep, NewtonMode::kFullNewton,
                                           NewtonMode::kFixedIterations));

// Torque-free rigid body: one frame node with an asymmetric inertia tensor.
struct SpinningBody {
  GeneralisedState state;
  std::vector<NodeInertia> inertia{1};
  Eigen::Vector3d body_omega0;
  SpinningBody(const Eigen::Vector3d& body_omega) : body_omega0(body_omega) {
    const Eigen::Matrix3d r0 = AxisAngle({1, 2, -1}, 40);
    state.AddFrameNode({0, 0, 0}, r0);
    inertia[0].mass_kg = 0.01;
    inertia[0].body_inertia = Eigen::Vector3d(1.0, 2.0, 3.0).asDiagonal();  // kg mm^2
    state.mutable_angular_velocities().row(0) = (r0 * body_omega).transpose();
  }
  // Runs `steps` implicit steps of dt_s (one-step mode: no elastic term, the
  // potential is quadratic in the step's rotation vector at its start).
  void Run(double dt_s, int steps) {
    GeneralisedImplicitEulerOptions o;
    o.dt_s = dt_s;
    GeneralisedImplicitEuler euler(o);
    for (int k = 0; k < steps; ++k) {
      const GeneralisedSummary s = euler.Step(&state, {}, {}, inertia);
      ASSERT_EQ(s.status, StepStatus::kConverged) << s.message;
    }
  }
  Eigen::Vector3d BodyOmega() const {
    return state.rotation(0).transpose() * state.angular_velocities().row(0).transpose();
  }
};

// Euler's equations I dW/dt = -W x I W, dR/dt = [R W]x R by RK4 (the reference).
Eigen::Vector3d EulerEquationsBodyOmega(const Eigen::Vector3d& w0, const Eigen::Vector3d& I,
                                        double t_end) {
  const auto f = [&](const Eigen::Vector3d& w) {
    const Eigen::Vector3d l = I.cwiseProduct(w);
    return Eigen::Vector3d(-(w.cross(l)).cwiseQuotient(I));
  };
  const int n = 200000;
  const double dt = t_end / n;
  Eigen::Vector3d w = w0;
  for (int k = 0; k < n; ++k) {
    const Eigen::Vector3d k1 = f(w), k2 = f(w + 0.5 * dt * k1), k3 = f(w + 0.5 * dt * k2),
                          k4 = f(w + dt * k3);
    w += dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4);
  }
  return w;
}

TEST(GeneralisedImplicitEuler, FreeRigidBodyKeepsAngularMomentumAndFollowsEulersEquations) {
  // Spin mostly about the axis of largest inertia with a wobble: the body axes precess.
  const Eigen::Vector3d w0(1.0, 1.5, 6.0);  // rad/s, body axes
  SpinningBody body(w0);
  const Eigen::Vector3d l0 = GeneralisedAngularMomentum(body.state, body.inertia);
  const double e0 = GeneralisedKineticEnergy(body.state, body.inertia);
  body.Run(1e-3, 1000);
  // Backward Euler on the momentum with no torque: L exactly, to rounding
  // (rounding accumulated over the 1000 steps: 1.3e-12 of |L| measured).
  EXPECT_LT((GeneralisedAngularMomentum(body.state, body.inertia) - l0).norm(), 1e-10 * l0.norm());
  EXPECT_EQ(GeneralisedLinearMomentum(body.state, body.inertia).norm(), 0.0);
  // The rotation advances by the step's start inertia (first order in h): the kinetic energy
  // 1/2 L I(R)^-1 L drifts by O(h) of it (+1.6e-3 measured at h = 1 ms over 1 s).
  EXPECT_LT(std::abs(GeneralisedKineticEnergy(body.state, body.inertia) - e0), 5e-3 * e0);
  // Body angular velocity against Euler's equations: first-order convergence (the
  // gyroscopic term is in the scheme; without it W would stay w0, an error of |w_ref - w0|).
  const Eigen::Vector3d I(1.0, 2.0, 3.0);
  const Eigen::Vector3d w_ref = EulerEquationsBodyOmega(w0, I, 1.0);
  ASSERT_GT((w_ref - w0).norm(), 0.4);  // 0.48 rad/s of precession
  const double err_h = (body.BodyOmega() - w_ref).norm();
  SpinningBody finer(w0);
  finer.Run(5e-4, 2000);
  const double err_h2 = (finer.BodyOmega() - w_ref).norm();
  EXPECT_LT(err_h, 0.2 * (w_ref - w0).norm());  // 0.076 rad/s at h = 1 ms
  EXPECT_GT(err_h / err_h2, 1.7);               // order 1: ratio 2 as h halves
  EXPECT_LT(err_h / err_h2, 2.3);
}

TEST(GeneralisedImplicitEuler, SpinAboutAPrincipalAxisIsExact) {
  SpinningBody body({0, 0, 4.0});
  const double e0 = GeneralisedKineticEnergy(body.state, body.inertia);
  const Eigen::Matrix3d r0 = body.state.rotation(0);
  const Eigen::Vector3d omega = body.state.angular_velocities().row(0).transpose();
  body.Run(0.01, 50);
  EXPECT_LT((body.state.rotation(0) - ExpSO3(0.5 * omega) * r0).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_NEAR(GeneralisedKineticEnergy(body.state, body.inertia), e0, 1e-12 * e0);
}

// A constant force on one node: E = -f . x (how a term outside this module plugs in).
class ConstantForce : public GeneralisedEnergyTerm {
 public:
  ConstantForce(int node, const Eigen::Vector3d& force_mn) : node_(node), force_(force_mn) {}
  std::string name() const override { return "constant-force"; }
  void AppendStencils(std::vector<std::vector<int>>* stencils) const override {
    stencils->push_back({node_});
  }
  double Value(const GeneralisedState& s) const override { return -force_.dot(s.position(node_)); }
  void AddGradient(const GeneralisedState& s, Eigen::VectorXd* g) const override {
    g->segment<3>(s.dof_offset(node_)) -= force_;
  }
  void AddHessian(const GeneralisedState&, double, HessianSink*) const override {}

 private:
  int node_;
  Eigen::Vector3d force_;
};

TEST(GeneralisedImplicitEuler, OffsetSpringPendulumSettlesAtTheStaticAngle) {
  // A rigid body (frame node at its centre of mass) hangs from a pivot by a stiff
  // zero-length spring at body offset r; gravity and a horizontal force F act on it.
  // Equilibrium: k d = m g + F (d = p - pivot) and no torque, so R r is antiparallel
  // to m g + F: the pendulum hangs at atan(|F| / (m g)) = 30 degrees from the vertical.
  const double m = 0.01, k = 50.0, r = 20.0;
  const Eigen::Vector3d g(0, 0, -kStandardGravityMmPerS2);
  const Eigen::Vector3d f(m * kStandardGravityMmPerS2 * std::tan(M_PI / 6), 0, 0);
  GeneralisedState state;
  const int node = state.AddFrameNode({0, 0, -r}, Eigen::Matrix3d::Identity());
  std::vector<NodeInertia> inertia(1);
  inertia[0].mass_kg = m;
  inertia[0].body_inertia = Eigen::Vector3d(2.0, 1.0, 1.5).asDiagonal();
  ZeroLengthSpringTerm spring;
  spring.Add(SpringAnchor::AtOffset(node, {0, 0, r}), SpringAnchor::Fixed({0, 0, 0}), k);
  GravityTerm gravity(inertia, g);
  ConstantForce push(node, f);
  GeneralisedImplicitEulerOptions o;
  o.dt_s = 0.01;
  o.newton_mode = NewtonMode::kFullNewton;
  o.newton_tolerance_mm = 1e-10;
  o.newton_tolerance_rad = 1e-12;
  o.rayleigh_mass_alpha = 5.0;
  GeneralisedImplicitEuler euler(o);
  for (int step = 0; step < 1500; ++step) {
    const GeneralisedSummary s = euler.Step(&state, {&spring}, {&gravity, &push}, inertia);
    ASSERT_EQ(s.status, StepStatus::kConverged) << s.message << " at step " << step;
  }
  const Eigen::Vector3d load = m * g + f;
  const Eigen::Vector3d d = load / k;
  const Eigen::Vector3d s = -r * load.normalized();
  EXPECT_LT((state.position(node) - (d - s)).norm(), 1e-8);
  const Eigen::Vector3d arm = state.rotation(node) * Eigen::Vector3d(0, 0, r);
  const double angle =
      std::acos(std::clamp(arm.normalized().dot(Eigen::Vector3d::UnitZ()), -1.0, 1.0));
  EXPECT_NEAR(angle, M_PI / 6, 1e-9);
  EXPECT_LT(state.velocities().norm() + state.angular_velocities().norm(), 1e-8);
}

// Best rotation R minimising sum |R r_i - y_i|^2 (Kabsch, det +1).
Eigen::Matrix3d Kabsch(const std::vector<Eigen::Vector3d>& r,
                       const std::vector<Eigen::Vector3d>& y) {
  Eigen::Matrix3d m = Eigen::Matrix3d::Zero();
  for (size_t i = 0; i < r.size(); ++i) m += y[i] * r[i].transpose();
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(m, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
  d(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() > 0 ? 1.0 : -1.0;
  return svd.matrixU() * d * svd.matrixV().transpose();
}

// A frame node pulled by springs at three body offsets towards targets that a
// translation c and a rotation R* of the offsets would reach (not exactly: a
// perturbation makes the fit a least-squares one).
struct PulledFrame {
  GeneralisedState state;
  ZeroLengthSpringTerm springs;
  int node;
  Eigen::Vector3d x0{1, 2, 3};
  std::vector<Eigen::Vector3d> offsets{{8, 0, 0}, {0, 6, 0}, {-3, -3, 5}}, targets;
  Eigen::Matrix3d r0 = AxisAngle({0, 1, 0}, 30);
  PulledFrame() {
    node = state.AddFrameNode(x0, r0);
    const Eigen::Matrix3d r_star = AxisAngle({1, 1, 1}, 120) * r0;
    const Eigen::Vector3d c(4, -2, 1);
    const Eigen::Vector3d wobble[3] = {{0.3, -0.2, 0.1}, {-0.1, 0.2, 0.3}, {0.2, 0.1, -0.4}};
    for (int i = 0; i < 3; ++i) {
      targets.push_back(x0 + c + r_star * offsets[i] + wobble[i]);
      springs.Add(SpringAnchor::AtOffset(node, offsets[i]), SpringAnchor::Fixed(targets[i]), 3.0);
    }
  }
  GeneralisedSummary Solve() {
    GeneralisedStaticSolver solver(GeneralisedStaticOptions{});
    return solver.Solve(&state, {&springs});
  }
};

TEST(GeneralisedStaticSolver, FreeFrameFitsTheTargetsLikeProcrustes) {
  PulledFrame p;
  const GeneralisedSummary s = p.Solve();
  ASSERT_EQ(s.status, StepStatus::kConverged) << s.message;
  // Equal stiffnesses: x + R r_i fits t_i in least squares; with the centroids
  // r_bar, t_bar: R = Kabsch(r_i - r_bar, t_i - t_bar), x = t_bar - R r_bar.
  Eigen::Vector3d rb = Eigen::Vector3d::Zero(), tb = Eigen::Vector3d::Zero();
  for (int i = 0; i < 3; ++i) rb += p.offsets[i] / 3, tb += p.targets[i] / 3;
  std::vector<Eigen::Vector3d> rc, tc;
  for (int i = 0; i < 3; ++i) rc.push_back(p.offsets[i] - rb), tc.push_back(p.targets[i] - tb);
  // The node's rotation maps body offsets: R = Kabsch over (body r_i, t_i).
  const Eigen::Matrix3d r = Kabsch(rc, tc);
  EXPECT_LT((p.state.rotation(p.node) - r).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_LT((p.state.position(p.node) - (tb - r * rb)).norm(), 1e-9);
}

TEST(GeneralisedStaticSolver, SimplySupportedFrameKeepsItsPositionAndTurns) {
  PulledFrame p;
  p.state.SetFixedTranslation(p.node, true);
  const GeneralisedSummary s = p.Solve();
  ASSERT_EQ(s.status, StepStatus::kConverged) << s.message;
  EXPECT_EQ(p.state.position(p.node), p.x0);  // bit for bit: zero increments
  std::vector<Eigen::Vector3d> y;
  for (int i = 0; i < 3; ++i) y.push_back(p.targets[i] - p.x0);
  EXPECT_LT((p.state.rotation(p.node) - Kabsch(p.offsets, y)).cwiseAbs().maxCoeff(), 1e-9);
}

TEST(GeneralisedStaticSolver, FixedRotationFrameOnlyTranslates) {
  PulledFrame p;
  p.state.SetFixedRotation(p.node, true);
  const GeneralisedSummary s = p.Solve();
  ASSERT_EQ(s.status, StepStatus::kConverged) << s.message;
  EXPECT_EQ(p.state.rotation(p.node), p.r0);  // bit for bit
  Eigen::Vector3d x = Eigen::Vector3d::Zero();
  for (int i = 0; i < 3; ++i) x += (p.targets[i] - p.r0 * p.offsets[i]) / 3;
  EXPECT_LT((p.state.position(p.node) - x).norm(), 1e-10)
      << s.newton_iterations << " " << s.last_increment_mm << " " << s.line_search_cuts;
}

TEST(GeneralisedImplicitEuler, FixedMasksZeroTheirIncrementsAndVelocities) {
  for (const bool fix_rotation : {false, true}) {
    PulledFrame p;
    std::vector<NodeInertia> inertia(1);
    inertia[0].mass_kg = 0.01;
    inertia[0].body_inertia = Eigen::Matrix3d::Identity();
    p.state.mutable_velocities().row(0) << 10, 0, 0;
    p.state.mutable_angular_velocities().row(0) << 0, 2, 0;
    if (fix_rotation)
      p.state.SetFixedRotation(p.node, true);
    else
      p.state.SetFixedTranslation(p.node, true);
    GeneralisedImplicitEuler euler(GeneralisedImplicitEulerOptions{});
    for (int k = 0; k < 3; ++k) euler.Step(&p.state, {&p.springs}, {}, inertia);
    if (fix_rotation) {
      EXPECT_EQ(p.state.rotation(p.node), p.r0);
      EXPECT_EQ(p.state.angular_velocities().row(0).norm(), 0.0);
      EXPECT_GT(p.state.velocities().row(0).norm(), 1.0);
    } else {
      EXPECT_EQ(p.state.position(p.node), p.x0);
      EXPECT_EQ(p.state.velocities().row(0).norm(), 0.0);
      EXPECT_GT(p.state.angular_velocities().row(0).norm(), 0.1);
    }
  }
}

// The tet cantilever with a rigid plate (one frame node) held at its free end by
// three offset springs (to free-end vertices not on a line: no hinge mode).
struct PlateOnCantilever : Cantilever {
  ZeroLengthSpringTerm springs;
  std::vector<NodeInertia> inertia;
  int plate;
  PlateOnCantilever() {
    plate = state.AddFrameNode({70, 10, 0}, Eigen::Matrix3d::Identity());
    for (const Eigen::Vector3d& offset :
         {Eigen::Vector3d(-10, -10, 0), Eigen::Vector3d(-10, 10, 0), Eigen::Vector3d(-10, 0, 20)}) {
      int vertex = -1;
      for (int v = 0; v < body.num_vertices(); ++v)
        if ((body.rest_position(v) - Eigen::Vector3d(70, 10, 0) - offset).norm() < 1e-9) vertex = v;
      springs.Add(SpringAnchor::AtOffset(plate, offset),
                  SpringAnchor::AtNode(tets->vertex_node()[vertex]), 20.0);
    }
    inertia = CollectNodeInertia(state, {tets.get()});
    inertia[plate].mass_kg = 0.002;
    inertia[plate].body_inertia = Eigen::Vector3d(0.07, 0.07, 0.13).asDiagonal();
    gterm->SetMasses(inertia);
  }
  GeneralisedSummary Step(GeneralisedImplicitEuler* euler) {
    return euler->Step(&state, {tets.get(), &springs}, {gterm.get()}, inertia);
  }
};

// The damped dynamic run settles where the static solver puts the coupled model.
TEST(GeneralisedImplicitEuler, CoupledTetsAndFrameReachTheStaticSolution) {
  PlateOnCantilever a, b;
  const int plate = a.plate;
  GeneralisedStaticOptions so;
  so.tolerance_mm = 1e-8;
  so.tolerance_rad = 1e-10;
  const GeneralisedSummary ss =
      GeneralisedStaticSolver(so).Solve(&a.state, {a.tets.get(), &a.springs, a.gterm.get()});
  ASSERT_EQ(ss.status, StepStatus::kConverged)
      << ss.message << " " << ss.newton_iterations << " " << ss.last_increment_mm << " "
      << ss.last_increment_rad << " cuts " << ss.line_search_cuts;
  GeneralisedImplicitEulerOptions o;
  o.dt_s = 0.02;
  o.rayleigh_mass_alpha = 10.0;
  o.rayleigh_stiffness_beta = 0.002;
  GeneralisedImplicitEuler euler(o);
  for (int step = 0; step < 600; ++step) {
    const GeneralisedSummary s = b.Step(&euler);
    ASSERT_EQ(s.status, StepStatus::kConverged) << s.message;
  }
  const double sag = (a.state.positions() - a.state.rest_positions()).cwiseAbs().maxCoeff();
  EXPECT_GT(sag, 1.0);
  EXPECT_LT((a.state.positions() - b.state.positions()).cwiseAbs().maxCoeff(), 1e-5 * sag);
  EXPECT_LT(LogSO3(a.state.rotation(plate) * b.state.rotation(plate).transpose()).norm(), 1e-6);
}

// The generalised matrix (6-DOF blocks among 3-DOF ones) through CG: the same steps as CHOLMOD.
TEST(GeneralisedImplicitEuler, ConjugateGradientStepsEqualCholmod) {
  for (const Preconditioner pc : {Preconditioner::kJacobi, Preconditioner::kBlockJacobi}) {
    PlateOnCantilever a, b;
    GeneralisedImplicitEulerOptions o;
    o.dt_s = 0.02;
    o.linear_solver.relative_tolerance = 1e-13;
    GeneralisedImplicitEuler direct(o);
    o.linear_solver.type = LinearSolverType::kConjugateGradient;
    o.linear_solver.preconditioner = pc;
    o.linear_solver.max_iterations = 10000;
    GeneralisedImplicitEuler cg(o);
    for (int step = 0; step < 5; ++step) {
      ASSERT_EQ(a.Step(&direct).status, StepStatus::kConverged);
      const GeneralisedSummary s = b.Step(&cg);
      ASSERT_EQ(s.status, StepStatus::kConverged) << s.message;
      EXPECT_GT(s.linear_iterations, 0);
    }
    const double sag = (a.state.positions() - a.state.rest_positions()).cwiseAbs().maxCoeff();
    EXPECT_LT((a.state.positions() - b.state.positions()).cwiseAbs().maxCoeff(), 1e-8 * sag);
    EXPECT_LT(LogSO3(a.state.rotation(a.plate) * b.state.rotation(a.plate).transpose()).norm(),
              1e-8);
  }
}

TEST(GeneralisedSolvers, EmptyStateIsConverged) {
  GeneralisedState state;
  ZeroLengthSpringTerm springs;
  EXPECT_EQ(GeneralisedStaticSolver(GeneralisedStaticOptions{}).Solve(&state, {&springs}).status,
            StepStatus::kConverged);
  EXPECT_EQ(GeneralisedImplicitEuler(GeneralisedImplicitEulerOptions{})
                .Step(&state, {}, {&springs}, {})
                .status,
            StepStatus::kConverged);
}

TEST(GeneralisedSolvers, OptionsCheckNamesTheField) {
  GeneralisedStaticOptions s;
  s.tolerance_rad = 0;
  EXPECT_THROW(s.Check(), Error);
  GeneralisedImplicitEulerOptions e;
  e.newton_tolerance_rad = -1;
  EXPECT_THROW(e.Check(), Error);
  try {
    e.Check();
  } catch (const Error& error) {
    EXPECT_NE(std::string(error.what()).find("newton_tolerance_rad"), std::string::npos);
  }
  GeneralisedImplicitEulerOptions m;
  GeneralisedImplicitEuler euler(m);
  GeneralisedState state;
  state.AddFrameNode({0, 0, 0}, Eigen::Matrix3d::Identity());
  EXPECT_THROW(euler.Step(&state, {}, {}, {}), Error);  // inertia for 0 of 1 nodes
}
}  // namespace
}  // namespace arreg::mechanics
