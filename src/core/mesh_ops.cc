#include "core/mesh_ops.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <numeric>
#include <utility>
#include <vector>

#include "core/error.h"

namespace arreg {

namespace {

constexpr double kPi = 3.14159265358979323846;

Eigen::Vector3d Row(const RowMatX3d& v, int i) { return v.row(i).transpose(); }

// Outward (from the tetrahedron) area vectors of the four faces; face k is
// the one opposite vertex k.
std::array<Eigen::Vector3d, 4> OutwardFaceNormals(const std::array<Eigen::Vector3d, 4>& p) {
  std::array<Eigen::Vector3d, 4> n;
  for (int k = 0; k < 4; ++k) {
    const Eigen::Vector3d& q0 = p[(k + 1) % 4];
    const Eigen::Vector3d& q1 = p[(k + 2) % 4];
    const Eigen::Vector3d& q2 = p[(k + 3) % 4];
    n[k] = (q1 - q0).cross(q2 - q0);
    if (n[k].dot(p[k] - q0) > 0) n[k] = -n[k];
  }
  return n;
}

// The six interior dihedral angles (radians); all zero when a face is degenerate.
std::array<double, 6> DihedralAngles(const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                     const Eigen::Vector3d& c, const Eigen::Vector3d& d) {
  const std::array<Eigen::Vector3d, 4> n = OutwardFaceNormals({a, b, c, d});
  std::array<double, 6> angles{};
  int e = 0;
  for (int k = 0; k < 4; ++k)
    for (int l = k + 1; l < 4; ++l, ++e) {
      const double nk = n[k].norm(), nl = n[l].norm();
      if (nk == 0 || nl == 0) return {};
      const double cosine = std::clamp(n[k].dot(n[l]) / (nk * nl), -1.0, 1.0);
      // Faces k and l meet at the edge opposite both; the interior angle is
      // the supplement of the angle between their outward normals.
      angles[e] = kPi - std::acos(cosine);
    }
  return angles;
}

class UnionFind {
 public:
  explicit UnionFind(int n) : parent_(n) { std::iota(parent_.begin(), parent_.end(), 0); }
  int Find(int x) {
    while (parent_[x] != x) {
      parent_[x] = parent_[parent_[x]];
      x = parent_[x];
    }
    return x;
  }
  void Union(int a, int b) {
    a = Find(a);
    b = Find(b);
    if (a != b) parent_[std::max(a, b)] = std::min(a, b);
  }
  // Labels 0..count-1 numbered in order of first appearance.
  Eigen::VectorXi Labels(int* count) {
    const int n = static_cast<int>(parent_.size());
    Eigen::VectorXi labels(n);
    std::vector<int> root_label(n, -1);
    int next = 0;
    for (int i = 0; i < n; ++i) {
      const int r = Find(i);
      if (root_label[r] < 0) root_label[r] = next++;
      labels[i] = root_label[r];
    }
    if (count) *count = next;
    return labels;
  }

 private:
  std::vector<int> parent_;
};

struct FaceKey {
  std::array<int, 3> sorted;
  int element;  // tet * 4 + local face
  bool operator<(const FaceKey& o) const {
    return sorted != o.sorted ? sorted < o.sorted : element < o.element;
  }
};

// Outward local faces of a positively oriented tetrahedron (a, b, c, d);
// each is counter-clockwise seen from outside.
constexpr int kTetFaces[4][3] = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};

std::vector<FaceKey> SortedTetFaces(const TetMesh& mesh) {
  std::vector<FaceKey> keys;
  keys.reserve(static_cast<size_t>(mesh.num_tetrahedra()) * 4);
  for (int t = 0; t < mesh.num_tetrahedra(); ++t)
    for (int f = 0; f < 4; ++f) {
      std::array<int, 3> s = {mesh.tetrahedra(t, kTetFaces[f][0]),
                              mesh.tetrahedra(t, kTetFaces[f][1]),
                              mesh.tetrahedra(t, kTetFaces[f][2])};
      std::sort(s.begin(), s.end());
      keys.push_back({s, t * 4 + f});
    }
  std::sort(keys.begin(), keys.end());
  return keys;
}

void CheckTetIndices(const TetMesh& mesh) {
  const int n = mesh.num_vertices();
  ARREG_ASSERT(mesh.tetrahedra.size() == 0 ||
                   (mesh.tetrahedra.minCoeff() >= 0 && mesh.tetrahedra.maxCoeff() < n),
               "tetrahedron vertex index out of range");
}

void CheckFaceIndices(const SurfaceMesh& mesh) {
  const int n = mesh.num_vertices();
  ARREG_ASSERT(mesh.faces.size() == 0 || (mesh.faces.minCoeff() >= 0 && mesh.faces.maxCoeff() < n),
               "face vertex index out of range");
}

}  // namespace

