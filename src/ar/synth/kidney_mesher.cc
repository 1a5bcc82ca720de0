// CGAL Mesh_3 lives in this translation unit only (it is slow to compile).
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Labeled_mesh_domain_3.h>
#include <CGAL/Mesh_complex_3_in_triangulation_3.h>
#include <CGAL/Mesh_criteria_3.h>
#include <CGAL/Mesh_triangulation_3.h>
#include <CGAL/make_mesh_3.h>

#include <cmath>
#include <functional>
#include <map>

#include "ar/synth/shapes.h"
#include "core/error.h"
#include "core/mesh_ops.h"

namespace arreg::synth {

void KidneyShape::Check() const {
  ARREG_CHECK_INPUT((size_mm.array() > 0).all(), "", "kidney.size_mm", "must be positive");
  ARREG_CHECK_INPUT((internal_size_mm.array() > 0).all(), "", "kidney.internal_size_mm",
                    "must be positive");
  ARREG_CHECK_INPUT((internal_size_mm.array() < size_mm.array()).all(), "",
                    "kidney.internal_size_mm", "must be smaller than the organ");
  ARREG_CHECK_INPUT(bend_mm >= 0 && bend_mm < 0.3 * size_mm.z(), "", "kidney.bend_mm",
                    "must be in [0, 0.3 x height)");
  ARREG_CHECK_INPUT(hilum_depth >= 0 && hilum_depth < 0.8, "", "kidney.hilum_depth",
                    "must be in [0, 0.8)");
}

int KidneyShape::Label(const Eigen::Vector3d& p) const {
  const Eigen::Vector3d r = internal_size_mm / 2;
  const Eigen::Vector3d q = (p - internal_center_mm).cwiseQuotient(r);
  if (q.squaredNorm() < 1) return 2;
  const Eigen::Vector3d a = size_mm / 2;
  const double u = p.x() / a.x();
  const double zb = p.z() - bend_mm * u * u;
  const double dent =
      hilum_depth * std::exp(-(std::pow(p.x() / (0.15 * size_mm.x()), 2) +
                               std::pow((p.z() + a.z()) / (0.22 * size_mm.z()), 2)));
  const double f = u * u + std::pow(p.y() / a.y(), 2) + std::pow(zb / a.z(), 2) - 1 + dent;
  return f < 0 ? 1 : 0;
}

void KidneyMeshOptions::Check() const {
  ARREG_CHECK_INPUT(cell_size_mm > 0, "", "cell_size_mm", "must be positive");
  ARREG_CHECK_INPUT(facet_size_mm > 0, "", "facet_size_mm", "must be positive");
  ARREG_CHECK_INPUT(facet_distance_mm > 0, "", "facet_distance_mm", "must be positive");
  ARREG_CHECK_INPUT(radius_edge_ratio >= 2, "", "radius_edge_ratio", "must be >= 2");
}

LabeledTetMesh MeshKidney(const KidneyShape& shape, const KidneyMeshOptions& options) {
  shape.Check();
  options.Check();
  using K = CGAL::Exact_predicates_inexact_constructions_kernel;
  using Function = std::function<int(const K::Point_3&)>;
  using Domain = CGAL::Labeled_mesh_domain_3<K>;
  using Tr = CGAL::Mesh_triangulation_3<Domain, CGAL::Default, CGAL::Sequential_tag>::type;
  using C3t3 = CGAL::Mesh_complex_3_in_triangulation_3<Tr>;
  using Criteria = CGAL::Mesh_criteria_3<Tr>;

  const Function label = [&shape](const K::Point_3& p) {
    return shape.Label(Eigen::Vector3d(p.x(), p.y(), p.z()));
  };
  const Eigen::Vector3d half = shape.size_mm / 2 + Eigen::Vector3d::Constant(2.0 + shape.bend_mm);
  // Fixed generator: the mesh must be the same on every run.
  CGAL::Random random(20261121);
  Domain domain(label,
                K::Iso_cuboid_3(-half.x(), -half.y(), -half.z(), half.x(), half.y(), half.z()),
                1e-6 * shape.size_mm.maxCoeff(), CGAL::Null_subdomain_index(), &random);
  namespace p = CGAL::parameters;
  Criteria criteria(p::facet_angle = 25, p::facet_size = options.facet_size_mm,
                    p::facet_distance = options.facet_distance_mm,
                    p::cell_radius_edge_ratio = options.radius_edge_ratio,
                    p::cell_size = options.cell_size_mm);
  CGAL::get_default_random() = CGAL::Random(20261121);
  const C3t3 c3t3 = CGAL::make_mesh_3<C3t3>(domain, criteria, CGAL::parameters::no_perturb(),
                                            CGAL::parameters::no_exude());
  std::map<Tr::Vertex_handle, int> index;
  std::vector<Eigen::Vector3d> vertices;
  std::vector<Eigen::Vector4i> tets;
  std::vector<int> labels;
  for (auto c = c3t3.cells_in_complex_begin(); c != c3t3.cells_in_complex_end(); ++c) {
    Eigen::Vector4i t;
    for (int k = 0; k < 4; ++k) {
      const Tr::Vertex_handle v = c->vertex(k);
      auto it = index.find(v);
      if (it == index.end()) {
        it = index.emplace(v, static_cast<int>(vertices.size())).first;
        const auto& p = v->point();
        vertices.emplace_back(CGAL::to_double(p.x()), CGAL::to_double(p.y()),
                              CGAL::to_double(p.z()));
      }
      t[k] = it->second;
    }
    tets.push_back(t);
    labels.push_back(c3t3.subdomain_index(c) == 2 ? 2 : 1);
  }
  ARREG_CHECK_INPUT(!tets.empty(), "", "kidney", "CGAL produced an empty mesh");
  LabeledTetMesh out;
  out.mesh.vertices.resize(vertices.size(), 3);
  for (size_t v = 0; v < vertices.size(); ++v) out.mesh.vertices.row(v) = vertices[v].transpose();
  out.mesh.tetrahedra.resize(tets.size(), 4);
  for (size_t t = 0; t < tets.size(); ++t) out.mesh.tetrahedra.row(t) = tets[t].transpose();
  out.labels = Eigen::Map<Eigen::VectorXi>(labels.data(), labels.size());
  FixOrientation(&out.mesh);
  return out;
}

}  // namespace arreg::synth
