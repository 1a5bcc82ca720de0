#include "ar/pipeline/pipeline_options.h"

#include <cmath>

#include "core/error.h"
#include "core/json_reader.h"
#include "core/mesh_ops.h"

namespace arreg::pipeline {

void MechanicsStageOptions::Check() const {
  ARREG_CHECK_INPUT(std::isfinite(spring_stiffness_relative) && spring_stiffness_relative > 0, "",
                    "mechanics.spring_stiffness_relative", "must be > 0, got ",
                    spring_stiffness_relative);
  ARREG_CHECK_INPUT(std::isfinite(spring_stiffness_n_per_m) && spring_stiffness_n_per_m >= 0, "",
                    "mechanics.spring_stiffness_n_per_m",
                    "must be > 0 (absolute override) or 0 (use spring_stiffness_relative), got ",
                    spring_stiffness_n_per_m);
  ARREG_CHECK_INPUT(substeps >= 1, "", "mechanics.substeps", "must be >= 1, got ", substeps);
  ARREG_CHECK_INPUT(std::isfinite(output_spring_factor) && output_spring_factor >= 0, "",
                    "mechanics.output_spring_factor", "must be >= 0, got ", output_spring_factor);
  ARREG_CHECK_INPUT(newton_iterations >= 1, "", "mechanics.newton_iterations", "must be >= 1, got ",
                    newton_iterations);
  ARREG_CHECK_INPUT(std::isfinite(rayleigh_mass_per_s), "", "mechanics.rayleigh_mass_per_s",
                    "must be finite");
  ARREG_CHECK_INPUT(std::isfinite(rayleigh_stiffness_s), "", "mechanics.rayleigh_stiffness_s",
                    "must be finite");
  ARREG_CHECK_INPUT(gravity_mm_per_s2.allFinite(), "", "mechanics.gravity_mm_per_s2",
                    "must be finite");
  for (int v : fixed_vertices)
    ARREG_CHECK_INPUT(v >= 0, "", "mechanics.fixed_vertices", "indices must be >= 0, got ", v);
  ARREG_CHECK_INPUT(std::isfinite(out_of_view_tether) && out_of_view_tether >= 0, "",
                    "mechanics.out_of_view_tether", "must be >= 0, got ", out_of_view_tether);
}

const char* CutConfigurationName(CutConfiguration configuration) {
  return NameOf(kCutConfigurationNames, configuration);
}

CutConfiguration ParseCutConfiguration(const std::string& name, const std::string& field) {
  return ParseName(kCutConfigurationNames, name, "", field);
}

void CuttingStageOptions::Check() const {
  detector.Check();
  ARREG_CHECK_INPUT(std::isfinite(spring_margin_mm) && spring_margin_mm >= 0, "",
                    "cutting.spring_margin_mm", "must be >= 0, got ", spring_margin_mm);
  ARREG_CHECK_INPUT(std::isfinite(extrusion_margin_mm) && extrusion_margin_mm >= 0, "",
                    "cutting.extrusion_margin_mm", "must be >= 0, got ", extrusion_margin_mm);
  ARREG_CHECK_INPUT(std::isfinite(snap_epsilon) && snap_epsilon >= 0, "", "cutting.snap_epsilon",
                    "must be >= 0, got ", snap_epsilon);
  ARREG_CHECK_INPUT(std::isfinite(on_surface_tolerance) && on_surface_tolerance >= 0, "",
                    "cutting.on_surface_tolerance", "must be >= 0, got ", on_surface_tolerance);
  ARREG_CHECK_INPUT(std::isfinite(foresight_mm) && foresight_mm >= 0, "", "cutting.foresight_mm",
                    "must be >= 0, got ", foresight_mm);
  ARREG_CHECK_INPUT(std::isfinite(tracking_noise_px) && tracking_noise_px > 0, "",
                    "cutting.tracking_noise_px", "must be > 0, got ", tracking_noise_px);
  ARREG_CHECK_INPUT(std::isfinite(min_outlier_measure_px) && min_outlier_measure_px >= 0, "",
                    "cutting.min_outlier_measure_px", "must be >= 0, got ", min_outlier_measure_px);
}

void RenderStageOptions::Check() const {
  ARREG_CHECK_INPUT(supersampling >= 1 && supersampling <= 8, "", "render.supersampling",
                    "must be in [1, 8], got ", supersampling);
  ARREG_CHECK_INPUT(organ_opacity >= 0 && organ_opacity <= 1, "", "render.organ_opacity",
                    "must be in [0, 1], got ", organ_opacity);
  ARREG_CHECK_INPUT(organ_color.minCoeff() >= 0 && organ_color.maxCoeff() <= 1, "",
                    "render.organ_color", "components must be in [0, 1]");
  ARREG_CHECK_INPUT(contour_color.minCoeff() >= 0 && contour_color.maxCoeff() <= 1, "",
                    "render.contour_color", "components must be in [0, 1]");
  ARREG_CHECK_INPUT(cut_edge_color.minCoeff() >= 0 && cut_edge_color.maxCoeff() <= 1, "",
                    "render.cut_edge_color", "components must be in [0, 1]");
  ARREG_CHECK_INPUT(contour_width_px >= 1 && contour_width_px <= 8, "", "render.contour_width_px",
                    "must be in [1, 8], got ", contour_width_px);
  ARREG_CHECK_INPUT(
      std::isfinite(cut_edge_angle_deg) && cut_edge_angle_deg > 0 && cut_edge_angle_deg < 180, "",
      "render.cut_edge_angle_deg", "must be in (0, 180), got ", cut_edge_angle_deg);
}

void OutputStageOptions::Check() const {
  ARREG_CHECK_INPUT(crf >= 0 && crf <= 51, "", "output.crf", "must be in [0, 51], got ", crf);
  ARREG_CHECK_INPUT(encode_threads >= 0, "", "output.encode_threads", "must be >= 0, got ",
                    encode_threads);
  ARREG_CHECK_INPUT(save_every >= 1, "", "output.save_every", "must be >= 1, got ", save_every);
}

void PipelineOptions::Check() const {
  tracking.Check();
  lifting.Check();
  mechanics.Check();
  cutting.Check();
  render.Check();
  output.Check();
  ARREG_CHECK_INPUT(max_frames == -1 || max_frames >= 1, "", "max_frames",
                    "must be -1 (all) or >= 1, got ", max_frames);
  ARREG_CHECK_INPUT(roi_dilation_px >= -1, "", "roi_dilation_px", "must be >= -1, got ",
                    roi_dilation_px);
  ARREG_CHECK_INPUT(attach_after_frames >= 0, "", "tracking.attach_after_frames",
                    "must be >= 0, got ", attach_after_frames);
  ARREG_CHECK_INPUT(attach_max_misfit_factor > 0 && std::isfinite(attach_max_misfit_factor), "",
                    "tracking.attach_max_misfit_factor", "must be > 0, got ",
                    attach_max_misfit_factor);
}

SpringStiffness ResolveSpringStiffness(const MechanicsStageOptions& mechanics,
                                       double youngs_modulus_pa, double volume_mm3,
                                       double visible_area_mm2, int springs) {
  SpringStiffness k;
  k.springs = springs;
  k.volume_mm3 = volume_mm3;
  k.visible_area_mm2 = visible_area_mm2;
  k.relative = mechanics.spring_stiffness_n_per_m <= 0;
  if (!k.relative) {
    k.n_per_m = mechanics.spring_stiffness_n_per_m;
    return k;
  }
  if (springs <= 0) return k;  // nothing attached: no spring to give a stiffness
  ARREG_CHECK_INPUT(std::isfinite(youngs_modulus_pa) && youngs_modulus_pa > 0, "",
                    "material.youngs_modulus_pa", "must be > 0, got ", youngs_modulus_pa);
  ARREG_CHECK_INPUT(std::isfinite(volume_mm3) && volume_mm3 > 0, "", "model",
                    "the relative spring stiffness needs a model volume > 0, got ", volume_mm3,
                    " mm^3");
  ARREG_CHECK_INPUT(std::isfinite(visible_area_mm2) && visible_area_mm2 > 0, "", "model",
                    "the relative spring stiffness needs surface facing the camera, got ",
                    visible_area_mm2, " mm^2");
  // Pa x mm = 1e-3 N/m.
  k.n_per_m = mechanics.spring_stiffness_relative * youngs_modulus_pa * volume_mm3 /
              (visible_area_mm2 * springs) * 1e-3;
  return k;
}

std::vector<VertexTether> OutOfViewTethers(const TetMesh& mesh, const PinholeCamera& camera,
                                           double factor, double total_spring_n_per_m,
                                           const std::vector<int>& fixed) {
  std::vector<VertexTether> tethers;
  if (!(factor > 0) || !(total_spring_n_per_m > 0) || mesh.num_tetrahedra() == 0) return tethers;
  const Eigen::VectorXd volumes = TetVolumes(mesh);
  Eigen::VectorXd share = Eigen::VectorXd::Zero(mesh.num_vertices());
  for (int t = 0; t < mesh.num_tetrahedra(); ++t)
    for (int a = 0; a < 4; ++a) share(mesh.tetrahedra(t, a)) += 0.25 * volumes(t);
  const double volume = volumes.sum();
  if (!(volume > 0)) return tethers;
  std::vector<char> held(mesh.num_vertices(), 0);
  for (int v : fixed)
    if (v >= 0 && v < mesh.num_vertices()) held[v] = 1;
  for (int v = 0; v < mesh.num_vertices(); ++v) {
    if (held[v] || !(share(v) > 0)) continue;
    const Eigen::Vector3d projected = camera.ProjectWithDepth(mesh.vertices.row(v).transpose());
    if (projected.z() > 0 && camera.IsInImage(projected.head<2>())) continue;
    tethers.push_back({v, factor * total_spring_n_per_m * share(v) / volume});
  }
  return tethers;
}

double AreaFacing(const SurfaceMesh& surface, const Eigen::Vector3d& eye_world) {
  double area_mm2 = 0;
  for (int f = 0; f < surface.faces.rows(); ++f) {
    const Eigen::Vector3d a = surface.vertices.row(surface.faces(f, 0)).transpose();
    const Eigen::Vector3d b = surface.vertices.row(surface.faces(f, 1)).transpose();
    const Eigen::Vector3d c = surface.vertices.row(surface.faces(f, 2)).transpose();
    const Eigen::Vector3d twice_area_normal = (b - a).cross(c - a);
    // The sign is the same at every point of the face's plane, so the test needs no centroid.
    if (twice_area_normal.dot(eye_world - a) > 0) area_mm2 += 0.5 * twice_area_normal.norm();
  }
  return area_mm2;
}

namespace {

void ReadTracking(const Scene& scene, FeatureTrackerOptions* o, PipelineOptions* p) {
  JsonObjectReader r(scene.tracking, scene.path, "tracking");
  r.Optional("max_features", &o->max_features);
  r.Optional("hessian_threshold", &o->surf.hessian_threshold);
  r.Optional("min_features", &o->min_features);
  r.Optional("min_hessian_threshold", &o->min_hessian_threshold);
  r.Optional("min_distance_px", &o->min_distance_px);
  r.Optional("border_px", &o->border_px);
  r.Optional("redetect_every_frames", &o->redetect_every_frames);
  r.Optional("redetect_hole_factor", &o->redetect_hole_factor);
  r.Optional("attach_after_frames", &p->attach_after_frames);
  r.Optional("attach_max_misfit_factor", &p->attach_max_misfit_factor);
  r.Optional("window_px", &o->lk.window_px);
  r.Optional("pyramid_levels", &o->lk.pyramid_levels);
  r.Optional("forward_backward_max_px", &o->lk.forward_backward_max_px);
  r.OptionalEnum("lk_backend", kLucasKanadeBackendNames, &o->lk.backend);
  r.Optional("outlier_filter", &o->outliers.enabled);
  r.Optional("outlier_ratio", &o->outliers.ratio);
  r.Optional("outlier_slack_px", &o->outliers.slack_px);
  r.Optional("specular_filter", &o->specular.enabled);
  r.Optional("appearance_check", &o->appearance.enabled);
  r.Optional("appearance_min_correlation", &o->appearance.min_correlation);
  r.Optional("drift_correction", &o->drift.enabled);
  r.Optional("drift_window_px", &o->drift.window_px);
  r.Optional("drift_every_frames", &o->drift.every_frames);
  r.Optional("drift_min_correlation", &o->drift.min_correlation);
  r.Optional("drift_max_correction_px", &o->drift.max_correction_px);
  r.Optional("instrument_rejection", &o->instruments.enabled);
  r.Optional("instrument_seed_max_warmth", &o->instruments.mask.seed_max_warmth);
  r.Optional("instrument_grow_max_warmth", &o->instruments.mask.grow_max_warmth);
  r.Optional("instrument_min_area_fraction", &o->instruments.mask.min_area_fraction);
  r.Optional("instrument_margin_px", &o->instruments.mask.margin_px);
  r.Optional("instrument_motion", &o->instruments.motion.enabled);
  r.Optional("reidentify_after_instrument", &o->reidentify.after_instrument);
  r.Finish();
}

void ReadLifting(const Scene& scene, lift::FeatureLifterOptions* o) {
  JsonObjectReader r(scene.lifting, scene.path, "lifting");
  r.OptionalEnum("target", lift::kLiftTargetNames, &o->target);
  r.OptionalEnum("surface_update", lift::kSurfaceUpdateNames, &o->surface_update);
  r.Optional("max_depth_jump_mm", &o->max_depth_jump_mm);
  r.Optional("follow_model_thinning", &o->follow_model_thinning);
  r.Finish();
}

void ReadMechanics(const Scene& scene, MechanicsStageOptions* o) {
  JsonObjectReader r(scene.mechanics, scene.path, "mechanics");
  r.Optional("spring_stiffness_relative", &o->spring_stiffness_relative);
  r.OptionalEnum("volume_term", mechanics::kVolumeTermNames, &o->volume_term);
  r.Optional("spring_stiffness_n_per_m", &o->spring_stiffness_n_per_m);
  r.Optional("substeps", &o->substeps);
  r.Optional("newton_iterations", &o->newton_iterations);
  r.Optional("rayleigh_mass_per_s", &o->rayleigh_mass_per_s);
  r.Optional("rayleigh_stiffness_s", &o->rayleigh_stiffness_s);
  r.Optional("gravity_mm_per_s2", &o->gravity_mm_per_s2);
  r.Optional("fixed_vertices", &o->fixed_vertices);
  r.Optional("out_of_view_tether", &o->out_of_view_tether);
  r.OptionalEnum("linear_solver", mechanics::kLinearSolverTypeNames, &o->linear_solver);
  r.Optional("line_search", &o->line_search);
  r.Optional("output_spring_factor", &o->output_spring_factor);
  r.Finish();
}

void ReadCutting(const Scene& scene, CuttingStageOptions* o) {
  JsonObjectReader r(scene.cutting, scene.path, "cutting");
  r.Optional("enabled", &o->enabled);
  r.Optional("neighbour_radius_mm", &o->detector.neighbour_radius_mm);
  r.Optional("neighbours_per_feature", &o->detector.neighbours_per_feature);
  r.Optional("outlier_weight_cap", &o->detector.outlier_weight_cap);
  r.Optional("reject_lone_features", &o->detector.reject_lone_features);
  r.Optional("reject_star_starts", &o->detector.reject_star_starts);
  r.Optional("confirm_starts_with_model_measure", &o->detector.confirm_starts_with_model_measure);
  r.Optional("closing_window_frames", &o->detector.closing_window_frames);
  r.Optional("max_closing_fraction", &o->detector.max_closing_fraction);
  r.Optional("outlier_factor", &o->detector.outlier_factor);
  r.Optional("mean_of_inliers", &o->detector.mean_of_inliers);
  r.Optional("min_outliers", &o->detector.min_outliers);
  r.Optional("cut_point_radius_mm", &o->detector.cut_point_radius_mm);
  r.OptionalEnum("measure", cutting::kCutMeasureNames, &o->detector.measure);
  r.Optional("require_opening", &o->detector.require_opening);
  r.Optional("ignore_occluded_pairs", &o->detector.ignore_occluded_pairs);
  r.Optional("cluster_outliers", &o->detector.cluster_outliers);
  r.Optional("min_opening_balance", &o->detector.min_opening_balance);
  r.Optional("min_opening_balance_bridges", &o->detector.min_opening_balance_bridges);
  r.Optional("min_lone_growth_balance", &o->detector.min_lone_growth_balance);
  r.Optional("grow_at_extremities_only", &o->detector.grow_at_extremities_only);
  r.Optional("min_outlier_measure_mm", &o->detector.min_outlier_measure_mm);
  r.Optional("bridge_radius_factor", &o->detector.bridge_radius_factor);
  r.Optional("bridge_cone_half_angle_deg", &o->detector.bridge_cone_half_angle_deg);
  r.Optional("probe_length_factor", &o->detector.probe_length_factor);
  r.Optional("probe_pair_length_factor", &o->detector.probe_pair_length_factor);
  r.Optional("probe_outlier_factor", &o->detector.probe_outlier_factor);
  r.Optional("probe_max_lead_factor", &o->detector.probe_max_lead_factor);
  r.OptionalEnum("decision", cutting::kCutDecisionNames, &o->detector.decision);
  r.Optional("false_alarm_probability", &o->detector.separation.false_alarm_probability);
  r.Optional("min_features_per_side", &o->detector.separation.min_features_per_side);
  r.Optional("separation_directions", &o->detector.separation.directions);
  r.Optional("strip_half_width", &o->detector.separation.strip_half_width);
  r.Optional("separation_radius_factor", &o->detector.separation_radius_factor);
  r.Optional("growth_cone_deg", &o->detector.growth_cone_deg);
  r.Optional("tracking_noise_px", &o->tracking_noise_px);
  r.Optional("spring_margin_mm", &o->spring_margin_mm);
  r.Optional("extrusion_margin_mm", &o->extrusion_margin_mm);
  r.OptionalEnum("method", cutting::kRemeshMethodNames, &o->method);
  r.Optional("snap_epsilon", &o->snap_epsilon);
  r.Optional("on_surface_tolerance", &o->on_surface_tolerance);
  r.Optional("keep_connected", &o->keep_connected);
  r.Optional("first_event_foresight", &o->first_event_foresight);
  r.Optional("min_outlier_measure_px", &o->min_outlier_measure_px);
  r.Optional("refuse_splitting_segments", &o->refuse_splitting_segments);
  r.OptionalEnum("cut_configuration", kCutConfigurationNames, &o->cut_configuration);
  r.Optional("internal_caps", &o->internal_caps);
  r.Finish();
}

void ReadRender(const Scene& scene, RenderStageOptions* o) {
  JsonObjectReader r(scene.render, scene.path, "render");
  r.OptionalEnum("style", kOverlayStyleNames, &o->style);
  r.Optional("contour_color", &o->contour_color);
  r.Optional("cut_edge_color", &o->cut_edge_color);
  r.Optional("contour_width_px", &o->contour_width_px);
  r.Optional("cut_edge_angle_deg", &o->cut_edge_angle_deg);
  r.Optional("legend", &o->legend);
  r.Optional("frame_counter", &o->frame_counter);
  r.Optional("supersampling", &o->supersampling);
  r.Optional("organ_opacity", &o->organ_opacity);
  r.Optional("organ_color", &o->organ_color);
  r.Optional("wireframe", &o->wireframe);
  r.Optional("show_features", &o->show_features);
  r.Optional("show_targets", &o->show_targets);
  r.Optional("show_springs", &o->show_springs);
  r.Finish();
}

void ReadOutput(const Scene& scene, OutputStageOptions* o) {
  JsonObjectReader r(scene.output, scene.path, "output");
  r.Optional("video", &o->video);
  r.Optional("crf", &o->crf);
  r.OptionalChoice("preset",
                   {"ultrafast", "superfast", "veryfast", "faster", "fast", "medium", "slow"},
                   &o->preset);
  r.Optional("png_frames", &o->png_frames);
  r.Optional("save_every", &o->save_every);
  r.Finish();
}

}  // namespace

PipelineOptions ReadPipelineOptions(const Scene& scene) {
  PipelineOptions o;
  o.tracking.max_features = 500;
  o.tracking.min_features = 350;
  // Video frames are BGR: features on instruments are dropped (docs/instruments.md).
  o.tracking.instruments.enabled = true;
  ReadTracking(scene, &o.tracking, &o);
  ReadLifting(scene, &o.lifting);
  ReadMechanics(scene, &o.mechanics);
  ReadCutting(scene, &o.cutting);
  ReadRender(scene, &o.render);
  ReadOutput(scene, &o.output);
  try {
    o.Check();
  } catch (const Error& e) {
    throw Error(scene.path, "", e.what());
  }
  return o;
}

nlohmann::json PipelineOptionsToJson(const PipelineOptions& o) {
  using nlohmann::json;
  auto vec = [](const Eigen::Vector3d& v) { return json::array({v.x(), v.y(), v.z()}); };
  json j;
  j["tracking"] = {{"max_features", o.tracking.max_features},
                   {"hessian_threshold", o.tracking.surf.hessian_threshold},
                   {"min_features", o.tracking.min_features},
                   {"min_hessian_threshold", o.tracking.min_hessian_threshold},
                   {"min_distance_px", o.tracking.min_distance_px},
                   {"border_px", o.tracking.border_px},
                   {"redetect_every_frames", o.tracking.redetect_every_frames},
                   {"redetect_hole_factor", o.tracking.redetect_hole_factor},
                   {"window_px", o.tracking.lk.window_px},
                   {"pyramid_levels", o.tracking.lk.pyramid_levels},
                   {"forward_backward_max_px", o.tracking.lk.forward_backward_max_px},
                   {"lk_backend", LucasKanadeBackendName(o.tracking.lk.backend)},
                   {"outlier_filter", o.tracking.outliers.enabled},
                   {"outlier_ratio", o.tracking.outliers.ratio},
                   {"outlier_slack_px", o.tracking.outliers.slack_px},
                   {"specular_filter", o.tracking.specular.enabled},
                   {"appearance_check", o.tracking.appearance.enabled},
                   {"appearance_min_correlation", o.tracking.appearance.min_correlation},
                   {"drift_correction", o.tracking.drift.enabled},
                   {"drift_window_px", o.tracking.drift.window_px},
                   {"drift_every_frames", o.tracking.drift.every_frames},
                   {"drift_min_correlation", o.tracking.drift.min_correlation},
                   {"drift_max_correction_px", o.tracking.drift.max_correction_px},
                   {"instrument_rejection", o.tracking.instruments.enabled},
                   {"instrument_seed_max_warmth", o.tracking.instruments.mask.seed_max_warmth},
                   {"instrument_grow_max_warmth", o.tracking.instruments.mask.grow_max_warmth},
                   {"instrument_min_area_fraction", o.tracking.instruments.mask.min_area_fraction},
                   {"instrument_margin_px", o.tracking.instruments.mask.margin_px},
                   {"instrument_motion", o.tracking.instruments.motion.enabled},
                   {"reidentify_after_instrument", o.tracking.reidentify.after_instrument}};
  j["lifting"] = {{"target", NameOf(lift::kLiftTargetNames, o.lifting.target)},
                  {"surface_update", NameOf(lift::kSurfaceUpdateNames, o.lifting.surface_update)},
                  {"max_depth_jump_mm", o.lifting.max_depth_jump_mm},
                  {"follow_model_thinning", o.lifting.follow_model_thinning}};
  j["mechanics"] = {{"spring_stiffness_relative", o.mechanics.spring_stiffness_relative},
                    {"volume_term", mechanics::VolumeTermName(o.mechanics.volume_term)},
                    {"spring_stiffness_n_per_m", o.mechanics.spring_stiffness_n_per_m},
                    {"substeps", o.mechanics.substeps},
                    {"newton_iterations", o.mechanics.newton_iterations},
                    {"rayleigh_mass_per_s", o.mechanics.rayleigh_mass_per_s},
                    {"rayleigh_stiffness_s", o.mechanics.rayleigh_stiffness_s},
                    {"gravity_mm_per_s2", vec(o.mechanics.gravity_mm_per_s2)},
                    {"fixed_vertices", o.mechanics.fixed_vertices},
                    {"out_of_view_tether", o.mechanics.out_of_view_tether},
                    {"linear_solver", mechanics::LinearSolverTypeName(o.mechanics.linear_solver)},
                    {"line_search", o.mechanics.line_search},
                    {"output_spring_factor", o.mechanics.output_spring_factor}};
  j["cutting"] = {
      {"enabled", o.cutting.enabled},
      {"neighbour_radius_mm", o.cutting.detector.neighbour_radius_mm},
      {"neighbours_per_feature", o.cutting.detector.neighbours_per_feature},
      {"outlier_weight_cap", o.cutting.detector.outlier_weight_cap},
      {"reject_lone_features", o.cutting.detector.reject_lone_features},
      {"reject_star_starts", o.cutting.detector.reject_star_starts},
      {"confirm_starts_with_model_measure", o.cutting.detector.confirm_starts_with_model_measure},
      {"closing_window_frames", o.cutting.detector.closing_window_frames},
      {"max_closing_fraction", o.cutting.detector.max_closing_fraction},
      {"outlier_factor", o.cutting.detector.outlier_factor},
      {"mean_of_inliers", o.cutting.detector.mean_of_inliers},
      {"min_outliers", o.cutting.detector.min_outliers},
      {"cut_point_radius_mm", o.cutting.detector.cut_point_radius_mm},
      {"measure", NameOf(cutting::kCutMeasureNames, o.cutting.detector.measure)},
      {"require_opening", o.cutting.detector.require_opening},
      {"ignore_occluded_pairs", o.cutting.detector.ignore_occluded_pairs},
      {"cluster_outliers", o.cutting.detector.cluster_outliers},
      {"min_opening_balance", o.cutting.detector.min_opening_balance},
      {"min_opening_balance_bridges", o.cutting.detector.min_opening_balance_bridges},
      {"min_lone_growth_balance", o.cutting.detector.min_lone_growth_balance},
      {"grow_at_extremities_only", o.cutting.detector.grow_at_extremities_only},
      {"min_outlier_measure_mm", o.cutting.detector.min_outlier_measure_mm},
      {"bridge_radius_factor", o.cutting.detector.bridge_radius_factor},
      {"bridge_cone_half_angle_deg", o.cutting.detector.bridge_cone_half_angle_deg},
      {"probe_length_factor", o.cutting.detector.probe_length_factor},
      {"probe_pair_length_factor", o.cutting.detector.probe_pair_length_factor},
      {"probe_outlier_factor", o.cutting.detector.probe_outlier_factor},
      {"probe_max_lead_factor", o.cutting.detector.probe_max_lead_factor},
      {"decision", NameOf(cutting::kCutDecisionNames, o.cutting.detector.decision)},
      {"false_alarm_probability", o.cutting.detector.separation.false_alarm_probability},
      {"min_features_per_side", o.cutting.detector.separation.min_features_per_side},
      {"separation_directions", o.cutting.detector.separation.directions},
      {"strip_half_width", o.cutting.detector.separation.strip_half_width},
      {"separation_radius_factor", o.cutting.detector.separation_radius_factor},
      {"growth_cone_deg", o.cutting.detector.growth_cone_deg},
      {"tracking_noise_px", o.cutting.tracking_noise_px},
      {"spring_margin_mm", o.cutting.spring_margin_mm},
      {"extrusion_margin_mm", o.cutting.extrusion_margin_mm},
      {"method", cutting::RemeshMethodName(o.cutting.method)},
      {"snap_epsilon", o.cutting.snap_epsilon},
      {"on_surface_tolerance", o.cutting.on_surface_tolerance},
      {"keep_connected", o.cutting.keep_connected},
      {"first_event_foresight", o.cutting.first_event_foresight},
      {"min_outlier_measure_px", o.cutting.min_outlier_measure_px},
      {"refuse_splitting_segments", o.cutting.refuse_splitting_segments},
      {"cut_configuration", CutConfigurationName(o.cutting.cut_configuration)},
      {"internal_caps", o.cutting.internal_caps}};
  j["render"] = {{"enabled", o.render.enabled},
                 {"style", NameOf(kOverlayStyleNames, o.render.style)},
                 {"contour_color", vec(o.render.contour_color)},
                 {"cut_edge_color", vec(o.render.cut_edge_color)},
                 {"contour_width_px", o.render.contour_width_px},
                 {"cut_edge_angle_deg", o.render.cut_edge_angle_deg},
                 {"legend", o.render.legend},
                 {"frame_counter", o.render.frame_counter},
                 {"supersampling", o.render.supersampling},
                 {"organ_opacity", o.render.organ_opacity},
                 {"organ_color", vec(o.render.organ_color)},
                 {"wireframe", o.render.wireframe},
                 {"show_features", o.render.show_features},
                 {"show_targets", o.render.show_targets},
                 {"show_springs", o.render.show_springs}};
  j["output"] = {{"video", o.output.video},           {"crf", o.output.crf},
                 {"preset", o.output.preset},         {"encode_threads", o.output.encode_threads},
                 {"png_frames", o.output.png_frames}, {"save_every", o.output.save_every}};
  j["max_frames"] = o.max_frames;
  j["roi_dilation_px"] = o.roi_dilation_px;
  j["attach_after_frames"] = o.attach_after_frames;
  j["attach_max_misfit_factor"] = o.attach_max_misfit_factor;
  return j;
}

}  // namespace arreg::pipeline
