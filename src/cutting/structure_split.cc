#include "cutting/structure_split.h"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_mesh_processing/clip.h>
#include <CGAL/Side_of_triangle_mesh.h>
#include <CGAL/Surface_mesh.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <array>
#include <map>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/mesh_ops.h"

namespace arreg::cutting {
namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = Kernel::Point_3;
using Mesh = CGAL::Surface_mesh<Point>;
using VertexIndex = Mesh::Vertex_index;
using FaceIndex = Mesh::Face_index;
namespace PMP = CGAL::Polygon_mesh_processing;

// Exact coordinates: the corefinement puts the same point into both meshes.
using Key = std::array<double, 3>;
Key KeyOf(const Point& p) { return {p.x(), p.y(), p.z()}; }
Key KeyOf(const Eigen::Vector3d& p) { return {p.x(), p.y(), p.z()}; }
Eigen::Vector3d ToEigen(const Point& p) { return {p.x(), p.y(), p.z()}; }

// `faces` (#F x 3 into `vertices`) as a CGAL mesh with the same vertex numbering; throws when a
// face cannot be added (non-manifold or inconsistently oriented input).
Mesh ToMesh(const RowMatX3d& vertices, const RowMatX3i& faces, const char* what) {
  Mesh m;
  std::vector<VertexIndex> index(vertices.rows());
  for (int v = 0; v < vertices.rows(); ++v)
    index[v] = m.add_vertex(Point(vertices(v, 0), vertices(v, 1), vertices(v, 2)));
  for (int f = 0; f < faces.rows(); ++f) {
    const FaceIndex added = m.add_face(index[faces(f, 0)], index[faces(f, 1)], index[faces(f, 2)]);
    ARREG_CHECK_INPUT(added != Mesh::null_face(), "", what, "face ", f,
                      " makes the surface non-manifold or inconsistently oriented");
  }
  return m;
}

// Area-weighted normal of the faces around v (length 2 x area).
Eigen::Vector3d VertexNormal(const Mesh& m, VertexIndex v) {
  Eigen::Vector3d n = Eigen::Vector3d::Zero();
  for (FaceIndex f : m.faces_around_target(m.halfedge(v))) {
    if (f == Mesh::null_face()) continue;
    auto h = m.halfedge(f);
    const Eigen::Vector3d a = ToEigen(m.point(m.source(h)));
    const Eigen::Vector3d b = ToEigen(m.point(m.target(h)));
    const Eigen::Vector3d c = ToEigen(m.point(m.target(m.next(h))));
    n += (b - a).cross(c - a);
  }
  return n;
}

}  // namespace

SurfaceMesh CrackSurface(const TetMesh& rest) {
  const SurfaceMesh boundary = ExtractBoundary(rest);
  // The lips of a crack are boundary faces with the same three rest positions.
  std::map<std::array<Key, 3>, std::vector<int>> by_position;
  for (int f = 0; f < boundary.num_faces(); ++f) {
    std::array<Key, 3> key;
    for (int k = 0; k < 3; ++k) key[k] = KeyOf(rest.vertices.row(boundary.faces(f, k)).transpose());
    std::sort(key.begin(), key.end());
    by_position[key].push_back(f);
  }
  // One face per pair, on one canonical vertex per position so neighbouring faces share edges.
  std::map<Key, int> canonical;
  std::vector<std::array<int, 3>> faces;
  for (const auto& [key, list] : by_position) {
    if (list.size() != 2) continue;
    std::array<int, 3> face;
    for (int k = 0; k < 3; ++k) {
      const int v = boundary.faces(list[0], k);
      face[k] = canonical.emplace(KeyOf(rest.vertices.row(v).transpose()), v).first->second;
    }
    faces.push_back(face);
  }
  // Orients the faces consistently across manifold edges (breadth first per part).
  std::map<std::pair<int, int>, std::vector<int>> edge_faces;
  for (size_t f = 0; f < faces.size(); ++f)
    for (int k = 0; k < 3; ++k) {
      const int a = faces[f][k], b = faces[f][(k + 1) % 3];
      edge_faces[{std::min(a, b), std::max(a, b)}].push_back(static_cast<int>(f));
    }
  const auto traverses = [&](int f, int a, int b) {
    for (int k = 0; k < 3; ++k)
      if (faces[f][k] == a && faces[f][(k + 1) % 3] == b) return true;
    return false;
  };
  std::vector<bool> done(faces.size(), false);
  for (size_t seed = 0; seed < faces.size(); ++seed) {
    if (done[seed]) continue;
    done[seed] = true;
    std::vector<int> queue = {static_cast<int>(seed)};
    while (!queue.empty()) {
      const int f = queue.back();
      queue.pop_back();
      for (int k = 0; k < 3; ++k) {
        const int a = faces[f][k], b = faces[f][(k + 1) % 3];
        const std::vector<int>& around = edge_faces[{std::min(a, b), std::max(a, b)}];
        if (around.size() != 2) continue;
        const int g = around[0] == f ? around[1] : around[0];
        if (done[g]) continue;
        if (traverses(g, a, b)) std::swap(faces[g][1], faces[g][2]);
        done[g] = true;
        queue.push_back(g);
      }
    }
  }
  SurfaceMesh out;
  out.vertices = rest.vertices;
  out.faces.resize(static_cast<Eigen::Index>(faces.size()), 3);
  for (size_t f = 0; f < faces.size(); ++f)
    out.faces.row(static_cast<Eigen::Index>(f)) << faces[f][0], faces[f][1], faces[f][2];
  return out;
}

