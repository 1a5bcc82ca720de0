#include "cutting/mesh_checks.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <numeric>
#include <sstream>
#include <unordered_map>
#include <vector>

#include "core/mesh_ops.h"
#include "cutting/predicates.h"

namespace arreg::cutting {

std::string MeshInvariants::ToString() const {
  std::ostringstream s;
  s << "nonpositive=" << num_nonpositive << " repeated=" << num_repeated_vertex
    << " overshared_faces=" << num_overshared_faces << " duplicates=" << num_duplicate_elements
    << " nonmanifold_edges=" << num_nonmanifold_edges
    << " nonmanifold_vertices=" << num_nonmanifold_vertices
    << " unreferenced=" << num_unreferenced_vertices << " volume=" << total_volume
    << " min_quality=" << min_quality << " min_dihedral_deg=" << min_dihedral_deg;
  return s.str();
}

MeshInvariants CheckMeshInvariants(const TetMesh& mesh) {
  MeshInvariants r;
  const int nt = mesh.num_tetrahedra(), nv = mesh.num_vertices();
  std::map<std::array<int, 3>, std::vector<std::array<int, 3>>> faces;  // sorted -> oriented
  std::map<std::array<int, 4>, int> elements;
  std::vector<char> used(nv, 0);
  r.min_quality = nt ? 1e300 : 0;
  r.min_dihedral_deg = nt ? 1e300 : 0;
  static constexpr int kFace[4][3] = {{1, 3, 2}, {0, 2, 3}, {0, 3, 1}, {0, 1, 2}};
  for (int t = 0; t < nt; ++t) {
    std::array<int, 4> q;
    std::array<Eigen::Vector3d, 4> x;
    for (int k = 0; k < 4; ++k) {
      q[k] = mesh.tetrahedra(t, k);
      used[q[k]] = 1;
      x[k] = mesh.vertices.row(q[k]).transpose();
    }
    std::array<int, 4> sorted = q;
    std::sort(sorted.begin(), sorted.end());
    if (std::adjacent_find(sorted.begin(), sorted.end()) != sorted.end()) ++r.num_repeated_vertex;
    if (elements[sorted]++ == 1) ++r.num_duplicate_elements;
    if (Orient3d(x[0], x[1], x[2], x[3]) <= 0) ++r.num_nonpositive;
    r.total_volume += TetVolume(x[0], x[1], x[2], x[3]);
    r.min_quality = std::min(r.min_quality, TetQuality(x[0], x[1], x[2], x[3]));
    r.min_dihedral_deg =
        std::min(r.min_dihedral_deg, MinDihedralAngle(x[0], x[1], x[2], x[3]) * 180.0 / M_PI);
    for (const auto& f : kFace) {
      // Outward orientation: (u, v, w, opposite) positive means the normal points
      // inwards, so the outward face is (u, w, v).
      std::array<int, 3> oriented = {q[f[0]], q[f[2]], q[f[1]]};
      std::array<int, 3> key = oriented;
      std::sort(key.begin(), key.end());
      faces[key].push_back(oriented);
    }
  }
  for (int v = 0; v < nv; ++v) r.num_unreferenced_vertices += used[v] ? 0 : 1;
  // Boundary faces and their edge/vertex manifoldness.
  std::map<std::pair<int, int>, int> edge_count;
  std::unordered_map<int, std::vector<std::array<int, 3>>> vertex_faces;
  for (const auto& [key, list] : faces) {
    if (list.size() > 2) ++r.num_overshared_faces;
    if (list.size() != 1) continue;
    const auto& f = list[0];
    for (int k = 0; k < 3; ++k) {
      const int a = f[k], b = f[(k + 1) % 3];
      ++edge_count[{std::min(a, b), std::max(a, b)}];
      vertex_faces[a].push_back(f);
    }
  }
  for (const auto& [e, count] : edge_count)
    if (count != 2) ++r.num_nonmanifold_edges;
  for (const auto& [v, list] : vertex_faces) {
    // The link of v on the boundary: edges (next, prev) of each face around v
    // must form exactly one cycle.
    std::unordered_map<int, int> next;
    bool bad = false;
    for (const auto& f : list) {
      int k = 0;
      while (f[k] != v) ++k;
      const int a = f[(k + 1) % 3], b = f[(k + 2) % 3];
      if (next.count(a)) bad = true;
      next[a] = b;
    }
    if (!bad) {
      int steps = 0;
      const int start = next.begin()->first;
      int c = start;
      do {
        auto it = next.find(c);
        if (it == next.end()) {
          bad = true;
          break;
        }
        c = it->second;
        ++steps;
      } while (c != start && steps <= static_cast<int>(next.size()));
      if (steps != static_cast<int>(next.size())) bad = true;
    }
    if (bad) ++r.num_nonmanifold_vertices;
  }
  return r;
}

}  // namespace arreg::cutting
