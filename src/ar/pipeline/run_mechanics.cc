#include "ar/pipeline/run_mechanics.h"

#include <memory>
#include <string>

#include "ar/pipeline/thin_model.h"
#include "core/log.h"
#include "mechanics/high_order_mesh.h"

namespace arreg::pipeline {
namespace {

mechanics::CorotationalOptions ElasticOptions(const PipelineOptions& o) {
  mechanics::CorotationalOptions e;
  e.volume_term = o.mechanics.volume_term;
  return e;
}

mechanics::ImplicitEulerOptions IntegratorOptions(const Scene& scene, const PipelineOptions& o,
                                                  double fps) {
  mechanics::ImplicitEulerOptions io;
  io.dt_s = 1.0 / fps;
  io.substeps = o.mechanics.substeps;
  io.newton_mode = o.mechanics.newton_iterations > 1 ? mechanics::NewtonMode::kFixedIterations
                                                     : mechanics::NewtonMode::kOneStep;
  io.max_newton_iterations = o.mechanics.newton_iterations;
  io.newton_tolerance_mm = 1e-6;
  io.rayleigh_mass_alpha = o.mechanics.rayleigh_mass_per_s >= 0
                               ? o.mechanics.rayleigh_mass_per_s
                               : scene.material.rayleigh_mass_per_s;
  io.rayleigh_stiffness_beta = o.mechanics.rayleigh_stiffness_s >= 0
                                   ? o.mechanics.rayleigh_stiffness_s
                                   : scene.material.rayleigh_stiffness_s;
  io.linear_solver.type = o.mechanics.linear_solver;
  io.line_search = o.mechanics.line_search;
  return io;
}

// The step options of a generalised system (thin structures, degree 2 and 3): the run's.
ThinSystemOptions GeneralisedOptions(const mechanics::ImplicitEulerOptions& io,
                                     const PipelineOptions& o) {
  ThinSystemOptions to;
  to.integrator.dt_s = io.dt_s;
  to.integrator.substeps = io.substeps;
  to.integrator.newton_mode = io.newton_mode;
  to.integrator.max_newton_iterations = io.max_newton_iterations;
  to.integrator.newton_tolerance_mm = io.newton_tolerance_mm;
  to.integrator.rayleigh_mass_alpha = io.rayleigh_mass_alpha;
  to.integrator.rayleigh_stiffness_beta = io.rayleigh_stiffness_beta;
  to.integrator.linear_solver = io.linear_solver;
  to.integrator.line_search = io.line_search;
  to.gravity_mm_per_s2 = o.mechanics.gravity_mm_per_s2;
  return to;
}

}  // namespace

RunMechanics::RunMechanics(const Scene& scene, const PipelineOptions& o, const LoadedModel& model,
                           double fps)
    : state(model.mesh, ToMechanicsMaterial(scene.material)),
      elastic_options(ElasticOptions(o)),
      elastic(elastic_options),
      integrator(IntegratorOptions(scene, o, fps)) {
  state.SetFixed(o.mechanics.fixed_vertices);
  if (o.mechanics.gravity_mm_per_s2.squaredNorm() > 0) {
    gravity.emplace(o.mechanics.gravity_mm_per_s2);
    other_terms.push_back(&*gravity);
  }
  terms = {&springs};
  terms.insert(terms.end(), other_terms.begin(), other_terms.end());
  const mechanics::ImplicitEulerOptions io = IntegratorOptions(scene, o, fps);
  if (!model.thin.empty()) {
    ThinSystemOptions to = GeneralisedOptions(io, o);
    to.elastic = elastic_options;
    thin.emplace(model.thin, scene, &state, &springs, to);
  }
  const int degree = scene.model_degree;
  if (degree > 1) {
    mechanics::BernsteinTetOptions bo;
    bo.material = ToMechanicsMaterial(scene.material);
    auto solid = std::make_unique<BernsteinTetTerms>(mechanics::RaiseTetMesh(model.mesh, degree),
                                                     bo, &springs);
    curved = solid.get();
    curved_system.emplace(std::vector<LoadedThin>(), scene, &state, &springs,
                          GeneralisedOptions(io, o), std::move(solid));
    curved_boundary =
        mechanics::TessellateBoundary(curved->mesh(), curved->mesh().nodes, kCurvedSubdivisions);
    curved_surface = curved_boundary->surface;
  }
  if (o.mechanics.output_spring_factor > 0 && has_tets() && degree == 1) {
    mechanics::QuasiStaticFitOptions fo;
    fo.spring_factor = o.mechanics.output_spring_factor;
    fo.elastic = elastic_options;
    fo.linear_solver = io.linear_solver;
    output_fit.emplace(fo);
  }
}

void RunMechanics::TetherOutOfView(const LoadedModel& model, const PinholeCamera& camera,
                                   const MechanicsStageOptions& options,
                                   double total_spring_n_per_m) {
  const std::vector<VertexTether> out_of_view = OutOfViewTethers(
      model.mesh, camera, options.out_of_view_tether, total_spring_n_per_m, options.fixed_vertices);
  if (thin || curved) {
    if (!out_of_view.empty())
      ARREG_LOG_WARNING("mechanics.out_of_view_tether: ", out_of_view.size(),
                        " model vertices out of view are not tethered (tetrahedra of degree 1 "
                        "without thin structures only)");
    return;
  }
  for (const VertexTether& t : out_of_view)
    tethers.Add(t.vertex, model.mesh.vertices.row(t.vertex).transpose(), t.stiffness_n_per_m);
  if (tethers.size() == 0) return;
  terms.push_back(&tethers);
  other_terms.push_back(&tethers);
  ARREG_LOG_INFO("mechanics: ", tethers.size(),
                 " model vertices out of view at frame 0 tethered to their place");
}

void RunMechanics::Step(FrameStats* stats) {
  if (ThinSystem* system = generalised()) {
    const mechanics::GeneralisedSummary step = system->Step(&state);
    stats->mechanics_status = mechanics::StepStatusName(step.status);
    stats->linear_iterations = step.linear_iterations;
    stats->factorizations = step.factorizations;
    stats->line_search_cuts = step.line_search_cuts;
  } else {
    const mechanics::StepSummary step = integrator.Step(&state, &elastic, terms);
    stats->mechanics_status = mechanics::StepStatusName(step.status);
    stats->inverted_elements = step.inverted_elements;
    stats->linear_iterations = step.linear_iterations;
    stats->factorizations = step.factorizations;
    stats->line_search_cuts = step.line_search_cuts;
  }
}

void RunMechanics::UpdateAnchors(FeatureRows* rows) {
  if (has_tets())
    rows->embedding.Positions(state.positions(), state.tetrahedra(), &rows->anchors_mm);
  if (curved) {
    curved_system->SyncSolid(&state);  // embeds springs added since the last step
    for (int r = 0; r < rows->size(); ++r)
      if (rows->views[r].spring >= 0)
        rows->anchors_mm.row(r) =
            curved->SpringAnchor(curved_system->state(), rows->views[r].spring).transpose();
  }
  for (size_t r = 0; r < rows->thin_spring.size(); ++r)
    if (rows->thin_spring[r] >= 0)
      rows->anchors_mm.row(r) = thin->FeatureAnchor(rows->thin_spring[r]).transpose();
}

const RowMatX3d& RunMechanics::Output(FrameStats* stats) {
  if (!output_fit) return state.positions();
  const mechanics::StepSummary fit = output_fit->Fit(state, springs, other_terms);
  stats->output_fit_status = mechanics::StepStatusName(fit.status);
  return output_fit->positions();
}

}  // namespace arreg::pipeline
