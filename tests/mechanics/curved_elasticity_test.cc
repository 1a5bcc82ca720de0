// Isoparametric (curved) Bernstein tetrahedra in BernsteinTetTerm: the raised ball's
// volume, mass and patch test, rigid motions, derivatives against differences.
#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include <cmath>
#include <map>
#include <memory>
#include <random>

#include "core/error.h"
#include "core/mesh_ops.h"
#include "curved_test_util.h"
#include "generalised_fd.h"
#include "mechanics/bernstein_tet.h"
#include "mechanics/curved_boundary.h"
#include "mechanics/generalised_solver.h"
#include "mechanics/generalised_terms.h"

namespace arreg::mechanics {
namespace {

using testing::kRadius;
using testing::RaisedBall;

struct Model {
  HighOrderTetMesh mesh;
  GeneralisedState state;
  std::vector<int> node;
  std::unique_ptr<BernsteinTetTerm> term;
};

std::unique_ptr<Model> CurvedBall(int level, int degree) {
  auto m = std::make_unique<Model>();
  m->mesh = RaisedBall(level, degree);
  m->node = AddHighOrderNodes(m->mesh, &m->state);
  m->term = std::make_unique<BernsteinTetTerm>(&m->mesh, m->node);
  return m;
}

TEST(CurvedBernsteinTet, VolumeAndMassAreThoseOfTheCurvedBall) {
  for (int k = 2; k <= 3; ++k) {
    auto m = CurvedBall(1, k);
    double volume = 0;
    for (int e = 0; e < m->term->num_elements(); ++e) volume += m->term->element_volume(e);
    // det J is a polynomial integrated exactly: the sum is the volume the Bezier surface
    // encloses (divergence theorem), here from its tessellation extrapolated in n.
    const CurvedBoundary b16 = TessellateBoundary(m->mesh, m->mesh.nodes, 16);
    const CurvedBoundary b32 = TessellateBoundary(m->mesh, m->mesh.nodes, 32);
    const double enclosed = (4 * EnclosedVolume(b32.surface) - EnclosedVolume(b16.surface)) / 3;
    EXPECT_NEAR(volume, enclosed, 1e-6 * enclosed) << k;
    const double sphere = 4.0 / 3.0 * M_PI * std::pow(kRadius, 3);
    EXPECT_NEAR(volume, sphere, 3e-3 * sphere) << k;
    // The straight corner tetrahedra hold 13 % less: the elements are curved.
    EXPECT_GT(volume, 1.1 * TetVolumes(testing::LinearBall(1)).sum()) << k;
    std::vector<NodeInertia> inertia(m->state.num_nodes());
    m->term->AddNodeInertia(m->state, &inertia);
    double mass = 0;
    for (const NodeInertia& i : inertia) mass += i.mass_kg;
    EXPECT_NEAR(mass, Material{}.DensityKgPerMm3() * volume, 1e-12 * mass);
  }
}

TEST(CurvedBernsteinTet, PatchTestAndRigidMotionsOnCurvedElements) {
  Eigen::Matrix3d A;
  A << 1.08, 0.05, -0.02, 0.03, 0.95, 0.04, -0.01, 0.06, 1.1;
  A = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, -2, 1).normalized()).toRotationMatrix() * A;
  const Eigen::RowVector3d b(1, -2, 3);
  for (int k = 2; k <= 3; ++k) {
    auto m = CurvedBall(1, k);
    std::vector<char> boundary(m->mesh.num_nodes(), 0);
    const auto indices = BernsteinIndices(k);
    for (const HighOrderBoundaryFace& f : HighOrderBoundaryFaces(m->mesh))
      for (size_t a = 0; a < indices.size(); ++a)
        if (indices[a][f.opposite] == 0) boundary[m->mesh.elements(f.element, a)] = 1;
    // Rigid motion: force-free.
    const Eigen::Matrix3d rotation =
        Eigen::AngleAxisd(2.0, Eigen::Vector3d(0, 1, 2).normalized()).toRotationMatrix();
    m->state.mutable_positions() = (m->state.rest_positions() * rotation.transpose()).rowwise() + b;
    m->term->Update(m->state);
    EXPECT_LT(testing::Gradient(*m->term, m->state).cwiseAbs().maxCoeff(), 1e-10) << k;
    // Constant strain: boundary control points on the affine map, interior solved.
    const RowMatX3d affine = (m->state.rest_positions() * A.transpose()).rowwise() + b;
    m->state.mutable_positions() = m->state.rest_positions();
    for (int i = 0; i < m->mesh.num_nodes(); ++i)
      if (boundary[i]) {
        m->state.SetFixedTranslation(m->node[i], true);
        m->state.mutable_positions().row(m->node[i]) = affine.row(m->node[i]);
      }
    GeneralisedStaticSolver solver({});
    const GeneralisedSummary summary = solver.Solve(&m->state, {m->term.get()});
    EXPECT_EQ(summary.status, StepStatus::kConverged) << summary.message;
    EXPECT_LT((m->state.positions() - affine).cwiseAbs().maxCoeff(), 1e-8) << k;
    for (int e = 0; e < m->term->num_elements(); e += 13)
      EXPECT_LT((m->term->DeformationGradientAt(m->state, e, {0.1, 0.2, 0.3, 0.4}) - A).norm(),
                1e-9);
  }
}

TEST(CurvedBernsteinTet, GradientMatchesDifferencesOfTheEnergy) {
  for (int k = 2; k <= 3; ++k) {
    auto m = CurvedBall(0, k);
    std::mt19937 rng(4);
    std::uniform_real_distribution<double> u(-0.5, 0.5);
    Eigen::VectorXd increment(m->state.num_dofs());
    for (int i = 0; i < increment.size(); ++i) increment[i] = u(rng);
    m->state.ApplyIncrement(increment);
    m->term->Update(m->state);
    const Eigen::VectorXd g = testing::Gradient(*m->term, m->state);
    const Eigen::VectorXd fd = testing::EnergyGradientByDifferences(m->term.get(), m->state, 1e-6);
    EXPECT_LT((g - fd).norm(), 1e-6 * g.norm()) << k;
  }
}

TEST(CurvedBernsteinTet, MixedFormulationRejectsCurvedElements) {
  const HighOrderTetMesh mesh = RaisedBall(0, 2);
  GeneralisedState state;
  const std::vector<int> node = AddHighOrderNodes(mesh, &state);
  BernsteinTetOptions options;
  options.pressure_degree = 0;
  EXPECT_THROW(BernsteinTetTerm(&mesh, node, options), Error);
}

}  // namespace
}  // namespace arreg::mechanics
