// Invariants and analytic values for mesh_ops and mesh_generators.
#include <gtest/gtest.h>

#include <cmath>
#include <set>

#include "core/error.h"
#include "core/mesh_generators.h"
#include "core/mesh_ops.h"

namespace arreg {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Regular tetrahedron with edge length 2 * sqrt(2), positively oriented.
std::array<Eigen::Vector3d, 4> RegularTet() {
  return {Eigen::Vector3d(1, 1, 1), Eigen::Vector3d(1, -1, -1), Eigen::Vector3d(-1, -1, 1),
          Eigen::Vector3d(-1, 1, -1)};
}

TEST(MeshOps, RegularTetrahedronValues) {
  const auto p = RegularTet();
  const double edge = 2 * std::sqrt(2.0);
  EXPECT_NEAR(SignedVolume(p[0], p[1], p[2], p[3]), edge * edge * edge / (6 * std::sqrt(2.0)),
              1e-12);
  EXPECT_NEAR(SignedVolume(p[0], p[1], p[3], p[2]), -8.0 / 3.0, 1e-12);
  EXPECT_NEAR(MinDihedralAngle(p[0], p[1], p[2], p[3]), std::acos(1.0 / 3.0), 1e-12);
  EXPECT_NEAR(MaxDihedralAngle(p[0], p[1], p[2], p[3]), std::acos(1.0 / 3.0), 1e-12);
  EXPECT_NEAR(RadiusRatio(p[0], p[1], p[2], p[3]), 1.0, 1e-12);
  EXPECT_NEAR(RadiusRatio(p[0], p[1], p[3], p[2]), -1.0, 1e-12);
}

TEST(MeshOps, RightCornerTetrahedron) {
  // Unit corner tet: three right dihedral angles at the origin's edges and
  // acos(1/sqrt(3)) at the slanted face; volume 1/6.
  const Eigen::Vector3d o(0, 0, 0), x(1, 0, 0), y(0, 1, 0), z(0, 0, 1);
  EXPECT_NEAR(SignedVolume(o, x, y, z), 1.0 / 6.0, 1e-15);
  EXPECT_NEAR(MinDihedralAngle(o, x, y, z), std::acos(1 / std::sqrt(3.0)), 1e-12);
  EXPECT_NEAR(MaxDihedralAngle(o, x, y, z), kPi / 2, 1e-12);
  // r = 1 / (3 + sqrt(3)), R = sqrt(3) / 2.
  const double expected = 3 * (1 / (3 + std::sqrt(3.0))) / (std::sqrt(3.0) / 2);
  EXPECT_NEAR(RadiusRatio(o, x, y, z), expected, 1e-12);
  EXPECT_EQ(RadiusRatio(o, x, y, Eigen::Vector3d(1, 1, 0)), 0.0);  // flat
}

class BoxMeshTest : public ::testing::TestWithParam<BoxTetSplit> {};

TEST_P(BoxMeshTest, VolumesBoundaryAndTopology) {
  const Eigen::Vector3d size(3.0, 2.0, 5.0);
  const Eigen::Vector3i cells(3, 4, 2);
  const TetMesh mesh = MakeBoxTetMesh(size, cells, GetParam());
  const int per_cell = GetParam() == BoxTetSplit::kSix ? 6 : 5;
  ASSERT_EQ(mesh.num_vertices(), 4 * 5 * 3);
  ASSERT_EQ(mesh.num_tetrahedra(), 24 * per_cell);
  const Eigen::VectorXd volumes = TetVolumes(mesh);
  EXPECT_GT(volumes.minCoeff(), 0);
  EXPECT_NEAR(volumes.sum(), 30.0, 1e-12);

  const SurfaceMesh boundary = ExtractBoundary(mesh);
  // 2 * (3*4 + 4*2 + 3*2) quads, two triangles each.
  EXPECT_EQ(boundary.num_faces(), 2 * 2 * (12 + 8 + 6));
  const SurfaceTopology topo = AnalyzeSurface(boundary);
  EXPECT_TRUE(topo.closed_oriented_manifold());
  EXPECT_EQ(topo.euler_characteristic, 2);
  EXPECT_EQ(topo.num_nonmanifold_edges, 0);
  EXPECT_NEAR(EnclosedVolume(boundary), volumes.sum(), 1e-12);
  EXPECT_NEAR(EnclosedVolume(boundary), 30.0, 1e-12);
  EXPECT_NEAR(SurfaceArea(boundary), 2 * (6.0 + 10.0 + 15.0), 1e-12);

  // Every boundary vertex lies on the box surface.
  for (int f = 0; f < boundary.num_faces(); ++f)
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d p = boundary.vertices.row(boundary.faces(f, k)).transpose();
      const bool on_face = (p.array() == 0).any() || (p.array() == size.array()).any();
      EXPECT_TRUE(on_face) << p.transpose();
    }

