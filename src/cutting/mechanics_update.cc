#include "cutting/mechanics_update.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <unordered_set>

#include "core/error.h"
#include "cutting/predicates.h"

namespace arreg::cutting {

std::vector<int> ApplyCutChange(const CutChange& change, mechanics::MechanicalState* state) {
  ARREG_CHECK_INPUT(state != nullptr, "", "ApplyCutChange", "state is null");
  ARREG_CHECK_INPUT(state->num_vertices() == change.num_vertices_before &&
                        state->num_tetrahedra() == change.num_tetrahedra_before,
                    "", "ApplyCutChange", "the state has ", state->num_vertices(), " vertices and ",
                    state->num_tetrahedra(), " elements, the change expects ",
                    change.num_vertices_before, " and ", change.num_tetrahedra_before);
  if (!change.snapped.empty()) {
    // Snaps are applied in order (a later one may use a vertex an earlier one
    // moved), to rest, current positions and velocities alike; only the rest
    // data of the elements around the snapped vertices are recomputed.
    RowMatX3d rest = state->rest_positions(), current = state->positions(),
              velocity = state->velocities();
    std::vector<int> vertices;
    for (const SnappedVertex& s : change.snapped) {
      ARREG_CHECK_INPUT(s.index >= 0 && s.index < change.num_vertices_before && s.a >= 0 &&
                            s.a < change.num_vertices_before && s.b >= 0 &&
                            s.b < change.num_vertices_before,
                        "", "ApplyCutChange", "snapped vertex index out of range");
      for (RowMatX3d* m : {&rest, &current, &velocity})
        m->row(s.index) = (1.0 - s.t) * m->row(s.a) + s.t * m->row(s.b);
      if (std::find(vertices.begin(), vertices.end(), s.index) == vertices.end())
        vertices.push_back(s.index);
    }
    RowMatX3d moved_rest(vertices.size(), 3);
    for (size_t i = 0; i < vertices.size(); ++i) moved_rest.row(i) = rest.row(vertices[i]);
    state->SetRestPositions(vertices, moved_rest);  // throws with the state unchanged
    for (int v : vertices) {
      state->mutable_positions().row(v) = current.row(v);
      state->mutable_velocities().row(v) = velocity.row(v);
    }
  }
  const int n_new = static_cast<int>(change.new_vertices.size());
  const int n = n_new + static_cast<int>(change.duplicated.size());
  if (n > 0) {
    RowMatX3d rest(n, 3), current(n, 3), velocity(n, 3);
    // Rows are filled in index order; duplicates may copy new vertices.
    auto row_of = [&](int v, const RowMatX3d& added, const RowMatX3d& base) -> Eigen::RowVector3d {
      return v < change.num_vertices_before
                 ? Eigen::RowVector3d(base.row(v))
                 : Eigen::RowVector3d(added.row(v - change.num_vertices_before));
    };
    for (int i = 0; i < n; ++i) {
      Eigen::RowVector3d r = Eigen::RowVector3d::Zero(), x = r, v = r;
      if (i < n_new) {
        const NewVertex& nv = change.new_vertices[i];
        ARREG_ASSERT(nv.index == change.num_vertices_before + i, "new vertex order");
        for (size_t k = 0; k < nv.parents.size(); ++k) {
          r += nv.weights[k] * row_of(nv.parents[k], rest, state->rest_positions());
          x += nv.weights[k] * row_of(nv.parents[k], current, state->positions());
          v += nv.weights[k] * row_of(nv.parents[k], velocity, state->velocities());
        }
      } else {
        const DuplicatedVertex& d = change.duplicated[i - n_new];
        ARREG_ASSERT(d.index == change.num_vertices_before + i, "duplicated vertex order");
        r = row_of(d.original, rest, state->rest_positions());
        x = row_of(d.original, current, state->positions());
        v = row_of(d.original, velocity, state->velocities());
      }
      rest.row(i) = r;
      current.row(i) = x;
      velocity.row(i) = v;
    }
    state->AddVertices(rest, current, velocity);
  }
  if (change.removed_tetrahedra.empty() && change.new_tetrahedra.rows() == 0) return {};
  const mechanics::Material material =
      state->material(change.removed_tetrahedra.empty() ? 0 : change.removed_tetrahedra.front());
  return state->ReplaceTetrahedra(change.removed_tetrahedra, change.new_tetrahedra, {material});
}

int ReembedAfterCut(const CutChange& change, const std::vector<int>& new_elements,
                    const mechanics::MechanicalState& state, const RowMatX3d& points_rest,
                    mechanics::EmbeddedPoints* points) {
  ARREG_CHECK_INPUT(points != nullptr && points->size() == points_rest.rows(), "",
                    "ReembedAfterCut", "need one reference position per embedded point");
  const std::unordered_set<int> removed(change.removed_tetrahedra.begin(),
                                        change.removed_tetrahedra.end());
  std::vector<int> ids;
  for (int i = 0; i < points->size(); ++i)
    if (removed.count((*points)[i].tet)) ids.push_back(i);
  if (!ids.empty())
    points->Reembed(ids, points_rest, state.rest_positions(), state.tetrahedra(), new_elements);
  return static_cast<int>(ids.size());
}

RowMatX3i RemoveTrianglesCrossing(const RowMatX3d& vertices, const RowMatX3i& triangles,
                                  const CutSurface& surface) {
  std::vector<int> kept;
  for (int f = 0; f < triangles.rows(); ++f) {
    bool crossed = false;
    for (int k = 0; k < 3 && !crossed; ++k) {
      const Eigen::Vector3d a = vertices.row(triangles(f, k)).transpose();
      const Eigen::Vector3d b = vertices.row(triangles(f, (k + 1) % 3)).transpose();
      crossed = SegmentCrossesSurface(surface, a, b);
    }
    if (!crossed) kept.push_back(f);
  }
  RowMatX3i out(kept.size(), 3);
  for (size_t i = 0; i < kept.size(); ++i) out.row(i) = triangles.row(kept[i]);
  return out;
}

}  // namespace arreg::cutting
