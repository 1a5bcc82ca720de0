#include "mechanics/high_order_mesh.h"

#include <algorithm>
#include <map>

#include "core/error.h"

namespace arreg::mechanics {

std::vector<std::array<int, 4>> BernsteinIndices(int degree) {
  std::vector<std::array<int, 4>> out;
  for (int a = degree; a >= 0; --a)
    for (int b = degree - a; b >= 0; --b)
      for (int c = degree - a - b; c >= 0; --c) out.push_back({a, b, c, degree - a - b - c});
  // Lexicographic descending order puts (k,0,0,0) first but (0,k,0,0) after all
  // points with a0 > 0; move the four vertex points to the front in vertex order
  // so that degree 1 and the first four entries of every degree are the vertices.
  std::stable_partition(out.begin(), out.end(), [degree](const std::array<int, 4>& alpha) {
    return *std::max_element(alpha.begin(), alpha.end()) == degree;
  });
  return out;
}

int BernsteinCount(int degree) { return (degree + 1) * (degree + 2) * (degree + 3) / 6; }

HighOrderTetMesh RaiseTetMesh(const TetMesh& mesh, int degree) {
  ARREG_CHECK_INPUT(degree >= 1 && degree <= 3, "", "degree", "must be 1, 2 or 3, got ", degree);
  const int num_vertices = mesh.num_vertices();
  for (int t = 0; t < mesh.num_tetrahedra(); ++t)
    for (int c = 0; c < 4; ++c)
      ARREG_CHECK_INPUT(mesh.tetrahedra(t, c) >= 0 && mesh.tetrahedra(t, c) < num_vertices, "",
                        "tetrahedra", "element ", t, " has vertex index ", mesh.tetrahedra(t, c),
                        " out of range");
  const std::vector<std::array<int, 4>> indices = BernsteinIndices(degree);
  HighOrderTetMesh out;
  out.degree = degree;
  out.num_vertices = num_vertices;
  out.elements.resize(mesh.num_tetrahedra(), static_cast<int>(indices.size()));
  std::vector<Eigen::RowVector3d> extra;
  // A control point is identified by the multiset of vertices that span it (vertex
  // v_i repeated alpha_i times, sorted): the same on every element sharing them.
  std::map<std::vector<int>, int> node_of;
  for (int t = 0; t < mesh.num_tetrahedra(); ++t) {
    for (size_t k = 0; k < indices.size(); ++k) {
      const std::array<int, 4>& alpha = indices[k];
      std::vector<int> key;
      Eigen::RowVector3d position = Eigen::RowVector3d::Zero();
      for (int i = 0; i < 4; ++i) {
        const int v = mesh.tetrahedra(t, i);
        key.insert(key.end(), alpha[i], v);
        position += alpha[i] * mesh.vertices.row(v) / degree;
      }
      std::sort(key.begin(), key.end());
      int node = -1;
      if (key.front() == key.back()) {
        node = key.front();  // a vertex
      } else {
        auto [it, inserted] =
            node_of.emplace(std::move(key), num_vertices + static_cast<int>(extra.size()));
        if (inserted) extra.push_back(position);
        node = it->second;
      }
      out.elements(t, static_cast<int>(k)) = node;
    }
  }
  out.nodes.resize(num_vertices + static_cast<int>(extra.size()), 3);
  out.nodes.topRows(num_vertices) = mesh.vertices;
  for (size_t i = 0; i < extra.size(); ++i) out.nodes.row(num_vertices + i) = extra[i];
  return out;
}

}  // namespace arreg::mechanics
