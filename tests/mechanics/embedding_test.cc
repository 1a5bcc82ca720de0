// Barycentric embedding: inside points, points outside the mesh, affine
// reproduction, local re-embedding.
#include <gtest/gtest.h>

#include "core/error.h"
#include "mechanics/embedding.h"
#include "mechanics_test_util.h"

namespace arreg::mechanics {
namespace {

RowMatX3d RandomPoints(int n, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, unsigned seed) {
  std::mt19937 rng(seed);
  RowMatX3d p(n, 3);
  for (int i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) p(i, c) = std::uniform_real_distribution<double>(lo[c], hi[c])(rng);
  return p;
}

TEST(Embedding, InsidePointsHaveNonNegativeWeightsAndAreReproduced) {
  const TetMesh mesh = testing::SmallBox({5, 4, 3}, {50, 40, 30});
  const RowMatX3d points = RandomPoints(500, {0, 0, 0}, {50, 40, 30}, 1);
  const EmbeddedPoints e = EmbeddedPoints::Embed(points, mesh.vertices, mesh.tetrahedra);
  EXPECT_EQ(e.num_outside(), 0);
  for (int i = 0; i < e.size(); ++i) {
    EXPECT_GE(e[i].barycentric.minCoeff(), -1e-9);
    EXPECT_NEAR(e[i].barycentric.sum(), 1.0, 1e-12);
  }
  EXPECT_LT((e.Positions(mesh.vertices, mesh.tetrahedra) - points).cwiseAbs().maxCoeff(), 1e-10);
}

TEST(Embedding, FollowsAnAffineDeformationExactlyIncludingOutsidePoints) {
  const TetMesh mesh = testing::SmallBox({4, 3, 3}, {40, 30, 30});
  // Points up to 3 mm outside the box are extrapolated from the closest tetrahedron.
  const RowMatX3d points = RandomPoints(300, {-3, -3, -3}, {43, 33, 33}, 2);
  const EmbeddedPoints e = EmbeddedPoints::Embed(points, mesh.vertices, mesh.tetrahedra);
  EXPECT_GT(e.num_outside(), 0);
  for (int i = 0; i < e.size(); ++i) {
    const Eigen::Vector3d p = points.row(i).transpose();
    const Eigen::Vector3d clamped =
        p.cwiseMax(Eigen::Vector3d::Zero()).cwiseMin(Eigen::Vector3d(40, 30, 30));
    // The chosen tetrahedron is a closest one: its distance equals the distance to the box.
    EXPECT_NEAR(e.outside_distance()[i], (p - clamped).norm(), 1e-9) << i;
  }
  Eigen::Matrix3d A;
  A << 1.1, 0.2, 0.0, -0.1, 0.9, 0.3, 0.05, 0.0, 1.2;
  const Eigen::RowVector3d b(3, -2, 7);
  const RowMatX3d deformed = (mesh.vertices * A.transpose()).rowwise() + b;
  const RowMatX3d expected = (points * A.transpose()).rowwise() + b;
  EXPECT_LT((e.Positions(deformed, mesh.tetrahedra) - expected).cwiseAbs().maxCoeff(), 1e-9);
}

TEST(Embedding, ReembedRestrictsTheSearchToCandidates) {
  const TetMesh mesh = testing::SmallBox({3, 3, 3}, {30, 30, 30});
  const RowMatX3d points = RandomPoints(50, {0, 0, 0}, {30, 30, 30}, 3);
  EmbeddedPoints e = EmbeddedPoints::Embed(points, mesh.vertices, mesh.tetrahedra);
  const EmbeddedPoints before = e;
  // Candidates: the first cell's six tetrahedra only; point 0 is re-embedded
  // among them (closest one if outside), the others keep their embedding.
  e.Reembed({0}, points, mesh.vertices, mesh.tetrahedra, {0, 1, 2, 3, 4, 5});
  EXPECT_LE(e[0].tet, 5);
  for (int i = 1; i < e.size(); ++i) EXPECT_EQ(e[i].tet, before[i].tet);
  EXPECT_LT((e.Positions(mesh.vertices, mesh.tetrahedra).row(0) - points.row(0)).norm(), 1e-9);
}

TEST(Embedding, ResizeKeepsThePointsAndAppendsOnesToEmbed) {
  const TetMesh mesh = testing::SmallBox({3, 3, 3}, {30, 30, 30});
  const RowMatX3d points = RandomPoints(20, {0, 0, 0}, {30, 30, 30}, 4);
  EmbeddedPoints e = EmbeddedPoints::Embed(points.topRows(12), mesh.vertices, mesh.tetrahedra);
  const EmbeddedPoints before = e;
  e.Resize(20);
  ASSERT_EQ(e.size(), 20);
  ASSERT_EQ(static_cast<int>(e.outside_distance().size()), 20);
  for (int i = 12; i < 20; ++i) EXPECT_EQ(e[i].tet, -1);
  e.Reembed({12, 13, 14, 15, 16, 17, 18, 19}, points, mesh.vertices, mesh.tetrahedra, {});
  for (int i = 0; i < 12; ++i) EXPECT_EQ(e[i].tet, before[i].tet);
  EXPECT_LT((e.Positions(mesh.vertices, mesh.tetrahedra) - points).cwiseAbs().maxCoeff(), 1e-10);
  e.Resize(5);
  EXPECT_EQ(e.size(), 5);
  EXPECT_EQ(e[4].tet, before[4].tet);
  EXPECT_THROW(e.Resize(-1), Error);
}

TEST(Embedding, PointTetDistance) {
  const Eigen::Vector3d a(0, 0, 0), b(1, 0, 0), c(0, 1, 0), d(0, 0, 1);
  EXPECT_EQ(PointTetDistance({0.1, 0.1, 0.1}, a, b, c, d), 0.0);
  EXPECT_NEAR(PointTetDistance({0.2, 0.2, -2.0}, a, b, c, d), 2.0, 1e-12);
  EXPECT_NEAR(PointTetDistance({2.0, 0, 0}, a, b, c, d), 1.0, 1e-12);
  EXPECT_NEAR(PointTetDistance({1, 1, 1}, a, b, c, d), std::sqrt(3.0) * (1 - 1.0 / 3.0), 1e-12);
}

}  // namespace
}  // namespace arreg::mechanics
