#include "ar/pipeline/registration_pipeline.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <filesystem>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <unordered_map>
#include <vector>

#include "ar/lift/lifting.h"
#include "ar/pipeline/cut_handler.h"
#include "ar/pipeline/overlay.h"
#include "ar/render/rasterizer.h"
#include "core/error.h"
#include "core/file_util.h"
#include "core/json_reader.h"
#include "core/log.h"
#include "core/mesh_io.h"
#include "core/mesh_ops.h"
#include "mechanics/curved_boundary.h"
#include "mechanics/elastic_energy.h"
#include "mechanics/embedding.h"
#include "mechanics/integrator.h"
#include "mechanics/mechanical_state.h"
#include "mechanics/quasi_static_fit.h"
#include "mechanics/spring_energy.h"
#include "tracking/video_io.h"

namespace arreg::pipeline {

StageTimes& StageTimes::operator+=(const StageTimes& o) {
  decode += o.decode;
  track += o.track;
  lift += o.lift;
  mechanics += o.mechanics;
  cutting += o.cutting;
  render += o.render;
  encode += o.encode;
  record += o.record;
  return *this;
}

nlohmann::json StageTimes::ToJson() const {
  return {{"decode", decode},   {"track", track},   {"lift", lift},     {"mechanics", mechanics},
          {"cutting", cutting}, {"render", render}, {"encode", encode}, {"record", record}};
}

nlohmann::json CutEvent::ToJson() const {
  nlohmann::json polyline = nlohmann::json::array();
  for (const Eigen::Vector3d& p : polyline_rest_mm) polyline.push_back({p.x(), p.y(), p.z()});
  nlohmann::json j = {{"frame", frame},
                      {"status", CutEventStatusName(status)},
                      {"message", message},
                      {"polyline_points", polyline_points},
                      {"new_tetrahedra", new_tetrahedra},
                      {"new_vertices", new_vertices},
                      {"springs_removed", springs_removed},
                      {"internal_triangles_removed", internal_triangles_removed},
                      {"internal_cap_faces", internal_cap_faces},
                      {"depth_fraction", depth_fraction},
                      {"configuration", configuration ? CutConfigurationName(*configuration) : ""},
                      {"welded_vertices", welded_vertices},
                      {"polyline_rest_mm", polyline}};
  if (thin) {
    j["thin_shells_cut"] = thin_shells_cut;
    j["thin_shell_nodes_added"] = thin_shell_nodes_added;
    j["thin_vessels_cut"] = thin_vessels_cut;
    j["thin_vessel_frames_added"] = thin_vessel_frames_added;
  }
  return j;
}

namespace {

// Milliseconds on the wall clock, or on this thread's CPU clock (timings on a shared machine).
double NowMs(bool thread_cpu) {
  if (thread_cpu) {
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
  }
  return std::chrono::duration<double, std::milli>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

// surface_every_k of a ground-truth folder, 0 when it has none.
int GroundTruthEveryK(const Scene& scene) {
  if (scene.ground_truth_path.empty()) return 0;
  const std::string meta = scene.ground_truth_path + "/meta.json";
  if (!FileExists(meta)) return 0;
  const nlohmann::json j = ParseJsonFile(meta);
  int k = 0;
  if (j.contains("surface_every_k"))
    ReadJsonValue(j.at("surface_every_k"), meta, "surface_every_k", &k);
  return std::max(k, 0);
}

// The detector's options with the outlier floor of CuttingStageOptions::min_outlier_measure_px
// and the separation test's noise floor of tracking_noise_px: that many pixels at the median
// camera depth of the features' frame-0 points `p0_mm`.
cutting::CutDetectorOptions WithPixelFloor(const CuttingStageOptions& o,
                                           const PinholeCamera& camera, const RowMatX3d& p0_mm) {
  cutting::CutDetectorOptions d = o.detector;
  if (p0_mm.rows() == 0) return d;
  std::vector<double> depth(p0_mm.rows());
  for (Eigen::Index i = 0; i < p0_mm.rows(); ++i)
    depth[i] = (camera.camera_from_world * p0_mm.row(i).transpose()).z();
  const auto mid = depth.begin() + depth.size() / 2;
  std::nth_element(depth.begin(), mid, depth.end());
  const double mm_per_px = *mid / (0.5 * (camera.fx + camera.fy));
  if (std::isfinite(mm_per_px) && mm_per_px > 0) {
    d.min_outlier_measure_mm =
        std::max(d.min_outlier_measure_mm, o.min_outlier_measure_px * mm_per_px);
    d.separation.noise_floor_mm = o.tracking_noise_px * mm_per_px;
  }
  return d;
}

// One mesh of several (vertices stacked, faces renumbered).
SurfaceMesh MergeSurfaces(const std::vector<SurfaceMesh>& parts) {
  SurfaceMesh out;
  int nv = 0, nf = 0;
  for (const SurfaceMesh& m : parts) nv += m.num_vertices(), nf += m.num_faces();
  out.vertices.resize(nv, 3);
  out.faces.resize(nf, 3);
  nv = nf = 0;
  for (const SurfaceMesh& m : parts) {
    out.vertices.middleRows(nv, m.num_vertices()) = m.vertices;
    out.faces.middleRows(nf, m.num_faces()) = m.faces.array() + nv;
    nv += m.num_vertices();
    nf += m.num_faces();
  }
  return out;
}

}  // namespace

LoadedModel LoadSceneModel(const Scene& scene) {
  LoadedModel model;
  if (!scene.model_mesh_path.empty()) {
    model.mesh = ReadTetMesh(scene.model_mesh_path);
    model.mesh.vertices = PlaceInWorld(model.mesh.vertices, scene);
    FixOrientation(&model.mesh);
  } else {
    // A scene of thin structures only (ParseScene allows it only then).
    model.mesh.vertices.resize(0, 3);
    model.mesh.tetrahedra.resize(0, 4);
    ARREG_CHECK_INPUT(scene.internal_structures.empty(), scene.path, "internal_structures",
                      "internal structures are embedded in the model, and the scene has none");
  }
  model.thin = LoadThinStructures(scene);
  for (const InternalStructure& s : scene.internal_structures) {
    SurfaceMesh mesh = ReadSurfaceMesh(s.mesh_path);
    mesh.vertices = PlaceInWorld(mesh.vertices, scene);
    mesh.normals.resize(0, 3);
    model.internal.push_back(std::move(mesh));
    model.internal_names.push_back(s.name);
    model.internal_colors.push_back(s.color_rgb);
    model.internal_opacity.push_back(s.opacity);
  }
  return model;
}

struct RegistrationPipeline::Impl {
  Scene scene;
  PipelineOptions options;
  std::vector<FrameObserver*> observers;
  LoadedModel model;
  VideoReader reader;
};

namespace {

// Steps per edge of each boundary face's lattice when a degree-2/3 organ's curved surface is
// tessellated for the overlay, the saved surfaces and the evaluation (16 triangles a face):
// a quadratic edge of sagitta h leaves h / 16 between the chords and the curve.
constexpr int kCurvedSubdivisions = 4;

// Whether a feature with this history is due to be attached in `frame`: detected exactly
// `after_frames` frames before and tracked in every frame since (re-identified ones too).
bool ProbationPassed(const std::vector<TrackObservation>& history, int frame, int after_frames) {
  if (history.empty() || history.front().frame != frame - after_frames) return false;
  for (const TrackObservation& obs : history)
    if (obs.status != TrackStatus::kTracked) return false;
  return true;
}

// Per point (#P x 3, on the model): whether the model agrees with the image around it
// (PipelineOptions::attach_max_misfit_factor): the mean spring length |anchor - target| of the
// features with an active spring whose anchors lie within `radius_mm` is at most `factor` times
// the median over all of them. True where no such feature is near.
std::vector<char> ModelAgrees(const RowMatX3d& points_mm, const RowMatX3d& anchors_mm,
                              const RowMatX3d& targets_mm, const std::vector<FeatureView>& features,
                              double radius_mm, double factor) {
  std::vector<int> rows;
  std::vector<double> length;
  for (int r = 0; r < static_cast<int>(features.size()); ++r)
    if (features[r].spring_active) {
      rows.push_back(r);
      length.push_back((anchors_mm.row(r) - targets_mm.row(r)).norm());
    }
  std::vector<char> agrees(points_mm.rows(), 1);
  if (rows.empty()) return agrees;
  std::vector<double> sorted = length;
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  const double limit = factor * sorted[sorted.size() / 2];
  for (int k = 0; k < points_mm.rows(); ++k) {
    double sum = 0.0;
    int count = 0;
    for (size_t i = 0; i < rows.size(); ++i)
      if ((anchors_mm.row(rows[i]) - points_mm.row(k)).squaredNorm() < radius_mm * radius_mm) {
        sum += length[i];
        ++count;
      }
    agrees[k] = count == 0 || sum / count <= limit;
  }
  return agrees;
}

// Adds the time from its construction to its end to one stage's milliseconds: every stage of
// the loop is timed through one of these, on the run's clock (RunOptions::thread_cpu_clock).
class StageTimer {
 public:
  StageTimer(bool thread_cpu, double* stage_ms)
      : thread_cpu_(thread_cpu), stage_ms_(stage_ms), start_(NowMs(thread_cpu)) {}
  ~StageTimer() { Stop(); }
  // Ends the timing before the scope does (the setup's stages declare what later code uses).
  void Stop() {
    if (stage_ms_ != nullptr) *stage_ms_ += NowMs(thread_cpu_) - start_;
    stage_ms_ = nullptr;
  }
  StageTimer(const StageTimer&) = delete;
  StageTimer& operator=(const StageTimer&) = delete;

