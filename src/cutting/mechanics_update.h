// Makes the mechanical state, embedded points and internal-structure triangles
// follow a cut: applies a CutChange locally (only changed elements recomputed).
#pragma once

#include <vector>

#include "core/mesh.h"
#include "cutting/cut_surface.h"
#include "cutting/tet_cutter.h"
#include "mechanics/embedding.h"
#include "mechanics/mechanical_state.h"

namespace arreg::cutting {

// Applies `change` (from CuttableMesh::Cut on a mesh numbered like `state`) to
// the mechanical state: new vertices get interpolated rest/current positions and
// velocities, duplicated ones copies, and the changed elements are replaced (new
// elements take the material of the first removed one). With the same weights in
// rest and current configuration, an undeformed state stays force-free.
// Vertices the cut snapped onto S move in rest and current configuration (and
// velocity) as in the cutter; the rest data of their elements are recomputed.
// Returns the indices of the new elements. Throws arreg::Error when the vertex or
// element counts do not match.
std::vector<int> ApplyCutChange(const CutChange& change, mechanics::MechanicalState* state);

// Re-embeds the points (reference positions `points_rest`, #P x 3, in the rest
// frame of `state`) whose element was removed by `change`, among `new_elements`.
// Returns how many points were re-embedded.
int ReembedAfterCut(const CutChange& change, const std::vector<int>& new_elements,
                    const mechanics::MechanicalState& state, const RowMatX3d& points_rest,
                    mechanics::EmbeddedPoints* points);

// Thesis eq. 7.12: internal-structure triangles (#F x 3 into `vertices`, same frame
// as S) with an edge crossing S are deleted. Returns the kept triangles.
RowMatX3i RemoveTrianglesCrossing(const RowMatX3d& vertices, const RowMatX3i& triangles,
                                  const CutSurface& surface);

}  // namespace arreg::cutting
