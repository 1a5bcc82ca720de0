// Element kernels: rest stiffness invariants, rotation extraction.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <random>

#include "mechanics/tet_element.h"

namespace arreg::mechanics {
namespace {

TetRestData SkewedTet(const Material& material = {}) {
  TetRestData rest;
  EXPECT_TRUE(ComputeTetRestData({0, 0, 0}, {2.0, 0.1, 0.3}, {0.4, 1.5, -0.2}, {0.3, 0.2, 1.8},
                                 material, &rest));
  return rest;
}

TEST(TetElement, RestStiffnessIsSymmetricWithSixRigidModes) {
  const TetRestData rest = SkewedTet();
  const Eigen::Matrix<double, 12, 12> k = RestStiffnessMatrix(rest);
  EXPECT_LT((k - k.transpose()).norm(), 1e-12 * k.norm());
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 12, 12>> eig(k);
  const auto& ev = eig.eigenvalues();  // ascending
  for (int i = 0; i < 6; ++i) EXPECT_LT(std::abs(ev[i]), 1e-10 * ev[11]) << i;
  EXPECT_GT(ev[6], 1e-4 * ev[11]);
}

TEST(TetElement, RestStiffnessMatchesBtCB) {
  // Independent construction from the strain-displacement matrix (Voigt
  // order xx yy zz yz xz xy, engineering shear strains).
  const Material m{5000.0, 0.3, 1000.0};
  const TetRestData rest = SkewedTet(m);
  Eigen::Matrix<double, 6, 12> B = Eigen::Matrix<double, 6, 12>::Zero();
  for (int a = 0; a < 4; ++a) {
    const Eigen::Vector3d g = rest.shape_gradients.row(a).transpose();
    B(0, 3 * a) = g[0];
    B(1, 3 * a + 1) = g[1];
    B(2, 3 * a + 2) = g[2];
    B(3, 3 * a + 1) = g[2];
    B(3, 3 * a + 2) = g[1];
    B(4, 3 * a) = g[2];
    B(4, 3 * a + 2) = g[0];
    B(5, 3 * a) = g[1];
    B(5, 3 * a + 1) = g[0];
  }
  const double e = 5.0, nu = 0.3;  // kPa
  Eigen::Matrix<double, 6, 6> C = Eigen::Matrix<double, 6, 6>::Zero();
  const double c = e / ((1 + nu) * (1 - 2 * nu));
  C.topLeftCorner<3, 3>().setConstant(c * nu);
  C.topLeftCorner<3, 3>().diagonal().setConstant(c * (1 - nu));
  C.bottomRightCorner<3, 3>().diagonal().setConstant(e / (2 * (1 + nu)));
  const Eigen::Matrix<double, 12, 12> expected = rest.volume_mm3 * B.transpose() * C * B;
  EXPECT_LT((RestStiffnessMatrix(rest) - expected).norm(), 1e-12 * expected.norm());
}

TEST(TetElement, RejectsInvertedElement) {
  TetRestData rest;
  EXPECT_FALSE(ComputeTetRestData({0, 0, 0}, {0, 1, 0}, {1, 0, 0}, {0, 0, 1}, Material{}, &rest));
  EXPECT_LT(rest.volume_mm3, 0.0);
}

class RotationTest : public ::testing::TestWithParam<RotationMethod> {};

TEST_P(RotationTest, RecoversPureRotationsUpTo179Degrees) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int trial = 0; trial < 50; ++trial) {
    const Eigen::Vector3d axis = Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized();
    const double angle = 3.12 * (trial + 1) / 50.0;
    const Eigen::Matrix3d R_true = Eigen::AngleAxisd(angle, axis).toRotationMatrix();
    Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
    ExtractRotation(R_true, GetParam(), &R, 100);
    EXPECT_LT((R - R_true).norm(), 1e-10) << "angle " << angle;
  }
}

INSTANTIATE_TEST_SUITE_P(AllMethods, RotationTest,
                         ::testing::Values(RotationMethod::kPolar, RotationMethod::kPolarSvd,
                                           RotationMethod::kQr));

TEST(Rotation, PolarIterationMatchesSvdAndGivesSymmetricStretch) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-0.4, 0.4);
  for (int trial = 0; trial < 100; ++trial) {
    Eigen::Matrix3d F =
        Eigen::AngleAxisd(2.0 * u(rng), Eigen::Vector3d(u(rng), u(rng), 1).normalized())
            .toRotationMatrix();
    Eigen::Matrix3d S;
    S << 1 + u(rng), u(rng), u(rng), 0, 1 + u(rng), u(rng), 0, 0, 1 + u(rng);
    S = (0.5 * (S + S.transpose())).eval();
    if (S.determinant() <= 0.1) continue;
    F = F * S;
    Eigen::Matrix3d R_iter = Eigen::Matrix3d::Identity(), R_svd;
    ExtractRotation(F, RotationMethod::kPolar, &R_iter, 100);
    ExtractRotation(F, RotationMethod::kPolarSvd, &R_svd);
    EXPECT_LT((R_iter - R_svd).norm(), 1e-9);
    const Eigen::Matrix3d stretch = R_iter.transpose() * F;
    EXPECT_LT((stretch - stretch.transpose()).norm(), 1e-9);
    EXPECT_NEAR(R_iter.determinant(), 1.0, 1e-12);
  }
}

// The exact polar rotation of F = U diag(sigma) V^T: the proper rotation
// maximising tr(R^T F), from the SVD.
Eigen::Matrix3d ExactPolar(const Eigen::Matrix3d& F) {
  Eigen::Matrix3d R;
  ExtractRotation(F, RotationMethod::kPolarSvd, &R);
  return R;
}

