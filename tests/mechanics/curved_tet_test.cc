// Curved Bernstein-Bezier tetrahedra: the map and its Jacobian, the inverse map by
// Newton, embedded points following the control points.
#include "mechanics/curved_tet.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "core/error.h"
#include "mechanics/bernstein_tet.h"
#include "mechanics_test_util.h"

namespace arreg::mechanics {
namespace {

using testing::SmallBox;

// A quadratic field (mm -> mm) that bends and stretches a 30 x 20 x 20 box.
Eigen::Vector3d Quadratic(const Eigen::Vector3d& x) {
  return Eigen::Vector3d(x.x() + 0.012 * x.y() * x.y() - 0.009 * x.x() * x.z(),
                         x.y() + 0.015 * x.x() * x.x() + 0.1 * x.z(),
                         x.z() - 0.012 * x.x() * x.y() + 0.006 * x.z() * x.z());
}

Eigen::Vector4d RandomBarycentric(std::mt19937* rng) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Eigen::Vector4d L;
  for (int i = 0; i < 4; ++i) L[i] = -std::log(u(*rng) + 1e-300);
  return L / L.sum();
}

// One straight element of `degree` on a reference-like tetrahedron with its control
// points interpolating Quadratic: a curved element with a known exact map.
Eigen::MatrixX3d CurvedElement(int degree, HighOrderTetMesh* mesh_out = nullptr) {
  TetMesh tet;
  tet.vertices.resize(4, 3);
  tet.vertices << 1, 2, 0, 12, 1, 1, 3, 11, 2, 2, 3, 10;
  tet.tetrahedra.resize(1, 4);
  tet.tetrahedra << 0, 1, 2, 3;
  HighOrderTetMesh mesh = RaiseTetMesh(tet, degree);
  mesh.nodes = InterpolateMap(mesh, mesh.nodes, Quadratic);
  if (mesh_out) *mesh_out = mesh;
  return ElementControlPoints(mesh, mesh.nodes, 0);
}

TEST(CurvedTet, BernsteinValuesArePartitionOfUnityAndMatchBernsteinValue) {
  std::mt19937 rng(1);
  for (int k = 0; k <= 3; ++k) {
    const auto indices = BernsteinIndices(k);
    const Eigen::Vector4d L = RandomBarycentric(&rng);
    const Eigen::VectorXd v = BernsteinValues(k, L);
    EXPECT_NEAR(v.sum(), 1.0, 1e-14);
    for (size_t a = 0; a < indices.size(); ++a)
      EXPECT_NEAR(v[a], BernsteinValue(indices[a], L), 1e-14);
  }
}

TEST(CurvedTet, InterpolatedQuadraticMapIsExactForDegreeTwoAndThree) {
  std::mt19937 rng(2);
  for (int k = 1; k <= 3; ++k) {
    const Eigen::MatrixX3d control = CurvedElement(k);
    double max_error = 0;
    for (int s = 0; s < 50; ++s) {
      const Eigen::Vector4d L = RandomBarycentric(&rng);
      const Eigen::Vector3d X = L[0] * Eigen::Vector3d(1, 2, 0) + L[1] * Eigen::Vector3d(12, 1, 1) +
                                L[2] * Eigen::Vector3d(3, 11, 2) + L[3] * Eigen::Vector3d(2, 3, 10);
      max_error = std::max(max_error, (BezierTetPoint(k, control, L) - Quadratic(X)).norm());
    }
    if (k >= 2)
      EXPECT_LT(max_error, 1e-12) << "degree " << k;
    else
      EXPECT_GT(max_error, 1e-3) << "a linear element cannot follow the quadratic field";
  }
}

TEST(CurvedTet, JacobianMatchesCentralDifferences) {
  std::mt19937 rng(3);
  for (int k = 1; k <= 3; ++k) {
    const Eigen::MatrixX3d control = CurvedElement(k);
    const Eigen::Vector4d L = RandomBarycentric(&rng);
    const Eigen::Matrix3d j = BezierTetJacobian(k, control, L);
    const double h = 1e-6;
    for (int c = 0; c < 3; ++c) {
      Eigen::Vector4d d = Eigen::Vector4d::Zero();
      d[c + 1] = h;
      d[0] = -h;
      const Eigen::Vector3d fd =
          (BezierTetPoint(k, control, L + d) - BezierTetPoint(k, control, L - d)) / (2 * h);
      EXPECT_LT((j.col(c) - fd).norm(), 1e-7 * j.norm()) << "degree " << k << " column " << c;
    }
  }
}

TEST(CurvedTet, NewtonInvertsTheCurvedMapTo1e10) {
  std::mt19937 rng(4);
  for (int k = 1; k <= 3; ++k) {
    const Eigen::MatrixX3d control = CurvedElement(k);
    // The element is curved: the mid-point of edge 0-1 leaves the chord by > 0.3 mm
    // (the edge is 11 mm long) for k >= 2.
    const Eigen::Vector3d mid = BezierTetPoint(k, control, Eigen::Vector4d(0.5, 0.5, 0, 0));
    const Eigen::Vector3d chord = 0.5 * (control.row(0) + control.row(1)).transpose();
    if (k >= 2) {
      EXPECT_GT((mid - chord).norm(), 0.3);
    }
    int max_iterations = 0;
    for (int s = 0; s < 200; ++s) {
      Eigen::Vector4d L = RandomBarycentric(&rng);
      if (s < 4) L = Eigen::Vector4d::Unit(s);  // the corners
      const InverseMapResult r = InvertBezierTet(k, control, BezierTetPoint(k, control, L));
      ASSERT_TRUE(r.converged) << "degree " << k << " sample " << s;
      EXPECT_TRUE(r.inside);
      EXPECT_LT((r.barycentric - L).norm(), 1e-10) << "degree " << k << " sample " << s;
      max_iterations = std::max(max_iterations, r.iterations);
    }
    EXPECT_LE(max_iterations, 10) << "degree " << k;
  }
}

TEST(CurvedTet, PointsOutsideAreReportedNotInside) {
  const Eigen::MatrixX3d control = CurvedElement(2);
  // Slightly outside: beyond face L0 = 0 along the map, Newton converges to L0 < 0.
  const Eigen::Vector4d L(-0.05, 0.4, 0.3, 0.35);
  const InverseMapResult near = InvertBezierTet(2, control, BezierTetPoint(2, control, L));
  EXPECT_TRUE(near.converged);
  EXPECT_FALSE(near.inside);
  EXPECT_NEAR(near.barycentric[0], -0.05, 1e-10);
  // Far away: Newton leaves the element's neighbourhood and gives up.
  const InverseMapResult far = InvertBezierTet(2, control, Eigen::Vector3d(500, -300, 200));
  EXPECT_FALSE(far.inside);
  EXPECT_FALSE(far.converged && far.barycentric.minCoeff() > -1.0);
}

TEST(HighOrderEmbedding, EmbeddedPointsFollowAQuadraticFieldExactlyForDegreeTwoAndThree) {
  const TetMesh box = SmallBox();
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> ux(0.0, 30.0), uyz(0.0, 20.0);
  RowMatX3d points(300, 3);
  for (int i = 0; i < points.rows(); ++i) points.row(i) << ux(rng), uyz(rng), uyz(rng);
  for (int k = 1; k <= 3; ++k) {
    const HighOrderTetMesh mesh = RaiseTetMesh(box, k);
    const HighOrderEmbedding embedded = HighOrderEmbedding::Embed(mesh, mesh.nodes, points);
    EXPECT_EQ(embedded.num_outside(), 0);
    EXPECT_LT((embedded.Positions(mesh.nodes) - points).cwiseAbs().maxCoeff(), 1e-12);
    const RowMatX3d deformed = InterpolateMap(mesh, mesh.nodes, Quadratic);
    const RowMatX3d moved = embedded.Positions(deformed);
    double max_error = 0;
    for (int i = 0; i < points.rows(); ++i)
      max_error = std::max(max_error, (moved.row(i).transpose() - Quadratic(points.row(i))).norm());
    if (k >= 2)
      EXPECT_LT(max_error, 1e-11) << "degree " << k;
    else
      EXPECT_GT(max_error, 1e-2) << "P1 cannot follow the quadratic field";
    // Re-embedding in the curved (deformed) mesh finds the same material coordinates.
    const HighOrderEmbedding again = HighOrderEmbedding::Embed(mesh, deformed, moved);
    for (int i = 0; i < points.rows(); ++i)
      EXPECT_LT((again.Positions(mesh.nodes).row(i) - points.row(i)).norm(), 1e-9)
          << "degree " << k << " point " << i;
  }
}

TEST(HighOrderEmbedding, PointsFarOutsideThrowNamingThePoint) {
  const HighOrderTetMesh mesh = RaiseTetMesh(SmallBox(), 2);
  RowMatX3d points(2, 3);
  points << 10, 10, 10, 15, 10, 45;
  try {
    HighOrderEmbedding::Embed(mesh, mesh.nodes, points);
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("point 1"), std::string::npos) << e.what();
  }
  // Just outside a face (0.2 mm of a 10 mm cell): extrapolated and counted.
  points.row(1) << 15, 10, 20.2;
  const HighOrderEmbedding embedded = HighOrderEmbedding::Embed(mesh, mesh.nodes, points);
  EXPECT_EQ(embedded.num_outside(), 1);
  EXPECT_LT((embedded.Positions(mesh.nodes) - points).cwiseAbs().maxCoeff(), 1e-12);
}

}  // namespace
}  // namespace arreg::mechanics