  int count = 0;
  ConnectedComponents(mesh, Adjacency::kFace, &count);
  EXPECT_EQ(count, 1);
  ConnectedComponents(boundary, Adjacency::kFace, &count);
  EXPECT_EQ(count, 1);

  const TetQualitySummary q = ComputeTetQuality(mesh);
  EXPECT_EQ(q.num_inverted, 0);
  EXPECT_EQ(q.num_degenerate, 0);
  EXPECT_NEAR(q.total_volume, 30.0, 1e-12);
  EXPECT_GT(q.min_dihedral_angle_rad, 0.1);
  EXPECT_LT(q.max_dihedral_angle_rad, kPi);
  EXPECT_GT(q.min_radius_ratio, 0.1);
  EXPECT_LE(q.mean_radius_ratio, 1.0);
}

INSTANTIATE_TEST_SUITE_P(Splits, BoxMeshTest,
                         ::testing::Values(BoxTetSplit::kSix, BoxTetSplit::kFive));

TEST(MeshOps, CubeWithKuhnSplitHasKnownAngles) {
  // The Kuhn tetrahedron of a cube: dihedral angles 45, 60 and 90 degrees.
  const TetMesh mesh = MakeBoxTetMesh(Eigen::Vector3d::Ones(), Eigen::Vector3i::Ones());
  const TetQualitySummary q = ComputeTetQuality(mesh);
  EXPECT_NEAR(q.min_dihedral_angle_rad, kPi / 4, 1e-12);
  EXPECT_NEAR(q.max_dihedral_angle_rad, kPi / 2, 1e-12);
  EXPECT_NEAR(q.min_volume, 1.0 / 6.0, 1e-15);
  EXPECT_NEAR(q.max_volume, 1.0 / 6.0, 1e-15);
}

TEST(MeshOps, FixOrientationFlipsOnlyInvertedAndBoundaryStaysOutward) {
  TetMesh mesh = MakeBoxTetMesh(Eigen::Vector3d(2, 2, 2), Eigen::Vector3i(2, 2, 2));
  const SurfaceMesh reference = ExtractBoundary(mesh);
  int expected = 0;
  for (int t = 0; t < mesh.num_tetrahedra(); t += 3, ++expected)
    std::swap(mesh.tetrahedra(t, 0), mesh.tetrahedra(t, 1));
  EXPECT_EQ(ComputeTetQuality(mesh).num_inverted, expected);
  // Boundary extraction follows each tetrahedron's own orientation.
  EXPECT_NEAR(EnclosedVolume(ExtractBoundary(mesh)), 8.0, 1e-12);
  EXPECT_EQ(FixOrientation(&mesh), expected);
  EXPECT_EQ(FixOrientation(&mesh), 0);
  EXPECT_GT(TetVolumes(mesh).minCoeff(), 0);
  EXPECT_EQ(ExtractBoundary(mesh).num_faces(), reference.num_faces());
}