double SignedVolume(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                    const Eigen::Vector3d& d) {
  return (b - a).cross(c - a).dot(d - a) / 6.0;
}

Eigen::VectorXd TetVolumes(const TetMesh& mesh) {
  CheckTetIndices(mesh);
  Eigen::VectorXd volumes(mesh.num_tetrahedra());
  for (int t = 0; t < mesh.num_tetrahedra(); ++t) {
    volumes[t] = SignedVolume(
        Row(mesh.vertices, mesh.tetrahedra(t, 0)), Row(mesh.vertices, mesh.tetrahedra(t, 1)),
        Row(mesh.vertices, mesh.tetrahedra(t, 2)), Row(mesh.vertices, mesh.tetrahedra(t, 3)));
  }
  return volumes;
}

double MinDihedralAngle(const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                        const Eigen::Vector3d& c, const Eigen::Vector3d& d) {
  const auto angles = DihedralAngles(a, b, c, d);
  return *std::min_element(angles.begin(), angles.end());
}

double MaxDihedralAngle(const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                        const Eigen::Vector3d& c, const Eigen::Vector3d& d) {
  const auto angles = DihedralAngles(a, b, c, d);
  return *std::max_element(angles.begin(), angles.end());
}

double RadiusRatio(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                   const Eigen::Vector3d& d) {
  const Eigen::Vector3d u = b - a, v = c - a, w = d - a;
  const double det = u.dot(v.cross(w));  // 6 * signed volume
  const double area = 0.5 * (u.cross(v).norm() + u.cross(w).norm() + v.cross(w).norm() +
                             (c - b).cross(d - b).norm());
  // Circumcentre relative to a is num / (2 det), so R = |num| / (2 |det|);
  // inradius r = 3 |V| / area = |det| / (2 area); hence 3 r / R = 3 det^2 / (area |num|).
  const Eigen::Vector3d num =
      u.squaredNorm() * v.cross(w) + v.squaredNorm() * w.cross(u) + w.squaredNorm() * u.cross(v);
  const double denominator = area * num.norm();
  if (det == 0 || denominator == 0 || !std::isfinite(denominator)) return 0;
  const double ratio = 3 * det * det / denominator;
  return det > 0 ? ratio : -ratio;
}

TetQualitySummary ComputeTetQuality(const TetMesh& mesh) {
  CheckTetIndices(mesh);
  TetQualitySummary s;
  s.num_tetrahedra = mesh.num_tetrahedra();
  if (s.num_tetrahedra == 0) return s;
  s.min_volume = std::numeric_limits<double>::infinity();
  s.max_volume = -std::numeric_limits<double>::infinity();
  s.min_dihedral_angle_rad = std::numeric_limits<double>::infinity();
  s.max_dihedral_angle_rad = 0;
  s.min_radius_ratio = std::numeric_limits<double>::infinity();
  double ratio_sum = 0;
  for (int t = 0; t < s.num_tetrahedra; ++t) {
    const Eigen::Vector3d a = Row(mesh.vertices, mesh.tetrahedra(t, 0));
    const Eigen::Vector3d b = Row(mesh.vertices, mesh.tetrahedra(t, 1));
    const Eigen::Vector3d c = Row(mesh.vertices, mesh.tetrahedra(t, 2));
    const Eigen::Vector3d d = Row(mesh.vertices, mesh.tetrahedra(t, 3));
    const double volume = SignedVolume(a, b, c, d);
    const double mean_edge = ((b - a).norm() + (c - a).norm() + (d - a).norm() + (c - b).norm() +
                              (d - b).norm() + (d - c).norm()) /
                             6;
    if (volume < 0) ++s.num_inverted;
    if (std::abs(volume) <= 1e-12 * mean_edge * mean_edge * mean_edge) ++s.num_degenerate;
    s.total_volume += volume;
    s.min_volume = std::min(s.min_volume, volume);
    s.max_volume = std::max(s.max_volume, volume);
    const auto angles = DihedralAngles(a, b, c, d);
    s.min_dihedral_angle_rad =
        std::min(s.min_dihedral_angle_rad, *std::min_element(angles.begin(), angles.end()));
    s.max_dihedral_angle_rad =
        std::max(s.max_dihedral_angle_rad, *std::max_element(angles.begin(), angles.end()));
    const double ratio = RadiusRatio(a, b, c, d);
    s.min_radius_ratio = std::min(s.min_radius_ratio, ratio);
    ratio_sum += ratio;
  }
  s.mean_radius_ratio = ratio_sum / s.num_tetrahedra;
  return s;
}