SplitStructure SplitAlongCrack(const SurfaceMesh& structure, const SurfaceMesh& crack,
                               double offset_mm) {
  ARREG_CHECK_INPUT(offset_mm > 0, "", "SplitAlongCrack", "offset_mm must be positive, got ",
                    offset_mm);
  SplitStructure out;
  out.surface.vertices = structure.vertices;
  out.surface.faces = structure.faces;
  out.embed_at_mm = structure.vertices;
  if (crack.num_faces() == 0 || structure.num_faces() == 0) return out;
  // A crack whose bounding box misses the structure's neither crosses it nor lies inside it.
  Eigen::AlignedBox3d crack_box, structure_box;
  for (int f = 0; f < crack.num_faces(); ++f)
    for (int k = 0; k < 3; ++k) crack_box.extend(crack.vertices.row(crack.faces(f, k)).transpose());
  for (int f = 0; f < structure.num_faces(); ++f)
    for (int k = 0; k < 3; ++k)
      structure_box.extend(structure.vertices.row(structure.faces(f, k)).transpose());
  if (!crack_box.intersects(structure_box)) return out;

  Mesh a = ToMesh(structure.vertices, structure.faces, "internal structure");
  Mesh b = ToMesh(crack.vertices, crack.faces, "crack surface");
  const bool closed = CGAL::is_closed(a);
  const Mesh original = a;
  const int faces_before = static_cast<int>(a.number_of_faces());
  try {
    // Corefines both meshes (the crack gets the intersection curve too) and duplicates the
    // structure's vertices along the curve.
    PMP::split(a, b);
  } catch (const std::exception& e) {
    throw Error("", "SplitAlongCrack", std::string("corefinement failed: ") + e.what());
  }
  out.added_faces = static_cast<int>(a.number_of_faces()) - faces_before;

  // Crack vertices by position, with their normals.
  std::map<Key, VertexIndex> on_crack;
  for (VertexIndex v : b.vertices())
    if (!b.is_isolated(v)) on_crack.emplace(KeyOf(b.point(v)), v);

  // The structure's vertices; a vertex on the crack that the split duplicated takes the side
  // of its faces (+1: where the crack's normal points), one it did not is on the crack's
  // front and serves both sides (0).
  std::map<Key, int> copies;
  for (VertexIndex v : a.vertices())
    if (!a.is_isolated(v) && on_crack.count(KeyOf(a.point(v)))) ++copies[KeyOf(a.point(v))];
  const int nv = static_cast<int>(a.number_of_vertices());
  std::vector<Eigen::Vector3d> positions, embed_at;
  std::map<std::pair<Key, int>, int> by_side;  // (position, side) -> output vertex
  positions.reserve(nv);
  for (VertexIndex v : a.vertices()) {
    const Eigen::Vector3d p = ToEigen(a.point(v));
    // The split adds vertices and removes none: output vertex i is the mesh's vertex i.
    const int i = static_cast<int>(v.idx());
    ARREG_ASSERT(i == static_cast<int>(positions.size()), "vertex ", i);
    positions.push_back(p);
    embed_at.push_back(p);
    const Key key = KeyOf(p);
    const auto c = on_crack.find(key);
    if (c == on_crack.end() || a.is_isolated(v)) continue;
    const Eigen::Vector3d n = VertexNormal(b, c->second).normalized();
    int side = 0;
    if (copies[key] > 1) {
      double s = 0;
      for (FaceIndex f : a.faces_around_target(a.halfedge(v))) {
        if (f == Mesh::null_face()) continue;
        Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
        for (VertexIndex w : a.vertices_around_face(a.halfedge(f))) centroid += ToEigen(a.point(w));
        s += (centroid / 3 - p).dot(n);
      }
      side = s > 0 ? 1 : (s < 0 ? -1 : 0);
    }
    if (side == 0) {
      by_side[{key, -1}] = i;
      by_side[{key, 1}] = i;
    } else {
      by_side[{key, side}] = i;
      embed_at.back() = p + side * offset_mm * n;
    }
  }
  std::vector<std::array<int, 3>> faces;
  for (FaceIndex f : a.faces()) {
    std::array<int, 3> face;
    int k = 0;
    for (VertexIndex w : a.vertices_around_face(a.halfedge(f)))
      face[k++] = static_cast<int>(w.idx());
    faces.push_back(face);
  }

  // Caps: the crack's faces inside the structure, once per side. The side behind the crack's
  // normal (-1) is closed by a cap facing along the normal, i.e. with the crack's orientation.
  if (closed) {
    out.capped = true;
    const CGAL::Side_of_triangle_mesh<Mesh, Kernel> inside(original);
    std::vector<FaceIndex> cap;
    for (FaceIndex f : b.faces()) {
      Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
      for (VertexIndex w : b.vertices_around_face(b.halfedge(f))) centroid += ToEigen(b.point(w));
      centroid /= 3;
      if (inside(Point(centroid.x(), centroid.y(), centroid.z())) == CGAL::ON_BOUNDED_SIDE)
        cap.push_back(f);
    }
    for (int side : {-1, 1}) {
      for (FaceIndex f : cap) {
        std::array<int, 3> face;
        int k = 0;
        for (VertexIndex w : b.vertices_around_face(b.halfedge(f))) {
          const Eigen::Vector3d p = ToEigen(b.point(w));
          const Key key = KeyOf(p);
          auto found = by_side.find({key, side});
          if (found == by_side.end()) {
            const int i = static_cast<int>(positions.size());
            positions.push_back(p);
            if (b.is_border(w)) {  // the crack's front: the model is not split there
              embed_at.push_back(p);
              by_side[{key, -side}] = i;
            } else {
              embed_at.push_back(p + side * offset_mm * VertexNormal(b, w).normalized());
            }
            found = by_side.emplace(std::make_pair(key, side), i).first;
          }
          face[k++] = found->second;
        }
        if (side == 1) std::swap(face[1], face[2]);
        faces.push_back(face);
        ++out.cap_faces;
      }
    }
  }

  out.surface.vertices.resize(static_cast<Eigen::Index>(positions.size()), 3);
  out.embed_at_mm.resize(out.surface.vertices.rows(), 3);
  for (size_t i = 0; i < positions.size(); ++i) {
    out.surface.vertices.row(static_cast<Eigen::Index>(i)) = positions[i].transpose();
    out.embed_at_mm.row(static_cast<Eigen::Index>(i)) = embed_at[i].transpose();
  }
  out.surface.faces.resize(static_cast<Eigen::Index>(faces.size()), 3);
  for (size_t f = 0; f < faces.size(); ++f)
    out.surface.faces.row(static_cast<Eigen::Index>(f)) << faces[f][0], faces[f][1], faces[f][2];
  return out;
}

mechanics::EmbeddedPoints EmbedSplitStructure(const SplitStructure& split, const TetMesh& rest) {
  mechanics::EmbeddedPoints e =
      mechanics::EmbeddedPoints::Embed(split.embed_at_mm, rest.vertices, rest.tetrahedra);
  for (int i = 0; i < e.size(); ++i) {
    if (split.embed_at_mm.row(i) == split.surface.vertices.row(i)) continue;
    const auto& t = rest.tetrahedra.row(e[i].tet);
    e[i].barycentric = mechanics::BarycentricCoordinates(
        split.surface.vertices.row(i).transpose(), rest.vertices.row(t(0)).transpose(),
        rest.vertices.row(t(1)).transpose(), rest.vertices.row(t(2)).transpose(),
        rest.vertices.row(t(3)).transpose());
  }
  return e;
}

}  // namespace arreg::cutting