TEST(MeshOps, FixOrientationKeepsQuadraticEdgeNodesOnTheirEdges) {
  TetMesh mesh;
  mesh.vertices.resize(10, 3);
  mesh.vertices.topRows(4) << 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 1, 0;  // negative order
  const int edges[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};
  mesh.tetrahedra.resize(1, 4);
  mesh.tetrahedra << 0, 1, 2, 3;
  mesh.high_order_nodes.resize(1, 6);
  for (int e = 0; e < 6; ++e) {
    mesh.vertices.row(4 + e) =
        0.5 * (mesh.vertices.row(edges[e][0]) + mesh.vertices.row(edges[e][1]));
    mesh.high_order_nodes(0, e) = 4 + e;
  }
  ASSERT_EQ(FixOrientation(&mesh), 1);
  for (int e = 0; e < 6; ++e) {
    const Eigen::RowVector3d mid = 0.5 * (mesh.vertices.row(mesh.tetrahedra(0, edges[e][0])) +
                                          mesh.vertices.row(mesh.tetrahedra(0, edges[e][1])));
    EXPECT_EQ(mesh.vertices.row(mesh.high_order_nodes(0, e)), mid) << "edge " << e;
  }
}

TEST(MeshOps, ComponentsOfDisjointAndTouchingBoxes) {
  TetMesh a = MakeBoxTetMesh(Eigen::Vector3d::Ones(), Eigen::Vector3i(1, 1, 1));
  // Three copies: one far away, one touching the first only at a corner vertex
  // (shared index), so face adjacency sees 3 components and vertex adjacency 2.
  TetMesh mesh;
  const int nv = a.num_vertices(), nt = a.num_tetrahedra();
  mesh.vertices.resize(3 * nv, 3);
  mesh.tetrahedra.resize(3 * nt, 4);
  for (int c = 0; c < 3; ++c) {
    mesh.vertices.middleRows(c * nv, nv) =
        a.vertices.rowwise() + Eigen::RowVector3d(c == 1 ? 10 : c, c, c);
    mesh.tetrahedra.middleRows(c * nt, nt) = a.tetrahedra.array() + c * nv;
  }
  // Copy 2 is shifted by (2,2,2)... make it share copy 0's max corner (index 7)
  // by shifting it by (1,1,1) and pointing its min corner at vertex 7.
  mesh.vertices.middleRows(2 * nv, nv) = a.vertices.rowwise() + Eigen::RowVector3d(1, 1, 1);
  for (int t = 2 * nt; t < 3 * nt; ++t)
    for (int k = 0; k < 4; ++k)
      if (mesh.tetrahedra(t, k) == 2 * nv) mesh.tetrahedra(t, k) = 7;
  int faces = 0, vertices = 0;
  const Eigen::VectorXi by_face = ConnectedComponents(mesh, Adjacency::kFace, &faces);
  const Eigen::VectorXi by_vertex = ConnectedComponents(mesh, Adjacency::kVertex, &vertices);
  EXPECT_EQ(faces, 3);
  EXPECT_EQ(vertices, 2);
  EXPECT_EQ(by_face[0], 0);
  EXPECT_EQ(by_face[nt], 1);
  EXPECT_EQ(by_face[2 * nt], 2);
  EXPECT_EQ(by_vertex[2 * nt], 0);
  EXPECT_EQ(by_vertex[nt], 1);

  const SurfaceMesh boundary = ExtractBoundary(mesh);
  ConnectedComponents(boundary, Adjacency::kFace, &faces);
  ConnectedComponents(boundary, Adjacency::kVertex, &vertices);
  EXPECT_EQ(faces, 3);
  EXPECT_EQ(vertices, 2);
}

TEST(MeshOps, RemoveUnreferencedVerticesKeepsGeometry) {
  const TetMesh mesh = MakeBoxTetMesh(Eigen::Vector3d(1, 1, 1), Eigen::Vector3i(3, 3, 3));
  SurfaceMesh boundary = ExtractBoundary(mesh);
  const double area = SurfaceArea(boundary);
  Eigen::VectorXi map;
  RemoveUnreferencedVertices(&boundary, &map);
  EXPECT_EQ(boundary.num_vertices(), 64 - 8);  // the 2x2x2 interior vertices go
  EXPECT_EQ((map.array() < 0).count(), 8);
  EXPECT_NEAR(SurfaceArea(boundary), area, 1e-12);
  EXPECT_EQ(AnalyzeSurface(boundary).euler_characteristic, 2);
}