int FixOrientation(TetMesh* mesh) {
  ARREG_ASSERT(mesh != nullptr, "null mesh");
  const Eigen::VectorXd volumes = TetVolumes(*mesh);
  const bool quadratic =
      mesh->high_order_nodes.rows() == mesh->num_tetrahedra() && mesh->high_order_nodes.cols() == 6;
  int flipped = 0;
  for (int t = 0; t < mesh->num_tetrahedra(); ++t) {
    if (!(volumes[t] < 0)) continue;
    std::swap(mesh->tetrahedra(t, 2), mesh->tetrahedra(t, 3));
    if (quadratic) {
      // Edge nodes (ab, ac, ad, bc, bd, cd) become (ab, ad, ac, bd, bc, cd).
      std::swap(mesh->high_order_nodes(t, 1), mesh->high_order_nodes(t, 2));
      std::swap(mesh->high_order_nodes(t, 3), mesh->high_order_nodes(t, 4));
    }
    ++flipped;
  }
  return flipped;
}

SurfaceMesh ExtractBoundary(const TetMesh& mesh) {
  CheckTetIndices(mesh);
  const Eigen::VectorXd volumes = TetVolumes(mesh);
  const std::vector<FaceKey> keys = SortedTetFaces(mesh);
  std::vector<std::pair<int, std::array<int, 3>>> faces;  // (tet * 4 + local face, triangle)
  for (size_t i = 0; i < keys.size();) {
    size_t j = i + 1;
    while (j < keys.size() && keys[j].sorted == keys[i].sorted) ++j;
    if (j - i == 1) {
      const int t = keys[i].element / 4, f = keys[i].element % 4;
      std::array<int, 3> tri = {mesh.tetrahedra(t, kTetFaces[f][0]),
                                mesh.tetrahedra(t, kTetFaces[f][1]),
                                mesh.tetrahedra(t, kTetFaces[f][2])};
      if (volumes[t] < 0) std::swap(tri[1], tri[2]);
      faces.push_back({keys[i].element, tri});
    }
    i = j;
  }
  // Tetrahedron order, then local face order: stable under vertex renumbering.
  std::sort(faces.begin(), faces.end());
  SurfaceMesh surface;
  surface.vertices = mesh.vertices;
  surface.faces.resize(static_cast<Eigen::Index>(faces.size()), 3);
  for (size_t f = 0; f < faces.size(); ++f)
    surface.faces.row(static_cast<Eigen::Index>(f)) << faces[f].second[0], faces[f].second[1],
        faces[f].second[2];
  return surface;
}

Eigen::VectorXi ConnectedComponents(const TetMesh& mesh, Adjacency adjacency, int* num_components) {
  CheckTetIndices(mesh);
  const int num_tets = mesh.num_tetrahedra();
  UnionFind sets(num_tets);
  if (adjacency == Adjacency::kFace) {
    const std::vector<FaceKey> keys = SortedTetFaces(mesh);
    for (size_t i = 1; i < keys.size(); ++i)
      if (keys[i].sorted == keys[i - 1].sorted)
        sets.Union(keys[i].element / 4, keys[i - 1].element / 4);
  } else {
    std::vector<int> first_tet(mesh.num_vertices(), -1);
    for (int t = 0; t < num_tets; ++t)
      for (int k = 0; k < 4; ++k) {
        int& first = first_tet[mesh.tetrahedra(t, k)];
        if (first < 0)
          first = t;
        else
          sets.Union(first, t);
      }
  }
  return sets.Labels(num_components);
}

Eigen::VectorXi ConnectedComponents(const SurfaceMesh& mesh, Adjacency adjacency,
                                    int* num_components) {
  CheckFaceIndices(mesh);
  const int num_faces = mesh.num_faces();
  UnionFind sets(num_faces);
  if (adjacency == Adjacency::kFace) {
    std::vector<std::pair<std::pair<int, int>, int>> edges;
    edges.reserve(static_cast<size_t>(num_faces) * 3);
    for (int f = 0; f < num_faces; ++f)
      for (int k = 0; k < 3; ++k) {
        const int a = mesh.faces(f, k), b = mesh.faces(f, (k + 1) % 3);
        if (a != b) edges.push_back({{std::min(a, b), std::max(a, b)}, f});
      }
    std::sort(edges.begin(), edges.end());
    for (size_t i = 1; i < edges.size(); ++i)
      if (edges[i].first == edges[i - 1].first) sets.Union(edges[i].second, edges[i - 1].second);
  } else {
    std::vector<int> first_face(mesh.num_vertices(), -1);
    for (int f = 0; f < num_faces; ++f)
      for (int k = 0; k < 3; ++k) {
        int& first = first_face[mesh.faces(f, k)];
        if (first < 0)
          first = f;
        else
          sets.Union(first, f);
      }
  }
  return sets.Labels(num_components);
}

