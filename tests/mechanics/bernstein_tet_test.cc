// Bernstein-Bezier tetrahedra (degree 1-3): closed-form integrals, the raised mesh,
// degree 1 against the P1 element, rigid motions, finite-difference derivatives,
// patch tests through the generalised static solver, a free implicit-Euler run.
#include "mechanics/bernstein_tet.h"

#include <gtest/gtest.h>
#include <Eigen/Eigenvalues>

#include <cmath>
#include <memory>
#include <set>

#include "core/error.h"
#include "dense_hessian_sink.h"
#include "mechanics/generalised_solver.h"
#include "mechanics/generalised_terms.h"
#include "mechanics/mechanical_state.h"
#include "mechanics_test_util.h"

namespace arreg::mechanics {
namespace {

using testing::DenseHessianSink;
using testing::Perturbed;
using testing::SmallBox;

struct Model {
  HighOrderTetMesh mesh;
  GeneralisedState state;
  std::vector<int> node;
  std::unique_ptr<BernsteinTetTerm> term;
};

std::unique_ptr<Model> MakeModel(const TetMesh& tets, int degree, const Material& material = {}) {
  auto m = std::make_unique<Model>();
  m->mesh = RaiseTetMesh(tets, degree);
  m->node = AddHighOrderNodes(m->mesh, &m->state);
  BernsteinTetOptions options;
  options.material = material;
  m->term = std::make_unique<BernsteinTetTerm>(&m->mesh, m->node, options);
  return m;
}

Eigen::VectorXd Gradient(Model* m) {
  m->term->Update(m->state);
  Eigen::VectorXd g = Eigen::VectorXd::Zero(m->state.num_dofs());
  m->term->AddGradient(m->state, &g);
  return g;
}

Eigen::Matrix3d RotationAbout(const Eigen::Vector3d& axis, double degrees) {
  return Eigen::AngleAxisd(degrees * M_PI / 180.0, axis.normalized()).toRotationMatrix();
}

TEST(BernsteinIntegrals, MultinomialFormulaAndBernsteinProducts) {
  const double volume = 2.5;
  // int L0^2 = V/10, int L0 L1 = V/20, int 1 = V (known P2 mass entries)
  EXPECT_NEAR(BarycentricMonomialIntegral({2, 0, 0, 0}, volume), volume / 10, 1e-15);
  EXPECT_NEAR(BarycentricMonomialIntegral({1, 1, 0, 0}, volume), volume / 20, 1e-15);
  EXPECT_NEAR(BarycentricMonomialIntegral({0, 0, 0, 0}, volume), volume, 1e-15);
  for (int k = 1; k <= 3; ++k) {
    const Eigen::MatrixXd m = BernsteinMassMatrix(k, volume, 1.0);
    ASSERT_EQ(m.rows(), BernsteinCount(k));
    // Partition of unity: the entries sum to the volume; rows to the lumped mass.
    EXPECT_NEAR(m.sum(), volume, 1e-13);
    for (int a = 0; a < m.rows(); ++a)
      EXPECT_NEAR(m.row(a).sum(), BernsteinLumpedMass(k, volume, 1.0), 1e-14);
    EXPECT_GT(BernsteinLumpedMass(k, volume, 1.0), 0);
    EXPECT_GT(Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(m).eigenvalues().minCoeff(), 0);
  }
  // A Bernstein basis sums to one and the gradients to zero anywhere.
  const Eigen::Vector4d L(0.1, 0.2, 0.3, 0.4);
  const Eigen::Matrix<double, 4, 3> g =
      (Eigen::Matrix<double, 4, 3>() << -1, -1, -1, 1, 0, 0, 0, 1, 0, 0, 0, 1).finished();
  for (int k = 1; k <= 3; ++k) {
    double sum = 0;
    for (const auto& alpha : BernsteinIndices(k)) sum += BernsteinValue(alpha, L);
    EXPECT_NEAR(sum, 1.0, 1e-15);
    EXPECT_LT(BernsteinGradients(k, g, L).colwise().sum().norm(), 1e-14);
  }
}

TEST(HighOrderMesh, RaisedMeshSharesEdgeAndFacePoints) {
  const TetMesh tets = SmallBox({2, 2, 1}, {20, 20, 10});
  std::set<std::pair<int, int>> edges;
  std::set<std::array<int, 3>> faces;
  for (int t = 0; t < tets.num_tetrahedra(); ++t)
    for (int i = 0; i < 4; ++i) {
      for (int j = i + 1; j < 4; ++j)
        edges.insert(std::minmax(tets.tetrahedra(t, i), tets.tetrahedra(t, j)));
      std::array<int, 3> f;
      int n = 0;
      for (int j = 0; j < 4; ++j)
        if (j != i) f[n++] = tets.tetrahedra(t, j);
      std::sort(f.begin(), f.end());
      faces.insert(f);
    }
  const int V = tets.num_vertices(), E = static_cast<int>(edges.size());
  const int F = static_cast<int>(faces.size()), T = tets.num_tetrahedra();
  EXPECT_EQ(RaiseTetMesh(tets, 1).num_nodes(), V);
  EXPECT_EQ(RaiseTetMesh(tets, 2).num_nodes(), V + E);
  const HighOrderTetMesh cubic = RaiseTetMesh(tets, 3);
  EXPECT_EQ(cubic.num_nodes(), V + 2 * E + F);  // no interior point at degree 3
  // Every control point sits at its element's Bezier point.
  const auto indices = BernsteinIndices(3);
  for (int t = 0; t < T; ++t)
    for (size_t a = 0; a < indices.size(); ++a) {
      Eigen::RowVector3d p = Eigen::RowVector3d::Zero();
      for (int i = 0; i < 4; ++i)
        p += indices[a][i] / 3.0 * tets.vertices.row(tets.tetrahedra(t, i));
      EXPECT_LT((cubic.nodes.row(cubic.elements(t, a)) - p).norm(), 1e-12);
    }
  EXPECT_THROW(RaiseTetMesh(tets, 4), Error);
}

TEST(BernsteinTet, MassMatrixIntegratesVolumeAndSecondMoment) {
  const Eigen::Vector3d size(30, 20, 20);
  const TetMesh tets = SmallBox({3, 2, 2}, size);
  Material material;
  const double rho = material.DensityKgPerMm3();
  const double volume = size.prod();
  for (int k = 1; k <= 3; ++k) {
    auto m = MakeModel(tets, k, material);
    // Consistent mass: 1^T M 1 = rho V and X^T M X = rho int x^2 dV (x linear, exact).
    double total = 0, second = 0;
    for (int e = 0; e < m->term->num_elements(); ++e) {
      const Eigen::MatrixXd me = BernsteinMassMatrix(k, m->term->element_volume(e), rho);
      Eigen::VectorXd x(me.rows());
      for (int a = 0; a < me.rows(); ++a) x[a] = m->mesh.nodes(m->mesh.elements(e, a), 0);
      total += me.sum();
      second += x.dot(me * x);
    }
    EXPECT_NEAR(total / (rho * volume), 1.0, 1e-12) << "degree " << k;
    const double exact_second = rho * size.y() * size.z() * std::pow(size.x(), 3) / 3.0;
    EXPECT_NEAR(second / exact_second, 1.0, 1e-12) << "degree " << k;
    // Lumped: the same total, all positive.
    const auto inertia = CollectNodeInertia(m->state, {m->term.get()});
    double lumped = 0;
    for (const NodeInertia& i : inertia) {
      EXPECT_GT(i.mass_kg, 0);
      lumped += i.mass_kg;
    }
    EXPECT_NEAR(lumped / (rho * volume), 1.0, 1e-12) << "degree " << k;
  }
}

TEST(BernsteinTet, DegreeOneIsTheP1Element) {
  const TetMesh tets = SmallBox();
  Material material;
  material.poisson_ratio = 0.4;
  auto m = MakeModel(tets, 1, material);
  for (int e = 0; e < tets.num_tetrahedra(); ++e) {
    TetRestData rest;
    const auto v = [&](int i) { return tets.vertices.row(tets.tetrahedra(e, i)).transpose(); };
    ASSERT_TRUE(ComputeTetRestData(v(0), v(1), v(2), v(3), material, &rest));
    const Eigen::MatrixXd p1 = RestStiffnessMatrix(rest);
    EXPECT_LT((m->term->element_stiffness(e) - p1).norm(), 1e-12 * p1.norm()) << e;
  }
  // Energy and gradient on a deformed state equal CorotationalElasticity (linear volume term).
  MechanicalState body(tets, material);
  GeneralisedState state;
  const std::vector<int> vertex_node = AddTetVertexNodes(body, &state);
  CorotationalOptions options;
  options.volume_term = VolumeTerm::kLinear;
  TetElasticityTerm p1(&body, vertex_node, options);
  const RowMatX3d x = Perturbed(tets.vertices * RotationAbout({1, 2, 3}, 50).transpose(), 2.0, 7);
  state.mutable_positions() = x;
  m->state.mutable_positions() = x;
  p1.Update(state);
  Eigen::VectorXd g1 = Eigen::VectorXd::Zero(state.num_dofs());
  p1.AddGradient(state, &g1);
  const Eigen::VectorXd g = Gradient(m.get());
  EXPECT_NEAR(m->term->Value(m->state), p1.Value(state), 1e-12 * p1.Value(state));
  EXPECT_LT((g - g1).norm(), 1e-10 * g1.norm());
  DenseHessianSink h(m->state), h1(state);
  m->term->AddHessian(m->state, 1.0, &h);
  p1.AddHessian(state, 1.0, &h1);
  EXPECT_LT((h.matrix() - h1.matrix()).norm(), 1e-12 * h1.matrix().norm());
}

// The quadratic field u = (0, x^2, 0) is exact at degree 2 and 3 (control values from
// the polar form of x^2); its strain energy 1/2 u^T K u is mu int 2 x^2 dV in closed form.
TEST(BernsteinTet, StiffnessIntegratesAQuadraticField) {
  const Eigen::Vector3d size(30, 20, 20);
  const TetMesh tets = SmallBox({3, 2, 2}, size);
  Material material;
  material.poisson_ratio = 0.3;
  const double mu = material.LameMuKpa();
  const double exact = 2.0 * mu * size.y() * size.z() * std::pow(size.x(), 3) / 3.0;
  for (int k = 2; k <= 3; ++k) {
    auto m = MakeModel(tets, k, material);
    const auto indices = BernsteinIndices(k);
    double energy = 0;
    for (int e = 0; e < m->term->num_elements(); ++e) {
      Eigen::VectorXd u = Eigen::VectorXd::Zero(3 * indices.size());
      for (size_t a = 0; a < indices.size(); ++a) {
        std::vector<double> args;  // x of the vertices spanning the control point
        for (int i = 0; i < 4; ++i)
          args.insert(args.end(), indices[a][i], tets.vertices(tets.tetrahedra(e, i), 0));
        double polar = 0;  // polar form of x^2: mean of the pairwise products
        for (int i = 0; i < k; ++i)
          for (int j = i + 1; j < k; ++j) polar += args[i] * args[j];
        u[3 * a + 1] = polar / (k * (k - 1) / 2);
      }
      energy += 0.5 * u.dot(m->term->element_stiffness(e) * u);
    }
    EXPECT_NEAR(energy / exact, 1.0, 1e-12) << "degree " << k;
  }
}

// Mixed u-p (discontinuous pressure condensed per element): at degree 1, and with a
// pressure of degree k - 1, the projection of div u is div u and K is the displacement
// element's; with a lower pressure degree it is softer (positive semi-definite) and a
// constant-strain patch stays exact.
TEST(BernsteinTet, MixedStiffnessCondensesTheElementPressure) {
  Material material;
  material.poisson_ratio = 0.499;
  const double lambda = material.LameLambdaKpa(), mu = material.LameMuKpa();
  Eigen::Matrix<double, 4, 3> x;
  x << 0, 0, 0, 10, 1, 0, 2, 9, 1, 1, 2, 8;
  TetRestData rest;
  ASSERT_TRUE(ComputeTetRestData(x.row(0), x.row(1), x.row(2), x.row(3), material, &rest));
  for (int k = 1; k <= 3; ++k) {
    const Eigen::MatrixXd K =
        BernsteinStiffnessMatrix(k, rest.shape_gradients, rest.volume_mm3, lambda, mu);
    const Eigen::MatrixXd top =
        BernsteinMixedStiffnessMatrix(k, k - 1, rest.shape_gradients, rest.volume_mm3, lambda, mu);
    EXPECT_LT((top - K).norm(), 1e-10 * K.norm()) << k;
    if (k == 1) continue;
    // Zero-energy modes of one element: the 6 rigid ones, and with a constant pressure
    // 3 more: the deviator vanishes on the dilation and the 3 special conformal fields
    // 2 (b.x) x - |x|^2 b (quadratic), of which one pressure constrains one combination.
    // They do not match across elements (the assembled meshes below are definite).
    for (int m = 0; m < k - 1; ++m) {
      const Eigen::MatrixXd Km =
          BernsteinMixedStiffnessMatrix(k, m, rest.shape_gradients, rest.volume_mm3, lambda, mu);
      Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(Km);
      const double top = eig.eigenvalues().maxCoeff();
      int zero = 0;
      for (int i = 0; i < Km.rows(); ++i) {
        EXPECT_GT(eig.eigenvalues()[i], -1e-9 * top);
        zero += eig.eigenvalues()[i] < 1e-9 * top;
      }
      EXPECT_EQ(zero, m == 0 ? 9 : 6) << "P" << k << "/P" << m;
      EXPECT_LT((Km - K).trace(), -1e-3 * K.trace());  // the volumetric constraint relaxed
    }
  }
  // Patch test of P2/P0 and P3/P1 through the solver: a constant strain stays exact.
  const Eigen::Vector3d size(20, 20, 20);
  const TetMesh tets = SmallBox({2, 2, 2}, size);
  Eigen::Matrix3d A;
  A << 1.05, 0.02, 0, 0.01, 0.97, 0.03, 0, 0.02, 1.04;
  for (const auto& [k, m] : {std::pair{2, 0}, std::pair{3, 1}}) {
    auto model = std::make_unique<Model>();
    model->mesh = RaiseTetMesh(tets, k);
    model->node = AddHighOrderNodes(model->mesh, &model->state);
    BernsteinTetOptions options;
    options.pressure_degree = m;  // default material: the patch needs no incompressibility
    model->term = std::make_unique<BernsteinTetTerm>(&model->mesh, model->node, options);
    const RowMatX3d affine = model->state.rest_positions() * A.transpose();
    for (int i = 0; i < model->state.num_nodes(); ++i) {
      const Eigen::Vector3d X = model->state.rest_positions().row(i).transpose();
      model->state.SetFixedTranslation(
          i, (X.array().abs() < 1e-9).any() || ((X - size).array().abs() < 1e-9).any());
    }
    model->state.mutable_positions() = Perturbed(affine, 0.5, 2);
    for (int i = 0; i < model->state.num_nodes(); ++i)
      if (model->state.fixed_translation(i))
        model->state.mutable_positions().row(i) = affine.row(i);
    GeneralisedStaticSolver solver({});
    EXPECT_EQ(solver.Solve(&model->state, {model->term.get()}).status, StepStatus::kConverged);
    EXPECT_LT((model->state.positions() - affine).cwiseAbs().maxCoeff(), 1e-8) << k << "/" << m;
  }
  const HighOrderTetMesh quadratic = RaiseTetMesh(tets, 2);
  BernsteinTetOptions bad;
  bad.pressure_degree = 2;  // not below the degree
  EXPECT_THROW(BernsteinTetTerm(&quadratic, std::vector<int>(quadratic.num_nodes(), 0), bad),
               Error);
}

TEST(BernsteinTet, RigidMotionsAreForceFree) {
  const TetMesh tets = SmallBox({2, 1, 1}, {20, 10, 10});
  for (int k = 1; k <= 3; ++k) {
    auto m = MakeModel(tets, k);
    const double scale = m->term->element_stiffness(0).norm() * 20.0;
    for (double angle : {90.0, 170.0}) {
      const Eigen::Matrix3d Q = RotationAbout({0.3, -1, 0.5}, angle);
      m->state.mutable_positions() =
          (m->state.rest_positions() * Q.transpose()).rowwise() + Eigen::RowVector3d(5, -3, 8);
      const Eigen::VectorXd g = Gradient(m.get());
      EXPECT_LT(g.lpNorm<Eigen::Infinity>(), 1e-12 * scale) << "degree " << k << " " << angle;
      EXPECT_LT(std::abs(m->term->Value(m->state)), 1e-12 * scale * 100) << k;
      for (int e = 0; e < m->term->num_elements(); ++e)
        EXPECT_LT((m->term->rotation(e) - Q).norm(), 1e-10);
    }
  }
}

// Central differences of the energy (rotations recomputed at every point) against
// the gradient, which includes dR/dx of the averaged deformation gradient's polar
// rotation; and, at a rigidly rotated state (zero stress), the Hessian against
// differences of the gradient (there the neglected dR/dx term vanishes).
TEST(BernsteinTet, FiniteDifferenceGradientAndHessian) {
  const TetMesh tets = SmallBox({1, 1, 1}, {10, 10, 10});
  for (int k = 1; k <= 3; ++k) {
    auto m = MakeModel(tets, k);
    const RowMatX3d x =
        Perturbed(m->state.rest_positions() * RotationAbout({1, 1, 0}, 70).transpose(), 1.5, 3);
    m->state.mutable_positions() = x;
    const Eigen::VectorXd g = Gradient(m.get());
    const double h = 1e-6;
    Eigen::VectorXd fd(g.size());
    for (int i = 0; i < g.size(); ++i) {
      m->state.mutable_positions() = x;
      m->state.mutable_positions()(i / 3, i % 3) += h;
      m->term->Update(m->state);
      const double ep = m->term->Value(m->state);
      m->state.mutable_positions()(i / 3, i % 3) -= 2 * h;
      m->term->Update(m->state);
      fd[i] = (ep - m->term->Value(m->state)) / (2 * h);
    }
    EXPECT_LT((g - fd).norm(), 1e-6 * g.norm()) << "degree " << k;
    // Without the dR/dx term the gradient would be off by more than that at degree >= 2.
    const RowMatX3d rigid = m->state.rest_positions() * RotationAbout({0, 1, 2}, 120).transpose();
    m->state.mutable_positions() = rigid;
    m->term->Update(m->state);
    DenseHessianSink sink(m->state);
    m->term->AddHessian(m->state, 1.0, &sink);
    Eigen::MatrixXd fd_h(g.size(), g.size());
    for (int i = 0; i < g.size(); ++i) {
      m->state.mutable_positions() = rigid;
      m->state.mutable_positions()(i / 3, i % 3) += h;
      const Eigen::VectorXd gp = Gradient(m.get());
      m->state.mutable_positions()(i / 3, i % 3) -= 2 * h;
      fd_h.col(i) = (gp - Gradient(m.get())) / (2 * h);
    }
    EXPECT_LT((sink.matrix() - fd_h).norm(), 1e-6 * sink.matrix().norm()) << "degree " << k;
  }
}

TEST(BernsteinTet, DerivativeOfTheRotationMattersAboveDegreeOne) {
  // The torque term is what makes the gradient exact: a bent quadratic element has a
  // non-zero one (the check above would fail without it).
  auto m = MakeModel(SmallBox({1, 1, 1}, {10, 10, 10}), 2);
  RowMatX3d x = m->state.rest_positions();
  for (int i = 0; i < x.rows(); ++i) x(i, 1) += 0.02 * x(i, 0) * x(i, 0);  // bending
  m->state.mutable_positions() = x * RotationAbout({0, 0, 1}, 30).transpose();
  const Eigen::VectorXd g = Gradient(m.get());
  Eigen::VectorXd warped = Eigen::VectorXd::Zero(g.size());  // R K u only
  for (int e = 0; e < m->term->num_elements(); ++e) {
    const Eigen::Matrix3d R = m->term->rotation(e);
    const int n = BernsteinCount(2);
    Eigen::VectorXd u(3 * n);
    for (int a = 0; a < n; ++a) {
      const int node = m->mesh.elements(e, a);
      u.segment<3>(3 * a) =
          R.transpose() * m->state.position(node) - m->mesh.nodes.row(node).transpose();
    }
    const Eigen::VectorXd f = m->term->element_stiffness(e) * u;
    for (int a = 0; a < n; ++a)
      warped.segment<3>(3 * m->mesh.elements(e, a)) += R * f.segment<3>(3 * a);
  }
  EXPECT_GT((g - warped).norm(), 1e-4 * g.norm());
}

// Patch test: boundary control points on an affine map x = A X + b (stretch, shear
// and a 40 degree rotation), interior ones released from a perturbed start; the
// static solve reproduces the affine field, and the deformation gradient is A
// everywhere. At the exact field the interior residual is zero.
TEST(BernsteinTet, PatchTestReproducesLinearFields) {
  const Eigen::Vector3d size(20, 20, 20);
  const TetMesh tets = SmallBox({2, 2, 2}, size);
  Eigen::Matrix3d A;
  A << 1.08, 0.05, -0.02, 0.03, 0.95, 0.04, -0.01, 0.06, 1.1;
  A = RotationAbout({1, -2, 1}, 40) * A;
  const Eigen::RowVector3d b(1, -2, 3);
  for (int k = 1; k <= 3; ++k) {
    auto m = MakeModel(tets, k);
    const RowMatX3d affine = (m->state.rest_positions() * A.transpose()).rowwise() + b;
    std::vector<int> interior;
    for (int i = 0; i < m->state.num_nodes(); ++i) {
      const Eigen::Vector3d X = m->state.rest_positions().row(i).transpose();
      const bool boundary =
          (X.array().abs() < 1e-9).any() || ((X - size).array().abs() < 1e-9).any();
      m->state.SetFixedTranslation(i, boundary);
      if (!boundary) interior.push_back(i);
    }
    ASSERT_FALSE(interior.empty());
    m->state.mutable_positions() = affine;
    const Eigen::VectorXd g0 = Gradient(m.get());
    double interior_residual = 0;
    for (int i : interior)
      interior_residual = std::max(interior_residual, g0.segment<3>(3 * i).norm());
    EXPECT_LT(interior_residual, 1e-10 * g0.norm()) << "degree " << k;
    m->state.mutable_positions() = Perturbed(affine, 1.0, 11);
    for (int i = 0; i < m->state.num_nodes(); ++i)
      if (m->state.fixed_translation(i)) m->state.mutable_positions().row(i) = affine.row(i);
    GeneralisedStaticSolver solver({});
    const GeneralisedSummary summary = solver.Solve(&m->state, {m->term.get()});
    EXPECT_EQ(summary.status, StepStatus::kConverged) << summary.message;
    EXPECT_LT((m->state.positions() - affine).cwiseAbs().maxCoeff(), 1e-8) << "degree " << k;
    for (int e = 0; e < m->term->num_elements(); e += 7)
      EXPECT_LT((m->term->DeformationGradientAt(m->state, e, {0.1, 0.2, 0.3, 0.4}) - A).norm(),
                1e-9);
  }
}

// A free body with random velocities: implicit Euler keeps the linear momentum and
// loses kinetic energy to numerical damping only (no energy gain).
TEST(BernsteinTet, ImplicitEulerOnAFreeBodyKeepsMomentum) {
  auto m = MakeModel(SmallBox({2, 1, 1}, {20, 10, 10}), 2);
  m->state.mutable_velocities() = Perturbed(RowMatX3d::Zero(m->state.num_nodes(), 3), 20.0, 5);
  const auto inertia = CollectNodeInertia(m->state, {m->term.get()});
  const Eigen::Vector3d p0 = GeneralisedLinearMomentum(m->state, inertia);
  const double kinetic0 = GeneralisedKineticEnergy(m->state, inertia);
  GeneralisedImplicitEulerOptions options;
  options.dt_s = 1e-3;
  options.newton_mode = NewtonMode::kFullNewton;
  GeneralisedImplicitEuler euler(options);
  double total0 = kinetic0;
  for (int step = 0; step < 20; ++step) {
    const GeneralisedSummary s = euler.Step(&m->state, {m->term.get()}, {}, inertia);
    ASSERT_NE(s.status, StepStatus::kLinearSolveFailed) << s.message;
    m->term->Update(m->state);
    const double total = GeneralisedKineticEnergy(m->state, inertia) + m->term->Value(m->state);
    EXPECT_LE(total, total0 * (1 + 1e-9));
    total0 = total;
  }
  EXPECT_LT((GeneralisedLinearMomentum(m->state, inertia) - p0).norm(), 1e-9 * p0.norm() + 1e-12);
}

}  // namespace
}  // namespace arreg::mechanics
