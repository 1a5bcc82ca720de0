// What a cut of the organ updates besides its tetrahedra: the features (embedding, spring
// anchors, springs near the cut) and the internal structures (split along the crack or
// trimmed by S).
#pragma once

#include <vector>

#include "ar/pipeline/feature_rows.h"
#include "ar/pipeline/frame_observer.h"
#include "ar/pipeline/pipeline_options.h"
#include "core/mesh.h"
#include "cutting/tet_cutter.h"
#include "mechanics/mechanical_state.h"
#include "mechanics/spring_energy.h"

namespace arreg::pipeline {

class BernsteinTetTerms;  // thin_model.h

// Owned by the pipeline, valid during CutHandler::Apply.
struct CutTargets {
  mechanics::MechanicalState* state = nullptr;
  mechanics::SpringEnergy* springs = nullptr;
  // Rows read and written: views, rest_mm (in the rest frame of `state`), embedding.
  FeatureRows* features = nullptr;
  EmbeddedStructures* internal = nullptr;
  // A degree-2 organ: its control net follows every cut of the corner mesh (null at degree 1).
  BernsteinTetTerms* curved = nullptr;
};

// After the state took `change` (`new_elements` as ApplyCutChange returns them; `rest` the
// state's rest mesh after it): re-embeds the features and moves their springs' anchors; splits
// each internal structure along the crack (CuttingStageOptions::internal_caps, with
// t.internal->original) or re-embeds it and deletes its triangles crossing `s` (eq. 7.12);
// removes the springs within options.spring_margin_mm of `s`. `in_rest`: `s` was cut in the
// rest configuration (the lips have not moved apart there, and a spring's side is its rest one).
// `edge_mm`: the mean rest edge length (vertices on the crack are placed a hair off it).
// Counts go to `ev`.
void FollowCut(const cutting::CutChange& change, const std::vector<int>& new_elements,
               const TetMesh& rest, const SurfaceMesh& s, bool in_rest, double edge_mm,
               const CuttingStageOptions& options, const CutTargets& t, CutEvent* ev);

}  // namespace arreg::pipeline
