// The curved boundary of Bernstein-Bezier tetrahedra: tessellation of a ball whose
// control points interpolate the sphere (area, volume, watertightness, convergence in
// the subdivisions, the mesh size and the degree) and raising a linear ball mesh onto
// the sphere (geometric error order, no inverted element).
#include "mechanics/curved_boundary.h"

#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <random>

#include "core/error.h"
#include "core/mesh_generators.h"
#include "core/mesh_ops.h"
#include "curved_test_util.h"

namespace arreg::mechanics {
namespace {

using testing::kRadius;
using testing::LinearBall;
using testing::OntoSphere;
using testing::RaisedBall;

const double kArea = 4 * M_PI * kRadius * kRadius;
const double kVolume = 4.0 / 3.0 * M_PI * kRadius * kRadius * kRadius;

double Rate(double coarse, double fine) { return std::log2(coarse / fine); }

double Ms(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
      .count();
}

TEST(CurvedBoundary, LinearBallIsAValidClosedBall) {
  for (int level = 0; level <= 3; ++level) {
    const TetMesh ball = LinearBall(level);
    EXPECT_GT(TetVolumes(ball).minCoeff(), 0) << level;
    const SurfaceMesh boundary = ExtractBoundary(ball);
    EXPECT_EQ(boundary.num_faces(), 20 << (2 * level));
    EXPECT_TRUE(AnalyzeSurface(boundary).closed_oriented_manifold());
    const HighOrderTetMesh mesh = RaiseTetMesh(ball, 2);
    EXPECT_EQ(HighOrderBoundaryFaces(mesh).size(), static_cast<size_t>(20 << (2 * level)));
  }
}

TEST(CurvedBoundary, TessellationIsWatertightOutwardAndMovesWithTheNodes) {
  const HighOrderTetMesh mesh = RaisedBall(1, 3);
  for (int n : {1, 3, 5}) {
    const CurvedBoundary boundary = TessellateBoundary(mesh, mesh.nodes, n);
    EXPECT_EQ(boundary.faces.size(), 80u);
    EXPECT_EQ(boundary.surface.num_faces(), 80 * n * n);
    const SurfaceTopology topology = AnalyzeSurface(boundary.surface);
    EXPECT_TRUE(topology.closed_oriented_manifold()) << n;
    EXPECT_EQ(topology.euler_characteristic, 2) << n;
    EXPECT_GT(EnclosedVolume(boundary.surface), 0.5 * kVolume) << "outward";
    // The lattice points of degree 3 are where the faces interpolate the sphere.
    if (n == 1 || n == 3) {
      for (int v = 0; v < boundary.surface.num_vertices(); ++v)
        EXPECT_NEAR(boundary.surface.vertices.row(v).norm(), kRadius, 1e-12);
    }
    // A surface vertex shared by faces of other elements lies on each of those faces'
    // curved maps too: Newton in that element finds it on the face (L_opposite = 0).
    int checked = 0;
    for (int t = 0; t < boundary.surface.num_faces(); ++t)
      for (int c = 0; c < 3; ++c) {
        const int v = boundary.surface.faces(t, c);
        const HighOrderBoundaryFace& face = boundary.faces[boundary.face_of_triangle[t]];
        if (boundary.vertices.element(v) == face.element) continue;
        const InverseMapResult r =
            InvertBezierTet(3, ElementControlPoints(mesh, mesh.nodes, face.element),
                            boundary.surface.vertices.row(v));
        EXPECT_TRUE(r.converged);
        EXPECT_NEAR(r.barycentric[face.opposite], 0, 1e-10);
        ++checked;
      }
    EXPECT_GT(checked, 0);
  }
  // A rigid motion of the nodes moves the tessellation rigidly.
  const Eigen::Matrix3d rotation =
      Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  const CurvedBoundary boundary = TessellateBoundary(mesh, mesh.nodes, 4);
  const RowMatX3d moved_nodes =
      (mesh.nodes * rotation.transpose()).rowwise() + Eigen::RowVector3d(1, 2, 3);
  const RowMatX3d expected =
      (boundary.surface.vertices * rotation.transpose()).rowwise() + Eigen::RowVector3d(1, 2, 3);
  EXPECT_LT((boundary.Evaluate(moved_nodes).vertices - expected).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_THROW(TessellateBoundary(mesh, mesh.nodes, 0), Error);
}

// Area and volume of the tessellated raised ball against 4 pi r^2 and 4/3 pi r^3: flat
// triangles on the curved faces converge as n^-2 down to the error of the Bezier surface
// itself, estimated by Richardson extrapolation in n (n = 16, 32), which falls with the
// mesh size at a rate that grows with the degree.
TEST(CurvedBoundary, AreaAndVolumeConvergeWithSubdivisionsMeshSizeAndDegree) {
  const int n_of[6] = {1, 2, 4, 8, 16, 32};
  std::printf("degree level  area error at n = 1 2 4 8 16 32 | extrapolated area, volume error\n");
  double surface_area[4][3], surface_volume[4][3];
  for (int k = 1; k <= 3; ++k) {
    for (int level = 0; level <= 2; ++level) {
      // The relaxation moves only interior control points: the surface is the same.
      const HighOrderTetMesh mesh = RaisedBall(level, k, nullptr, false);
      double area[6], volume[6];
      std::printf("%6d %5d ", k, level);
      for (int ni = 0; ni < 6; ++ni) {
        const CurvedBoundary b = TessellateBoundary(mesh, mesh.nodes, n_of[ni]);
        area[ni] = SurfaceArea(b.surface);
        volume[ni] = EnclosedVolume(b.surface);
        std::printf(" %9.2e", std::abs(area[ni] - kArea) / kArea);
      }
      surface_area[k][level] = std::abs((4 * area[5] - area[4]) / 3 - kArea) / kArea;
      surface_volume[k][level] = std::abs((4 * volume[5] - volume[4]) / 3 - kVolume) / kVolume;
      std::printf(" | %9.2e %9.2e\n", surface_area[k][level], surface_volume[k][level]);
      if (k >= 2) {
        // n^-2 while the tessellation dominates
        EXPECT_GT(Rate(std::abs(area[1] - area[5]), std::abs(area[2] - area[5])), 1.8);
        EXPECT_GT(Rate(std::abs(area[2] - area[5]), std::abs(area[3] - area[5])), 1.8);
      }
    }
  }
  std::printf("rates of the extrapolated error with the mesh size (levels 0-1, 1-2):\n");
  for (int k = 1; k <= 3; ++k) {
    std::printf("degree %d: area %.2f %.2f volume %.2f %.2f\n", k,
                Rate(surface_area[k][0], surface_area[k][1]),
                Rate(surface_area[k][1], surface_area[k][2]),
                Rate(surface_volume[k][0], surface_volume[k][1]),
                Rate(surface_volume[k][1], surface_volume[k][2]));
    // Interpolation of degree k: at least order k + 1 (P2 shows 4, the even-degree
    // superconvergence of area and volume).
    EXPECT_GT(Rate(surface_area[k][1], surface_area[k][2]), k + 1 - 0.3) << k;
    EXPECT_GT(Rate(surface_volume[k][1], surface_volume[k][2]), k + 1 - 0.3) << k;
    if (k > 1) {
      EXPECT_LT(surface_area[k][2], 0.01 * surface_area[1][2]) << k;
      EXPECT_LT(surface_volume[k][2], 0.01 * surface_volume[1][2]) << k;
    }
  }
}

// The linear ball raised onto the sphere (analytic projector): the largest distance of the
// tessellated surface (n = 6) from the sphere falls at order k + 1; no element inverted
// (the Bernstein bound of det J positive).
TEST(CurvedBoundary, RaisingOntoTheSphereConvergesAtOrderKPlusOneWithoutInversion) {
  std::printf(
      "degree level relax  max |r - 10| (mm)  rate  inverted undecided  min det ratio "
      "(sampled / bound)  interior move (mm)  elements  nodes  ms\n");
  double finest[4] = {0, 0, 0, 0};
  for (int k = 1; k <= 3; ++k) {
    double previous = 0;
    for (int level = 0; level <= 2; ++level) {
      for (bool relax : {true, false}) {
        SurfaceRaiseSummary summary;
        const TetMesh linear = LinearBall(level);
        SurfaceRaiseOptions options;
        options.project = OntoSphere;
        options.relax_interior = relax;
        const auto start = std::chrono::steady_clock::now();
        const HighOrderTetMesh mesh = RaiseTetMeshOntoSurface(linear, k, options, &summary);
        const double ms =
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
                .count();
        const CurvedBoundary b = TessellateBoundary(mesh, mesh.nodes, 6);
        double error = 0;
        for (int v = 0; v < b.surface.num_vertices(); ++v)
          error = std::max(error, std::abs(b.surface.vertices.row(v).norm() - kRadius));
        std::printf("%6d %5d %5d  %17.3e  %4.2f  %8d %9d  %6.3f / %6.3f  %.3f  %d  %d  %.0f\n", k,
                    level, relax, error, relax && previous > 0 ? Rate(previous, error) : 0.0,
                    summary.num_inverted, summary.num_undecided, summary.min_sampled_ratio,
                    summary.min_coefficient_ratio, summary.max_interior_move_mm,
                    mesh.num_elements(), mesh.num_nodes(), ms);
        if (relax) {
          EXPECT_EQ(summary.num_inverted, 0) << k << " " << level;
          EXPECT_EQ(summary.num_undecided, 0) << k << " " << level;
          EXPECT_GT(summary.min_coefficient_ratio, 0.5) << k << " " << level;
          // distance to the sphere: order k + 1 from level 1 to 2
          if (level == 2) {
            EXPECT_GT(Rate(previous, error), k + 1 - 0.3) << k;
          }
          finest[k] = error;
          previous = error;
        }
      }
    }
  }
  EXPECT_LT(finest[2], 0.01 * finest[1]);
  EXPECT_LT(finest[3], finest[2]);
}

// Points embedded in the curved (raised) ball by the inverse map come back where they were
// and follow an affine motion of the control points exactly; the cost of embedding, of
// re-evaluating the points and of tessellating and re-evaluating the boundary is printed.
TEST(CurvedBoundary, PointsEmbeddedInTheCurvedBallFollowTheControlPoints) {
  std::printf(
      "degree tets nodes | embed 1000 points ms | positions ms | tessellate n = 4: "
      "triangles ms | evaluate ms\n");
  for (int k = 2; k <= 3; ++k) {
    // Without relaxation (its solve is the slow part; the boundary elements are curved).
    const HighOrderTetMesh mesh = RaisedBall(2, k, nullptr, false);
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> u(-kRadius, kRadius);
    RowMatX3d points(1000, 3);
    for (int n = 0; n < points.rows();) {
      const Eigen::Vector3d p(u(rng), u(rng), u(rng));
      if (p.norm() < 0.97 * kRadius) points.row(n++) = p.transpose();
    }
    auto start = std::chrono::steady_clock::now();
    const HighOrderEmbedding embedded = HighOrderEmbedding::Embed(mesh, mesh.nodes, points);
    const double embed_ms = Ms(start);
    EXPECT_EQ(embedded.num_outside(), 0);
    start = std::chrono::steady_clock::now();
    const RowMatX3d back = embedded.Positions(mesh.nodes);
    const double positions_ms = Ms(start);
    EXPECT_LT((back - points).cwiseAbs().maxCoeff(), 1e-11);
    const Eigen::Matrix3d a =
        Eigen::AngleAxisd(0.4, Eigen::Vector3d(0, 1, 1).normalized()).toRotationMatrix() *
        Eigen::Vector3d(1.2, 0.9, 1.05).asDiagonal();
    const auto affine = [&](const Eigen::Vector3d& x) -> Eigen::Vector3d {
      return a * x + Eigen::Vector3d(3, -2, 1);
    };
    const RowMatX3d moved = embedded.Positions(InterpolateMap(mesh, mesh.nodes, affine));
    for (int i = 0; i < points.rows(); ++i)
      EXPECT_LT((moved.row(i).transpose() - affine(points.row(i))).norm(), 1e-11);
    start = std::chrono::steady_clock::now();
    const CurvedBoundary boundary = TessellateBoundary(mesh, mesh.nodes, 4);
    const double tessellate_ms = Ms(start);
    start = std::chrono::steady_clock::now();
    const SurfaceMesh surface = boundary.Evaluate(mesh.nodes);
    const double evaluate_ms = Ms(start);
    std::printf("%6d %d %d | %.1f | %.3f | %d %.1f | %.3f\n", k, mesh.num_elements(),
                mesh.num_nodes(), embed_ms, positions_ms, surface.num_faces(), tessellate_ms,
                evaluate_ms);
  }
}

// The same raise with the sphere given as a finer triangle mesh (closest point): the
// result matches the analytic projector up to the mesh's own chordal error.
TEST(CurvedBoundary, RaisingOntoAFinerSurfaceMeshMatchesTheAnalyticProjector) {
  const SurfaceMesh fine = MakeUvSphere(Eigen::Vector3d::Zero(), kRadius, 48, 96);
  // Largest distance of the UV sphere from the true sphere: a quad's centre sags by
  // about r (1 - cos(pi / 96) cos(pi / 96)).
  const double chordal = kRadius * (1 - std::cos(M_PI / 96) * std::cos(M_PI / 96));
  SurfaceRaiseOptions options;
  options.project = ClosestPointProjector(fine);
  SurfaceRaiseSummary summary;
  const HighOrderTetMesh mesh = RaiseTetMeshOntoSurface(LinearBall(1), 2, options, &summary);
  const HighOrderTetMesh exact = RaisedBall(1, 2);
  EXPECT_EQ(summary.num_inverted, 0);
  EXPECT_LT((mesh.nodes - exact.nodes).rowwise().norm().maxCoeff(), 4 * chordal);
  EXPECT_GT((mesh.nodes - exact.nodes).rowwise().norm().maxCoeff(), 0);
  EXPECT_THROW(ClosestPointProjector(SurfaceMesh{}), Error);
}

// A concave boundary over thin elements, where the relaxation matters: a 20 x 20 x 10 mm
// box in 2 x 2 x 2 cells with its middle layer raised to z = 8.5 (top layer 1.5 mm thick),
// its top face pressed into a dimple of depth A sin^2(pi x / 10) sin^2(pi y / 10) (zero at
// the vertices). Without relaxation the straight interior control points stay above the
// dipping top and the top elements invert; the elastic solve carries the dip inside.
TEST(CurvedBoundary, RelaxationKeepsThinElementsUnderAConcaveBoundaryValid) {
  TetMesh slab = MakeBoxTetMesh(Eigen::Vector3d(20, 20, 10), Eigen::Vector3i(2, 2, 2));
  for (int v = 0; v < slab.num_vertices(); ++v)
    if (std::abs(slab.vertices(v, 2) - 5) < 1e-9) slab.vertices(v, 2) = 8.5;
  std::printf(
      "degree depth (mm)  inverted without / with relaxation  min det ratio without / with\n");
  bool relaxation_helped = false;
  for (int k = 2; k <= 3; ++k) {
    for (double depth : {0.5, 1.0, 1.5, 2.0}) {
      SurfaceRaiseOptions options;
      options.project = [depth](const Eigen::Vector3d& x) -> Eigen::Vector3d {
        if (x.z() < 10 - 1e-9) return x;
        const double sx = std::sin(M_PI * x.x() / 10), sy = std::sin(M_PI * x.y() / 10);
        return Eigen::Vector3d(x.x(), x.y(), 10 - depth * sx * sx * sy * sy);
      };
      SurfaceRaiseSummary with, without;
      options.relax_interior = false;
      RaiseTetMeshOntoSurface(slab, k, options, &without);
      options.relax_interior = true;
      RaiseTetMeshOntoSurface(slab, k, options, &with);
      std::printf("%6d %10.1f  %16d / %d  %12.3f / %.3f\n", k, depth, without.num_inverted,
                  with.num_inverted, without.min_sampled_ratio, with.min_sampled_ratio);
      EXPECT_LE(with.num_inverted, without.num_inverted) << k << " " << depth;
      EXPECT_GE(with.min_sampled_ratio, without.min_sampled_ratio) << k << " " << depth;
      if (without.num_inverted > 0 && with.num_inverted == 0 && with.num_undecided == 0)
        relaxation_helped = true;
    }
  }
  EXPECT_TRUE(relaxation_helped);
}

}  // namespace
}  // namespace arreg::mechanics
