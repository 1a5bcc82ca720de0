#include "cutting/structure_split.h"

#include <CGAL/Box_intersection_d/Box_with_info_d.h>
#include <CGAL/Exact_predicates_exact_constructions_kernel.h>
#include <CGAL/Polygon_mesh_processing/clip.h>
#include <CGAL/Polygon_mesh_processing/orient_polygon_soup.h>
#include <CGAL/Polygon_mesh_processing/polygon_soup_to_polygon_mesh.h>
#include <CGAL/Side_of_triangle_mesh.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/box_intersection_d.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <numeric>
#include <optional>
#include <set>
#include <string>
#include <tuple>
#include <vector>

#include "core/error.h"
#include "core/mesh_ops.h"

namespace arreg::cutting {
namespace {

// Exact constructions: intersection points a hair apart (a crack vertex within 1e-11 mm of the
// structure, as where two meshes of one shape share sample points) stay distinct points.
using Kernel = CGAL::Exact_predicates_exact_constructions_kernel;
using Point = Kernel::Point_3;
using Mesh = CGAL::Surface_mesh<Point>;
using VertexIndex = Mesh::Vertex_index;
using FaceIndex = Mesh::Face_index;
namespace PMP = CGAL::Polygon_mesh_processing;

// Rest positions of the tet mesh, compared exactly (the two lips of a crack share them).
using Key = std::array<double, 3>;
Key KeyOf(const Eigen::Vector3d& p) { return {p.x(), p.y(), p.z()}; }
Eigen::Vector3d ToEigen(const Point& p) {
  return {CGAL::to_double(p.x()), CGAL::to_double(p.y()), CGAL::to_double(p.z())};
}

// Numbers the distinct exact points: the corefinement puts the same point into both meshes.
class PointIds {
 public:
  int operator()(const Point& p) {
    return ids_.emplace(p, static_cast<int>(ids_.size())).first->second;
  }

