// Energy terms: finite-difference checks of gradients and Hessians, rigid
// invariance of the corotational forces, symmetry of the assembled matrix.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <cmath>

#include "core/error.h"
#include "mechanics/elastic_energy.h"
#include "mechanics/spring_energy.h"
#include "mechanics_test_util.h"

namespace arreg::mechanics {
namespace {

using testing::Perturbed;
using testing::SmallBox;

// Central-difference gradient of term.Value at x (rotations as currently set:
// the caller decides whether they are frozen).
RowMatX3d NumericGradient(const EnergyTerm& term, const MechanicalState& state, const RowMatX3d& x,
                          double step) {
  RowMatX3d g(x.rows(), 3);
  RowMatX3d xp = x;
  for (int i = 0; i < x.rows(); ++i)
    for (int c = 0; c < 3; ++c) {
      xp(i, c) = x(i, c) + step;
      const double ep = term.Value(state, xp);
      xp(i, c) = x(i, c) - step;
      const double em = term.Value(state, xp);
      xp(i, c) = x(i, c);
      g(i, c) = (ep - em) / (2 * step);
    }
  return g;
}

RowMatX3d Gradient(const EnergyTerm& term, const MechanicalState& state, const RowMatX3d& x) {
  RowMatX3d g = RowMatX3d::Zero(x.rows(), 3);
  term.AddGradient(state, x, &g);
  return g;
}

double RelativeError(const RowMatX3d& a, const RowMatX3d& b) {
  return (a - b).norm() / std::max(b.norm(), 1e-300);
}

class ElasticTest : public ::testing::TestWithParam<RotationMethod> {
 protected:
  CorotationalElasticity MakeElastic(VolumeTerm volume = VolumeTerm::kJacobian) const {
    CorotationalOptions o;
    o.rotation_method = GetParam();
    o.volume_term = volume;
    o.polar_max_iterations = 100;
    return CorotationalElasticity(o);
  }
};

TEST_P(ElasticTest, RigidMotionsGiveZeroForce) {
  const MechanicalState state(SmallBox(), Material{5000, 0.4, 1000});
  CorotationalElasticity elastic = MakeElastic();
  // Reference force scale: 1 % stretch along x.
  RowMatX3d stretched = state.rest_positions();
  stretched.col(0) *= 1.01;
  elastic.Update(state, stretched);
  const double reference = Gradient(elastic, state, stretched).norm();
  ASSERT_GT(reference, 0.0);
  for (const double degrees : {90.0, 45.0, 170.0}) {
    const Eigen::Matrix3d R =
        Eigen::AngleAxisd(degrees * M_PI / 180.0, Eigen::Vector3d(1, 2, 3).normalized())
            .toRotationMatrix();
    const RowMatX3d x =
        (state.rest_positions() * R.transpose()).rowwise() + Eigen::RowVector3d(5, -3, 2);
    CorotationalElasticity fresh = MakeElastic();  // rotations start at identity
    fresh.Update(state, x);
    EXPECT_LT(Gradient(fresh, state, x).norm(), 1e-9 * reference) << degrees << " deg";
    EXPECT_LT(std::abs(fresh.Value(state, x)), 1e-12 * elastic.Value(state, stretched));
  }
}

TEST_P(ElasticTest, ForceMatchesFiniteDifferencesOfFrozenRotationEnergy) {
  const MechanicalState state(SmallBox(), Material{5000, 0.3, 1000});
  CorotationalElasticity elastic = MakeElastic();
  const Eigen::Matrix3d R =
      Eigen::AngleAxisd(0.7, Eigen::Vector3d(0, 1, 1).normalized()).toRotationMatrix();
  const RowMatX3d x = Perturbed(state.rest_positions() * R.transpose(), 1.5, 3);
  elastic.Update(state, x);  // rotations now frozen
  const RowMatX3d analytic = Gradient(elastic, state, x);
  EXPECT_LT(RelativeError(analytic, NumericGradient(elastic, state, x, 1e-4)), 1e-7);
}

TEST_P(ElasticTest, HessianMatchesFiniteDifferencesOfGradientAndIsSymmetric) {
  // The linear volume term, whose frozen-rotation Hessian is exact (the Jacobian term's is
  // Gauss-Newton: volume_term_test.cc).
  const MechanicalState state(SmallBox({2, 2, 1}), Material{5000, 0.3, 1000});
  CorotationalElasticity elastic = MakeElastic(VolumeTerm::kLinear);
  const RowMatX3d x = Perturbed(state.rest_positions(), 1.0, 5);
  elastic.Update(state, x);
  SystemMatrix H(state.num_vertices(), state.tetrahedra());
  elastic.AddHessian(state, x, 1.0, &H);
  const Eigen::MatrixXd dense = Eigen::MatrixXd(H.matrix());
  EXPECT_LT((dense - dense.transpose()).norm(), 1e-12 * dense.norm());
  const double step = 1e-5;
  Eigen::MatrixXd numeric(dense.rows(), dense.cols());
  for (int i = 0; i < state.num_vertices(); ++i)
    for (int c = 0; c < 3; ++c) {
      RowMatX3d xp = x, xm = x;
      xp(i, c) += step;
      xm(i, c) -= step;
      const RowMatX3d d =
          (Gradient(elastic, state, xp) - Gradient(elastic, state, xm)) / (2 * step);
      numeric.col(3 * i + c) = Eigen::Map<const Eigen::VectorXd>(d.data(), d.size());
    }
  EXPECT_LT((dense - numeric).norm(), 1e-7 * dense.norm());
  // Positive semi-definite with (at least) the six rigid modes in the null space.
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(dense);
  EXPECT_GT(eig.eigenvalues()[0], -1e-10 * eig.eigenvalues().maxCoeff());
}

INSTANTIATE_TEST_SUITE_P(AllMethods, ElasticTest,
                         ::testing::Values(RotationMethod::kPolar, RotationMethod::kPolarSvd,
                                           RotationMethod::kQr));

TEST(Elastic, PolarForceIsTheExactGradientWithRotationsRecomputed) {
  // With the polar rotation the dR/dx terms cancel: the corotational force is
  // the gradient of E(x) = sum V psi(R(x)^T F(x)), not only of the frozen one.
  const MechanicalState state(SmallBox(), Material{5000, 0.3, 1000});
  CorotationalOptions o;
  o.rotation_method = RotationMethod::kPolarSvd;
  CorotationalElasticity elastic(o);
  const RowMatX3d x = Perturbed(state.rest_positions(), 2.0, 9);
  elastic.Update(state, x);
  const RowMatX3d analytic = Gradient(elastic, state, x);
  RowMatX3d numeric(x.rows(), 3);
  const double step = 1e-5;
  for (int i = 0; i < x.rows(); ++i)
    for (int c = 0; c < 3; ++c) {
      RowMatX3d xp = x, xm = x;
      xp(i, c) += step;
      xm(i, c) -= step;
      elastic.Update(state, xp);
      const double ep = elastic.Value(state, xp);
      elastic.Update(state, xm);
      const double em = elastic.Value(state, xm);
      numeric(i, c) = (ep - em) / (2 * step);
    }
  EXPECT_LT(RelativeError(analytic, numeric), 1e-6);
}

// Update skips the rotations when called again at the same positions of the same state (the
// integrator's line search ends where the next step starts), and recomputes them otherwise.
TEST(Elastic, UpdateAtTheSamePositionsKeepsTheRotations) {
  MechanicalState state(SmallBox(), Material{5000, 0.3, 1000});
  CorotationalElasticity elastic;
  const RowMatX3d x = Perturbed(state.rest_positions(), 2.0, 3);
  const RowMatX3d y = Perturbed(state.rest_positions(), 2.0, 4);
  elastic.Update(state, x);
  const std::vector<Eigen::Matrix3d> at_x = elastic.rotations();
  elastic.Update(state, x);
  EXPECT_EQ(elastic.rotations(), at_x);
  elastic.Update(state, y);
  double change = 0.0;
  for (size_t t = 0; t < at_x.size(); ++t)
    change = std::max(change, (elastic.rotations()[t] - at_x[t]).norm());
  EXPECT_GT(change, 1e-3);
  // Back at x: the same rotations as computed there (to the polar tolerance).
  elastic.Update(state, x);
  for (size_t t = 0; t < at_x.size(); ++t)
    EXPECT_LT((elastic.rotations()[t] - at_x[t]).norm(), 1e-10) << "element " << t;
  // Another state with the same positions but other rest positions: recomputed.
  MechanicalState stretched(SmallBox({3, 2, 2}, {60, 20, 20}), Material{5000, 0.3, 1000});
  ASSERT_EQ(stretched.num_vertices(), state.num_vertices());
  elastic.Update(stretched, x);
  double other = 0.0;
  for (size_t t = 0; t < at_x.size(); ++t)
    other = std::max(other, (elastic.rotations()[t] - at_x[t]).norm());
  EXPECT_GT(other, 1e-3);
}

TEST(Springs, GradientAndHessianMatchFiniteDifferences) {
  const MechanicalState state(SmallBox({2, 1, 1}), Material{});
  SpringEnergy springs;
  springs.Add({0, Eigen::Vector4d(0.1, 0.2, 0.3, 0.4)}, {1, 2, 3}, 50.0);
  springs.Add({3, Eigen::Vector4d(0.7, 0.1, 0.1, 0.1)}, {-4, 2, 30}, 20.0);
  const int removed = springs.Add({5, Eigen::Vector4d(0.25, 0.25, 0.25, 0.25)}, {0, 0, 0}, 1e3);
  springs.Remove(removed);
  EXPECT_EQ(springs.num_active(), 2);
  const RowMatX3d x = Perturbed(state.rest_positions(), 1.0, 1);
  const RowMatX3d analytic = Gradient(springs, state, x);
  EXPECT_LT(RelativeError(analytic, NumericGradient(springs, state, x, 1e-4)), 1e-8);
  SystemMatrix H(state.num_vertices(), state.tetrahedra());
  springs.AddHessian(state, x, 1.0, &H);
  // Quadratic energy: the Hessian maps a displacement to the gradient change.
  const RowMatX3d dx = Perturbed(RowMatX3d::Zero(x.rows(), 3), 1.0, 2);
  const RowMatX3d dg = Gradient(springs, state, x + dx) - analytic;
  const Eigen::VectorXd predicted =
      H.matrix() * Eigen::Map<const Eigen::VectorXd>(dx.data(), dx.size());
  EXPECT_LT((predicted - Eigen::Map<const Eigen::VectorXd>(dg.data(), dg.size())).norm(),
            1e-10 * dg.norm());
}

TEST(Gravity, GradientIsMinusWeightAndTotalForceIsMg) {
  const MechanicalState state(SmallBox(), Material{3000, 0.45, 1000});
  GravityEnergy gravity({0, -9806.65, 0});
  const RowMatX3d x = Perturbed(state.rest_positions(), 1.0, 4);
  const RowMatX3d g = Gradient(gravity, state, x);
  EXPECT_LT(RelativeError(g, NumericGradient(gravity, state, x, 1e-3)), 1e-8);
  // 30 x 20 x 20 mm of water: 12 g; total force = m g in mN.
  EXPECT_NEAR(state.TotalMassKg(), 0.012, 1e-12);
  EXPECT_NEAR(-g.col(1).sum(), -0.012 * 9806.65, 1e-9);
}

TEST(PointForces, EnergyIsMinusWork) {
  const MechanicalState state(SmallBox({1, 1, 1}), Material{});
  PointForceEnergy forces;
  forces.AddForce(2, {1, 2, 3});
  forces.AddForce(2, {1, 0, 0});
  const RowMatX3d x = Perturbed(state.rest_positions(), 1.0, 8);
  EXPECT_NEAR(forces.Value(state, x), -(2 * x(2, 0) + 2 * x(2, 1) + 3 * x(2, 2)), 1e-12);
  EXPECT_LT(RelativeError(Gradient(forces, state, x), NumericGradient(forces, state, x, 1e-3)),
            1e-9);
}

TEST(VertexTethers, GradientAndHessianMatchFiniteDifferences) {
  const MechanicalState state(SmallBox({2, 1, 1}), Material{});
  VertexTetherEnergy tethers;
  tethers.Add(0, {1, 2, 3}, 50.0);
  tethers.Add(4, state.rest_positions().row(4).transpose(), 20.0);
  const RowMatX3d x = Perturbed(state.rest_positions(), 1.0, 3);
  // At the rest positions only the first tether (target away from vertex 0) pulls.
  const RowMatX3d g0 = Gradient(tethers, state, state.rest_positions());
  EXPECT_EQ(g0.row(4).norm(), 0.0);
  EXPECT_NEAR(g0.row(0).norm(),
              50.0 * (state.rest_positions().row(0) - Eigen::RowVector3d(1, 2, 3)).norm(), 1e-9);
  const RowMatX3d analytic = Gradient(tethers, state, x);
  EXPECT_LT(RelativeError(analytic, NumericGradient(tethers, state, x, 1e-4)), 1e-8);
  SystemMatrix H(state.num_vertices(), state.tetrahedra());
  tethers.AddHessian(state, x, 1.0, &H);
  const RowMatX3d dx = Perturbed(RowMatX3d::Zero(x.rows(), 3), 1.0, 5);
  const RowMatX3d dg = Gradient(tethers, state, x + dx) - analytic;
  const Eigen::VectorXd predicted =
      H.matrix() * Eigen::Map<const Eigen::VectorXd>(dx.data(), dx.size());
  EXPECT_LT((predicted - Eigen::Map<const Eigen::VectorXd>(dg.data(), dg.size())).norm(),
            1e-10 * dg.norm());
}

TEST(VertexTethers, RejectsBadInput) {
  const MechanicalState state(SmallBox({1, 1, 1}), Material{});
  VertexTetherEnergy tethers;
  EXPECT_THROW(tethers.Add(-1, {0, 0, 0}, 1.0), Error);
  EXPECT_THROW(tethers.Add(0, {0, 0, 0}, -1.0), Error);
  EXPECT_THROW(tethers.Add(0, {0, std::nan(""), 0}, 1.0), Error);
  tethers.Add(0, {0, 0, 0}, 1.0);
  EXPECT_THROW(tethers.Add(0, {1, 0, 0}, 1.0), Error);
  tethers.Add(state.num_vertices(), {0, 0, 0}, 1.0);  // checked against the state when used
  EXPECT_THROW(tethers.Value(state, state.rest_positions()), Error);
}

}  // namespace
}  // namespace arreg::mechanics
