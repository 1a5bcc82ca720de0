// The volumetric term of the corotational energy (VolumeTerm): the uniaxial stretch of a bar
// against the closed-form lateral contraction of each term, the exact gradient of the
// Jacobian term, and its Gauss-Newton Hessian.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include "core/error.h"
#include "mechanics/elastic_energy.h"
#include "mechanics/integrator.h"
#include "mechanics_test_util.h"

namespace arreg::mechanics {
namespace {

using testing::Perturbed;
using testing::SmallBox;

// Lateral stretch l of a homogeneous uniaxial stretch F = diag(s, l, l) with free lateral
// faces: the root of d psi / d l = 0 for psi = mu |F - I|^2 + lambda/2 v^2, v = tr(F - I)
// (kLinear: l = 1 - nu (s - 1)) or v = det F - 1 (kJacobian), by bisection.
double LateralStretch(VolumeTerm term, const Material& m, double s) {
  const double mu = m.LameMuKpa(), lambda = m.LameLambdaKpa();
  auto dpsi = [&](double l) {
    if (term == VolumeTerm::kLinear) return 4 * mu * (l - 1) + 2 * lambda * (s - 1 + 2 * (l - 1));
    return 4 * mu * (l - 1) + 2 * lambda * (s * l * l - 1) * s * l;
  };
  double lo = 0.05, hi = 1.0;  // dpsi(lo) < 0 < dpsi(hi) for s > 1
  for (int i = 0; i < 200; ++i) {
    const double mid = 0.5 * (lo + hi);
    (dpsi(mid) < 0 ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

struct StretchedBar {
  double axial = 0.0;    // stretch of the middle half
  double lateral = 0.0;  // width and depth of the middle section over their rest values
};

// Bar 120 x 10 x 10 mm (24 x 2 x 2 cells), both end faces clamped, the end x = 120 pulled to
// `stretch` x 120 mm; static equilibrium; the middle section is far (> 4 widths) from the
// clamps, so it is in uniaxial stress.
StretchedBar StretchBar(VolumeTerm term, const Material& m, double stretch) {
  MechanicalState state(MakeBoxTetMesh({120, 10, 10}, {24, 2, 2}), m);
  std::vector<int> fixed;
  for (int v = 0; v < state.num_vertices(); ++v) {
    const double x = state.rest_position(v).x();
    if (x < 1e-9 || x > 120 - 1e-9) fixed.push_back(v);
  }
  state.SetFixed(fixed);
  // Start from the homogeneous stretch (lateral size unchanged) so Newton starts near.
  RowMatX3d& x = state.mutable_positions();
  x.col(0) *= stretch;
  CorotationalOptions co;
  co.volume_term = term;
  CorotationalElasticity elastic(co);
  StaticSolverOptions so;
  so.max_iterations = 300;
  StaticSolver solver(so);
  const StepSummary summary = solver.Solve(&state, &elastic, {});
  // The warped Hessian (no dR/dx) stalls at increments of a few 1e-4 mm under this tension;
  // 1e-3 mm is 1e-4 of the width, far below the tolerance of the comparison.
  EXPECT_LT(summary.last_increment_mm, 1e-3) << VolumeTermName(term);
  StretchedBar out;
  double x30 = 0, x90 = 0, lo_y = 1e9, hi_y = -1e9, lo_z = 1e9, hi_z = -1e9;
  int n30 = 0, n90 = 0;
  for (int v = 0; v < state.num_vertices(); ++v) {
    const Eigen::Vector3d r = state.rest_position(v), p = state.position(v);
    if (std::abs(r.x() - 30) < 1e-9) x30 += p.x(), ++n30;
    if (std::abs(r.x() - 90) < 1e-9) x90 += p.x(), ++n90;
    if (std::abs(r.x() - 60) < 1e-9) {
      lo_y = std::min(lo_y, p.y()), hi_y = std::max(hi_y, p.y());
      lo_z = std::min(lo_z, p.z()), hi_z = std::max(hi_z, p.z());
    }
  }
  out.axial = (x90 / n90 - x30 / n30) / 60.0;
  out.lateral = 0.5 * ((hi_y - lo_y) + (hi_z - lo_z)) / 10.0;
  return out;
}

TEST(VolumeTerm, UniaxialStretchContractsAsTheClosedForm) {
  // nu = 0.45 (the registration's tissue), stretched to 180 %: each term's bar contracts as its
  // own closed form says, and the two differ by far more than the tolerance - the linear term
  // thins the bar to a volume ratio near 0.66, the Jacobian term keeps it near 1.
  const Material m{100000.0, 0.45, 1000.0};
  for (VolumeTerm term : {VolumeTerm::kLinear, VolumeTerm::kJacobian}) {
    const StretchedBar bar = StretchBar(term, m, 1.8);
    const double expected = LateralStretch(term, m, bar.axial);
    std::printf("%s: axial %.4f lateral %.4f (closed form %.4f) volume ratio %.3f\n",
                VolumeTermName(term), bar.axial, bar.lateral, expected,
                bar.axial * bar.lateral * bar.lateral);
    EXPECT_GT(bar.axial, 1.7);
    EXPECT_NEAR(bar.lateral, expected, 0.02) << VolumeTermName(term);
  }
  const StretchedBar linear = StretchBar(VolumeTerm::kLinear, m, 1.8);
  const StretchedBar jacobian = StretchBar(VolumeTerm::kJacobian, m, 1.8);
  EXPECT_LT(linear.axial * linear.lateral * linear.lateral, 0.75);
  EXPECT_GT(jacobian.axial * jacobian.lateral * jacobian.lateral, 0.9);
}

TEST(VolumeTerm, SmallStrainIsTheLinearTerm) {
  // At 0.1 % stretch both terms give the same contraction (the closed forms agree to O(e^2)).
  const Material m{100000.0, 0.45, 1000.0};
  const StretchedBar linear = StretchBar(VolumeTerm::kLinear, m, 1.001);
  const StretchedBar jacobian = StretchBar(VolumeTerm::kJacobian, m, 1.001);
  EXPECT_NEAR(linear.lateral, jacobian.lateral, 1e-5);
  EXPECT_NEAR(1.0 - linear.lateral, 0.45 * (linear.axial - 1.0), 2e-5);
}

RowMatX3d Gradient(const EnergyTerm& term, const MechanicalState& state, const RowMatX3d& x) {
  RowMatX3d g = RowMatX3d::Zero(x.rows(), 3);
  term.AddGradient(state, x, &g);
  return g;
}

TEST(VolumeTerm, JacobianGradientIsTheExactGradientWithRotationsRecomputed) {
  // Large perturbation (J far from 1): central differences of the energy with the polar
  // rotations recomputed at every point equal the analytic gradient.
  const MechanicalState state(SmallBox(), Material{5000, 0.45, 1000});
  CorotationalOptions o;
  o.rotation_method = RotationMethod::kPolarSvd;
  o.volume_term = VolumeTerm::kJacobian;
  const Eigen::Matrix3d R =
      Eigen::AngleAxisd(0.9, Eigen::Vector3d(1, 0, 1).normalized()).toRotationMatrix();
  RowMatX3d x = state.rest_positions() * R.transpose();
  x.col(1) *= 1.6;  // a 60 % stretch, then noise
  x = Perturbed(x, 2.0, 11);
  CorotationalElasticity elastic(o);
  elastic.Update(state, x);
  const RowMatX3d analytic = Gradient(elastic, state, x);
  const double step = 1e-5;
  RowMatX3d numeric(x.rows(), 3);
  for (int i = 0; i < x.rows(); ++i)
    for (int c = 0; c < 3; ++c) {
      RowMatX3d xp = x, xm = x;
      xp(i, c) += step;
      xm(i, c) -= step;
      CorotationalElasticity ep(o), em(o);
      ep.Update(state, xp);
      em.Update(state, xm);
      numeric(i, c) = (ep.Value(state, xp) - em.Value(state, xm)) / (2 * step);
    }
  EXPECT_LT((analytic - numeric).norm(), 1e-6 * numeric.norm());
  // And the linear term's energy differs there: the terms are not the same function.
  CorotationalOptions lo = o;
  lo.volume_term = VolumeTerm::kLinear;
  CorotationalElasticity linear(lo);
  linear.Update(state, x);
  EXPECT_GT(std::abs(linear.Value(state, x) - elastic.Value(state, x)),
            1e-3 * elastic.Value(state, x));
}

TEST(VolumeTerm, JacobianHessianIsGaussNewton) {
  // Symmetric positive semi-definite; at a rigid rotation (J = 1, cof F = R) it is the warped
  // linear Hessian; after a stretch it is the derivative of the gradient minus the dropped
  // term lambda V (J - 1) d2J/dx2, which a pure shear (J = 1 exactly) removes.
  const MechanicalState state(SmallBox({2, 2, 1}), Material{5000, 0.45, 1000});
  CorotationalOptions jo, lo;
  jo.volume_term = VolumeTerm::kJacobian;
  lo.volume_term = VolumeTerm::kLinear;
  auto hessian = [&](const CorotationalOptions& o, const RowMatX3d& x) {
    CorotationalElasticity e(o);
    e.Update(state, x);
    SystemMatrix H(state.num_vertices(), state.tetrahedra());
    e.AddHessian(state, x, 1.0, &H);
    return Eigen::MatrixXd(H.matrix());
  };
  const Eigen::Matrix3d R =
      Eigen::AngleAxisd(1.1, Eigen::Vector3d(1, 2, 0).normalized()).toRotationMatrix();
  const RowMatX3d rotated = state.rest_positions() * R.transpose();
  const Eigen::MatrixXd hj = hessian(jo, rotated), hl = hessian(lo, rotated);
  EXPECT_LT((hj - hl).norm(), 1e-10 * hl.norm());
  // Pure shear x' = x + 0.4 y: det F = 1 in every element, so Gauss-Newton is exact for the
  // volume part; the shear part is the frozen-rotation Hessian, exact as for kLinear.
  RowMatX3d sheared = state.rest_positions();
  sheared.col(0) += 0.4 * state.rest_positions().col(1);
  CorotationalElasticity e(jo);
  e.Update(state, sheared);
  const Eigen::MatrixXd hs = hessian(jo, sheared);
  EXPECT_LT((hs - hs.transpose()).norm(), 1e-12 * hs.norm());
  const double step = 1e-6;
  Eigen::MatrixXd numeric(hs.rows(), hs.cols());
  for (int i = 0; i < state.num_vertices(); ++i)
    for (int c = 0; c < 3; ++c) {
      RowMatX3d xp = sheared, xm = sheared;
      xp(i, c) += step;
      xm(i, c) -= step;
      const RowMatX3d d = (Gradient(e, state, xp) - Gradient(e, state, xm)) / (2 * step);
      numeric.col(3 * i + c) = Eigen::Map<const Eigen::VectorXd>(d.data(), d.size());
    }
  EXPECT_LT((hs - numeric).norm(), 1e-6 * hs.norm());
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(hs);
  EXPECT_GT(eig.eigenvalues()[0], -1e-10 * eig.eigenvalues().maxCoeff());
}

TEST(VolumeTerm, ParseAndName) {
  EXPECT_EQ(ParseVolumeTerm("linear"), VolumeTerm::kLinear);
  EXPECT_EQ(ParseVolumeTerm("jacobian"), VolumeTerm::kJacobian);
  EXPECT_STREQ(VolumeTermName(VolumeTerm::kJacobian), "jacobian");
  EXPECT_THROW(ParseVolumeTerm("neo-hookean"), Error);
}

}  // namespace
}  // namespace arreg::mechanics