TEST(MeshOps, OpenSurfaceTopology) {
  SurfaceMesh square;
  square.vertices.resize(4, 3);
  square.vertices << 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0;
  square.faces.resize(2, 3);
  square.faces << 0, 1, 2, 0, 2, 3;
  SurfaceTopology t = AnalyzeSurface(square);
  EXPECT_FALSE(t.closed());
  EXPECT_EQ(t.num_boundary_edges, 4);
  EXPECT_EQ(t.euler_characteristic, 1);
  square.faces << 0, 1, 2, 0, 3, 2;  // second face flipped
  t = AnalyzeSurface(square);
  EXPECT_EQ(t.num_misoriented_edges, 1);
  EXPECT_NEAR(SurfaceArea(square), 1.0, 1e-15);
}

TEST(MeshGenerators, RejectsBadArguments) {
  EXPECT_THROW(MakeBoxTetMesh(Eigen::Vector3d(1, 0, 1), Eigen::Vector3i(1, 1, 1)), Error);
  EXPECT_THROW(MakeBoxTetMesh(Eigen::Vector3d(1, NAN, 1), Eigen::Vector3i(1, 1, 1)), Error);
  EXPECT_THROW(MakeBoxTetMesh(Eigen::Vector3d(1, 1, 1), Eigen::Vector3i(1, 0, 1)), Error);
  EXPECT_THROW(MakeUvSphere(Eigen::Vector3d::Zero(), 0, 4, 8), Error);
  EXPECT_THROW(MakeUvSphere(Eigen::Vector3d::Zero(), 1, 1, 8), Error);
  EXPECT_THROW(MakeUvSphere(Eigen::Vector3d::Zero(), 1, 4, 2), Error);
}

// The sphere is a closed oriented manifold of genus 0 whose volume converges to 4/3 pi r^3
// from below as it is refined.
TEST(MeshGenerators, UvSphereIsAClosedSphere) {
  const double exact = 4.0 / 3.0 * M_PI * 8.0;
  double previous = 0;
  for (int rings : {6, 12, 24, 48}) {
    const SurfaceMesh s = MakeUvSphere(Eigen::Vector3d(1, 2, 3), 2.0, rings, 2 * rings);
    const SurfaceTopology t = AnalyzeSurface(s);
    EXPECT_TRUE(t.closed_oriented_manifold());
    EXPECT_EQ(t.euler_characteristic, 2);
    const double v = EnclosedVolume(s);
    EXPECT_LT(v, exact);
    EXPECT_GT(v, previous);
    previous = v;
  }
  EXPECT_NEAR(previous, exact, 0.005 * exact);
}

TEST(MeshGenerators, FiveSplitIsConforming) {
  // A conforming mesh has every interior face shared by exactly two tets, so
  // the boundary contains only faces on the box surface: 2 per boundary quad.
  const TetMesh mesh =
      MakeBoxTetMesh(Eigen::Vector3d(1, 1, 1), Eigen::Vector3i(3, 3, 3), BoxTetSplit::kFive);
  EXPECT_EQ(ExtractBoundary(mesh).num_faces(), 6 * 9 * 2);
  std::set<std::array<int, 4>> unique;
  for (int t = 0; t < mesh.num_tetrahedra(); ++t) {
    std::array<int, 4> s = {mesh.tetrahedra(t, 0), mesh.tetrahedra(t, 1), mesh.tetrahedra(t, 2),
                            mesh.tetrahedra(t, 3)};
    std::sort(s.begin(), s.end());
    unique.insert(s);
  }
  EXPECT_EQ(unique.size(), 27u * 5);
}

}  // namespace
}  // namespace arreg
