#include "ar/pipeline/cut_handler.h"

#include "core/error.h"
#include "core/log.h"
#include "cutting/cut_extrusion.h"
#include "cutting/cut_surface.h"
#include "cutting/mechanics_update.h"

namespace arreg::pipeline {

CutHandler::CutHandler(const CuttingStageOptions& options, const mechanics::MechanicalState& state)
    : options_(options) {
  options_.Check();
  (void)state;
}

CutHandler::~CutHandler() = default;

CutEvent CutHandler::Apply(int frame, const std::vector<Eigen::Vector3d>& polyline_mm,
                           const Eigen::Vector3d& eye_mm, const CutTargets& t,
                           SurfaceMesh* cut_surface) {
  ARREG_CHECK_INPUT(t.state && t.springs && t.features && t.features_rest_mm &&
                        t.feature_embedding && t.internal && t.internal_rest_mm &&
                        t.internal_embedding,
                    "", "CutHandler::Apply", "every target must be set");
  mechanics::MechanicalState& state = *t.state;
  std::vector<FeatureView>& features = *t.features;
  const int nf = static_cast<int>(features.size());
  CutEvent ev;
  ev.frame = frame;
  ev.polyline_points = static_cast<int>(polyline_mm.size());
  try {
    const cutting::CutExtrusionOptions ext = cutting::CutExtrusionCovering(
        polyline_mm, eye_mm, state.positions(), options_.extrusion_margin_mm);
    SurfaceMesh s = cutting::ExtrudeCutPolyline(polyline_mm, eye_mm, ext);
    const cutting::CutSurface cs{s.vertices, s.faces};
    cutting::CuttableMesh cuttable(state.RestMesh(), state.positions(), state.velocities());
    cutting::CutOptions co;
    co.method = options_.method == "bielser" ? cutting::RemeshMethod::kBielser
                                             : cutting::RemeshMethod::kFlips;
    co.snap_epsilon = 0.0;  // MechanicalState keeps rest positions: no snapping
    cutting::CutChange change;
    const cutting::CutSummary cut = cuttable.Cut(cs, co, &change);
    ev.message = cut.message;
    if (cut.status == cutting::CutStatus::kCut) {
      ev.status = "cut";
      const int v_before = state.num_vertices(), t_before = state.num_tetrahedra();
      const std::vector<int> new_elements = cutting::ApplyCutChange(change, &state);
      cutting::ReembedAfterCut(change, new_elements, state, *t.features_rest_mm,
                               t.feature_embedding);
      for (int r = 0; r < nf; ++r)
        if (features[r].spring >= 0)
          t.springs->SetAnchor(features[r].spring, (*t.feature_embedding)[r]);
      std::vector<SurfaceMesh>& internal = *t.internal;
      for (size_t k = 0; k < internal.size(); ++k) {
        cutting::ReembedAfterCut(change, new_elements, state, (*t.internal_rest_mm)[k],
                                 &(*t.internal_embedding)[k]);
        const RowMatX3d current =
            (*t.internal_embedding)[k].Positions(state.positions(), state.tetrahedra());
        const RowMatX3i kept = cutting::RemoveTrianglesCrossing(current, internal[k].faces, cs);
        ev.internal_triangles_removed += static_cast<int>(internal[k].faces.rows() - kept.rows());
        internal[k].faces = kept;
      }
      RowMatX3d anchors;
      t.feature_embedding->Positions(state.positions(), state.tetrahedra(), &anchors);
      for (int idx : cutting::PointsWithinMargin(s, anchors, options_.spring_margin_mm)) {
        FeatureView& v = features[idx];
        if (!v.spring_active) continue;
        t.springs->Remove(v.spring);
        v.spring_active = false;
        ++ev.springs_removed;
      }
      ev.new_vertices = state.num_vertices() - v_before;
      ev.new_tetrahedra = state.num_tetrahedra() - t_before;
    } else {
      ev.status = cut.status == cutting::CutStatus::kNoCrossing ? "no-crossing" : "rejected";
    }
    if (cut_surface) *cut_surface = std::move(s);
  } catch (const Error& e) {
    ev.status = "failed";
    ev.message = e.what();
    ARREG_LOG_WARNING("run: frame ", frame, ": cut not applied: ", e.what());
  }
  return ev;
}

}  // namespace arreg::pipeline
