#include "mechanics/high_order_mesh.h"

#include <algorithm>
#include <map>

#include "core/error.h"
#include "core/mesh_io.h"
#include "core/mesh_ops.h"

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

HighOrderTetMesh HighOrderFromQuadraticTetMesh(const TetMesh& mesh, const std::string& file) {
  const int num_tets = mesh.num_tetrahedra();
  ARREG_CHECK_INPUT(mesh.high_order_nodes.rows() == num_tets && mesh.high_order_nodes.cols() == 6,
                    file, "high_order_nodes", "expected ", num_tets, " x 6 edge nodes, got ",
                    mesh.high_order_nodes.rows(), " x ", mesh.high_order_nodes.cols());
  const int n = mesh.num_vertices();
  for (Eigen::Index i = 0; i < mesh.high_order_nodes.size(); ++i)
    ARREG_CHECK_INPUT(mesh.high_order_nodes.data()[i] >= 0 && mesh.high_order_nodes.data()[i] < n,
                      file, "high_order_nodes", "node index ", mesh.high_order_nodes.data()[i],
                      " out of range (", n, " nodes)");
  for (Eigen::Index i = 0; i < mesh.tetrahedra.size(); ++i)
    ARREG_CHECK_INPUT(mesh.tetrahedra.data()[i] >= 0 && mesh.tetrahedra.data()[i] < n, file,
                      "tetrahedra", "vertex index ", mesh.tetrahedra.data()[i], " out of range (",
                      n, " nodes)");
  // The corners alone, in their order, as a linear mesh; raising it numbers the edges.
  std::vector<int> corner(n, -1);
  for (Eigen::Index i = 0; i < mesh.tetrahedra.size(); ++i) corner[mesh.tetrahedra.data()[i]] = 0;
  TetMesh linear;
  int num_corners = 0;
  for (int v = 0; v < n; ++v)
    if (corner[v] == 0) corner[v] = num_corners++;
  linear.vertices.resize(num_corners, 3);
  for (int v = 0; v < n; ++v)
    if (corner[v] >= 0) linear.vertices.row(corner[v]) = mesh.vertices.row(v);
  linear.tetrahedra.resize(num_tets, 4);
  for (int t = 0; t < num_tets; ++t)
    for (int c = 0; c < 4; ++c) linear.tetrahedra(t, c) = corner[mesh.tetrahedra(t, c)];
  HighOrderTetMesh out = RaiseTetMesh(linear, 2);
  // Local control point of edge (i, j) in BernsteinIndices(2) order.
  const std::vector<std::array<int, 4>> indices = BernsteinIndices(2);
  constexpr int kEdges[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};
  int local[6];
  for (int e = 0; e < 6; ++e) {
    std::array<int, 4> alpha = {0, 0, 0, 0};
    ++alpha[kEdges[e][0]];
    ++alpha[kEdges[e][1]];
    local[e] = static_cast<int>(std::find(indices.begin(), indices.end(), alpha) - indices.begin());
  }
  std::vector<int> mid_of(out.num_nodes(), -1);
  for (int t = 0; t < num_tets; ++t) {
    for (int e = 0; e < 6; ++e) {
      const int node = out.elements(t, local[e]);
      const int mid = mesh.high_order_nodes(t, e);
      if (mid_of[node] >= 0) {
        ARREG_CHECK_INPUT(mesh.vertices.row(mid) == mesh.vertices.row(mid_of[node]), file,
                          "high_order_nodes", "tetrahedron ", t, " gives its edge ",
                          mesh.tetrahedra(t, kEdges[e][0]), "-", mesh.tetrahedra(t, kEdges[e][1]),
                          " the mid-node ", mid, ", another tetrahedron the mid-node ",
                          mid_of[node], " at a different position");
        continue;
      }
      mid_of[node] = mid;
      out.nodes.row(node) =
          2 * mesh.vertices.row(mid) - 0.5 * (mesh.vertices.row(mesh.tetrahedra(t, kEdges[e][0])) +
                                              mesh.vertices.row(mesh.tetrahedra(t, kEdges[e][1])));
    }
  }
  return out;
}

HighOrderTetMesh ReadHighOrderTetMesh(const std::string& path, int linear_degree) {
  TetMesh mesh = ReadTetMesh(path);
  FixOrientation(&mesh);
  if (mesh.high_order_nodes.size() > 0) return HighOrderFromQuadraticTetMesh(mesh, path);
  return RaiseTetMesh(mesh, linear_degree);
}

}  // namespace arreg::mechanics
