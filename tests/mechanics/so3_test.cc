#include "mechanics/so3.h"

#include <gtest/gtest.h>

#include <Eigen/LU>
#include <cmath>

#include "core/error.h"
#include "mechanics/generalised_state.h"

namespace arreg::mechanics {
namespace {

const Eigen::Vector3d kAxis = Eigen::Vector3d(0.3, -0.8, 0.52).normalized();

TEST(So3, ExpIsARotationAndLogInvertsIt) {
  for (double t : {0.0, 1e-9, 1e-5, 0.3, 1.7, 3.0, M_PI - 1e-6}) {
    const Eigen::Vector3d theta = t * kAxis;
    const Eigen::Matrix3d r = ExpSO3(theta);
    EXPECT_LT((r.transpose() * r - Eigen::Matrix3d::Identity()).norm(), 1e-14) << t;
    EXPECT_NEAR(r.determinant(), 1.0, 1e-14) << t;
    EXPECT_LT((r * kAxis - kAxis).norm(), 1e-14) << t;  // the axis is fixed
    EXPECT_LT((LogSO3(r) - theta).norm(), 1e-9 * std::max(1.0, t)) << t;
  }
  // Rotation by t about z moves x to (cos t, sin t, 0).
  const Eigen::Vector3d x = ExpSO3(Eigen::Vector3d(0, 0, 0.4)) * Eigen::Vector3d::UnitX();
  EXPECT_NEAR(x.x(), std::cos(0.4), 1e-15);
  EXPECT_NEAR(x.y(), std::sin(0.4), 1e-15);
}

TEST(So3, LeftJacobianMatchesFiniteDifferencesAndItsInverse) {
  for (double t : {1e-6, 0.4, 2.5}) {
    const Eigen::Vector3d theta = t * kAxis;
    const Eigen::Matrix3d jl = LeftJacobianSO3(theta);
    EXPECT_LT((jl * LeftJacobianInverseSO3(theta) - Eigen::Matrix3d::Identity()).norm(), 1e-12);
    // Exp(theta + h e_k) Exp(theta)^T = Exp(h J_l e_k) + O(h^2).
    const double h = 1e-6;
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d d = h * Eigen::Vector3d::Unit(k);
      const Eigen::Matrix3d rp = ExpSO3(theta + d) * ExpSO3(theta).transpose();
      const Eigen::Matrix3d rm = ExpSO3(theta - d) * ExpSO3(theta).transpose();
      const Eigen::Vector3d col = (LogSO3(rp) - LogSO3(rm)) / (2 * h);
      EXPECT_LT((col - jl.col(k)).norm(), 1e-8) << t << " " << k;
    }
  }
}

TEST(GeneralisedState, LaysOutPointAndFrameDofsAndAppliesIncrements) {
  GeneralisedState s;
  EXPECT_EQ(s.AddPointNode({1, 2, 3}), 0);
  EXPECT_EQ(s.AddFrameNode({0, 0, 0}, ExpSO3({0, 0, 0.5})), 1);
  EXPECT_EQ(s.AddPointNode({4, 5, 6}), 2);
  EXPECT_EQ(s.num_dofs(), 12);
  EXPECT_EQ(s.dof_offset(2), 9);
  EXPECT_THROW(s.AddFrameNode({0, 0, 0}, 2.0 * Eigen::Matrix3d::Identity()), Error);
  Eigen::VectorXd inc = Eigen::VectorXd::Zero(12);
  inc.segment<3>(3) << 1, 0, 0;
  inc.segment<3>(6) << 0, 0, 0.25;
  s.ApplyIncrement(inc);
  EXPECT_DOUBLE_EQ(s.position(1).x(), 1.0);
  EXPECT_LT((LogSO3(s.rotation(1)) - Eigen::Vector3d(0, 0, 0.75)).norm(), 1e-14);
  s.SetFixedRotation(1, true);
  const std::vector<char> mask = s.FixedDofMask();
  EXPECT_EQ(mask[3], 0);
  EXPECT_EQ(mask[6], 1);
  EXPECT_EQ(mask[9], 0);
}

}  // namespace
}  // namespace arreg::mechanics
