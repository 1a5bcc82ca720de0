// The application half of the pipeline's cutting stage (thesis 7.5.3): one detected cut
// becomes a remeshing of the model that mechanics, features and internal structures follow.
#pragma once

#include <Eigen/Core>
#include <memory>
#include <vector>

#include "ar/pipeline/cut_targets.h"
#include "ar/pipeline/debris_welds.h"
#include "ar/pipeline/frame_observer.h"
#include "ar/pipeline/pipeline_options.h"
#include "core/mesh.h"
#include "cutting/cut_extrusion.h"
#include "cutting/tet_cutter.h"
#include "mechanics/mechanical_state.h"
#include "mechanics/spring_energy.h"

namespace arreg::pipeline {

// Keeps one cuttable topology (cutting::CuttableMesh, numbered like the mechanical state)
// across the events of a run, so a partial cut's open front is continued by the next event
// and the front's free vertices are moved onto S instead of the front being remeshed again.
class CutHandler {
 public:
  // `state` is the model before any cut (positive elements in its rest configuration).
  // Throws arreg::Error for bad options or a non-positive rest element.
  CutHandler(const CuttingStageOptions& options, const mechanics::MechanicalState& state);
  ~CutHandler();

  // One detected cut in frame `frame`: extrudes the polyline along the rays from `eye_mm` into
  // S, cuts the model, applies the change to the mechanical state, re-embeds features, splits
  // and caps the internal structures along the crack (or deletes their triangles crossing S,
  // eq. 7.12; options.internal_caps) and removes the
  // springs within options.spring_margin_mm of S. `polyline_mm` is the detector's (extended)
  // polyline in this frame (world, mm), `rest_polyline_mm` the same points at frame 0, where
  // the model is in its rest configuration (options.cut_configuration says which one is cut).
  // The returned event says what happened ("cut", "no-crossing", "rejected", or "failed" with
  // the error text; the targets are then unchanged). `cut_surface` (optional) receives S
  // extruded from `polyline_mm` (this frame's view of it).
  CutEvent Apply(int frame, const std::vector<Eigen::Vector3d>& polyline_mm,
                 const std::vector<Eigen::Vector3d>& rest_polyline_mm,
                 const Eigen::Vector3d& eye_mm, const CutTargets& targets,
                 SurfaceMesh* cut_surface = nullptr);

  // Whether Apply with these arguments would reject the event because S splits the model at
  // every depth tried, in every configuration (options.keep_connected); false when it would
  // cut, or reject or fail for another reason. Leaves the topology unchanged; the cost of one
  // event's cut attempts (CutDetector::SetSegmentCheck asks before adding a segment). A cut it
  // finds is kept for the next Apply, which takes it when called with the same arguments on the
  // same state instead of planning the event again.
  bool SplitsTheModel(const std::vector<Eigen::Vector3d>& polyline_mm,
                      const std::vector<Eigen::Vector3d>& rest_polyline_mm,
                      const Eigen::Vector3d& eye_mm, const mechanics::MechanicalState& state);

  // The persistent topology (rest/current positions as of the last event).
  const cutting::CuttableMesh& mesh() const { return *mesh_; }

  // Debris (pieces below 0.5 % of the rest volume, cut off between two nearly coincident
  // cracks) is welded: its vertices are fixed in the state and follow one element of the
  // nearest piece affinely (rest barycentric coordinates). Call after every mechanics step;
  // Apply calls it after an event.
  void FollowWelds(mechanics::MechanicalState* state) const { welds_.Follow(state); }
  int num_welded_vertices() const { return welds_.num_vertices(); }

 private:
  bool Applied(const Eigen::Vector3d& p) const;
  // Cuts mesh_ with S; a rejection is retried with the on-surface tolerance halved (down to
  // 0.01), then with the exact test.
  cutting::CutSummary CutWithRetry(const SurfaceMesh& s, cutting::CutChange* change);
  // The strips of the polyline's segments that have a point not applied before.
  SurfaceMesh NewPart(const std::vector<Eigen::Vector3d>& polyline_mm,
                      const Eigen::Vector3d& eye_mm, const cutting::CutExtrusionOptions& ext) const;

  // Finds the event's cut: the configurations and depths tried, as documented in Apply. On
  // return mesh_ holds the cut when the plan's status is kCut, else it is as before.
  struct Plan;
  Plan PlanCut(const std::vector<Eigen::Vector3d>& polyline_mm,
               const std::vector<Eigen::Vector3d>& rest_polyline_mm, const Eigen::Vector3d& eye_mm,
               const mechanics::MechanicalState& state, const ModelPieces& pieces_before);
  // A plan SplitsTheModel found that cuts, with what it was planned from; reset by every Apply.
  struct Planned;
  std::unique_ptr<Planned> planned_;
  DebrisWelds welds_;

  CuttingStageOptions options_;
  std::unique_ptr<cutting::CuttableMesh> mesh_;
  std::vector<Eigen::Vector3d> applied_points_;  // polyline points of applied events
  // The depth fraction of the cut's first event in the rest configuration; later events go no
  // deeper (options_.foresight_mm > 0).
  double depth_of_cut_ = 1.0;
};

}  // namespace arreg::pipeline
