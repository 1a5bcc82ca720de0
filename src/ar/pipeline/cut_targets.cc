#include "ar/pipeline/cut_targets.h"

#include <cstdio>
#include <string>

#include "core/error.h"
#include "core/log.h"
#include "core/mesh_io.h"
#include "cutting/cut_extrusion.h"
#include "cutting/cut_surface.h"
#include "cutting/mechanics_update.h"
#include "cutting/structure_split.h"

namespace arreg::pipeline {
namespace {

// Vertices of internal structures on the crack are embedded this far off it (x the mean rest
// edge length): far beyond the embedding's inside tolerance, far below any element's size.
constexpr double kCrackOffsetFraction = 1e-4;

// Splits internal structure k (`original`, as loaded) along `crack` (of `rest`, the state's
// rest mesh) and replaces its faces, rest vertices, embedding and positions; false (with a
// warning, nothing changed) when the split fails. With options.refused_split_dir the failed
// split's inputs are written there.
bool SplitInternal(const SurfaceMesh& original, const SurfaceMesh& crack, const TetMesh& rest,
                   double edge_mm, const CuttingStageOptions& options,
                   const mechanics::MechanicalState& state, size_t k, EmbeddedStructures* internal,
                   CutEvent* ev) {
  try {
    // The crack is rebuilt from the whole cut mesh, so the structure as loaded is split at
    // every event; a vertex on the crack is placed a hair off it, towards its side.
    const cutting::SplitStructure split =
        cutting::SplitAlongCrack(original, crack, kCrackOffsetFraction * edge_mm);
    // Vertices off the crack keep their embedding where their element is unchanged.
    internal->embedding[k] =
        cutting::EmbedSplitStructure(split, rest, {&internal->embedding[k], &internal->rest_mm[k]});
    internal->rest_mm[k] = split.surface.vertices;
    internal->surfaces[k].faces = split.surface.faces;
    internal->embedding[k].Positions(state.positions(), state.tetrahedra(),
                                     &internal->surfaces[k].vertices);
    ev->internal_cap_faces += split.cap_faces;
    return true;
  } catch (const Error& e) {
    std::string inputs;
    if (!options.refused_split_dir.empty()) {
      char prefix[64];
      std::snprintf(prefix, sizeof(prefix), "/%06d_split_%zu_", ev->frame, k);
      const std::string path = options.refused_split_dir + prefix;
      try {
        WriteSurfaceMesh(path + "structure.obj", original);
        WriteSurfaceMesh(path + "crack.obj", crack);
        inputs = "; its inputs: " + path + "structure.obj, " + path + "crack.obj";
      } catch (const Error& w) {
        inputs = std::string("; its inputs were not written: ") + w.what();
      }
    }
    ARREG_LOG_WARNING(
        "run: frame ", ev->frame, ": internal structure ", k,
        " not split along the crack (its triangles crossing S are deleted): ", e.what(), inputs);
    return false;
  }
}

}  // namespace

void FollowCut(const cutting::CutChange& change, const std::vector<int>& new_elements,
               const TetMesh& rest, const SurfaceMesh& s, bool in_rest, double edge_mm,
               const CuttingStageOptions& options, const CutTargets& t, CutEvent* ev) {
  const mechanics::MechanicalState& state = *t.state;
  FeatureRows& rows = *t.features;
  cutting::ReembedAfterCut(change, new_elements, state, rows.rest_mm, &rows.embedding);
  for (int r = 0; r < rows.size(); ++r)
    if (rows.views[r].spring >= 0) t.springs->SetAnchor(rows.views[r].spring, rows.embedding[r]);
  EmbeddedStructures& internal = *t.internal;
  const RowMatX3d& after = in_rest ? state.rest_positions() : state.positions();
  const cutting::CutSurface cs{s.vertices, s.faces};
  const bool split = options.internal_caps && internal.original && !internal.surfaces.empty();
  const SurfaceMesh crack = split ? cutting::CrackSurface(rest) : SurfaceMesh();
  for (size_t k = 0; k < internal.surfaces.size(); ++k) {
    if (split && SplitInternal((*internal.original)[k], crack, rest, edge_mm, options, state, k,
                               &internal, ev))
      continue;
    cutting::ReembedAfterCut(change, new_elements, state, internal.rest_mm[k],
                             &internal.embedding[k]);
    const RowMatX3d points = internal.embedding[k].Positions(after, state.tetrahedra());
    const RowMatX3i kept = cutting::RemoveTrianglesCrossing(points, internal.surfaces[k].faces, cs);
    ev->internal_triangles_removed +=
        static_cast<int>(internal.surfaces[k].faces.rows() - kept.rows());
    internal.surfaces[k].faces = kept;
  }
  RowMatX3d anchors;
  rows.embedding.Positions(after, state.tetrahedra(), &anchors);
  for (int idx : cutting::PointsWithinMargin(s, anchors, options.spring_margin_mm)) {
    FeatureView& v = rows.views[idx];
    // Features on thin structures (no SpringEnergy spring) are re-anchored by their cut.
    if (!v.spring_active || v.spring < 0) continue;
    t.springs->Remove(v.spring);
    v.spring_active = false;
    ++ev->springs_removed;
  }
}

}  // namespace arreg::pipeline
