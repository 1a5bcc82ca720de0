// The mechanical model of a run: the organ's corotational tetrahedra, the feature springs,
// gravity and out-of-view tethers, stepped by implicit Euler once per frame (thesis 7.3); with
// thin structures all of them in one generalised system (ThinSystem), at degree 2 and 3 the
// organ's Bernstein tetrahedra in one of their own; and the output fit (docs/springs.md).
#pragma once

#include <optional>
#include <vector>

#include "ar/pipeline/feature_rows.h"
#include "ar/pipeline/frame_observer.h"
#include "ar/pipeline/pipeline_options.h"
#include "ar/pipeline/registration_pipeline.h"
#include "core/scene.h"
#include "mechanics/curved_boundary.h"
#include "mechanics/elastic_energy.h"
#include "mechanics/integrator.h"
#include "mechanics/mechanical_state.h"
#include "mechanics/quasi_static_fit.h"
#include "mechanics/spring_energy.h"

namespace arreg::pipeline {

// Steps per edge of each boundary face's lattice when a degree-2/3 organ's curved surface is
// tessellated for the overlay, the saved surfaces and the evaluation (16 triangles a face):
// a quadratic edge of sagitta h leaves h / 16 between the chords and the curve.
constexpr int kCurvedSubdivisions = 4;

// Holds pointers into itself (the systems keep the state and springs): neither copied nor moved.
class RunMechanics {
 public:
  // The model of `model` (frame 0) with the options' material, damping, solver and time step
  // 1 / fps. Throws arreg::Error for options the models reject.
  RunMechanics(const Scene& scene, const PipelineOptions& options, const LoadedModel& model,
               double fps);
  RunMechanics(const RunMechanics&) = delete;
  RunMechanics& operator=(const RunMechanics&) = delete;

  bool has_tets() const { return state.num_tetrahedra() > 0; }
  // The system that steps the state when it is not the tetrahedra alone: the thin structures'
  // or the curved organ's; null otherwise.
  ThinSystem* generalised() { return thin ? &*thin : curved ? &*curved_system : nullptr; }

  // Tethers the model vertices out of view at frame 0 (MechanicsStageOptions::
  // out_of_view_tether), `total_spring_n_per_m` being the feature springs' total stiffness.
  void TetherOutOfView(const LoadedModel& model, const PinholeCamera& camera,
                       const MechanicsStageOptions& options, double total_spring_n_per_m);
  // One implicit Euler step of the frame; its figures go to `stats`.
  void Step(FrameStats* stats);
  // Every row's anchor (`rows->anchors_mm`): embedded in the tetrahedra, on the curved organ,
  // or on a shell.
  void UpdateAnchors(FeatureRows* rows);
  // The organ's configuration shown, saved and evaluated: the output fit's (when enabled) or
  // the stepped state's.
  const RowMatX3d& Output(FrameStats* stats);

  mechanics::MechanicalState state;
  mechanics::CorotationalOptions elastic_options;
  mechanics::CorotationalElasticity elastic;
  mechanics::SpringEnergy springs;
  std::optional<mechanics::GravityEnergy> gravity;
  mechanics::VertexTetherEnergy tethers;
  std::vector<mechanics::EnergyTerm*> other_terms;  // all but the springs (the output fit's)
  std::vector<mechanics::EnergyTerm*> terms;        // the springs, then other_terms
  mechanics::ImplicitEulerIntegrator integrator;
  // Thin structures: the organ, shells, vessels and all springs in one generalised system.
  std::optional<ThinSystem> thin;
  // Degree 2 and 3: the organ's Bernstein tetrahedra (straight-sided raise of the model mesh:
  // a scene gives no smooth surface to raise onto) in a generalised system of their own.
  std::optional<ThinSystem> curved_system;
  BernsteinTetTerms* curved = nullptr;  // owned by curved_system
  std::optional<mechanics::CurvedBoundary> curved_boundary;
  SurfaceMesh curved_surface;  // the curved boundary's tessellation, current
  // The output fit is a linear-tetrahedron solve: degree 2 and 3 show the stepped state.
  std::optional<mechanics::QuasiStaticFit> output_fit;
};

}  // namespace arreg::pipeline
