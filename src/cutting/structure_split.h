// Internal structures (tumour, vessels) cut where the model is cut: the surface is split along
// the model's crack and, when it is closed, each side is closed again by a cap on the crack.
#pragma once

#include <Eigen/Core>

#include "core/mesh.h"
#include "mechanics/embedding.h"

namespace arreg::cutting {

// The cracks of a cut tetrahedral mesh in its rest configuration: one face of each pair of
// coincident boundary faces (the two lips of a crack share their rest positions). `vertices`
// are the mesh's rest vertices (unreferenced ones stay); faces are oriented consistently
// within each connected part of the crack where it is manifold.
SurfaceMesh CrackSurface(const TetMesh& rest);

// A surface split along a crack.
struct SplitStructure {
  SurfaceMesh surface;  // rest positions; the input's faces (subdivided) plus the caps
  // (#V x 3) per vertex, the point at which to embed it: a vertex on the crack is moved off it
  // by offset_mm along the crack's normal, towards its side, so that it is carried by an
  // element of that side; any other vertex is its own position.
  RowMatX3d embed_at_mm;
  int added_faces = 0;  // faces the subdivision along the crack added to the input's
  int cap_faces = 0;    // faces added on the crack (both sides)
  bool capped = false;  // the input was closed, so each side was closed by a cap
};

// Splits `structure` (rest positions, triangles oriented outward, no self-intersection) along
// `crack` (CrackSurface of the same rest frame): faces the crack crosses are subdivided on it
// (CGAL corefinement) and the vertices on it are duplicated, one copy per side. When
// `structure` is closed, the part of the crack inside it is added twice, once per side with
// that side's orientation, so every side of the structure stays a closed surface; along the
// crack's front, where the model is not split, both caps share their vertices. A structure the
// crack does not reach comes back unchanged. Throws arreg::Error when CGAL cannot represent the
// inputs as meshes or the corefinement fails (e.g. self-intersecting inputs), and when a closed
// structure would not stay a closed manifold (cracks that touch inside it). Where three or more
// crack faces share an edge (a branch: more than two sides), the structure is split along the
// two that continue each other most nearly straight and stays whole across the others. Where
// the crack touches the structure's surface, a double layer (a face and its exact reverse) is
// removed and a face cut loose along all its edges is joined back to the faces around its hole;
// a split that is still not a closed manifold is made again with the crack moved by 1e-9 x (1 +
// the structure's diagonal) along fixed generic directions (the cap's vertices are then that far
// off the crack), which turns an exact contact into a crossing or none. Where sheets of the crack
// touch in a vertex (a non-manifold vertex, which the corefinement's mesh holds as coincident
// copies, a self-intersection it does not allow), each copy is moved 1e-6 mean edge lengths
// towards the centroid of its own faces.
SplitStructure SplitAlongCrack(const SurfaceMesh& structure, const SurfaceMesh& crack,
                               double offset_mm);

// The structure's embedding before an event, for EmbedSplitStructure to keep where it still holds.
struct PreviousEmbedding {
  const mechanics::EmbeddedPoints* points = nullptr;  // the embedding before the event
  const RowMatX3d* rest_mm = nullptr;                 // the points it embeds (rest, #P x 3)
};

// Embeds the split structure in the rest mesh `rest`: each vertex in the element that contains
// its embed_at_mm point, with its own barycentric coordinates there (on the crack they lie on
// that element's face). With `previous`, the re-embedding is local: a vertex off the crack that
// is the same point as the previous one of its index keeps that embedding where it still gives
// the point in `rest` (its element was neither replaced nor moved by snapping); only the others
// (on the crack, the caps', those of changed elements) are located again.
mechanics::EmbeddedPoints EmbedSplitStructure(const SplitStructure& split, const TetMesh& rest,
                                              const PreviousEmbedding& previous = {});

}  // namespace arreg::cutting
