// Vessel model (mechanics/vessel.h): derivatives against finite differences, a
// slender cantilever against Euler-Bernoulli, rigid motions of a curved
// vessel, and the separation of a vessel by a cut.
#include "mechanics/vessel.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <cstdio>
#include <random>
#include <set>

#include "core/error.h"
#include "generalised_fd.h"
#include "mechanics/generalised_solver.h"
#include "mechanics/so3.h"
#include "mechanics/units.h"

namespace arreg::mechanics {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Points on a circular arc of radius `radius` in the xy plane, `degrees` long.
RowMatX3d Arc(double radius, double degrees, int points) {
  RowMatX3d c(points, 3);
  for (int p = 0; p < points; ++p) {
    const double a = degrees / 180.0 * kPi * p / (points - 1);
    c.row(p) << radius * std::cos(a), radius * std::sin(a), 0.1 * a * radius;
  }
  return c;
}

RowMatX3d Straight(double length) {
  RowMatX3d c(2, 3);
  c << 0, 0, 0, length, 0, 0;
  return c;
}

VesselOptions Options(double radius, double spacing) {
  VesselOptions o;
  o.radius_mm = radius;
  o.frame_spacing_mm = spacing;
  return o;
}

// Rigid motion of every frame of the state: x -> Q x + t, R -> Q R (from rest).
void MoveRigidly(const Eigen::Matrix3d& q, const Eigen::Vector3d& t, GeneralisedState* state) {
  for (int n = 0; n < state->num_nodes(); ++n) {
    state->mutable_positions().row(n) =
        (q * state->rest_positions().row(n).transpose() + t).transpose();
    state->mutable_rotation(n) = q * state->rest_rotation(n);
  }
}

TEST(Vessel, FramesFollowTheCentreline) {
  GeneralisedState state;
  const Vessel v = MakeVessel(Arc(20, 120, 13), Material{1e6, 0, 1000}, Options(1.5, 4), &state);
  ASSERT_EQ(v.frame_nodes.size(), v.elements.size() + 1);
  for (size_t i = 0; i < v.frame_nodes.size(); ++i) {
    const Eigen::Matrix3d& r = state.rest_rotation(v.frame_nodes[i]);
    EXPECT_LT((r.transpose() * r - Eigen::Matrix3d::Identity()).norm(), 1e-12);
    if (i == 0 || i + 1 == v.frame_nodes.size()) continue;
    // z along the tangent, x transported: consecutive x axes turn only by the
    // turn of the tangent (no twist about it).
    const Eigen::Vector3d t = (state.rest_positions().row(v.frame_nodes[i + 1]) -
                               state.rest_positions().row(v.frame_nodes[i - 1]))
                                  .transpose()
                                  .normalized();
    EXPECT_GT(r.col(2).dot(t), 1 - 1e-3);
    const Eigen::Matrix3d& prev = state.rest_rotation(v.frame_nodes[i - 1]);
    const Eigen::Matrix3d transport =
        Eigen::Quaterniond::FromTwoVectors(prev.col(2), r.col(2)).toRotationMatrix();
    EXPECT_LT((transport * prev - r).norm(), 1e-12);
  }
  // Volume of the tube: chord lengths times pi r^2.
  double volume = 0, chords = 0;
  for (const FrameSample& s : v.samples) volume += s.volume_mm3;
  for (const Eigen::Vector2i& e : v.elements)
    chords += (state.rest_positions().row(v.frame_nodes[e[1]]) -
               state.rest_positions().row(v.frame_nodes[e[0]]))
                  .norm();
  EXPECT_NEAR(volume, chords * kPi * 1.5 * 1.5, 1e-10 * volume);
  EXPECT_THROW(MakeVessel(Straight(10), Material{1e6, 0, 1000}, Options(0, 1), &state), Error);
  EXPECT_THROW(MakeVessel(RowMatX3d::Zero(2, 3), Material{1e6, 0, 1000}, Options(1, 1), &state),
               Error);
}

TEST(Vessel, DerivativesMatchFiniteDifferences) {
  for (double angle : {0.0, 0.5 * kPi, 170.0 / 180.0 * kPi}) {
    GeneralisedState state;
    VesselOptions o = Options(2, 8);
    o.model.project_hessian = false;
    const Vessel v = MakeVessel(Arc(15, 90, 7), Material{30000, 0.3, 1000}, o, &state);
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> u(-1, 1);
    for (int n = 0; n < state.num_nodes(); ++n) {
      state.mutable_positions().row(n) += Eigen::RowVector3d(u(rng), u(rng), u(rng));
      const Eigen::Vector3d axis = Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized();
      state.mutable_rotation(n) = ExpSO3((angle + 0.1 * u(rng)) * axis) * state.rotation(n);
    }
    const FrameModel& term = *v.model;
    const Eigen::VectorXd g = testing::Gradient(term, state);
    const Eigen::MatrixXd hessian = testing::Hessian(term, state);
    const double h = 1e-6;
    Eigen::VectorXd fd_gradient(g.size());
    Eigen::MatrixXd fd_hessian(g.size(), g.size());
    for (int k = 0; k < g.size(); ++k) {
      fd_gradient[k] = (term.Value(testing::Perturbed(state, k, h)) -
                        term.Value(testing::Perturbed(state, k, -h))) /
                       (2 * h);
      fd_hessian.col(k) =
          (testing::GradientAlong(term, state, k, h) - testing::GradientAlong(term, state, k, -h)) /
          (2 * h);
    }
    EXPECT_LT((fd_gradient - g).norm(), 1e-6 * g.norm()) << "angle " << angle;
    EXPECT_LT((fd_hessian - hessian).norm(), 1e-6 * hessian.norm()) << "angle " << angle;
  }
}

TEST(Vessel, CurvedVesselHasNoEnergyUnderRigidMotion) {
  GeneralisedState state;
  const Vessel v = MakeVessel(Arc(20, 120, 25), Material{1e6, 0.3, 1000}, Options(1.5, 3), &state);
  // Energy scale: a 1 % stretch of the frame positions about the origin.
  GeneralisedState stretched = state;
  stretched.mutable_positions() *= 1.01;
  const double scale = v.model->Value(stretched);
  ASSERT_GT(scale, 0);
  for (double degrees : {90.0, 170.0}) {
    const Eigen::Matrix3d q = ExpSO3(degrees / 180 * kPi * Eigen::Vector3d(1, 2, -1).normalized());
    MoveRigidly(q, {3, -7, 11}, &state);
    EXPECT_LT(std::abs(v.model->Value(state)), 1e-12 * scale) << degrees;
    EXPECT_LT(testing::Gradient(*v.model, state).norm(),
              1e-10 * testing::Gradient(*v.model, stretched).norm())
        << degrees;
  }
}

// The weights are not linearly complete across the section, so turning all
// frames about their own positions strains the tube: only the 6 rigid modes
// are free.
TEST(Vessel, FreeVesselHasOnlyRigidZeroModes) {
  GeneralisedState state;
  VesselOptions o = Options(1.5, 3);
  o.model.project_hessian = false;
  const Vessel v = MakeVessel(Arc(20, 120, 25), Material{1e6, 0.3, 1000}, o, &state);
  const Eigen::VectorXd eigenvalues =
      Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(testing::Hessian(*v.model, state))
          .eigenvalues();
  int zero = 0;
  for (int k = 0; k < eigenvalues.size(); ++k)
    zero += std::abs(eigenvalues[k]) < 1e-9 * eigenvalues.maxCoeff();
  std::printf("free vessel: %d zero modes, smallest non-zero eigenvalue %.3g of %.3g\n", zero,
              eigenvalues[6], eigenvalues.maxCoeff());
  EXPECT_EQ(zero, 6);
  EXPECT_GT(eigenvalues[6], 1e-7 * eigenvalues.maxCoeff());
}

// Straight vessel along x, clamped at x = 0, sagging under its own weight.
// Euler-Bernoulli: tip deflection q L^4 / (8 E I), q = rho g pi r^2,
// I = pi r^4 / 4. nu = 0, so lambda + 2 mu = E (rigid cross-sections). The
// frame chain is a Timoshenko beam: shear adds 4 E I / (G A L^2) = 2 r^2 / L^2
// (0.08 % here), linear elements with mid-element samples err by O(1/N^2) (40
// elements), and the geometric nonlinearity of a 1.2 % sag is of order
// (sag / L)^2: within 1 % in all.
TEST(Vessel, SlenderCantileverSagsAsEulerBernoulli) {
  const double length = 100, radius = 2;
  const Material material{1e8, 0.0, 1000};
  GeneralisedState state;
  Vessel v = MakeVessel(Straight(length), material, Options(radius, 2.5), &state);
  state.SetFixedTranslation(v.frame_nodes[0], true);
  state.SetFixedRotation(v.frame_nodes[0], true);
  FrameGravity gravity(v.model.get(), {0, 0, -kStandardGravityMmPerS2});
  GeneralisedStaticOptions so;
  so.max_iterations = 100;
  const GeneralisedSummary summary =
      GeneralisedStaticSolver(so).Solve(&state, {v.model.get(), &gravity});
  ASSERT_EQ(summary.status, StepStatus::kConverged) << summary.message;
  const double q = material.DensityKgPerMm3() * kStandardGravityMmPerS2 * kPi * radius * radius;
  const double ei = material.youngs_modulus_pa / 1000 * kPi * std::pow(radius, 4) / 4;
  const double reference = q * std::pow(length, 4) / (8 * ei);
  const double sag = -state.position(v.frame_nodes.back()).z();
  std::printf("cantilever sag %.6f mm, Euler-Bernoulli %.6f mm (%+.3f %%), %d Newton iterations\n",
              sag, reference, 100 * (sag / reference - 1), summary.newton_iterations);
  EXPECT_NEAR(sag, reference, 0.01 * reference);
}

// A vessel clamped at both ends under its own weight, then cut through its
// middle frame: before, a clamped-clamped beam (mid sag q L^4 / (384 E I) +
// q L^2 / (8 G A)); after, two cantilevers of L / 2 (tip sag
// q l^4 / (8 E I) + q l^2 / (2 G A)). Timoshenko references with shear factor
// 1 (rigid sections; the shear terms are 1 % and 0.3 % here); 40 elements
// and a sag of 0.15 % of the span leave 0.5 %.
TEST(Vessel, CutClampedBeamBecomesTwoCantilevers) {
  const double length = 100, radius = 2;
  const Material material{1e8, 0.0, 1000};
  GeneralisedState state;
  Vessel v = MakeVessel(Straight(length), material, Options(radius, 2.5), &state);
  ASSERT_EQ(v.frame_nodes.size(), 41u);
  for (int node : {v.frame_nodes.front(), v.frame_nodes.back()}) {
    state.SetFixedTranslation(node, true);
    state.SetFixedRotation(node, true);
  }
  const double q = material.DensityKgPerMm3() * kStandardGravityMmPerS2 * kPi * radius * radius;
  const double ei = material.youngs_modulus_pa / 1000 * kPi * std::pow(radius, 4) / 4;
  const double ga = material.youngs_modulus_pa / 1000 / 2 * kPi * radius * radius;
  GeneralisedStaticOptions so;
  so.max_iterations = 100;
  {
    FrameGravity gravity(v.model.get(), {0, 0, -kStandardGravityMmPerS2});
    const GeneralisedSummary summary =
        GeneralisedStaticSolver(so).Solve(&state, {v.model.get(), &gravity});
    ASSERT_EQ(summary.status, StepStatus::kConverged) << summary.message;
  }
  const double clamped_reference =
      q * std::pow(length, 4) / (384 * ei) + q * length * length / (8 * ga);
  const double clamped_sag = -state.position(v.frame_nodes[20]).z();
  VesselCutPlane plane;
  plane.point = state.position(v.frame_nodes[20]);  // through the middle frame
  plane.normal = {1, 0, 0};
  const VesselCutResult r = CutVessel(plane, &state, &v);
  ASSERT_EQ(r.duplicated.size(), 1u);
  EXPECT_EQ(r.duplicated[0].first, v.frame_nodes[20]);
  FrameGravity gravity(v.model.get(), {0, 0, -kStandardGravityMmPerS2});
  const GeneralisedSummary summary =
      GeneralisedStaticSolver(so).Solve(&state, {v.model.get(), &gravity});
  ASSERT_EQ(summary.status, StepStatus::kConverged) << summary.message;
  const double half = length / 2;
  const double cantilever_reference = q * std::pow(half, 4) / (8 * ei) + q * half * half / (2 * ga);
  const double near_sag = -state.position(r.duplicated[0].first).z();
  const double far_sag = -state.position(r.duplicated[0].second).z();
  std::printf(
      "clamped-clamped mid sag %.6f mm (Timoshenko %.6f, %+.3f %%); cut: tips %.6f and "
      "%.6f mm (Timoshenko %.6f, %+.3f %%)\n",
      clamped_sag, clamped_reference, 100 * (clamped_sag / clamped_reference - 1), near_sag,
      far_sag, cantilever_reference, 100 * (near_sag / cantilever_reference - 1));
  EXPECT_NEAR(clamped_sag, clamped_reference, 0.005 * clamped_reference);
  EXPECT_NEAR(near_sag, cantilever_reference, 0.005 * cantilever_reference);
  EXPECT_NEAR(far_sag, cantilever_reference, 0.005 * cantilever_reference);
}

// A straight vessel clamped at x = 0, cut at x = 51 (frames every 5 mm), its
// free end then clamped at a rigidly moved pose: the far piece follows rigidly
// with no strain energy, the near piece stays at rest. Without the cut the same
// pull strains the vessel.
TEST(Vessel, CutSeparatesTheChain) {
  const Material material{1e6, 0.0, 1000};
  const Eigen::Matrix3d q = ExpSO3(30.0 / 180 * kPi * Eigen::Vector3d::UnitZ());
  const Eigen::Vector3d t(5, 8, -3);
  double energies[2];
  for (int cut = 0; cut < 2; ++cut) {
    GeneralisedState state;
    Vessel v = MakeVessel(Straight(100), material, Options(1.5, 5), &state);
    ASSERT_EQ(v.frame_nodes.size(), 21u);
    const int clamped = v.frame_nodes[0], pulled = v.frame_nodes[20];
    for (int node : {clamped, pulled}) {
      state.SetFixedTranslation(node, true);
      state.SetFixedRotation(node, true);
    }
    std::set<int> near, far;
    if (cut) {
      VesselCutPlane plane;
      plane.point = {51, 0, 0};
      plane.normal = {1, 0, 0};
      const VesselCutResult r = CutVessel(plane, &state, &v);
      ASSERT_EQ(r.crossed_elements.size(), 1u);
      ASSERT_EQ(r.duplicated.size(), 1u);
      EXPECT_EQ(r.duplicated[0].first, v.frame_nodes[10]);  // nearest the plane
      EXPECT_EQ(state.num_nodes(), 22);
      for (int i = 0; i <= 10; ++i) near.insert(i);
      for (int i = 11; i <= 21; ++i) far.insert(i);
      // No sample couples the two sides; all material kept.
      for (const FrameSample& s : v.samples) {
        const bool in_near = near.count(s.frames[0]) && near.count(s.frames[1]);
        const bool in_far = far.count(s.frames[0]) && far.count(s.frames[1]);
        EXPECT_TRUE(in_near != in_far);
      }
      EXPECT_EQ(v.samples.size(), 20u * 12u);
    }
    // Pull: the free end moved to a rigid pose in 20 load steps (a large jump
    // can land the end element in an inverted state, a zero of the Saint
    // Venant-Kirchhoff energy).
    const Eigen::Vector3d x0 = state.rest_positions().row(pulled).transpose();
    GeneralisedStaticOptions so;
    so.max_iterations = 200;
    so.tolerance_mm = so.tolerance_rad = 1e-8;  // the bent uncut vessel converges linearly
    GeneralisedStaticSolver solver(so);
    const int steps = 20;
    int iterations = 0;
    for (int step = 1; step <= steps; ++step) {
      const double f = static_cast<double>(step) / steps;
      const Eigen::Matrix3d qs = ExpSO3(f * 30.0 / 180 * kPi * Eigen::Vector3d::UnitZ());
      state.mutable_positions().row(pulled) = (qs * x0 + f * t).transpose();
      state.mutable_rotation(pulled) = qs * state.rest_rotation(pulled);
      const GeneralisedSummary summary = solver.Solve(&state, {v.model.get()});
      ASSERT_EQ(summary.status, StepStatus::kConverged)
          << (cut ? "cut" : "uncut") << " step " << step << " " << summary.message << " "
          << summary.last_increment_mm << " mm " << summary.last_increment_rad << " rad";
      iterations += summary.newton_iterations;
    }
    energies[cut] = v.model->Value(state);
    if (!cut) continue;
    double near_error = 0, far_error = 0;
    for (int i : near) {
      const int n = v.frame_nodes[i];
      near_error =
          std::max({near_error, (state.positions().row(n) - state.rest_positions().row(n)).norm(),
                    (state.rotation(n) - state.rest_rotation(n)).norm()});
    }
    for (int i : far) {
      const int n = v.frame_nodes[i];
      const Eigen::Vector3d rigid = q * state.rest_positions().row(n).transpose() + t;
      far_error = std::max({far_error, (state.position(n) - rigid).norm(),
                            (state.rotation(n) - q * state.rest_rotation(n)).norm()});
    }
    std::printf(
        "cut: near piece max error %.3g, far piece max error %.3g, energy %.3g uJ (%d "
        "Newton iterations)\n",
        near_error, far_error, energies[1], iterations);
    EXPECT_LT(near_error, 1e-8);
    EXPECT_LT(far_error, 1e-6);
  }
  std::printf("energy after the pull: uncut %.6g uJ, cut %.3g uJ\n", energies[0], energies[1]);
  EXPECT_GT(energies[0], 1.0);
  EXPECT_LT(energies[1], 1e-12 * energies[0]);
}

// A plane through a frame duplicates that frame with its whole state; the
// same cut again, a cut near a free end, and a crossing outside the cut's
// radius change nothing.
TEST(Vessel, CutThroughAFrameCopiesItsStateAndIsNotRepeated) {
  GeneralisedState state;
  Vessel v = MakeVessel(Straight(20), Material{1e6, 0.0, 1000}, Options(1, 5), &state);
  ASSERT_EQ(v.frame_nodes.size(), 5u);
  const int node = v.frame_nodes[2];  // at x = 10
  state.mutable_positions().row(node) << 10.5, 0.3, -0.2;
  state.mutable_rotation(node) = ExpSO3(Eigen::Vector3d(0.1, 0.2, 0.3)) * state.rotation(node);
  state.mutable_velocities().row(node) << 1, 2, 3;
  state.mutable_angular_velocities().row(node) << -1, 0.5, 4;
  state.SetFixedTranslation(node, true);
  VesselCutPlane plane;
  plane.point = {10.5, 0, 0};
  plane.normal = {1, 0, 0};
  plane.radius_mm = 0.1;  // the crossing is 0.36 mm off the point
  EXPECT_TRUE(CutVessel(plane, &state, &v).crossed_elements.empty());
  plane.radius_mm = 1;
  const VesselCutResult r = CutVessel(plane, &state, &v);
  ASSERT_EQ(r.duplicated.size(), 1u);
  const int copy = r.duplicated[0].second;
  EXPECT_EQ(r.duplicated[0].first, node);
  EXPECT_EQ(state.rest_positions().row(copy), state.rest_positions().row(node));
  EXPECT_EQ(state.rest_rotation(copy), state.rest_rotation(node));
  EXPECT_EQ(state.positions().row(copy), state.positions().row(node));
  EXPECT_EQ(state.rotation(copy), state.rotation(node));
  EXPECT_EQ(state.velocities().row(copy), state.velocities().row(node));
  EXPECT_EQ(state.angular_velocities().row(copy), state.angular_velocities().row(node));
  EXPECT_TRUE(state.fixed_translation(copy));
  EXPECT_FALSE(state.fixed_rotation(copy));
  // Element (1, 2) keeps the frame, element (2, 3) has the copy.
  EXPECT_EQ(v.elements[1], Eigen::Vector2i(1, 2));
  EXPECT_EQ(v.elements[2], Eigen::Vector2i(5, 3));
  EXPECT_EQ(v.model->num_frames(), 6);
  // Repeated, and near a free end: nothing changes.
  EXPECT_TRUE(CutVessel(plane, &state, &v).duplicated.empty());
  plane.point = {19, 0, 0};
  EXPECT_TRUE(CutVessel(plane, &state, &v).duplicated.empty());
  EXPECT_EQ(state.num_nodes(), 6);
}

}  // namespace
}  // namespace arreg::mechanics