 private:
  bool thread_cpu_;
  double* stage_ms_;
  double start_;
};

// Decode: the next frame into `bgr`; false at the end of the video. A damaged frame (the
// reader's last good one again) is marked in `stats` and listed in `summary`.
bool Decode(VideoReader& reader, int frame, cv::Mat* bgr, FrameStats* stats, RunSummary* summary) {
  if (!reader.Read(bgr)) return false;
  const std::vector<int>& damaged = reader.damaged_frames();
  stats->damaged = std::find(damaged.begin(), damaged.end(), frame) != damaged.end();
  if (stats->damaged) summary->damaged_frames.push_back(frame);
  return true;
}

// The region the tracker searches: the projected lifting surface (vertices, faces), dilated by
// `dilation_px`; empty (the whole image) when `dilation_px` < 0.
cv::Mat TrackingRegion(const render::RasterCamera& raster, const RowMatX3d& vertices,
                       const RowMatX3i& faces, int dilation_px) {
  cv::Mat roi;
  if (dilation_px < 0) return roi;
  roi = render::RenderMask(raster, vertices, faces);
  if (dilation_px > 0)
    cv::dilate(roi, roi,
               cv::getStructuringElement(cv::MORPH_ELLIPSE,
                                         cv::Size(2 * dilation_px + 1, 2 * dilation_px + 1)));
  return roi;
}

// Track (after FeatureTracker::Track): the followed features' rows of `features`, `pixels` and
// `tracked` take the tracker's positions and states; losses are counted in `stats`. Returns the
// features not followed yet whose probation ended this frame (they join in JoinFeatures).
std::vector<const FeatureState*> FollowTracks(const FeatureTracker& tracker,
                                              const std::unordered_map<int, int>& row_of_id,
                                              int frame, int attach_after_frames,
                                              std::vector<FeatureView>* features, RowMatX2d* pixels,
                                              std::vector<char>* tracked, FrameStats* stats) {
  std::vector<const FeatureState*> detected;
  for (const FeatureState& f : tracker.current()) {
    const auto it = row_of_id.find(f.id);
    if (it == row_of_id.end()) {
      if (f.status == TrackStatus::kTracked &&
          ProbationPassed(tracker.store().history(f.id), frame, attach_after_frames))
        detected.push_back(&f);
      continue;
    }
    FeatureView& v = (*features)[it->second];
    v.pixel = Eigen::Vector2d(f.position_px.x, f.position_px.y);
    v.track_status = f.status;
    v.window_on_instrument =
        f.status == TrackStatus::kTracked && tracker.WindowOnInstrument(f.position_px);
    pixels->row(it->second) = v.pixel.transpose();
    if (f.status != TrackStatus::kTracked && (*tracked)[it->second]) {
      ++stats->lost;
      if (f.status == TrackStatus::kOutlierSpatioTemporal) ++stats->outliers;
    }
  }
  for (size_t r = 0; r < features->size(); ++r)
    (*tracked)[r] = (*features)[r].track_status == TrackStatus::kTracked;
  return detected;
}

// Mechanics, first half: each active spring follows its feature's target `targets` row; a
// feature no longer tracked loses its spring (in `thin` where `thin_spring` names one there).
void FollowTargets(const std::vector<lift::LiftStatus>& lift_status, const RowMatX3d& targets,
                   const std::vector<char>& tracked, const std::vector<int>& thin_spring,
                   ThinSystem* thin, mechanics::SpringEnergy* springs,
                   std::vector<FeatureView>* features) {
  for (size_t r = 0; r < features->size(); ++r) {
    FeatureView& v = (*features)[r];
    v.lift_status = lift_status[r];
    if (!v.spring_active) continue;
    if (!tracked[r]) {
      if (thin_spring[r] >= 0)
        thin->RemoveFeatureSpring(thin_spring[r]);
      else
        springs->Remove(v.spring);
      v.spring_active = false;
      continue;
    }
    if (thin_spring[r] >= 0)
      thin->SetFeatureTarget(thin_spring[r], targets.row(r).transpose());
    else
      springs->SetTarget(v.spring, targets.row(r).transpose());
  }
}

// Mechanics, second half: one implicit Euler step of `state`, in the generalised system
// `generalised` (thin structures, degree 2 and 3) when there is one, else by `integrator`
// with `elastic` and `terms`; the step's figures go to `stats`.
void StepMechanics(ThinSystem* generalised, mechanics::ImplicitEulerIntegrator* integrator,
                   mechanics::CorotationalElasticity* elastic,
                   const std::vector<mechanics::EnergyTerm*>& terms,
                   mechanics::MechanicalState* state, FrameStats* stats) {
  if (generalised) {
    const mechanics::GeneralisedSummary step = generalised->Step(state);
    stats->mechanics_status = mechanics::StepStatusName(step.status);
    stats->linear_iterations = step.linear_iterations;
    stats->factorizations = step.factorizations;
    stats->line_search_cuts = step.line_search_cuts;
  } else {
    const mechanics::StepSummary step = integrator->Step(state, elastic, terms);
    stats->mechanics_status = mechanics::StepStatusName(step.status);
    stats->inverted_elements = step.inverted_elements;
    stats->linear_iterations = step.linear_iterations;
    stats->factorizations = step.factorizations;
    stats->line_search_cuts = step.line_search_cuts;
  }
}

// Detect: the detector's input, the features with an active spring (ids = feature rows) with
// their targets, their anchors on the model and whether an instrument lies in their window.
cutting::FrameFeatures DetectorInput(const std::vector<FeatureView>& features,
                                     const RowMatX3d& targets, const RowMatX3d& anchors) {
  cutting::FrameFeatures ff;
  for (size_t r = 0; r < features.size(); ++r)
    if (features[r].spring_active) ff.ids.push_back(static_cast<int>(r));
  ff.target_mm.resize(ff.ids.size(), 3);
  ff.model_mm.resize(ff.ids.size(), 3);
  ff.occluded.resize(ff.ids.size());
  for (size_t i = 0; i < ff.ids.size(); ++i) {
    ff.target_mm.row(i) = targets.row(ff.ids[i]);
    ff.model_mm.row(i) = anchors.row(ff.ids[i]);
    ff.occluded[i] = features[ff.ids[i]].window_on_instrument ? 1 : 0;
  }
  return ff;
}

// Render: the structures drawn over the organ, the internal ones filled in their scene colours,
// the thin ones (`thin` non-null only where an organ is drawn under them) as outlines.
std::vector<OverlayStructure> OverlayStructures(const std::vector<SurfaceMesh>& internal,
                                                const LoadedModel& model,
                                                const std::vector<SurfaceMesh>& thin_surfaces,
                                                const ThinSystem* thin) {
  std::vector<OverlayStructure> layers;
  for (size_t k = 0; k < internal.size(); ++k)
    layers.push_back({&internal[k].vertices, &internal[k].faces, model.internal_colors[k],
                      model.internal_opacity[k], model.internal_names[k], /*outline=*/false});
  if (thin)
    for (size_t k = 0; k < thin_surfaces.size(); ++k)
      layers.push_back({&thin_surfaces[k].vertices, &thin_surfaces[k].faces, thin->colors()[k],
                        thin->opacities()[k], thin->names()[k], /*outline=*/true});
  return layers;
}

// The frame's spring statistics: a feature is alive while its spring acts; its spring length
// is |anchor - target|. Fills `alive_rows` (the overlay's) and the features' views.
void SpringStatistics(const RowMatX3d& anchors, const RowMatX3d& targets,
                      std::vector<FeatureView>* features, std::vector<char>* alive_rows,
                      FrameStats* stats) {
  double sum = 0;
  for (size_t r = 0; r < features->size(); ++r) {
    FeatureView& v = (*features)[r];
    v.alive = v.spring_active;
    (*alive_rows)[r] = v.alive;
    v.spring_length_mm = v.alive ? (anchors.row(r) - targets.row(r)).norm() : 0.0;
    if (!v.alive) continue;
    ++stats->features_alive;
    sum += v.spring_length_mm;
    stats->spring_length_max_mm = std::max(stats->spring_length_max_mm, v.spring_length_mm);
  }
  stats->spring_length_mean_mm = stats->features_alive ? sum / stats->features_alive : 0.0;
}

}  // namespace

RegistrationPipeline::RegistrationPipeline(const Scene& scene, const PipelineOptions& options)
    : impl_(std::make_unique<Impl>()) {
  impl_->scene = scene;
  impl_->options = options;
  options.Check();
  scene.camera.Check(scene.path);
  impl_->model = LoadSceneModel(scene);
  impl_->reader.Open(scene.video_path);
  ARREG_CHECK_INPUT(
      impl_->reader.width() == scene.camera.width && impl_->reader.height() == scene.camera.height,
      scene.video_path, "size", "video is ", impl_->reader.width(), "x", impl_->reader.height(),
      " but the camera is ", scene.camera.width, "x", scene.camera.height);
  for (int v : options.mechanics.fixed_vertices)
    ARREG_CHECK_INPUT(v < impl_->model.mesh.vertices.rows(), scene.path, "mechanics.fixed_vertices",
                      "index ", v, " >= vertex count ", impl_->model.mesh.vertices.rows());
  // Degree 2 and 3 (docs/higher-order.md, "In the registration"): no quadratic cutting, so
  // the run must not change topology; the thin structures' ties embed in linear tetrahedra.
  if (scene.model_degree > 1) {
    ARREG_CHECK_INPUT(!options.cutting.enabled, scene.path, "model.degree", "degree ",
                      scene.model_degree,
                      " elements cannot be cut (there is no quadratic cutting): run with "
                      "--no-topology");
    ARREG_CHECK_INPUT(impl_->model.thin.empty(), scene.path, "model.degree", "degree ",
                      scene.model_degree, " is not available with thin_structures");
  }
}

RegistrationPipeline::~RegistrationPipeline() = default;
void RegistrationPipeline::AddObserver(FrameObserver* observer) {
  impl_->observers.push_back(observer);
}
const Scene& RegistrationPipeline::scene() const { return impl_->scene; }
const PipelineOptions& RegistrationPipeline::options() const { return impl_->options; }

RunSummary RegistrationPipeline::Run(const RunOptions& run_options) {
  const Scene& scene = impl_->scene;
  const PipelineOptions& o = impl_->options;
  const PinholeCamera& camera = scene.camera;
  VideoReader& reader = impl_->reader;
  reader.Seek(0);
  const double fps = reader.fps() > 0 ? reader.fps() : 25.0;
  const bool cpu_clock = run_options.thread_cpu_clock;
  int num_frames = reader.frame_count();
  if (o.max_frames > 0) num_frames = std::min(num_frames, o.max_frames);
  int save_every = run_options.save_every;
  if (save_every <= 0) save_every = GroundTruthEveryK(scene);
  if (save_every <= 0) save_every = o.output.save_every;

  // --- Mechanics setup.
  mechanics::MechanicalState state(impl_->model.mesh, ToMechanicsMaterial(scene.material));
  state.SetFixed(o.mechanics.fixed_vertices);
  mechanics::CorotationalOptions elastic_options;
  elastic_options.volume_term = o.mechanics.volume_term;
  mechanics::CorotationalElasticity elastic(elastic_options);
  mechanics::SpringEnergy springs;
  std::optional<mechanics::GravityEnergy> gravity;
  std::vector<mechanics::EnergyTerm*> other_terms;  // all but the springs (the output fit's)
  if (o.mechanics.gravity_mm_per_s2.squaredNorm() > 0) {
    gravity.emplace(o.mechanics.gravity_mm_per_s2);
    other_terms.push_back(&*gravity);
  }
  std::vector<mechanics::EnergyTerm*> terms = {&springs};
  terms.insert(terms.end(), other_terms.begin(), other_terms.end());
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
  mechanics::ImplicitEulerIntegrator integrator(io);
  // The run's step options for a generalised system (thin structures, degree 2 and 3).
  const auto generalised_options = [&] {
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
  };
  // Thin structures: the organ, shells, vessels and all springs in one generalised system.
  const bool has_tets = state.num_tetrahedra() > 0;
  std::optional<ThinSystem> thin;
  if (!impl_->model.thin.empty()) {
    ThinSystemOptions to = generalised_options();
    to.elastic = elastic_options;
    thin.emplace(impl_->model.thin, scene, &state, &springs, to);
  }
  // Degree 2 and 3: the organ's Bernstein tetrahedra (straight-sided raise of the model
  // mesh: a scene gives no smooth surface to raise onto) in a generalised system of their own.
  const int degree = scene.model_degree;
  std::optional<ThinSystem> curved_system;
  BernsteinTetTerms* curved = nullptr;
  std::optional<mechanics::CurvedBoundary> curved_boundary;
  SurfaceMesh curved_surface;
  if (degree > 1) {
    mechanics::BernsteinTetOptions bo;
    bo.material = ToMechanicsMaterial(scene.material);
    auto terms = std::make_unique<BernsteinTetTerms>(
        mechanics::RaiseTetMesh(impl_->model.mesh, degree), bo, &springs);
    curved = terms.get();
    ThinSystemOptions to = generalised_options();
    curved_system.emplace(std::vector<LoadedThin>(), scene, &state, &springs, to, std::move(terms));
    curved_boundary =
        mechanics::TessellateBoundary(curved->mesh(), curved->mesh().nodes, kCurvedSubdivisions);
    curved_surface = curved_boundary->surface;
  }
  std::optional<mechanics::QuasiStaticFit> output_fit;
  // The output fit is a linear-tetrahedron solve: degree 2 and 3 show the stepped state.
  if (o.mechanics.output_spring_factor > 0 && has_tets && degree == 1) {
    mechanics::QuasiStaticFitOptions fo;
    fo.spring_factor = o.mechanics.output_spring_factor;
    fo.elastic = elastic_options;
    fo.linear_solver = io.linear_solver;
    output_fit.emplace(fo);
  }

  SurfaceMesh surface = ExtractBoundary(state.CurrentMesh());
  const RowMatX3i frame0_faces = surface.faces;  // lifting keeps frame-0 connectivity
  std::vector<SurfaceMesh> internal = impl_->model.internal;
  std::vector<RowMatX3d> internal_rest = [&] {
    std::vector<RowMatX3d> r;
    r.reserve(internal.size());
    for (const SurfaceMesh& m : internal) r.push_back(m.vertices);
    return r;
  }();
  std::vector<mechanics::EmbeddedPoints> internal_embedding;
  // The surface features are lifted onto: the organ's boundary, and with thin structures the
  // shells' frame-0 mid-surfaces after it (vertices: the organ's, then ThinSystem's lift
  // vertices). `lifted` is what lifting and the tracking region use.
  const int organ_vertices = impl_->model.mesh.num_vertices();
  const int organ_faces0 = surface.num_faces();
  SurfaceMesh lift_surface;
  const auto lift_vertices = [&] {
    RowMatX3d v(organ_vertices + (thin ? thin->num_lift_vertices() : 0), 3);
    v.topRows(organ_vertices) = state.positions().topRows(organ_vertices);
    if (thin) v.bottomRows(thin->num_lift_vertices()) = thin->LiftVertices();
    return v;
  };
  if (thin) {
    lift_surface.vertices = lift_vertices();
    lift_surface.faces.resize(organ_faces0 + thin->lift_triangles().rows(), 3);
    lift_surface.faces.topRows(organ_faces0) = surface.faces;
    lift_surface.faces.bottomRows(thin->lift_triangles().rows()) =
        thin->lift_triangles().array() + organ_vertices;
  }
  const SurfaceMesh& lifted = thin ? lift_surface : surface;
  std::vector<mechanics::HighOrderEmbedding> internal_curved;  // degree 2 and 3
  for (const SurfaceMesh& m : internal) {
    if (curved)
      internal_curved.push_back(
          mechanics::HighOrderEmbedding::Embed(curved->mesh(), curved->mesh().nodes, m.vertices));
    else
      internal_embedding.push_back(
          mechanics::EmbeddedPoints::Embed(m.vertices, state.rest_positions(), state.tetrahedra()));
  }

  // --- Frame 0: detection inside the model's silhouette, attachment by ray casting.
  const render::RasterCamera raster = ToRasterCamera(camera);
  cv::Mat bgr;
  StageTimes ms;
  {
    StageTimer timer(cpu_clock, &ms.decode);
    ARREG_CHECK_INPUT(reader.Read(&bgr), scene.video_path, "frame 0",
                      "cannot read the first frame");
  }

  StageTimer track_timer(cpu_clock, &ms.track);
  FeatureTracker tracker(o.tracking);
  cv::Mat roi = render::RenderMask(raster, lifted.vertices, lifted.faces);
  tracker.Initialize(bgr, roi);
  std::vector<FeatureView> features;
  std::unordered_map<int, int> row_of_id;
  RowMatX2d pixels(tracker.current().size(), 2);
  for (const FeatureState& f : tracker.current()) {
    const int r = static_cast<int>(features.size());
    FeatureView v;
    v.id = f.id;
    v.pixel = Eigen::Vector2d(f.position_px.x, f.position_px.y);
    v.track_status = f.status;
    pixels.row(r) = v.pixel.transpose();
    row_of_id[f.id] = r;
    features.push_back(v);
  }
  track_timer.Stop();
  int nf = static_cast<int>(features.size());

  StageTimer lift_timer(cpu_clock, &ms.lift);
  lift::FeatureLifter lifter(o.lifting);
  const std::vector<lift::FeatureAttachment> attachments =
      lifter.Attach(camera, pixels, &lifted, std::nullopt);
  lift_timer.Stop();

  StageTimer springs_timer(cpu_clock, &ms.mechanics);
  RowMatX3d attach_points(nf, 3);
  for (int r = 0; r < nf; ++r) attach_points.row(r) = attachments[r].point_mm.transpose();
  mechanics::EmbeddedPoints feature_embedding;
  if (has_tets)
    feature_embedding =
        mechanics::EmbeddedPoints::Embed(attach_points, state.rest_positions(), state.tetrahedra());
  else
    feature_embedding.Resize(nf);
  // Per feature row: its ThinSystem spring when it sits on a shell, else -1.
  std::vector<int> thin_spring(nf, -1);
  const auto on_shell = [&](const lift::FeatureAttachment& a) {
    return thin && a.attached && a.face >= organ_faces0;
  };
  // Anchors of every feature row: embedded in the tetrahedra, or on a shell's surface.
  const auto update_anchors = [&](RowMatX3d* anchors) {
    if (has_tets) feature_embedding.Positions(state.positions(), state.tetrahedra(), anchors);
    if (curved) {
      curved_system->SyncSolid(&state);  // embeds springs added since the last step
      for (size_t r = 0; r < features.size(); ++r)
        if (features[r].spring >= 0)
          anchors->row(r) =
              curved->SpringAnchor(curved_system->state(), features[r].spring).transpose();
    }
    for (size_t r = 0; r < thin_spring.size(); ++r)
      if (thin_spring[r] >= 0) anchors->row(r) = thin->FeatureAnchor(thin_spring[r]).transpose();
  };
  int attached = 0;
  for (const lift::FeatureAttachment& a : attachments) attached += a.attached ? 1 : 0;
  const double feature_spacing_mm = [&] {
    RowMatX3d p(attached, 3);
    for (int r = 0, k = 0; r < nf; ++r)
      if (attachments[r].attached) p.row(k++) = attach_points.row(r);
    return cutting::MedianKthNeighbourDistance(p, 1);
  }();
  // With thin structures the stiffness scale E V / A sums the organ and the shells (a sheet's
  // volume is area x thickness, its whole area is seen from one side; E volume-weighted).
  const double organ_volume = has_tets ? TetVolumes(impl_->model.mesh).sum() : 0.0;
  const double thin_volume = thin ? thin->ShellVolume() : 0.0;
  const double modulus = thin ? (scene.material.youngs_modulus_pa * organ_volume +
                                 thin->ShellMeanModulusPa() * thin_volume) /
                                    std::max(organ_volume + thin_volume, 1e-300)
                              : scene.material.youngs_modulus_pa;
  const SpringStiffness stiffness =
      ResolveSpringStiffness(o.mechanics, modulus, organ_volume + thin_volume,
                             (has_tets ? AreaFacing(surface, camera.CenterInWorld()) : 0.0) +
                                 (thin ? thin->ShellArea() : 0.0),
                             attached);
  int on_thin = 0;
  for (int r = 0; r < nf; ++r) {
    FeatureView& v = features[r];
    v.lift_status = lifter.status()[r];
    if (!attachments[r].attached) continue;
    if (on_shell(attachments[r])) {
      thin_spring[r] =
          thin->AddFeatureSpring(attachments[r].face - organ_faces0, attachments[r].point_mm,
                                 attachments[r].point_mm, stiffness.n_per_m);
      ++on_thin;
    } else {
      v.spring = springs.Add(feature_embedding[r], attachments[r].point_mm, stiffness.n_per_m);
    }
    v.alive = v.spring_active = v.attached = true;
  }
  mechanics::VertexTetherEnergy tethers;
  if (o.mechanics.out_of_view_tether > 0 && attached > 0 && has_tets) {
    const std::vector<VertexTether> out_of_view =
        OutOfViewTethers(impl_->model.mesh, camera, o.mechanics.out_of_view_tether,
                         stiffness.n_per_m * stiffness.springs, o.mechanics.fixed_vertices);
    if (thin || degree > 1) {
      if (!out_of_view.empty())
        ARREG_LOG_WARNING("mechanics.out_of_view_tether: ", out_of_view.size(),
                          " model vertices out of view are not tethered (tetrahedra of degree 1 "
                          "without thin structures only)");
    } else {
      for (const VertexTether& t : out_of_view)
        tethers.Add(t.vertex, impl_->model.mesh.vertices.row(t.vertex).transpose(),
                    t.stiffness_n_per_m);
      if (tethers.size() > 0) {
        terms.push_back(&tethers);
        other_terms.push_back(&tethers);
        ARREG_LOG_INFO("mechanics: ", tethers.size(),
                       " model vertices out of view at frame 0 tethered to their place");
      }
    }
  }
  springs_timer.Stop();

  // Cut detection over the attached features (detector ids = feature rows).
  std::optional<cutting::CutDetector> detector;
  std::optional<CutHandler> cut_handler;
  const CutTargets cut_targets{
      &state,    &springs,       &features,           &attach_points,        &feature_embedding,
      &internal, &internal_rest, &internal_embedding, &impl_->model.internal};
  cutting::DetectionResult detection;
  const bool topology = o.cutting.enabled;
  if (topology) {
    std::vector<int> ids;
    for (int r = 0; r < nf; ++r)
      if (features[r].alive) ids.push_back(r);
    RowMatX3d p0(ids.size(), 3);
    for (size_t i = 0; i < ids.size(); ++i) p0.row(i) = attach_points.row(ids[i]);
    detector.emplace(WithPixelFloor(o.cutting, camera, p0));
    detector->Initialize(p0, ids);
    CuttingStageOptions co = o.cutting;
    co.foresight_mm = co.first_event_foresight ? detector->options().neighbour_radius_mm : 0.0;
    if (has_tets) cut_handler.emplace(co, state);
    // A segment whose cut keep_connected would reject at every depth is no growth
    // (CuttingStageOptions::refuse_splitting_segments).
    if (cut_handler && co.keep_connected && co.refuse_splitting_segments)
      detector->SetSegmentCheck([&](const std::vector<Eigen::Vector3d>& extended_mm,
                                    const std::vector<Eigen::Vector3d>& extended_initial_mm) {
        return !cut_handler->SplitsTheModel(extended_mm, extended_initial_mm,
                                            camera.CenterInWorld(), state);
      });
  }

  OverlayRenderer overlay(camera, o.render);
  VideoWriter writer;
  if (!run_options.overlay_video_path.empty()) {
    VideoWriterOptions wo;
    wo.crf = o.output.crf;
    wo.preset = o.output.preset;
    wo.tune = "zerolatency";  // each frame is encoded as it comes (no lookahead, no B-frames)
    wo.encode_threads = o.output.encode_threads;
    const std::string parent =
        std::filesystem::path(run_options.overlay_video_path).parent_path().string();
    if (!parent.empty()) CreateDirectories(parent);
    writer.Open(run_options.overlay_video_path, camera.width, camera.height, fps, wo);
  }

  RunStart start;
  start.scene = &scene;
  start.options = &o;
  start.expected_frames = num_frames;
  start.fps = fps;
  start.width = camera.width;
  start.height = camera.height;
  start.model_vertices = state.num_vertices();
  start.model_tetrahedra = state.num_tetrahedra();
  if (thin) {
    start.thin_shell_elements = thin->num_shell_elements();
    start.thin_nodes = thin->state().num_nodes();
    start.features_on_thin = on_thin;
  }
  start.features_detected = nf;
  start.features_attached = attached;
  start.springs = &stiffness;
  start.tethered_vertices = tethers.size();
  if (detector) start.detector = &detector->options();
  for (FrameObserver* ob : impl_->observers) ob->OnStart(start);
  ARREG_LOG_DEBUG("run: ", nf, " features detected in the model silhouette, ", attached,
                  " attached to the surface");

  RunSummary summary;
  summary.topology = topology;
  RowMatX3d anchors(nf, 3), targets = attach_points;
  std::vector<char> tracked(nf, 1), alive_rows(nf, 0);
  std::optional<SurfaceMesh> cut_surface;
  std::vector<CutEvent> events;
  cv::Mat overlay_image;
  const auto run_start = std::chrono::steady_clock::now();
  RowMatX3d frame0_surface_vertices;
  std::vector<SurfaceMesh> thin_surfaces;

  for (int frame = 0; frame < num_frames; ++frame) {
    events.clear();
    FrameStats stats;
    if (frame > 0) {
      ms = StageTimes();
      {
        StageTimer timer(cpu_clock, &ms.decode);
        if (!Decode(reader, frame, &bgr, &stats, &summary)) break;
      }

      // Track. A damaged frame is the last good one again: tracking it would read as a
      // standstill of every feature, so it is skipped and the next good frame is tracked from
      // the last. Re-detected features through their probation (attach_after_frames) join below.
      std::vector<const FeatureState*> detected;
      {
        StageTimer timer(cpu_clock, &ms.track);
        const cv::Mat frame_roi =
            thin ? TrackingRegion(raster, lift_vertices(), lift_surface.faces, o.roi_dilation_px)
            : curved ? TrackingRegion(raster, curved_surface.vertices, curved_surface.faces,
                                      o.roi_dilation_px)
                     : TrackingRegion(raster, state.positions(), surface.faces, o.roi_dilation_px);
        if (!stats.damaged) tracker.Track(bgr, frame_roi);
        detected = FollowTracks(tracker, row_of_id, frame, o.attach_after_frames, &features,
                                &pixels, &tracked, &stats);
      }

      // Features re-detected in holes (tracking.redetect_every_frames) join like frame 0's:
      // cast against the model as it stands, embedded where the ray meets it, their rest
      // points (the configuration the detector compares with) carried back by that embedding,
      // and a zero-length spring each.
      if (!detected.empty()) {
        StageTimer timer(cpu_clock, &ms.lift);
        const int added = static_cast<int>(detected.size());
        RowMatX2d new_pixels(added, 2);
        for (int k = 0; k < added; ++k)
          new_pixels.row(k) << detected[k]->position_px.x, detected[k]->position_px.y;
        frame0_surface_vertices =
            thin ? lift_vertices() : RowMatX3d(state.positions().topRows(organ_vertices));
        const std::vector<lift::FeatureAttachment> more = lifter.AttachMore(
            lift::RaysThroughPixels(camera, new_pixels), &frame0_surface_vertices);
        RowMatX3d points(added, 3);
        for (int k = 0; k < added; ++k) points.row(k) = more[k].point_mm.transpose();
        const std::vector<char> trusted =
            ModelAgrees(points, anchors, targets, features, 3.0 * feature_spacing_mm,
                        o.attach_max_misfit_factor);
        mechanics::EmbeddedPoints current;
        RowMatX3d rest = points;
        if (has_tets) {
          current = mechanics::EmbeddedPoints::Embed(points, state.positions(), state.tetrahedra());
          rest = current.Positions(state.rest_positions(), state.tetrahedra());
        } else {
          current.Resize(added);
        }
        pixels.conservativeResize(nf + added, 2);
        attach_points.conservativeResize(nf + added, 3);
        anchors.conservativeResize(nf + added, 3);
        targets.conservativeResize(nf + added, 3);
        tracked.resize(nf + added, 1);
        alive_rows.resize(nf + added, 0);
        feature_embedding.Resize(nf + added);
        thin_spring.resize(nf + added, -1);
        std::vector<int> joining;
        for (int k = 0; k < added; ++k) {
          const int r = nf + k;
          FeatureView v;
          v.id = detected[k]->id;
          v.pixel = new_pixels.row(k).transpose();
          v.track_status = detected[k]->status;
          v.lift_status = lifter.status()[r];
          pixels.row(r) = new_pixels.row(k);
          attach_points.row(r) = rest.row(k);
          anchors.row(r) = points.row(k);
          targets.row(r) = points.row(k);
          feature_embedding[r] = current[k];
          row_of_id[v.id] = r;
          if (more[k].attached && trusted[k] && on_shell(more[k])) {
            thin_spring[r] = thin->AddFeatureSpring(more[k].face - organ_faces0, more[k].point_mm,
                                                    more[k].point_mm, stiffness.n_per_m);
            attach_points.row(r) = thin->FeatureRestAnchor(thin_spring[r]).transpose();
            v.alive = v.spring_active = v.attached = true;
            joining.push_back(r);
            ++stats.added;
          } else if (more[k].attached && trusted[k] && has_tets) {
            v.spring = springs.Add(current[k], more[k].point_mm, stiffness.n_per_m);
            v.alive = v.spring_active = v.attached = true;
            joining.push_back(r);
            ++stats.added;
          }
          features.push_back(v);
        }
        nf += added;
        if (detector && !joining.empty()) {
          RowMatX3d joining_rest(joining.size(), 3);
          for (size_t k = 0; k < joining.size(); ++k)
            joining_rest.row(k) = attach_points.row(joining[k]);
          detector->AddFeatures(joining_rest, joining);
        }
      }

      // Lift: the tracked pixels to 3D targets.
      {
        StageTimer timer(cpu_clock, &ms.lift);
        const RowMatX3d* cast_surface = nullptr;
        if (o.lifting.surface_update == lift::SurfaceUpdate::kRayCastWithFallback ||
            o.lifting.follow_model_thinning) {
          // The frame-0 boundary's vertices keep their indices through cuts (cuts only add).
          frame0_surface_vertices =
              thin ? lift_vertices() : RowMatX3d(state.positions().topRows(organ_vertices));
          cast_surface = &frame0_surface_vertices;
        }
        lifter.Update(camera, pixels, tracked, cast_surface);
        targets = lifter.targets_mm();
      }

      // Mechanics: springs follow the targets, one implicit Euler step.
      StageTimer timer(cpu_clock, &ms.mechanics);
      FollowTargets(lifter.status(), targets, tracked, thin_spring, thin ? &*thin : nullptr,
                    &springs, &features);
      StepMechanics(thin     ? &*thin
                    : curved ? &*curved_system
                             : nullptr,
                    &integrator, &elastic, terms, &state, &stats);
      if (cut_handler) cut_handler->FollowWelds(&state);
    } else {
      stats.mechanics_status = mechanics::StepStatusName(mechanics::StepStatus::kConverged);
    }
    {
      StageTimer timer(cpu_clock, &ms.mechanics);
      update_anchors(&anchors);
    }

    // Detect, and cut on a new segment.
    if (topology) {
      StageTimer timer(cpu_clock, &ms.cutting);
      detector->Update(DetectorInput(features, targets, anchors), &detection);
      if (detection.segment_added && detection.extended_polyline_mm.size() >= 2) {
        SurfaceMesh s;
        const std::vector<Eigen::Vector3d> rest_polyline = detector->ExtendedPolyline(true);
        CutEvent ev;
        ev.frame = frame;
        ev.status = CutEventStatus::kNoCrossing;
        ev.polyline_points = static_cast<int>(detection.extended_polyline_mm.size());
        if (cut_handler)
          ev = cut_handler->Apply(frame, detection.extended_polyline_mm, rest_polyline,
                                  camera.CenterInWorld(), cut_targets, &s);
        if (thin && ev.status != CutEventStatus::kFailed) {
          // The shells along the rest polyline, seen from the camera; the vessels by the plane
          // of the current polyline and the viewing direction.
          Eigen::Vector3d centre = Eigen::Vector3d::Zero();
          for (const Eigen::Vector3d& p : rest_polyline) centre += p;
          centre /= static_cast<double>(std::max<size_t>(rest_polyline.size(), 1));
          const ThinCutEvent te = thin->Cut(rest_polyline, detection.extended_polyline_mm,
                                            centre - camera.CenterInWorld());
          ev.thin = true;
          ev.thin_shells_cut = te.shells_cut;
          ev.thin_shell_nodes_added = te.shell_nodes_added;
          ev.thin_vessels_cut = te.vessels_cut;
          ev.thin_vessel_frames_added = te.vessel_frames_added;
          if (te.shells_cut + te.vessels_cut > 0 && ev.status != CutEventStatus::kCut) {
            ev.status = CutEventStatus::kCut;
            ev.message.clear();
            ev.polyline_rest_mm = rest_polyline;
          }
        }
        if (ev.status == CutEventStatus::kCut) {
          if (has_tets) surface = ExtractBoundary(state.CurrentMesh());
          update_anchors(&anchors);
          ++summary.cuts_applied;
        }
        if (ev.status != CutEventStatus::kFailed && (cut_handler || s.num_faces() > 0))
          cut_surface = std::move(s);
        events.push_back(ev);
        ++summary.cut_events;
      }
    }

    // The output configuration (docs/springs.md, "Output fit"), embedded structures, the
    // boundary; statistics (timed with the mechanics).
    const RowMatX3d* shown = &state.positions();
    {
      StageTimer timer(cpu_clock, &ms.mechanics);
      if (output_fit) {
        const mechanics::StepSummary fit = output_fit->Fit(state, springs, other_terms);
        stats.output_fit_status = mechanics::StepStatusName(fit.status);
        shown = &output_fit->positions();
      }
      surface.vertices = *shown;
      if (thin) {
        thin_surfaces = thin->Surfaces();
        // Without an organ the structures are what is registered: surface/ and the overlay's
        // contour show the shells and vessels together.
        if (!has_tets) surface = MergeSurfaces(thin_surfaces);
      }
      if (curved) {
        const RowMatX3d nodes = curved->NodePositions(curved_system->state());
        curved_surface.vertices = curved_boundary->vertices.Positions(nodes);
        for (size_t k = 0; k < internal.size(); ++k)
          internal[k].vertices = internal_curved[k].Positions(nodes);
      } else {
        for (size_t k = 0; k < internal.size(); ++k)
          internal_embedding[k].Positions(*shown, state.tetrahedra(), &internal[k].vertices);
      }
      SpringStatistics(anchors, targets, &features, &alive_rows, &stats);
    }
    // What is shown, saved and evaluated: the curved boundary's tessellation at degree 2, 3.
    const SurfaceMesh& shown_surface = curved ? curved_surface : surface;

    // Render and encode.
    if (o.render.enabled) {
      StageTimer timer(cpu_clock, &ms.render);
      bgr.copyTo(overlay_image);
      const std::vector<OverlayStructure> layers_internal = OverlayStructures(
          internal, impl_->model, thin_surfaces, thin && has_tets ? &*thin : nullptr);
      OverlayLayers layers;
      layers.feature_pixels = &pixels;
      layers.targets_mm = &targets;
      layers.anchors_mm = &anchors;
      layers.alive = &alive_rows;
      layers.frame = frame;
      overlay.Render(shown_surface.vertices, shown_surface.faces, layers_internal, layers,
                     &overlay_image);
    } else {
      overlay_image = cv::Mat();
    }
    if (writer.is_open()) {
      StageTimer timer(cpu_clock, &ms.encode);
      writer.Write(overlay_image.empty() ? bgr : overlay_image);
    }

    const bool stopping = run_options.stop != nullptr && run_options.stop->load();
    FrameState fs;
    fs.frame = frame;
    fs.time_s = frame / fps;
    fs.is_last = stopping || frame == num_frames - 1;
    fs.save_meshes = fs.is_last || frame % save_every == 0;
    fs.image = &bgr;
    fs.overlay = &overlay_image;
    fs.features = &features;
    fs.instrument_mask = &tracker.instrument_mask();
    fs.targets_mm = &targets;
    fs.anchors_mm = &anchors;
    fs.detection = topology ? &detection : nullptr;
    fs.cut_events = &events;
    fs.cut_surface = cut_surface ? &*cut_surface : nullptr;
    fs.state = &state;
    fs.positions = shown;
    fs.surface = &shown_surface;
    fs.internal = &internal;
    fs.internal_names = &impl_->model.internal_names;
    if (thin) {
      fs.thin = &thin_surfaces;
      fs.thin_names = &thin->names();
    }
    fs.stats = stats;
    fs.ms = ms;
    {
      StageTimer timer(cpu_clock, &ms.record);
      for (FrameObserver* ob : impl_->observers) ob->OnFrame(fs);
    }
    summary.total_ms += ms;
    ++summary.frames;
    if (stopping && frame < num_frames - 1) {
      summary.interrupted = true;
      break;
    }
  }
  if (writer.is_open()) {
    StageTimer timer(cpu_clock, &summary.total_ms.encode);
    writer.Close();
  }
  summary.seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - run_start).count();
  for (FrameObserver* ob : impl_->observers) ob->OnFinish(summary);
  return summary;
}

}  // namespace arreg::pipeline
