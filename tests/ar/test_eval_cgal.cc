// Cross-check of the evaluation's directed Hausdorff distances against CGAL's
// independent implementation (Polygon_mesh_processing::approximate_Hausdorff_distance).
#include <gtest/gtest.h>

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_mesh_processing/distance.h>
#include <CGAL/Surface_mesh.h>
#include <cmath>
#include <cstdio>

#include "ar/eval/hausdorff.h"
#include "core/mesh_generators.h"
#include "core/mesh_io.h"
#include "core/mesh_ops.h"
#include "test_util.h"

namespace arreg::eval {
namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using CgalMesh = CGAL::Surface_mesh<Kernel::Point_3>;
namespace PMP = CGAL::Polygon_mesh_processing;

// Drops the vertices that no face uses (ExtractBoundary keeps interior ones).
SurfaceMesh Compact(const SurfaceMesh& mesh) {
  std::vector<int> index(mesh.num_vertices(), -1);
  int n = 0;
  for (int f = 0; f < mesh.num_faces(); ++f)
    for (int k = 0; k < 3; ++k)
      if (index[mesh.faces(f, k)] < 0) index[mesh.faces(f, k)] = n++;
  SurfaceMesh out;
  out.vertices.resize(n, 3);
  for (int v = 0; v < mesh.num_vertices(); ++v)
    if (index[v] >= 0) out.vertices.row(index[v]) = mesh.vertices.row(v);
  out.faces.resize(mesh.num_faces(), 3);
  for (int f = 0; f < mesh.num_faces(); ++f)
    for (int k = 0; k < 3; ++k) out.faces(f, k) = index[mesh.faces(f, k)];
  return out;
}

CgalMesh ToCgal(const SurfaceMesh& mesh) {
  CgalMesh out;
  std::vector<CgalMesh::Vertex_index> v;
  for (int i = 0; i < mesh.num_vertices(); ++i)
    v.push_back(out.add_vertex(
        Kernel::Point_3(mesh.vertices(i, 0), mesh.vertices(i, 1), mesh.vertices(i, 2))));
  for (int f = 0; f < mesh.num_faces(); ++f)
    out.add_face(v[mesh.faces(f, 0)], v[mesh.faces(f, 1)], v[mesh.faces(f, 2)]);
  return out;
}

// A smooth, non-rigid deformation (bending, twisting, local bulge) whose
// amplitude is `fraction` of the mesh's largest extent.
SurfaceMesh Deform(const SurfaceMesh& mesh, double fraction) {
  SurfaceMesh out = mesh;
  const Eigen::Vector3d center = mesh.vertices.colwise().mean().transpose();
  const double extent =
      (mesh.vertices.colwise().maxCoeff() - mesh.vertices.colwise().minCoeff()).maxCoeff();
  for (int v = 0; v < mesh.num_vertices(); ++v) {
    const Eigen::Vector3d p = mesh.vertices.row(v).transpose() - center;
    const Eigen::Vector3d q = p / extent;
    Eigen::Vector3d d(
        std::sin(3.0 * q.y()) * 0.8, std::cos(2.5 * q.x()) * q.z(),
        0.6 * q.x() * q.x() + std::exp(-20.0 * (q - Eigen::Vector3d(0.2, 0.1, 0.3)).squaredNorm()));
    out.vertices.row(v) += fraction * extent * d.transpose();
  }
  return out;
}

void ExpectAgreesWithCgal(const SurfaceMesh& model, const SurfaceMesh& truth) {
  HausdorffOptions options;
  options.sampling.samples_per_area = 0.0;
  options.sampling.min_random_samples = options.sampling.max_random_samples = 50000;
  const HausdorffResult ours = ComputeHausdorff(model, truth, options);
  const CgalMesh a = ToCgal(model), b = ToCgal(truth);
  const auto np = CGAL::parameters::number_of_points_on_faces(50000).random_seed(7);
  const double cgal_ab = PMP::approximate_Hausdorff_distance<CGAL::Sequential_tag>(a, b, np);
  const double cgal_ba = PMP::approximate_Hausdorff_distance<CGAL::Sequential_tag>(b, a, np);
  std::printf("model->gt: ours %.6f, CGAL %.6f; gt->model: ours %.6f, CGAL %.6f\n",
              ours.max_model_to_gt, cgal_ab, ours.max_gt_to_model, cgal_ba);
  EXPECT_GT(cgal_ab, 0.1);
  EXPECT_NEAR(ours.max_model_to_gt, cgal_ab, 0.01 * cgal_ab);
  EXPECT_NEAR(ours.max_gt_to_model, cgal_ba, 0.01 * cgal_ba);
  EXPECT_NEAR(ours.max, std::max(cgal_ab, cgal_ba), 0.01 * std::max(cgal_ab, cgal_ba));
  // Both directed parts are genuinely different for this non-rigid pair.
  EXPECT_LT(ours.mean_model_to_gt, ours.max_model_to_gt);
}

TEST(HausdorffVsCgal, DeformedBoxSurface) {
  const SurfaceMesh box = Compact(
      ExtractBoundary(MakeBoxTetMesh(Eigen::Vector3d(60, 40, 30), Eigen::Vector3i(12, 8, 6))));
  ExpectAgreesWithCgal(Deform(box, 0.06), box);
}

TEST(HausdorffVsCgal, DeformedSofaLiver) {
  ARREG_REQUIRE_SHARED(path, "meshes/sofa/liver-smooth.obj");
  const SurfaceMesh liver = Compact(ReadSurfaceMesh(path));
  ExpectAgreesWithCgal(Deform(liver, 0.05), liver);
}

}  // namespace
}  // namespace arreg::eval