double SurfaceArea(const SurfaceMesh& mesh) {
  CheckFaceIndices(mesh);
  double area = 0;
  for (int f = 0; f < mesh.num_faces(); ++f) {
    const Eigen::Vector3d a = Row(mesh.vertices, mesh.faces(f, 0));
    const Eigen::Vector3d b = Row(mesh.vertices, mesh.faces(f, 1));
    const Eigen::Vector3d c = Row(mesh.vertices, mesh.faces(f, 2));
    area += 0.5 * (b - a).cross(c - a).norm();
  }
  return area;
}

double EnclosedVolume(const SurfaceMesh& mesh) {
  CheckFaceIndices(mesh);
  if (mesh.num_faces() == 0) return 0;
  // Relative to the centroid of the vertices, to limit cancellation for
  // surfaces far from the origin (the sum is translation invariant when closed).
  const Eigen::Vector3d origin = mesh.vertices.colwise().mean().transpose();
  double volume = 0;
  for (int f = 0; f < mesh.num_faces(); ++f) {
    const Eigen::Vector3d a = Row(mesh.vertices, mesh.faces(f, 0)) - origin;
    const Eigen::Vector3d b = Row(mesh.vertices, mesh.faces(f, 1)) - origin;
    const Eigen::Vector3d c = Row(mesh.vertices, mesh.faces(f, 2)) - origin;
    volume += a.dot(b.cross(c));
  }
  return volume / 6.0;
}

SurfaceTopology AnalyzeSurface(const SurfaceMesh& mesh) {
  CheckFaceIndices(mesh);
  SurfaceTopology topo;
  topo.num_faces = mesh.num_faces();
  std::vector<char> used(mesh.num_vertices(), 0);
  // (min, max) vertex pair and whether the face runs min -> max.
  std::vector<std::pair<std::pair<int, int>, bool>> half_edges;
  half_edges.reserve(static_cast<size_t>(topo.num_faces) * 3);
  for (int f = 0; f < topo.num_faces; ++f) {
    const int a = mesh.faces(f, 0), b = mesh.faces(f, 1), c = mesh.faces(f, 2);
    if (a == b || b == c || a == c) ++topo.num_degenerate_faces;
    for (int k = 0; k < 3; ++k) {
      const int u = mesh.faces(f, k), v = mesh.faces(f, (k + 1) % 3);
      used[u] = 1;
      if (u != v) half_edges.push_back({{std::min(u, v), std::max(u, v)}, u < v});
    }
  }
  std::sort(half_edges.begin(), half_edges.end());
  for (size_t i = 0; i < half_edges.size();) {
    size_t j = i + 1;
    while (j < half_edges.size() && half_edges[j].first == half_edges[i].first) ++j;
    ++topo.num_edges;
    const size_t count = j - i;
    if (count == 1)
      ++topo.num_boundary_edges;
    else if (count > 2)
      ++topo.num_nonmanifold_edges;
    else if (half_edges[i].second == half_edges[i + 1].second)
      ++topo.num_misoriented_edges;
    i = j;
  }
  topo.num_referenced_vertices = static_cast<int>(std::count(used.begin(), used.end(), 1));
  topo.euler_characteristic = topo.num_referenced_vertices - topo.num_edges + topo.num_faces;
  return topo;
}

void RemoveUnreferencedVertices(SurfaceMesh* mesh, Eigen::VectorXi* old_to_new) {
  ARREG_ASSERT(mesh != nullptr, "null mesh");
  CheckFaceIndices(*mesh);
  const int n = mesh->num_vertices();
  Eigen::VectorXi map = Eigen::VectorXi::Constant(n, -1);
  for (int f = 0; f < mesh->num_faces(); ++f)
    for (int k = 0; k < 3; ++k) map[mesh->faces(f, k)] = 0;
  int next = 0;
  for (int v = 0; v < n; ++v)
    if (map[v] == 0) map[v] = next++;
  auto compact = [&](RowMatX3d* values) {
    if (values->rows() != n) return;
    RowMatX3d kept(next, 3);
    for (int v = 0; v < n; ++v)
      if (map[v] >= 0) kept.row(map[v]) = values->row(v);
    *values = std::move(kept);
  };
  compact(&mesh->vertices);
  compact(&mesh->normals);
  compact(&mesh->colors);
  for (int f = 0; f < mesh->num_faces(); ++f)
    for (int k = 0; k < 3; ++k) mesh->faces(f, k) = map[mesh->faces(f, k)];
  if (old_to_new) *old_to_new = std::move(map);
}

BoundingBox ComputeBoundingBox(const RowMatX3d& points) {
  BoundingBox box;
  if (points.rows() == 0) return box;
  box.min = points.colwise().minCoeff().transpose();
  box.max = points.colwise().maxCoeff().transpose();
  return box;
}

}  // namespace arreg
