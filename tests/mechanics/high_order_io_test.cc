// Gmsh second-order meshes (element type 11, 10-node tetrahedra) read into Bernstein
// degree 2: the Gmsh node order, the Lagrange-to-Bernstein edge conversion, shared
// edges, and the errors.
#include <gtest/gtest.h>

#include <fstream>
#include <map>
#include <random>
#include <sstream>

#include "core/error.h"
#include "core/mesh_io.h"
#include "mechanics/curved_tet.h"
#include "mechanics/high_order_mesh.h"
#include "test_util.h"

namespace arreg::mechanics {
namespace {

// A quadratic field (mm -> mm).
Eigen::Vector3d Quadratic(const Eigen::Vector3d& x) {
  return Eigen::Vector3d(x.x() + 0.02 * x.y() * x.y() - 0.01 * x.x() * x.z(),
                         x.y() + 0.03 * x.x() * x.x() + 0.1 * x.z(),
                         x.z() - 0.02 * x.x() * x.y() + 0.01 * x.z() * x.z());
}

// Gmsh's 10-node tetrahedron: nodes 4..9 on the edges 0-1, 1-2, 2-0, 3-0, 3-2, 3-1.
constexpr int kGmshEdge[6][2] = {{0, 1}, {1, 2}, {2, 0}, {3, 0}, {3, 2}, {3, 1}};

std::string Write(const std::string& name, const std::string& text) {
  const std::string path = testing::ScratchDir("high_order_io") + "/" + name;
  std::ofstream(path) << text;
  return path;
}

// Nodes (1-based tags in order) and 10-node tetrahedra as a Gmsh 2.2 or 4.1 ASCII file.
std::string GmshFile(const std::vector<Eigen::Vector3d>& nodes,
                     const std::vector<std::array<int, 10>>& tets, bool v41) {
  std::ostringstream s;
  s.precision(17);
  s << "$MeshFormat\n" << (v41 ? "4.1" : "2.2") << " 0 8\n$EndMeshFormat\n$Nodes\n";
  if (v41) {
    s << "1 " << nodes.size() << " 1 " << nodes.size() << "\n3 1 0 " << nodes.size() << "\n";
    for (size_t i = 0; i < nodes.size(); ++i) s << i + 1 << "\n";
    for (const auto& x : nodes) s << x.x() << " " << x.y() << " " << x.z() << "\n";
  } else {
    s << nodes.size() << "\n";
    for (size_t i = 0; i < nodes.size(); ++i)
      s << i + 1 << " " << nodes[i].x() << " " << nodes[i].y() << " " << nodes[i].z() << "\n";
  }
  s << "$EndNodes\n$Elements\n";
  if (v41)
    s << "1 " << tets.size() << " 1 " << tets.size() << "\n3 1 11 " << tets.size() << "\n";
  else
    s << tets.size() << "\n";
  for (size_t t = 0; t < tets.size(); ++t) {
    s << t + 1 << (v41 ? "" : " 11 2 0 1");
    for (int n : tets[t]) s << " " << n;
    s << "\n";
  }
  s << "$EndElements\n";
  return s.str();
}

// Two tetrahedra sharing the face (1, 2, 3) (tags 2, 3, 4), every node through Quadratic
// (a Lagrange P2 interpolation of the field): edge nodes tagged 6.. per distinct edge.
struct TwoTets {
  std::vector<Eigen::Vector3d> nodes;
  std::vector<std::array<int, 10>> tets;
  std::vector<Eigen::Vector3d> straight_corners;
};
TwoTets MakeTwoTets(bool curved) {
  TwoTets m;
  m.straight_corners = {{0, 0, 0}, {10, 0, 0}, {0, 10, 0}, {0, 0, 10}, {8, 8, 8}};
  const auto map = [&](const Eigen::Vector3d& x) { return curved ? Quadratic(x) : x; };
  for (const auto& x : m.straight_corners) m.nodes.push_back(map(x));
  std::map<std::pair<int, int>, int> edge_tag;
  const int corners[2][4] = {{1, 2, 3, 4}, {2, 3, 4, 5}};  // tags; the second is positive too
  for (const auto& c : corners) {
    std::array<int, 10> tet;
    for (int i = 0; i < 4; ++i) tet[i] = c[i];
    for (int e = 0; e < 6; ++e) {
      const int a = c[kGmshEdge[e][0]], b = c[kGmshEdge[e][1]];
      auto [it, inserted] =
          edge_tag.emplace(std::minmax(a, b), static_cast<int>(m.nodes.size()) + 1);
      if (inserted)
        m.nodes.push_back(map(0.5 * (m.straight_corners[a - 1] + m.straight_corners[b - 1])));
      tet[4 + e] = it->second;
    }
    m.tets.push_back(tet);
  }
  return m;
}

TEST(GmshQuadratic, StraightEdgeNodesGiveTheRaisedMesh) {
  const TwoTets m = MakeTwoTets(false);
  for (bool v41 : {false, true}) {
    const HighOrderTetMesh mesh =
        ReadHighOrderTetMesh(Write("straight.msh", GmshFile(m.nodes, m.tets, v41)));
    EXPECT_EQ(mesh.degree, 2);
    EXPECT_EQ(mesh.num_vertices, 5);
    EXPECT_EQ(mesh.num_nodes(), 5 + 9);
    TetMesh linear;
    linear.vertices.resize(5, 3);
    for (int i = 0; i < 5; ++i) linear.vertices.row(i) = m.straight_corners[i].transpose();
    linear.tetrahedra.resize(2, 4);
    linear.tetrahedra << 0, 1, 2, 3, 1, 2, 3, 4;
    const HighOrderTetMesh raised = RaiseTetMesh(linear, 2);
    EXPECT_EQ(mesh.elements, raised.elements);
    EXPECT_LT((mesh.nodes - raised.nodes).cwiseAbs().maxCoeff(), 1e-14);
  }
}

TEST(GmshQuadratic, CurvedElementsInterpolateEveryFileNodeAndTheQuadraticField) {
  const TwoTets m = MakeTwoTets(true);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (bool v41 : {false, true}) {
    const HighOrderTetMesh mesh =
        ReadHighOrderTetMesh(Write("curved.msh", GmshFile(m.nodes, m.tets, v41)));
    ASSERT_EQ(mesh.num_elements(), 2);
    EXPECT_EQ(mesh.num_nodes(), 14);
    for (int t = 0; t < 2; ++t) {
      const Eigen::MatrixX3d control = ElementControlPoints(mesh, mesh.nodes, t);
      // Every file node of the element is where the Bezier map puts it (the Gmsh order).
      for (int e = 0; e < 6; ++e) {
        Eigen::Vector4d L = Eigen::Vector4d::Zero();
        L[kGmshEdge[e][0]] = L[kGmshEdge[e][1]] = 0.5;
        const Eigen::Vector3d file_node = m.nodes[m.tets[t][4 + e] - 1];
        EXPECT_LT((BezierTetPoint(2, control, L) - file_node).norm(), 1e-12)
            << "tet " << t << " Gmsh edge node " << 4 + e;
      }
      // The P2 Lagrange interpolant of a quadratic field is the field: the Bezier map is
      // Quadratic(X(L)) everywhere.
      for (int s = 0; s < 20; ++s) {
        Eigen::Vector4d L(u(rng), u(rng), u(rng), u(rng));
        L /= L.sum();
        Eigen::Vector3d X = Eigen::Vector3d::Zero();
        for (int i = 0; i < 4; ++i) X += L[i] * m.straight_corners[m.tets[t][i] - 1];
        EXPECT_LT((BezierTetPoint(2, control, L) - Quadratic(X)).norm(), 1e-12);
      }
    }
  }
}

// The same curved mesh through VTK (quadratic tetra, its own node order), ASCII and binary:
// the control points equal the in-memory conversion's.
TEST(GmshQuadratic, VtkQuadraticTetraGiveTheSameControlPoints) {
  const TwoTets m = MakeTwoTets(true);
  TetMesh mesh;
  mesh.vertices.resize(static_cast<int>(m.nodes.size()), 3);
  for (size_t i = 0; i < m.nodes.size(); ++i)
    mesh.vertices.row(static_cast<int>(i)) = m.nodes[i].transpose();
  mesh.tetrahedra.resize(2, 4);
  mesh.high_order_nodes.resize(2, 6);
  // TetMesh edge order (ab, ac, ad, bc, bd, cd) from the Gmsh one (01, 12, 20, 30, 32, 31).
  constexpr int kFromGmsh[6] = {0, 2, 3, 1, 5, 4};
  for (int t = 0; t < 2; ++t) {
    for (int c = 0; c < 4; ++c) mesh.tetrahedra(t, c) = m.tets[t][c] - 1;
    for (int e = 0; e < 6; ++e) mesh.high_order_nodes(t, e) = m.tets[t][4 + kFromGmsh[e]] - 1;
  }
  const HighOrderTetMesh expected = HighOrderFromQuadraticTetMesh(mesh);
  for (bool binary : {false, true}) {
    const std::string path = testing::ScratchDir("high_order_io") + "/curved.vtk";
    MeshWriteOptions options;
    options.binary = binary;
    WriteTetMesh(path, mesh, options);
    const HighOrderTetMesh read = ReadHighOrderTetMesh(path);
    EXPECT_EQ(read.elements, expected.elements);
    EXPECT_LT((read.nodes - expected.nodes).cwiseAbs().maxCoeff(), 1e-12) << binary;
    EXPECT_GT((read.nodes.bottomRows(9) - RaiseTetMesh(
                                              [&] {
                                                TetMesh corners;
                                                corners.vertices = mesh.vertices.topRows(5);
                                                corners.tetrahedra = mesh.tetrahedra;
                                                return corners;
                                              }(),
                                              2)
                                              .nodes.bottomRows(9))
                  .cwiseAbs()
                  .maxCoeff(),
              0.1)
        << "the edges are curved";
  }
}

TEST(GmshQuadratic, ErrorsNameTheFileAndTheLineOrTheField) {
  TwoTets m = MakeTwoTets(true);
  std::string text = GmshFile(m.nodes, m.tets, false);
  // Drop the last node of the second element: 9 nodes for a 10-node tetrahedron.
  const size_t end = text.find("\n$EndElements");
  text = text.substr(0, text.rfind(' ', end)) + text.substr(end);
  const std::string path = Write("short.msh", text);
  try {
    ReadHighOrderTetMesh(path);
    FAIL() << "expected an error";
  } catch (const Error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(path), std::string::npos) << what;
    EXPECT_NE(what.find("line"), std::string::npos) << what;
  }
  // Two tetrahedra giving their shared edge mid-nodes at different positions.
  TetMesh mesh;
  mesh.vertices.resize(5 + 12, 3);
  for (int i = 0; i < 5; ++i) mesh.vertices.row(i) = m.straight_corners[i].transpose();
  mesh.tetrahedra.resize(2, 4);
  mesh.tetrahedra << 0, 1, 2, 3, 1, 2, 3, 4;
  mesh.high_order_nodes.resize(2, 6);
  for (int t = 0; t < 2; ++t)
    for (int e = 0; e < 6; ++e) {
      const int node = 5 + 6 * t + e;
      mesh.high_order_nodes(t, e) = node;
      mesh.vertices.row(node) = 0.5 * (mesh.vertices.row(mesh.tetrahedra(t, e < 3   ? 0
                                                                            : e < 5 ? 1
                                                                                    : 2)) +
                                       mesh.vertices.row(mesh.tetrahedra(t, e < 3   ? e + 1
                                                                            : e < 5 ? e - 1
                                                                                    : 3)));
    }
  mesh.vertices.row(5 + 6 + 0) += Eigen::RowVector3d(0, 0, 0.5);  // tet 1's edge 1-2 moved
  try {
    HighOrderFromQuadraticTetMesh(mesh, "in-memory");
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("high_order_nodes"), std::string::npos) << e.what();
  }
  mesh.high_order_nodes.resize(2, 5);
  EXPECT_THROW(HighOrderFromQuadraticTetMesh(mesh), Error);
}

}  // namespace
}  // namespace arreg::mechanics