Eigen::Matrix3d RandomRotation(std::mt19937* rng, double max_angle) {
  std::uniform_real_distribution<double> u(-1, 1);
  const Eigen::Vector3d axis = Eigen::Vector3d(u(*rng), u(*rng), u(*rng)).normalized();
  return Eigen::AngleAxisd(max_angle * std::abs(u(*rng)), axis).toRotationMatrix();
}

// Deformation gradients drifting from frame to frame, each polar rotation
// warm-started from the previous one (as CorotationalElasticity does), equal
// the exact polar rotation to 1e-10 - also for nearly flat, nearly collapsed
// to a line and inverted elements.
TEST(Rotation, WarmStartedPolarMatchesTheExactPolarRotation) {
  std::mt19937 rng(23);
  std::uniform_real_distribution<double> u(0.5, 1.5);
  const std::vector<Eigen::Vector3d> degenerate = {
      {1.0, 1.0, 1.0}, {1.3, 0.8, 1e-9}, {1.0, 1e-3, 1e-3}, {1.0, 0.9, -0.2}, {1.0, 0.3, -1e-6}};
  int calls = 0, total_updates = 0;
  for (int sequence = 0; sequence < 40; ++sequence) {
    Eigen::Matrix3d U = RandomRotation(&rng, M_PI), V = RandomRotation(&rng, M_PI);
    Eigen::Quaterniond warm = Eigen::Quaterniond::Identity();
    for (int frame = 0; frame < 30; ++frame) {
      // Singular values: random, or one of the degenerate sets; the frames
      // rotate by up to 0.05 rad each.
      Eigen::Vector3d sigma(u(rng), u(rng), u(rng));
      if (sequence % 4 == 0) sigma = degenerate[(sequence / 4) % degenerate.size()];
      U = RandomRotation(&rng, 0.05) * U;
      V = RandomRotation(&rng, 0.05) * V;
      const Eigen::Matrix3d F = U * sigma.asDiagonal() * V.transpose();
      Eigen::Matrix3d R;
      total_updates += PolarRotation(F, &warm, &R);
      ++calls;
      const Eigen::Matrix3d exact = ExactPolar(F);
      ASSERT_LT((R - exact).norm(), 1e-10)
          << "sequence " << sequence << " frame " << frame << " sigma " << sigma.transpose();
      EXPECT_LT((R - warm.toRotationMatrix()).norm(), 1e-14);
      EXPECT_LT((R.transpose() * R - Eigen::Matrix3d::Identity()).norm(), 1e-14);
      EXPECT_NEAR(R.determinant(), 1.0, 1e-14);
    }
  }
  // Warm starts make it cheap: about two Newton updates per call (the first
  // call of each sequence starts from the identity and needs more).
  EXPECT_LT(static_cast<double>(total_updates) / calls, 3.0);
}

// The batched kernel (four elements in lockstep, a count that is not a
// multiple of four) gives exactly the per-element results.
TEST(Rotation, BatchedPolarRotationsEqualOneByOne) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(0.2, 1.8);
  const int n = 23;
  std::vector<Eigen::Matrix3d> F(n), R_batch(n), R_single(n);
  std::vector<Eigen::Quaterniond> q_batch(n), q_single(n);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d sigma(u(rng), u(rng), i % 5 == 0 ? -0.1 : u(rng));
    F[i] = RandomRotation(&rng, M_PI) * sigma.asDiagonal() * RandomRotation(&rng, M_PI);
    // Warm starts near the answer, far from it, and the identity.
    const Eigen::Matrix3d start =
        i % 3 == 0
            ? Eigen::Matrix3d::Identity()
            : Eigen::Matrix3d(RandomRotation(&rng, i % 3 == 1 ? 0.1 : 2.0) * ExactPolar(F[i]));
    q_batch[i] = q_single[i] = Eigen::Quaterniond(start);
  }
  int single_updates = 0;
  for (int i = 0; i < n; ++i) single_updates += PolarRotation(F[i], &q_single[i], &R_single[i]);
  EXPECT_EQ(PolarRotations(n, F.data(), q_batch.data(), R_batch.data()), single_updates);
  for (int i = 0; i < n; ++i) {
    EXPECT_EQ(R_batch[i], R_single[i]) << i;
    EXPECT_EQ(q_batch[i].coeffs(), q_single[i].coeffs()) << i;
    EXPECT_LT((R_batch[i] - ExactPolar(F[i])).norm(), 1e-10) << i;
  }
}

TEST(Rotation, InvertedDeformationStillGivesProperRotation) {
  const Eigen::Matrix3d F = Eigen::Vector3d(1.0, 1.0, -0.3).asDiagonal();
  for (RotationMethod m :
       {RotationMethod::kPolar, RotationMethod::kPolarSvd, RotationMethod::kQr}) {
    Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
    ExtractRotation(F, m, &R);
    EXPECT_NEAR(R.determinant(), 1.0, 1e-12) << RotationMethodName(m);
    EXPECT_LT((R * R.transpose() - Eigen::Matrix3d::Identity()).norm(), 1e-12);
  }
}

TEST(Material, CheckNamesTheField) {
  Material m;
  m.poisson_ratio = 0.5;
  try {
    m.Check();
    FAIL() << "expected arreg::Error";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("poisson_ratio"), std::string::npos);
  }
}

}  // namespace
}  // namespace arreg::mechanics