 private:
  struct Less {
    bool operator()(const Point& a, const Point& b) const {
      return CGAL::compare_xyz(a, b) == CGAL::SMALLER;
    }
  };
  std::map<Point, int, Less> ids_;
};

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

// The crack's `kept` faces as a CGAL mesh. Where cracks meet along an edge or touch at a vertex (a
// curved S folding through snapped vertices), the halfedge mesh cannot hold them as they are:
// orient_polygon_soup duplicates the vertices there and keeps the sheets' orientations.
Mesh CrackToMesh(const SurfaceMesh& crack, const std::vector<bool>& kept) {
  std::vector<Point> points;
  std::vector<std::array<std::size_t, 3>> polygons;
  std::vector<int> index(crack.vertices.rows(), -1);
  for (int f = 0; f < crack.num_faces(); ++f) {
    if (!kept[f]) continue;
    std::array<std::size_t, 3> polygon;
    for (int k = 0; k < 3; ++k) {
      const int v = crack.faces(f, k);
      if (index[v] < 0) {
        index[v] = static_cast<int>(points.size());
        points.emplace_back(crack.vertices(v, 0), crack.vertices(v, 1), crack.vertices(v, 2));
      }
      polygon[k] = static_cast<std::size_t>(index[v]);
    }
    polygons.push_back(polygon);
  }
  const size_t given = points.size();
  PMP::orient_polygon_soup(points, polygons);
  if (points.size() > given) {
    // orient_polygon_soup duplicated the crack's non-manifold vertices (where two sheets of the
    // crack touch in a point); coincident copies make the mesh self-intersecting, which the
    // corefinement does not allow (it crashed on such a crack). Each copy, and the vertex it
    // copies, moves a tiny step towards the centroid of its own faces, so the sheets no longer
    // touch.
    std::map<Key, std::vector<size_t>> copies;
    for (size_t i = 0; i < points.size(); ++i)
      copies[{CGAL::to_double(points[i].x()), CGAL::to_double(points[i].y()),
              CGAL::to_double(points[i].z())}]
          .push_back(i);
    std::vector<Eigen::Vector3d> centroid(points.size(), Eigen::Vector3d::Zero());
    std::vector<int> count(points.size(), 0);
    double edge_sum = 0;
    int edges = 0;
    for (const auto& polygon : polygons)
      for (int k = 0; k < 3; ++k) {
        const Point& p = points[polygon[k]];
        const Point& q = points[polygon[(k + 1) % 3]];
        edge_sum += std::sqrt(CGAL::to_double(CGAL::squared_distance(p, q)));
        ++edges;
        for (int j = 0; j < 3; ++j) {
          const Point& r = points[polygon[j]];
          centroid[polygon[k]] += Eigen::Vector3d(CGAL::to_double(r.x()), CGAL::to_double(r.y()),
                                                  CGAL::to_double(r.z())) /
                                  3.0;
        }
        ++count[polygon[k]];
      }
    const double step = 1e-6 * (edges > 0 ? edge_sum / edges : 1.0);
    for (const auto& [at, same] : copies) {
      if (same.size() < 2) continue;
      const Eigen::Vector3d p(at[0], at[1], at[2]);
      for (size_t i : same) {
        if (count[i] == 0) continue;
        Eigen::Vector3d d = centroid[i] / count[i] - p;
        if (d.norm() == 0) continue;
        const Eigen::Vector3d moved = p + step * d.normalized();
        points[i] = Point(moved.x(), moved.y(), moved.z());
      }
    }
  }
  Mesh m;
  PMP::polygon_soup_to_polygon_mesh(points, polygons, m);
  return m;
}

// Where three or more of the crack's `kept` faces share an edge, keeps the two that continue
// each other most nearly straight across it and clears the others from `kept`; returns whether
// it cleared any. Such an edge is where the cutter unsewed a face across a fold of S (all three of
// its vertices within the on-surface tolerance, the face itself tilted across the slab): an
// element then hangs between two sheets of the crack, which has three sides there, while a
// split structure has two. Not split along a cleared face, the structure stays whole across it,
// and the element between the sheets carries it with the side that element is attached to.
bool DropCrackBranches(const SurfaceMesh& crack, std::vector<bool>* kept) {
  std::map<std::pair<int, int>, std::vector<int>> edge_faces;
  for (int f = 0; f < crack.num_faces(); ++f) {
    if (!(*kept)[f]) continue;
    for (int k = 0; k < 3; ++k) {
      const int u = crack.faces(f, k), w = crack.faces(f, (k + 1) % 3);
      edge_faces[std::minmax(u, w)].push_back(f);
    }
  }
  std::vector<int> branches;
  for (const auto& [edge, around] : edge_faces) {
    if (around.size() <= 2) continue;
    const Eigen::Vector3d a = crack.vertices.row(edge.first).transpose();
    const Eigen::Vector3d t = (crack.vertices.row(edge.second).transpose() - a).normalized();
    // Unit direction from the edge into each face, perpendicular to the edge.
    std::vector<Eigen::Vector3d> wing;
    for (int f : around) {
      int c = -1;  // the face's third vertex (a face with a repeated vertex has none)
      for (int k = 0; k < 3; ++k)
        if (crack.faces(f, k) != edge.first && crack.faces(f, k) != edge.second)
          c = crack.faces(f, k);
      const Eigen::Vector3d d =
          c >= 0 ? Eigen::Vector3d(crack.vertices.row(c).transpose() - a) : Eigen::Vector3d::Zero();
      wing.push_back((d - d.dot(t) * t).normalized());
    }
    size_t keep_i = 0, keep_j = 1;
    for (size_t i = 0; i < around.size(); ++i)
      for (size_t j = i + 1; j < around.size(); ++j)
        if (wing[i].dot(wing[j]) < wing[keep_i].dot(wing[keep_j])) {
          keep_i = i;
          keep_j = j;
        }
    for (size_t i = 0; i < around.size(); ++i)
      if (i != keep_i && i != keep_j) branches.push_back(around[i]);
  }
  for (int f : branches) (*kept)[f] = false;
  return !branches.empty();
}

// Removes each face whose exact reverse (same three vertices, other orientation) is a face
// too, and that reverse; returns whether it removed any.
bool RemoveDoubleLayers(std::vector<std::array<int, 3>>* faces) {
  std::map<std::array<int, 3>, std::vector<size_t>> by_vertices;
  for (size_t f = 0; f < faces->size(); ++f) {
    std::array<int, 3> key = (*faces)[f];
    std::sort(key.begin(), key.end());
    by_vertices[key].push_back(f);
  }
  std::vector<bool> drop(faces->size(), false);
  bool any = false;
  for (const auto& [key, list] : by_vertices) {
    if (list.size() != 2) continue;
    const std::array<int, 3>& f = (*faces)[list[0]];
    const std::array<int, 3>& g = (*faces)[list[1]];
    const std::array<int, 3> reversed = {g[0], g[2], g[1]};
    const bool opposite = reversed == f || reversed == std::array<int, 3>{f[1], f[2], f[0]} ||
                          reversed == std::array<int, 3>{f[2], f[0], f[1]};
    if (!opposite) continue;
    drop[list[0]] = drop[list[1]] = true;
    any = true;
  }
  if (!any) return false;
  std::vector<std::array<int, 3>> kept;
  for (size_t f = 0; f < faces->size(); ++f)
    if (!drop[f]) kept.push_back((*faces)[f]);
  faces->swap(kept);
  return true;
}

// Merges the vertices of each open half-edge (no face runs the other way along it) into those of
// the one open half-edge that runs the other way between the same two positions, when each is
// the only one there; the vertex of more faces stays. Returns whether it merged any.
bool StitchCoincidentOpenEdges(const std::vector<Eigen::Vector3d>& positions,
                               std::vector<std::array<int, 3>>* faces) {
  std::map<std::pair<int, int>, int> directed;
  std::vector<int> uses(positions.size(), 0);
  for (const auto& f : *faces)
    for (int k = 0; k < 3; ++k) {
      ++directed[{f[k], f[(k + 1) % 3]}];
      ++uses[f[k]];
    }
  std::map<std::pair<Key, Key>, std::vector<std::pair<int, int>>> open_by_position;
  for (const auto& [edge, count] : directed)
    if (count == 1 && !directed.count({edge.second, edge.first}))
      open_by_position[{KeyOf(positions[edge.first]), KeyOf(positions[edge.second])}].push_back(
          edge);
  std::vector<int> merged(positions.size());
  for (size_t v = 0; v < merged.size(); ++v) merged[v] = static_cast<int>(v);
  const auto root = [&](int v) {
    while (merged[v] != v) v = merged[v];
    return v;
  };
  bool any = false;
  for (const auto& [key, list] : open_by_position) {
    if (list.size() != 1) continue;
    const auto other = open_by_position.find({key.second, key.first});
    if (other == open_by_position.end() || other->second.size() != 1) continue;
    const auto [u, w] = list[0];
    const auto [w2, u2] = other->second[0];
    for (const auto& [a, b] : {std::make_pair(u, u2), std::make_pair(w, w2)}) {
      const int ra = root(a), rb = root(b);
      if (ra == rb) continue;
      if (uses[ra] >= uses[rb]) {
        merged[rb] = ra;
      } else {
        merged[ra] = rb;
      }
      any = true;
    }
  }
  if (!any) return false;
  for (auto& f : *faces)
    for (int& v : f) v = root(v);
  return true;
}

// Two flaws of a split closed structure where the crack touches the structure's surface, mended
// in place (positions are not changed, so neither is the enclosed volume), each as often as the
// other's mending uncovers more (a few rounds):
// - a face and its exact reverse (same three vertices), as where both caps run over a part of
//   the crack whose vertices serve both sides: a double layer enclosing nothing; both go;
// - a face cut loose along all of the curve, as a structure triangle lying in the crack: its
//   open edges run, with other vertices at the same positions, opposite to open edges of the
//   faces around the hole it left; their vertices are merged into those of the hole's faces.
void MendCoincidences(const std::vector<Eigen::Vector3d>& positions,
                      std::vector<std::array<int, 3>>* faces) {
  for (int round = 0; round < 4; ++round) {
    const bool removed = RemoveDoubleLayers(faces);
    const bool stitched = StitchCoincidentOpenEdges(positions, faces);
    if (!removed && !stitched) return;
  }
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

namespace {

// The corefinement numbers the vertices it adds in an order that follows addresses in memory:
// the same split came out numbered differently from two builds. Renumbers the vertices from
// `fixed` on (the input's keep their indices, which EmbedSplitStructure relies on) in the order
// of their positions, the copies of one position by the side their embedding point lies on
// (along a direction no mesh is aligned with: the offsets are opposite, and the normals they
// follow are sums whose rounding follows the same order), starts each face at its smallest
// index (keeping its orientation) and sorts the faces, so the output depends on the geometry.
void NumberCanonically(int fixed, std::vector<Eigen::Vector3d>* positions,
                       std::vector<Eigen::Vector3d>* embed_at,
                       std::vector<std::array<int, 3>>* faces) {
  const int n = static_cast<int>(positions->size());
  const Eigen::Vector3d generic = Eigen::Vector3d(1, std::sqrt(2.0), std::sqrt(3.0)).normalized();
  // Positions to 1e-9 mm: the two copies of a vertex can differ in their last bits, and which
  // copy gets which bits follows that order too.
  using Key = std::tuple<long long, long long, long long, double>;
  std::vector<Key> key(n);
  for (int i = fixed; i < n; ++i) {
    const Eigen::Vector3d& p = (*positions)[i];
    key[i] = {std::llround(p.x() * 1e9), std::llround(p.y() * 1e9), std::llround(p.z() * 1e9),
              ((*embed_at)[i] - p).dot(generic)};
  }
  std::vector<int> order(n - fixed);
  std::iota(order.begin(), order.end(), fixed);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return key[a] < key[b]; });
  std::vector<int> index(n);
  std::iota(index.begin(), index.end(), 0);
  std::vector<Eigen::Vector3d> p(*positions), e(*embed_at);
  for (int k = 0; k < n - fixed; ++k) {
    index[order[k]] = fixed + k;
    p[fixed + k] = (*positions)[order[k]];
    e[fixed + k] = (*embed_at)[order[k]];
  }
  *positions = std::move(p);
  *embed_at = std::move(e);
  for (std::array<int, 3>& f : *faces) {
    for (int& v : f) v = index[v];
    std::rotate(f.begin(), std::min_element(f.begin(), f.end()), f.end());
  }
  std::sort(faces->begin(), faces->end());
}

// One try of SplitAlongCrack (below), without its final check: a capped result is only meant to
// be used when it is a closed oriented manifold.
SplitStructure SplitOnce(const SurfaceMesh& structure, const SurfaceMesh& crack, double offset_mm) {
  SplitStructure out;
  out.surface.vertices = structure.vertices;
  out.surface.faces = structure.faces;
  out.embed_at_mm = structure.vertices;
  if (crack.num_faces() == 0 || structure.num_faces() == 0) return out;
  // Bounding boxes per face (double coordinates: exact), and of each whole surface.
  using Box = CGAL::Box_intersection_d::Box_with_info_d<double, 3, int>;
  const auto face_boxes = [](const SurfaceMesh& m, CGAL::Bbox_3* all) {
    std::vector<Box> boxes;
    boxes.reserve(static_cast<size_t>(m.num_faces()));
    for (int f = 0; f < m.num_faces(); ++f) {
      CGAL::Bbox_3 box;
      for (int k = 0; k < 3; ++k) {
        const auto& p = m.vertices.row(m.faces(f, k));
        box += CGAL::Bbox_3(p.x(), p.y(), p.z(), p.x(), p.y(), p.z());
      }
      *all += box;
      boxes.emplace_back(box, f);
    }
    return boxes;
  };
  CGAL::Bbox_3 structure_box, crack_box;
  std::vector<Box> structure_boxes = face_boxes(structure, &structure_box);  // sorted below
  std::vector<Box> crack_boxes = face_boxes(crack, &crack_box);
  // A crack whose bounding box misses the structure's neither crosses it nor lies inside it.
  if (!CGAL::do_overlap(crack_box, structure_box)) return out;

  // Only the structure's faces near the crack take part in the corefinement (the patch): those
  // whose bounding box meets a crack face's, and every face around their vertices, so that the
  // intersection curve and the stars of the vertices it may duplicate lie inside the patch.
  // Likewise only the crack's faces whose box meets the structure's can cross it or lie in it.
  const int n_structure = static_cast<int>(structure.vertices.rows());
  std::vector<bool> crack_kept(crack.num_faces(), false);
  crack_boxes.erase(
      std::remove_if(crack_boxes.begin(), crack_boxes.end(),
                     [&](const Box& b) { return !CGAL::do_overlap(b.bbox(), structure_box); }),
      crack_boxes.end());
  for (const Box& b : crack_boxes) crack_kept[b.info()] = true;
  if (DropCrackBranches(crack, &crack_kept))
    crack_boxes.erase(std::remove_if(crack_boxes.begin(), crack_boxes.end(),
                                     [&](const Box& b) { return !crack_kept[b.info()]; }),
                      crack_boxes.end());
  std::vector<bool> near_vertex(n_structure, false);
  CGAL::box_intersection_d(structure_boxes.begin(), structure_boxes.end(), crack_boxes.begin(),
                           crack_boxes.end(), [&](const Box& s, const Box&) {
                             for (int k = 0; k < 3; ++k)
                               near_vertex[structure.faces(s.info(), k)] = true;
                           });
  std::vector<int> patch_faces, other_faces;
  for (int f = 0; f < structure.num_faces(); ++f) {
    const auto& face = structure.faces.row(f);
    (near_vertex[face(0)] || near_vertex[face(1)] || near_vertex[face(2)] ? patch_faces
                                                                          : other_faces)
        .push_back(f);
  }
  const SurfaceTopology topology = AnalyzeSurface(structure);
  const bool closed = topology.closed() && topology.num_nonmanifold_edges == 0;

  // The patch as a CGAL mesh: patch vertex j (before the split) is structure vertex
  // patch_vertex[j]; the vertices the split adds follow the structure's in the output.
  std::vector<int> local(n_structure, -1), patch_vertex;
  RowMatX3i patch(static_cast<Eigen::Index>(patch_faces.size()), 3);
  for (size_t f = 0; f < patch_faces.size(); ++f)
    for (int k = 0; k < 3; ++k) {
      const int v = structure.faces(patch_faces[f], k);
      if (local[v] < 0) {
        local[v] = static_cast<int>(patch_vertex.size());
        patch_vertex.push_back(v);
      }
      patch(static_cast<Eigen::Index>(f), k) = local[v];
    }
  RowMatX3d patch_positions(static_cast<Eigen::Index>(patch_vertex.size()), 3);
  for (size_t j = 0; j < patch_vertex.size(); ++j)
    patch_positions.row(static_cast<Eigen::Index>(j)) = structure.vertices.row(patch_vertex[j]);
  Mesh a = ToMesh(patch_positions, patch, "internal structure");
  Mesh b = CrackToMesh(crack, crack_kept);
  const int faces_before = static_cast<int>(a.number_of_faces());
  if (faces_before > 0) {
    try {
      // Corefines both meshes (the crack gets the intersection curve too) and duplicates the
      // structure's vertices along the curve.
      PMP::split(a, b);
    } catch (const std::exception& e) {
      throw Error("", "SplitAlongCrack", std::string("corefinement failed: ") + e.what());
    }
  }
  out.added_faces = static_cast<int>(a.number_of_faces()) - faces_before;
  const int n_patch = static_cast<int>(patch_vertex.size());
  // Output index of patch vertex j (the split adds vertices and removes none).
  const auto global = [&](VertexIndex v) {
    const int j = static_cast<int>(v.idx());
    return j < n_patch ? patch_vertex[j] : n_structure + (j - n_patch);
  };

  // The crack's vertices by point id.
  PointIds id_of;
  std::map<int, VertexIndex> on_crack;
  std::vector<int> crack_id(b.num_vertices(), -1);
  for (VertexIndex v : b.vertices()) {
    crack_id[v.idx()] = id_of(b.point(v));
    if (!b.is_isolated(v)) on_crack.emplace(crack_id[v.idx()], v);
  }

  // The output's vertices and faces and, per position on the crack, how many copies it has.
  const int nv = n_structure + static_cast<int>(a.number_of_vertices()) - n_patch;
  std::vector<Eigen::Vector3d> positions(nv), embed_at;
  for (int i = 0; i < n_structure; ++i) positions[i] = structure.vertices.row(i).transpose();
  std::vector<int> key_of(nv, -1);  // the point id of a patch vertex
  std::map<int, int> copies;
  for (VertexIndex v : a.vertices()) {
    const int i = global(v);
    positions[i] = ToEigen(a.point(v));
    key_of[i] = id_of(a.point(v));
    if (!a.is_isolated(v) && on_crack.count(key_of[i])) ++copies[key_of[i]];
  }
  embed_at = positions;
  std::vector<std::array<int, 3>> faces;
  faces.reserve(other_faces.size() + a.number_of_faces());
  for (const int f : other_faces)
    faces.push_back({structure.faces(f, 0), structure.faces(f, 1), structure.faces(f, 2)});
  for (FaceIndex f : a.faces()) {
    std::array<int, 3> face;
    int k = 0;
    for (VertexIndex w : a.vertices_around_face(a.halfedge(f))) face[k++] = global(w);
    faces.push_back(face);
  }
  // (position, side) -> output vertex; side -1 is behind the crack's normal, +1 in front. A
  // vertex on the crack the split did not duplicate (where the curve ends) serves both sides.
  std::map<std::pair<int, int>, int> by_side;
  for (int i = 0; i < nv; ++i) {
    const auto c = copies.find(key_of[i]);
    if (c == copies.end() || c->second != 1) continue;
    by_side[{c->first, -1}] = i;
    by_side[{c->first, 1}] = i;
  }
  std::vector<int> side_of(nv, 0);

  // Caps: the crack's faces inside the structure, once per side. The side behind the crack's
  // normal (-1) is closed by a cap facing along the normal, i.e. with the crack's orientation.
  std::vector<std::array<VertexIndex, 3>> cap_faces;
  if (closed) {
    out.capped = true;
    // Each side's cap meets the structure's copy of the curve that runs the other way: in a
    // closed oriented surface every edge is traversed once in each direction. This pairs the
    // copies with the sides exactly, where tiny faces of the corefinement along the curve would
    // make a geometric side test guess. (Edges are counted among the patch's vertices: the
    // curve lies inside the patch.)
    std::map<std::pair<int, int>, int> uses;
    for (const auto& face : faces)
      for (int k = 0; k < 3; ++k) {
        const int u = face[k], w = face[(k + 1) % 3];
        if (key_of[u] >= 0 && key_of[w] >= 0) ++uses[std::minmax(u, w)];
      }
    std::map<std::pair<int, int>, std::pair<int, int>> open_edges;  // directed, by point ids
    for (size_t f = other_faces.size(); f < faces.size(); ++f)
      for (int k = 0; k < 3; ++k) {
        const auto& face = faces[f];
        const int u = face[k], w = face[(k + 1) % 3];
        if (uses[std::minmax(u, w)] == 1 && copies.count(key_of[u]) && copies.count(key_of[w]))
          open_edges[{key_of[u], key_of[w]}] = {u, w};
      }
    // The intersection curve (the crack's edges that are edges of the corefined structure too,
    // split there or not) cuts the crack into regions, each inside the structure, outside it or
    // on it (the curve bounds coplanar overlaps too), so one exact test per region classifies
    // all its faces: at its first face's exact centroid, however small that face.
    std::set<std::pair<int, int>> structure_edges;  // by point ids
    for (const auto& [edge, count] : uses)
      structure_edges.insert(std::minmax(key_of[edge.first], key_of[edge.second]));
    const auto on_curve = [&](Mesh::Halfedge_index h) {
      return structure_edges.count(
                 std::minmax(crack_id[b.source(h).idx()], crack_id[b.target(h).idx()])) > 0;
    };
    const Mesh original = ToMesh(structure.vertices, structure.faces, "internal structure");
    const CGAL::Side_of_triangle_mesh<Mesh, Kernel> inside(original);
    std::vector<bool> reached(b.num_faces(), false);
    for (FaceIndex seed : b.faces()) {
      if (reached[seed.idx()]) continue;
      std::array<VertexIndex, 3> face;
      int k = 0;
      for (VertexIndex w : b.vertices_around_face(b.halfedge(seed))) face[k++] = w;
      const Point centroid = CGAL::centroid(b.point(face[0]), b.point(face[1]), b.point(face[2]));
      const bool in = inside(centroid) == CGAL::ON_BOUNDED_SIDE;
      reached[seed.idx()] = true;
      std::vector<FaceIndex> stack = {seed};
      while (!stack.empty()) {
        const FaceIndex f = stack.back();
        stack.pop_back();
        std::array<VertexIndex, 3> corners;
        int c = 0;
        for (VertexIndex w : b.vertices_around_face(b.halfedge(f))) corners[c++] = w;
        if (in) cap_faces.push_back(corners);
        for (Mesh::Halfedge_index h : b.halfedges_around_face(b.halfedge(f))) {
          const FaceIndex g = b.face(b.opposite(h));
          if (g == Mesh::null_face() || reached[g.idx()] || on_curve(h)) continue;
          reached[g.idx()] = true;
          stack.push_back(g);
        }
      }
    }
    for (int side : {-1, 1})
      for (const auto& face : cap_faces)
        for (int k = 0; k < 3; ++k) {
          VertexIndex from = face[k], to = face[(k + 1) % 3];
          if (side == 1) std::swap(from, to);  // the front side's cap is reversed
          const int p = crack_id[from.idx()], q = crack_id[to.idx()];
          const auto e = open_edges.find({q, p});
          if (e == open_edges.end()) continue;
          by_side[{q, side}] = e->second.first;
          by_side[{p, side}] = e->second.second;
          side_of[e->second.first] = side_of[e->second.second] = side;
        }
  }
  // Copies on the crack are embedded a hair off it on their side; a copy no cap met (an open
  // structure) takes the side its faces lie on.
  for (VertexIndex v : a.vertices()) {
    const int i = global(v);
    const int key = key_of[i];
    const auto c = copies.find(key);
    if (c == copies.end() || c->second == 1 || a.is_isolated(v)) continue;
    const Eigen::Vector3d n = VertexNormal(b, on_crack.at(key)).normalized();
    int side = side_of[i];
    if (side == 0) {
      double s = 0;
      for (FaceIndex f : a.faces_around_target(a.halfedge(v))) {
        if (f == Mesh::null_face()) continue;
        Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
        for (VertexIndex w : a.vertices_around_face(a.halfedge(f))) centroid += ToEigen(a.point(w));
        s += (centroid / 3 - positions[i]).dot(n);
      }
      side = s >= 0 ? 1 : -1;
      by_side.emplace(std::make_pair(key, side), i);
    }
    embed_at[i] = positions[i] + side * offset_mm * n;
  }

  if (closed) {
    // The cap's vertices: the crack's, plus midpoints of chords (below).
    struct CapVertex {
      Eigen::Vector3d p, n;  // position, unit normal of the crack
      int key;               // point id; -1 for a chord's midpoint, below for a curve edge's
      bool shared;           // one vertex for both sides
    };
    std::vector<CapVertex> vertices;
    std::map<VertexIndex, int> of_crack_vertex;
    std::vector<std::array<int, 3>> cap;
    for (const auto& crack_face : cap_faces) {
      std::array<int, 3> face;
      for (int k = 0; k < 3; ++k) {
        const VertexIndex w = crack_face[k];
        auto [it, added] = of_crack_vertex.emplace(w, static_cast<int>(vertices.size()));
        if (added) {
          // Shared: where the crack ends inside the structure (its front, or the organ's
          // surface when the structure reaches beyond it), or where the structure's split
          // ends (a curve vertex serving both sides).
          const int key = crack_id[w.idx()];
          const auto l = by_side.find({key, -1}), r = by_side.find({key, 1});
          const bool shared = b.is_border(w) ||
                              (l != by_side.end() && r != by_side.end() && l->second == r->second);
          vertices.push_back({ToEigen(b.point(w)), VertexNormal(b, w).normalized(), key, shared});
        }
        face[k] = it->second;
      }
      cap.push_back(face);
    }
    // A point of the crack can be several vertices of it (orient_polygon_soup duplicates the
    // points where sheets touch); shared by one of them, it is shared by all: both sides use
    // one output vertex there, so the chords through it are split below on every sheet.
    std::set<int> shared_keys;
    for (const CapVertex& v : vertices)
      if (v.shared && v.key >= 0) shared_keys.insert(v.key);
    for (CapVertex& v : vertices)
      if (v.key >= 0 && shared_keys.count(v.key)) v.shared = true;
    // A chord (an edge inside the cap between two shared vertices) would become one edge of
    // both caps, with four faces: it is split at its midpoint, which has a copy per side.
    std::map<std::pair<int, int>, int> uses;
    for (const auto& face : cap)
      for (int k = 0; k < 3; ++k) {
        const int u = face[k], w = face[(k + 1) % 3];
        ++uses[{std::min(u, w), std::max(u, w)}];
      }
    for (const auto& [edge, count] : uses) {
      if (count != 2 || !vertices[edge.first].shared || !vertices[edge.second].shared) continue;
      const int m = static_cast<int>(vertices.size());
      const CapVertex& u = vertices[edge.first];
      const CapVertex& w = vertices[edge.second];
      const CapVertex mid{(u.p + w.p) / 2, (u.n + w.n).normalized(), -1, false};
      vertices.push_back(mid);  // after `mid` is built: push_back may move u and w
      for (size_t f = 0, n = cap.size(); f < n; ++f)
        for (int k = 0; k < 3; ++k) {
          const int a0 = cap[f][k], a1 = cap[f][(k + 1) % 3], a2 = cap[f][(k + 2) % 3];
          if (std::min(a0, a1) != edge.first || std::max(a0, a1) != edge.second) continue;
          cap[f] = {a0, m, a2};
          cap.push_back({m, a1, a2});
          break;
        }
    }
    // A curve edge between two curve ends (a piece of the curve one edge long) is not split,
    // so its two faces and the two caps would make four on one edge: the edge is split at its
    // midpoint in the structure's faces too, with a copy of the midpoint per side.
    std::map<std::pair<int, int>, int> structure_face;  // directed edge -> face (the patch's)
    const auto index_faces = [&](size_t from) {
      for (size_t f = from; f < faces.size(); ++f)
        for (int k = 0; k < 3; ++k)
          structure_face[{faces[f][k], faces[f][(k + 1) % 3]}] = static_cast<int>(f);
    };
    const auto single = [&](const CapVertex& v) {  // the output vertex serving both sides
      const auto l = v.key >= 0 ? by_side.find({v.key, -1}) : by_side.end();
      const auto r = v.key >= 0 ? by_side.find({v.key, 1}) : by_side.end();
      return l != by_side.end() && r != by_side.end() && l->second == r->second ? l->second : -1;
    };
    int next_key = -2;  // keys of such midpoints: below -1, apart from point ids
    for (size_t f = 0; f < cap.size(); ++f)
      for (int k = 0; k < 3; ++k) {
        const int a0 = cap[f][k], a1 = cap[f][(k + 1) % 3], a2 = cap[f][(k + 2) % 3];
        const auto count = uses.find({std::min(a0, a1), std::max(a0, a1)});
        if (count == uses.end() || count->second != 1) continue;
        const int s0 = single(vertices[a0]), s1 = single(vertices[a1]);
        if (s0 < 0 || s1 < 0) continue;
        if (structure_face.empty()) index_faces(other_faces.size());  // once, when needed
        // The side -1 cap runs a0 -> a1 (the crack's orientation): the structure's face of that
        // side runs s1 -> s0, the other side's s0 -> s1.
        const auto behind = structure_face.find({s1, s0}), front = structure_face.find({s0, s1});
        if (behind == structure_face.end() || front == structure_face.end()) continue;
        const CapVertex& u = vertices[a0];
        const CapVertex& w = vertices[a1];
        const CapVertex mid{(u.p + w.p) / 2, (u.n + w.n).normalized(), next_key--, false};
        for (int side : {-1, 1}) {
          const int m = static_cast<int>(positions.size());
          positions.push_back(mid.p);
          embed_at.push_back(mid.p + side * offset_mm * mid.n);
          by_side[{mid.key, side}] = m;
          const int from = side < 0 ? s1 : s0, to = side < 0 ? s0 : s1;
          const int split = (side < 0 ? behind : front)->second;
          int third = -1;
          for (int c = 0; c < 3; ++c)
            if (faces[split][c] != from && faces[split][c] != to) third = faces[split][c];
          faces[split] = {from, m, third};
          faces.push_back({m, to, third});
          for (const int g : {split, static_cast<int>(faces.size()) - 1})
            for (int c = 0; c < 3; ++c) structure_face[{faces[g][c], faces[g][(c + 1) % 3]}] = g;
        }
        const int c = static_cast<int>(vertices.size());
        vertices.push_back(mid);  // after `mid` is used: push_back may move u and w
        cap[f] = {a0, c, a2};
        cap.push_back({c, a1, a2});
        k = -1;  // the face's other edges again
      }
    for (int side : {-1, 1}) {
      std::vector<int> index(vertices.size(), -1);
      for (const auto& cap_face : cap) {
        std::array<int, 3> face;
        for (int k = 0; k < 3; ++k) {
          const int c = cap_face[k];
          if (index[c] < 0) {
            const CapVertex& v = vertices[c];
            const auto found = v.key != -1 ? by_side.find({v.key, side}) : by_side.end();
            if (found != by_side.end()) {
              index[c] = found->second;
            } else {
              index[c] = static_cast<int>(positions.size());
              positions.push_back(v.p);
              embed_at.push_back(v.shared ? v.p : v.p + side * offset_mm * v.n);
              if (v.key >= 0) by_side[{v.key, side}] = index[c];
              if (v.shared && v.key >= 0) by_side[{v.key, -side}] = index[c];
            }
          }
          face[k] = index[c];
        }
        if (side == 1) std::swap(face[1], face[2]);
        faces.push_back(face);
        ++out.cap_faces;
      }
    }
  }

  if (out.capped) MendCoincidences(positions, &faces);
  NumberCanonically(n_structure, &positions, &embed_at, &faces);
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

}  // namespace

SplitStructure SplitAlongCrack(const SurfaceMesh& structure, const SurfaceMesh& crack,
                               double offset_mm) {
  ARREG_CHECK_INPUT(offset_mm > 0, "", "SplitAlongCrack", "offset_mm must be positive, got ",
                    offset_mm);
  // A first attempt that fails, by corefinement error or non-manifold caps, is retried below.
  // CGAL's corefinement refuses intersection curves that cross each other off a vertex
  // ("Unauthorized intersections of constraints"), which a crack grazing the structure's faces
  // can make; the moved crack meets the structure generically.
  std::optional<Error> first_error;
  SurfaceTopology result;
  try {
    SplitStructure out = SplitOnce(structure, crack, offset_mm);
    if (!out.capped) return out;
    result = AnalyzeSurface(out.surface);
    if (result.closed_oriented_manifold()) return out;
  } catch (const Error& e) {
    first_error = e;
  }
  // The exact predicates see the crack's contacts with the structure's surface as they are: a
  // crack vertex on a structure face or edge, a crack face in a structure face's plane. The
  // mendings above repair the usual results of such contacts; where a contact still leaves the
  // caps on a non-manifold edge (e.g. a curve piece ending at a curve vertex that the
  // corefinement duplicated for another piece, and did not split itself), the crack is moved
  // by a step far below any length of the model, along a direction no mesh is aligned with, and
  // the split made again: the contact is then a crossing or no contact, as it is for almost every
  // placement of the crack.
  const BoundingBox box = ComputeBoundingBox(structure.vertices);
  const double step = 1e-9 * (1 + box.size().norm());  // mm
  for (const Eigen::RowVector3d& direction :
       {Eigen::RowVector3d(1, std::sqrt(2.0), std::sqrt(3.0)).normalized(),
        Eigen::RowVector3d(-std::sqrt(3.0), 1, -std::sqrt(2.0)).normalized()}) {
    SurfaceMesh moved = crack;
    moved.vertices.rowwise() += step * direction;
    SplitStructure retried;
    try {
      retried = SplitOnce(structure, moved, offset_mm);
    } catch (const Error&) {
      continue;
    }
    if (!retried.capped || AnalyzeSurface(retried.surface).closed_oriented_manifold())
      return retried;
  }
  if (first_error) throw *first_error;
  // Two caps describe two sides; where cracks branch inside the structure (three sheets on one
  // edge) the sides are more than two, which this construction cannot represent.
  throw Error(
      "", "SplitAlongCrack",
      internal::Concat("the split structure is not a closed manifold (", result.num_boundary_edges,
                       " open and ", result.num_nonmanifold_edges,
                       " non-manifold edges): cracks branch or touch inside it"));
}

mechanics::EmbeddedPoints EmbedSplitStructure(const SplitStructure& split, const TetMesh& rest,
                                              const PreviousEmbedding& previous) {
  const RowMatX3d& at = split.embed_at_mm;
  const RowMatX3d& position = split.surface.vertices;
  mechanics::EmbeddedPoints e;
  if (previous.points == nullptr) {
    e = mechanics::EmbeddedPoints::Embed(at, rest.vertices, rest.tetrahedra);
  } else {
    ARREG_CHECK_INPUT(
        previous.rest_mm != nullptr && previous.rest_mm->rows() == previous.points->size(), "",
        "EmbedSplitStructure", "the previous embedding needs its points");
    e = *previous.points;
    const int kept = std::min(e.size(), static_cast<int>(position.rows()));
    e.Resize(static_cast<int>(position.rows()));
    std::vector<int> again;
    for (int i = 0; i < e.size(); ++i) {
      bool same = i < kept && at.row(i) == position.row(i) &&
                  previous.rest_mm->row(i) == position.row(i) && e[i].tet >= 0 &&
                  e[i].tet < rest.num_tetrahedra();
      if (same) {
        Eigen::Vector3d p = Eigen::Vector3d::Zero();
        for (int a = 0; a < 4; ++a)
          p += e[i].barycentric(a) * rest.vertices.row(rest.tetrahedra(e[i].tet, a)).transpose();
        const Eigen::Vector3d x = position.row(i).transpose();
        same = (p - x).norm() <= 1e-9 * (1 + x.norm());
      }
      if (!same) again.push_back(i);
    }
    if (!again.empty()) e.Reembed(again, at, rest.vertices, rest.tetrahedra, {});
  }
  for (int i = 0; i < e.size(); ++i) {
    if (at.row(i) == position.row(i)) continue;
    const auto& t = rest.tetrahedra.row(e[i].tet);
    e[i].barycentric = mechanics::BarycentricCoordinates(
        position.row(i).transpose(), rest.vertices.row(t(0)).transpose(),
        rest.vertices.row(t(1)).transpose(), rest.vertices.row(t(2)).transpose(),
        rest.vertices.row(t(3)).transpose());
  }
  return e;
}

}  // namespace arreg::cutting
