#include "ar/pipeline/frame_loop.h"

#include <algorithm>
#include <cmath>
#include <ctime>
#include <filesystem>
#include <opencv2/imgproc.hpp>
#include <string>
#include <utility>

#include "core/error.h"
#include "core/file_util.h"
#include "core/json_reader.h"
#include "core/log.h"
#include "core/mesh_ops.h"
#include "mechanics/embedding.h"

namespace arreg::pipeline {
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

// Adds the time from its construction to its end to one stage's milliseconds.
class StageTimer {
 public:
  StageTimer(bool thread_cpu, double* stage_ms)
      : thread_cpu_(thread_cpu), stage_ms_(stage_ms), start_(NowMs(thread_cpu)) {}
  ~StageTimer() { *stage_ms_ += NowMs(thread_cpu_) - start_; }
  StageTimer(const StageTimer&) = delete;
  StageTimer& operator=(const StageTimer&) = delete;

 private:
  bool thread_cpu_;
  double* stage_ms_;
  double start_;
};

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
std::vector<char> ModelAgrees(const RowMatX3d& points_mm, const FeatureRows& rows, double radius_mm,
                              double factor) {
  std::vector<int> active;
  std::vector<double> length;
  for (int r = 0; r < rows.size(); ++r)
    if (rows.views[r].spring_active) {
      active.push_back(r);
      length.push_back((rows.anchors_mm.row(r) - rows.targets_mm.row(r)).norm());
    }
  std::vector<char> agrees(points_mm.rows(), 1);
  if (active.empty()) return agrees;
  std::vector<double> sorted = length;
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  const double limit = factor * sorted[sorted.size() / 2];
  for (int k = 0; k < points_mm.rows(); ++k) {
    double sum = 0.0;
    int count = 0;
    for (size_t i = 0; i < active.size(); ++i)
      if ((rows.anchors_mm.row(active[i]) - points_mm.row(k)).squaredNorm() <
          radius_mm * radius_mm) {
        sum += length[i];
        ++count;
      }
    agrees[k] = count == 0 || sum / count <= limit;
  }
  return agrees;
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

// After FeatureTracker::Track: the followed features' rows take the tracker's positions and
// states; losses are counted in `stats`. Returns the features not followed yet whose probation
// ended this frame.
std::vector<const FeatureState*> FollowTracks(const FeatureTracker& tracker, int frame,
                                              int attach_after_frames, FeatureRows* rows,
                                              FrameStats* stats) {
  std::vector<const FeatureState*> detected;
  for (const FeatureState& f : tracker.current()) {
    const auto it = rows->row_of_id.find(f.id);
    if (it == rows->row_of_id.end()) {
      if (f.status == TrackStatus::kTracked &&
          ProbationPassed(tracker.store().history(f.id), frame, attach_after_frames))
        detected.push_back(&f);
      continue;
    }
    FeatureView& v = rows->views[it->second];
    v.pixel = Eigen::Vector2d(f.position_px.x, f.position_px.y);
    v.track_status = f.status;
    v.window_on_instrument =
        f.status == TrackStatus::kTracked && tracker.WindowOnInstrument(f.position_px);
    rows->pixels.row(it->second) = v.pixel.transpose();
    if (f.status != TrackStatus::kTracked && rows->tracked[it->second]) {
      ++stats->lost;
      if (f.status == TrackStatus::kOutlierSpatioTemporal) ++stats->outliers;
    }
  }
  for (int r = 0; r < rows->size(); ++r)
    rows->tracked[r] = rows->views[r].track_status == TrackStatus::kTracked;
  return detected;
}

// Each active spring follows its feature's target; a feature no longer tracked loses its spring
// (in `thin` where the row names a spring there).
void FollowTargets(const std::vector<lift::LiftStatus>& lift_status, ThinSystem* thin,
                   mechanics::SpringEnergy* springs, FeatureRows* rows) {
  for (int r = 0; r < rows->size(); ++r) {
    FeatureView& v = rows->views[r];
    v.lift_status = lift_status[r];
    if (!v.spring_active) continue;
    const int thin_spring = rows->thin_spring[r];
    if (!rows->tracked[r]) {
      if (thin_spring >= 0)
        thin->RemoveFeatureSpring(thin_spring);
      else
        springs->Remove(v.spring);
      v.spring_active = false;
      continue;
    }
    if (thin_spring >= 0)
      thin->SetFeatureTarget(thin_spring, rows->targets_mm.row(r).transpose());
    else
      springs->SetTarget(v.spring, rows->targets_mm.row(r).transpose());
  }
}

// The detector's input: the features with an active spring (ids = feature rows) with their
// targets, their anchors on the model and whether an instrument lies in their window.
cutting::FrameFeatures DetectorInput(const FeatureRows& rows) {
  cutting::FrameFeatures ff;
  for (int r = 0; r < rows.size(); ++r)
    if (rows.views[r].spring_active) ff.ids.push_back(r);
  ff.target_mm.resize(ff.ids.size(), 3);
  ff.model_mm.resize(ff.ids.size(), 3);
  ff.occluded.resize(ff.ids.size());
  for (size_t i = 0; i < ff.ids.size(); ++i) {
    ff.target_mm.row(i) = rows.targets_mm.row(ff.ids[i]);
    ff.model_mm.row(i) = rows.anchors_mm.row(ff.ids[i]);
    ff.occluded[i] = rows.views[ff.ids[i]].window_on_instrument ? 1 : 0;
  }
  return ff;
}

// The structures drawn over the organ, the internal ones filled in their scene colours, the thin
// ones (`thin` non-null only where an organ is drawn under them) as outlines.
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
// is |anchor - target|.
void SpringStatistics(FeatureRows* rows, FrameStats* stats) {
  double sum = 0;
  for (int r = 0; r < rows->size(); ++r) {
    FeatureView& v = rows->views[r];
    v.alive = v.spring_active;
    rows->alive[r] = v.alive;
    v.spring_length_mm = v.alive ? (rows->anchors_mm.row(r) - rows->targets_mm.row(r)).norm() : 0.0;
    if (!v.alive) continue;
    ++stats->features_alive;
    sum += v.spring_length_mm;
    stats->spring_length_max_mm = std::max(stats->spring_length_max_mm, v.spring_length_mm);
  }
  stats->spring_length_mean_mm = stats->features_alive ? sum / stats->features_alive : 0.0;
}

double FramesPerSecond(const VideoReader& reader) { return reader.fps() > 0 ? reader.fps() : 25.0; }

}  // namespace

template <class Stage>
decltype(auto) FrameLoop::Timed(double StageTimes::*field, Stage&& stage) {
  StageTimer timer(cpu_clock_, &(ms_.*field));
  return stage();
}

FrameLoop::FrameLoop(const Scene& scene, const PipelineOptions& options, const LoadedModel& model,
                     VideoReader* reader, const RunOptions& run_options,
                     const std::vector<FrameObserver*>& observers)
    : scene_(scene),
      o_(options),
      model_(model),
      reader_(*reader),
      run_options_(run_options),
      observers_(observers),
      camera_(scene.camera),
      raster_(ToRasterCamera(scene.camera)),
      fps_(FramesPerSecond(*reader)),
      cpu_clock_(run_options.thread_cpu_clock),
      mech_(scene, options, model, fps_),
      tracker_(options.tracking),
      lifter_(options.lifting),
      overlay_(scene.camera, options.render) {
  reader_.Seek(0);
  num_frames_ = reader_.frame_count();
  if (o_.max_frames > 0) num_frames_ = std::min(num_frames_, o_.max_frames);
  save_every_ = run_options.save_every;
  if (save_every_ <= 0) save_every_ = GroundTruthEveryK(scene);
  if (save_every_ <= 0) save_every_ = o_.output.save_every;

  surface_ = ExtractBoundary(mech_.state.CurrentMesh());
  organ_vertices_ = model.mesh.num_vertices();
  organ_faces0_ = surface_.num_faces();
  if (mech_.thin) {
    const ThinSystem& thin = *mech_.thin;
    lift_surface_.vertices = LiftVertices();
    lift_surface_.faces.resize(organ_faces0_ + thin.lift_triangles().rows(), 3);
    lift_surface_.faces.topRows(organ_faces0_) = surface_.faces;
    lift_surface_.faces.bottomRows(thin.lift_triangles().rows()) =
        thin.lift_triangles().array() + organ_vertices_;
  }
  internal_.surfaces = model.internal;
  internal_.original = &model.internal;
  for (const SurfaceMesh& m : internal_.surfaces) {
    internal_.rest_mm.push_back(m.vertices);
    // A curved organ's structures follow the curved map; the linear embedding is what a cut
    // updates (CutTargets), and the curved one is taken from it after the cut.
    if (mech_.curved)
      internal_curved_.push_back(mechanics::HighOrderEmbedding::Embed(
          mech_.curved->mesh(), mech_.curved->mesh().nodes, m.vertices));
    internal_.embedding.push_back(mechanics::EmbeddedPoints::Embed(
        m.vertices, mech_.state.rest_positions(), mech_.state.tetrahedra()));
  }
}

RowMatX3d FrameLoop::LiftVertices() const {
  const int thin_vertices = mech_.thin ? mech_.thin->num_lift_vertices() : 0;
  RowMatX3d v(organ_vertices_ + thin_vertices, 3);
  v.topRows(organ_vertices_) = mech_.state.positions().topRows(organ_vertices_);
  if (mech_.thin) v.bottomRows(thin_vertices) = mech_.thin->LiftVertices();
  return v;
}

void FrameLoop::Start() {
  Timed(&StageTimes::decode, [&] {
    ARREG_CHECK_INPUT(reader_.Read(&bgr_), scene_.video_path, "frame 0",
                      "cannot read the first frame");
  });
  Timed(&StageTimes::track, [&] { DetectInitialFeatures(); });
  const std::vector<lift::FeatureAttachment> attachments =
      Timed(&StageTimes::lift, [&] { return LiftInitialFeatures(); });
  Timed(&StageTimes::mechanics, [&] { AttachSprings(attachments); });
  StartDetector();
  OpenOverlayVideo();

  RunStart start;
  start.scene = &scene_;
  start.options = &o_;
  start.expected_frames = num_frames_;
  start.fps = fps_;
  start.width = camera_.width;
  start.height = camera_.height;
  start.model_vertices = mech_.state.num_vertices();
  start.model_tetrahedra = mech_.state.num_tetrahedra();
  if (mech_.thin) {
    start.thin_shell_elements = mech_.thin->num_shell_elements();
    start.thin_nodes = mech_.thin->state().num_nodes();
    start.features_on_thin = on_thin_;
  }
  start.features_detected = rows_.size();
  start.features_attached = attached_;
  start.springs = &stiffness_;
  start.tethered_vertices = mech_.tethers.size();
  if (detector_) start.detector = &detector_->options();
  for (FrameObserver* ob : observers_) ob->OnStart(start);
  ARREG_LOG_DEBUG("run: ", rows_.size(), " features detected in the model silhouette, ", attached_,
                  " attached to the surface");
  summary_.topology = o_.cutting.enabled;
  run_start_ = std::chrono::steady_clock::now();
}

// Frame 0's features: detected inside the lifting surface's silhouette, one row each.
void FrameLoop::DetectInitialFeatures() {
  const SurfaceMesh& lifted = Lifted();
  tracker_.Initialize(bgr_, render::RenderMask(raster_, lifted.vertices, lifted.faces));
  rows_.Resize(static_cast<int>(tracker_.current().size()));
  for (const FeatureState& f : tracker_.current()) {
    const int r = rows_.size();
    FeatureView v;
    v.id = f.id;
    v.pixel = Eigen::Vector2d(f.position_px.x, f.position_px.y);
    v.track_status = f.status;
    rows_.pixels.row(r) = v.pixel.transpose();
    rows_.row_of_id[f.id] = r;
    rows_.views.push_back(v);
  }
}

std::vector<lift::FeatureAttachment> FrameLoop::LiftInitialFeatures() {
  return lifter_.Attach(camera_, rows_.pixels, &Lifted(), std::nullopt);
}

// The springs of frame 0's attached features, with the stiffness resolved from the model and the
// features (MechanicsStageOptions), and the out-of-view tethers.
void FrameLoop::AttachSprings(const std::vector<lift::FeatureAttachment>& attachments) {
  const int nf = rows_.size();
  for (int r = 0; r < nf; ++r) rows_.rest_mm.row(r) = attachments[r].point_mm.transpose();
  rows_.targets_mm = rows_.rest_mm;
  mechanics::MechanicalState& state = mech_.state;
  if (mech_.has_tets())
    rows_.embedding =
        mechanics::EmbeddedPoints::Embed(rows_.rest_mm, state.rest_positions(), state.tetrahedra());
  for (const lift::FeatureAttachment& a : attachments) attached_ += a.attached ? 1 : 0;
  feature_spacing_mm_ = [&] {
    RowMatX3d p(attached_, 3);
    for (int r = 0, k = 0; r < nf; ++r)
      if (attachments[r].attached) p.row(k++) = rows_.rest_mm.row(r);
    return cutting::MedianKthNeighbourDistance(p, 1);
  }();
  // With thin structures the stiffness scale E V / A sums the organ and the shells (a sheet's
  // volume is area x thickness, its whole area is seen from one side; E volume-weighted).
  const ThinSystem* thin = mech_.thin ? &*mech_.thin : nullptr;
  const double organ_volume = mech_.has_tets() ? TetVolumes(model_.mesh).sum() : 0.0;
  const double thin_volume = thin ? thin->ShellVolume() : 0.0;
  const double modulus = thin ? (scene_.material.youngs_modulus_pa * organ_volume +
                                 thin->ShellMeanModulusPa() * thin_volume) /
                                    std::max(organ_volume + thin_volume, 1e-300)
                              : scene_.material.youngs_modulus_pa;
  const double area_seen =
      (mech_.has_tets() ? AreaFacing(surface_, camera_.CenterInWorld()) : 0.0) +
      (thin ? thin->ShellArea() : 0.0);
  stiffness_ = ResolveSpringStiffness(o_.mechanics, modulus, organ_volume + thin_volume, area_seen,
                                      attached_);
  for (int r = 0; r < nf; ++r) {
    FeatureView& v = rows_.views[r];
    v.lift_status = lifter_.status()[r];
    if (!attachments[r].attached) continue;
    if (OnShell(attachments[r])) {
      rows_.thin_spring[r] =
          mech_.thin->AddFeatureSpring(attachments[r].face - organ_faces0_, attachments[r].point_mm,
                                       attachments[r].point_mm, stiffness_.n_per_m);
      ++on_thin_;
    } else {
      v.spring = mech_.springs.Add(rows_.embedding[r], attachments[r].point_mm, stiffness_.n_per_m);
    }
    v.alive = v.spring_active = v.attached = true;
  }
  if (o_.mechanics.out_of_view_tether > 0 && attached_ > 0 && mech_.has_tets())
    mech_.TetherOutOfView(model_, camera_, o_.mechanics, stiffness_.n_per_m * stiffness_.springs);
}

// Cut detection over the attached features (detector ids = feature rows), and the cut handler.
void FrameLoop::StartDetector() {
  if (!o_.cutting.enabled) return;
  std::vector<int> ids;
  for (int r = 0; r < rows_.size(); ++r)
    if (rows_.views[r].alive) ids.push_back(r);
  RowMatX3d p0(ids.size(), 3);
  for (size_t i = 0; i < ids.size(); ++i) p0.row(i) = rows_.rest_mm.row(ids[i]);
  detector_.emplace(WithPixelFloor(o_.cutting, camera_, p0));
  detector_->Initialize(p0, ids);
  CuttingStageOptions co = o_.cutting;
  co.foresight_mm = co.first_event_foresight ? detector_->options().neighbour_radius_mm : 0.0;
  if (mech_.has_tets()) cut_handler_.emplace(co, mech_.state);
  // A segment whose cut keep_connected would reject at every depth is no growth
  // (CuttingStageOptions::refuse_splitting_segments).
  if (cut_handler_ && co.keep_connected && co.refuse_splitting_segments)
    detector_->SetSegmentCheck([this](const std::vector<Eigen::Vector3d>& extended_mm,
                                      const std::vector<Eigen::Vector3d>& extended_initial_mm) {
      return !cut_handler_->SplitsTheModel(extended_mm, extended_initial_mm,
                                           camera_.CenterInWorld(), mech_.state);
    });
}

void FrameLoop::OpenOverlayVideo() {
  if (run_options_.overlay_video_path.empty()) return;
  VideoWriterOptions wo;
  wo.crf = o_.output.crf;
  wo.preset = o_.output.preset;
  wo.tune = "zerolatency";  // each frame is encoded as it comes (no lookahead, no B-frames)
  wo.encode_threads = o_.output.encode_threads;
  const std::string parent =
      std::filesystem::path(run_options_.overlay_video_path).parent_path().string();
  if (!parent.empty()) CreateDirectories(parent);
  writer_.Open(run_options_.overlay_video_path, camera_.width, camera_.height, fps_, wo);
}

bool FrameLoop::Step(int frame) {
  FrameWork w;
  w.frame = frame;
  events_.clear();
  if (frame > 0) {
    ms_ = StageTimes();
    if (!Timed(&StageTimes::decode, [&] { return Decode(&w); })) return false;
    Timed(&StageTimes::track, [&] { Track(&w); });
    if (!w.detected.empty()) Timed(&StageTimes::lift, [&] { JoinDetected(&w); });
    Timed(&StageTimes::lift, [&] { Lift(); });
    Timed(&StageTimes::mechanics, [&] { StepMechanics(&w); });
  } else {
    w.stats.mechanics_status = mechanics::StepStatusName(mechanics::StepStatus::kConverged);
  }
  Timed(&StageTimes::mechanics, [&] { mech_.UpdateAnchors(&rows_); });
  if (detector_) Timed(&StageTimes::cutting, [&] { DetectAndCut(&w); });
  Timed(&StageTimes::mechanics, [&] { Output(&w); });
  if (o_.render.enabled)
    Timed(&StageTimes::render, [&] { Render(&w); });
  else
    overlay_image_ = cv::Mat();
  if (writer_.is_open())
    Timed(&StageTimes::encode,
          [&] { writer_.Write(overlay_image_.empty() ? bgr_ : overlay_image_); });
  const bool stopping = run_options_.stop != nullptr && run_options_.stop->load();
  const FrameState fs = Describe(w, stopping || frame == num_frames_ - 1);
  Timed(&StageTimes::record, [&] {
    for (FrameObserver* ob : observers_) ob->OnFrame(fs);
  });
  summary_.total_ms += ms_;
  ++summary_.frames;
  summary_.interrupted = stopping && frame < num_frames_ - 1;
  return !summary_.interrupted;
}

// The next frame into bgr_; false at the end of the video. A damaged frame (the reader's last
// good one again) is marked in the frame's statistics and listed in the summary.
bool FrameLoop::Decode(FrameWork* w) {
  if (!reader_.Read(&bgr_)) return false;
  const std::vector<int>& damaged = reader_.damaged_frames();
  w->stats.damaged = std::find(damaged.begin(), damaged.end(), w->frame) != damaged.end();
  if (w->stats.damaged) summary_.damaged_frames.push_back(w->frame);
  return true;
}

// Tracking inside the projected lifting surface. A damaged frame is the last good one again:
// tracking it would read as a standstill of every feature, so it is skipped and the next good
// frame is tracked from the last.
void FrameLoop::Track(FrameWork* w) {
  const int dilation = o_.roi_dilation_px;
  const cv::Mat roi =
      mech_.thin     ? TrackingRegion(raster_, LiftVertices(), lift_surface_.faces, dilation)
      : mech_.curved ? TrackingRegion(raster_, mech_.curved_surface.vertices,
                                      mech_.curved_surface.faces, dilation)
                     : TrackingRegion(raster_, mech_.state.positions(), surface_.faces, dilation);
  if (!w->stats.damaged) tracker_.Track(bgr_, roi);
  w->detected = FollowTracks(tracker_, w->frame, o_.attach_after_frames, &rows_, &w->stats);
}

// Features re-detected in holes (tracking.redetect_every_frames) join like frame 0's: cast
// against the model as it stands, embedded where the ray meets it, their rest points (the
// configuration the detector compares with) carried back by that embedding, and a zero-length
// spring each where the model agrees with the image around them.
void FrameLoop::JoinDetected(FrameWork* w) {
  const std::vector<const FeatureState*>& detected = w->detected;
  const int added = static_cast<int>(detected.size());
  const int nf = rows_.size();
  mechanics::MechanicalState& state = mech_.state;
  RowMatX2d new_pixels(added, 2);
  for (int k = 0; k < added; ++k)
    new_pixels.row(k) << detected[k]->position_px.x, detected[k]->position_px.y;
  cast_vertices_ =
      mech_.thin ? LiftVertices() : RowMatX3d(state.positions().topRows(organ_vertices_));
  const std::vector<lift::FeatureAttachment> more =
      lifter_.AttachMore(lift::RaysThroughPixels(camera_, new_pixels), &cast_vertices_);
  RowMatX3d points(added, 3);
  for (int k = 0; k < added; ++k) points.row(k) = more[k].point_mm.transpose();
  const std::vector<char> trusted =
      ModelAgrees(points, rows_, 3.0 * feature_spacing_mm_, o_.attach_max_misfit_factor);
  mechanics::EmbeddedPoints current;
  RowMatX3d rest = points;
  if (mech_.has_tets()) {
    current = mechanics::EmbeddedPoints::Embed(points, state.positions(), state.tetrahedra());
    rest = current.Positions(state.rest_positions(), state.tetrahedra());
  } else {
    current.Resize(added);
  }
  rows_.Resize(nf + added);
  std::vector<int> joining;
  for (int k = 0; k < added; ++k) {
    const int r = nf + k;
    FeatureView v;
    v.id = detected[k]->id;
    v.pixel = new_pixels.row(k).transpose();
    v.track_status = detected[k]->status;
    v.lift_status = lifter_.status()[r];
    rows_.pixels.row(r) = new_pixels.row(k);
    rows_.rest_mm.row(r) = rest.row(k);
    rows_.anchors_mm.row(r) = points.row(k);
    rows_.targets_mm.row(r) = points.row(k);
    rows_.embedding[r] = current[k];
    rows_.row_of_id[v.id] = r;
    if (more[k].attached && trusted[k] && OnShell(more[k])) {
      rows_.thin_spring[r] = mech_.thin->AddFeatureSpring(
          more[k].face - organ_faces0_, more[k].point_mm, more[k].point_mm, stiffness_.n_per_m);
      rows_.rest_mm.row(r) = mech_.thin->FeatureRestAnchor(rows_.thin_spring[r]).transpose();
      v.alive = v.spring_active = v.attached = true;
      joining.push_back(r);
      ++w->stats.added;
    } else if (more[k].attached && trusted[k] && mech_.has_tets()) {
      v.spring = mech_.springs.Add(current[k], more[k].point_mm, stiffness_.n_per_m);
      v.alive = v.spring_active = v.attached = true;
      joining.push_back(r);
      ++w->stats.added;
    }
    rows_.views.push_back(v);
  }
  if (detector_ && !joining.empty()) {
    RowMatX3d joining_rest(joining.size(), 3);
    for (size_t k = 0; k < joining.size(); ++k) joining_rest.row(k) = rows_.rest_mm.row(joining[k]);
    detector_->AddFeatures(joining_rest, joining);
  }
}

// The tracked pixels lifted to 3D targets.
void FrameLoop::Lift() {
  const RowMatX3d* cast_surface = nullptr;
  if (o_.lifting.surface_update == lift::SurfaceUpdate::kRayCastWithFallback ||
      o_.lifting.follow_model_thinning) {
    // The frame-0 boundary's vertices keep their indices through cuts (cuts only add).
    cast_vertices_ =
        mech_.thin ? LiftVertices() : RowMatX3d(mech_.state.positions().topRows(organ_vertices_));
    cast_surface = &cast_vertices_;
  }
  lifter_.Update(camera_, rows_.pixels, rows_.tracked, cast_surface);
  rows_.targets_mm = lifter_.targets_mm();
}

// The springs follow the targets; one implicit Euler step; welded debris follows its element.
void FrameLoop::StepMechanics(FrameWork* w) {
  FollowTargets(lifter_.status(), mech_.thin ? &*mech_.thin : nullptr, &mech_.springs, &rows_);
  mech_.Step(&w->stats);
  if (cut_handler_) cut_handler_->FollowWelds(&mech_.state);
}

void FrameLoop::DetectAndCut(FrameWork* w) {
  detector_->Update(DetectorInput(rows_), &detection_);
  if (detection_.segment_added && detection_.extended_polyline_mm.size() >= 2) ApplyCut(w);
}

// A new segment: the organ is cut by the cut handler, the thin structures by their own cut.
void FrameLoop::ApplyCut(FrameWork* w) {
  SurfaceMesh s;
  const std::vector<Eigen::Vector3d> rest_polyline = detector_->ExtendedPolyline(true);
  CutEvent ev;
  ev.frame = w->frame;
  ev.status = CutEventStatus::kNoCrossing;
  ev.polyline_points = static_cast<int>(detection_.extended_polyline_mm.size());
  if (cut_handler_)
    ev = cut_handler_->Apply(
        w->frame, detection_.extended_polyline_mm, rest_polyline, camera_.CenterInWorld(),
        CutTargets{&mech_.state, &mech_.springs, &rows_, &internal_, mech_.curved}, &s);
  if (mech_.thin && ev.status != CutEventStatus::kFailed) {
    // The shells along the rest polyline, seen from the camera; the vessels by the plane of the
    // current polyline and the viewing direction.
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    for (const Eigen::Vector3d& p : rest_polyline) centre += p;
    centre /= static_cast<double>(std::max<size_t>(rest_polyline.size(), 1));
    const ThinCutEvent te = mech_.thin->Cut(rest_polyline, detection_.extended_polyline_mm,
                                            centre - camera_.CenterInWorld());
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
    if (mech_.has_tets()) surface_ = ExtractBoundary(mech_.state.CurrentMesh());
    if (mech_.curved) FollowCurvedCut();
    mech_.UpdateAnchors(&rows_);
    ++summary_.cuts_applied;
  }
  if (ev.status != CutEventStatus::kFailed && (cut_handler_ || s.num_faces() > 0))
    cut_surface_ = std::move(s);
  events_.push_back(ev);
  ++summary_.cut_events;
}

// A degree-2 organ after a cut: its boundary tessellated again, its internal structures placed
// on the curved elements at their linear embedding's elements and coordinates (the cut mesh's
// elements are the state's; a structure split along the crack stays on its side).
void FrameLoop::FollowCurvedCut() {
  const mechanics::HighOrderTetMesh& mesh = mech_.curved->mesh();
  mech_.curved_boundary = mechanics::TessellateBoundary(mesh, mesh.nodes, kCurvedSubdivisions);
  mech_.curved_surface = mech_.curved_boundary->surface;
  for (size_t k = 0; k < internal_.surfaces.size(); ++k) {
    const mechanics::EmbeddedPoints& e = internal_.embedding[k];
    std::vector<int> elements(e.size());
    std::vector<Eigen::Vector4d> coordinates(e.size());
    for (int i = 0; i < e.size(); ++i) {
      elements[i] = e[i].tet;
      coordinates[i] = e[i].barycentric;
    }
    internal_curved_[k] = mechanics::HighOrderEmbedding::FromCoordinates(mesh, std::move(elements),
                                                                         std::move(coordinates));
  }
}

// The output configuration (docs/springs.md, "Output fit"), the embedded structures, the
// boundary and the spring statistics.
void FrameLoop::Output(FrameWork* w) {
  w->shown = &mech_.Output(&w->stats);
  surface_.vertices = *w->shown;
  if (mech_.thin) {
    thin_surfaces_ = mech_.thin->Surfaces();
    // Without an organ the structures are what is registered: surface/ and the overlay's
    // contour show the shells and vessels together.
    if (!mech_.has_tets()) surface_ = MergeSurfaces(thin_surfaces_);
  }
  if (mech_.curved) {
    const RowMatX3d nodes = mech_.curved->NodePositions(mech_.curved_system->state());
    mech_.curved_surface.vertices = mech_.curved_boundary->vertices.Positions(nodes);
    for (size_t k = 0; k < internal_.surfaces.size(); ++k)
      internal_.surfaces[k].vertices = internal_curved_[k].Positions(nodes);
  } else {
    for (size_t k = 0; k < internal_.surfaces.size(); ++k)
      internal_.embedding[k].Positions(*w->shown, mech_.state.tetrahedra(),
                                       &internal_.surfaces[k].vertices);
  }
  SpringStatistics(&rows_, &w->stats);
  // What is shown, saved and evaluated: the curved boundary's tessellation at degree 2, 3.
  w->shown_surface = mech_.curved ? &mech_.curved_surface : &surface_;
}

void FrameLoop::Render(FrameWork* w) {
  bgr_.copyTo(overlay_image_);
  const std::vector<OverlayStructure> structures =
      OverlayStructures(internal_.surfaces, model_, thin_surfaces_,
                        mech_.thin && mech_.has_tets() ? &*mech_.thin : nullptr);
  OverlayLayers layers;
  layers.feature_pixels = &rows_.pixels;
  layers.targets_mm = &rows_.targets_mm;
  layers.anchors_mm = &rows_.anchors_mm;
  layers.alive = &rows_.alive;
  layers.frame = w->frame;
  overlay_.Render(w->shown_surface->vertices, w->shown_surface->faces, structures, layers,
                  &overlay_image_);
}

// What the observers are told about the frame.
FrameState FrameLoop::Describe(const FrameWork& w, bool is_last) const {
  FrameState fs;
  fs.frame = w.frame;
  fs.time_s = w.frame / fps_;
  fs.is_last = is_last;
  fs.save_meshes = is_last || w.frame % save_every_ == 0;
  fs.image = &bgr_;
  fs.overlay = &overlay_image_;
  fs.features = &rows_.views;
  fs.instrument_mask = &tracker_.instrument_mask();
  fs.targets_mm = &rows_.targets_mm;
  fs.anchors_mm = &rows_.anchors_mm;
  fs.detection = detector_ ? &detection_ : nullptr;
  fs.cut_events = &events_;
  fs.cut_surface = cut_surface_ ? &*cut_surface_ : nullptr;
  fs.state = &mech_.state;
  fs.positions = w.shown;
  fs.surface = w.shown_surface;
  fs.internal = &internal_.surfaces;
  fs.internal_names = &model_.internal_names;
  if (mech_.thin) {
    fs.thin = &thin_surfaces_;
    fs.thin_names = &mech_.thin->names();
  }
  fs.stats = w.stats;
  fs.ms = ms_;
  return fs;
}

RunSummary FrameLoop::Finish() {
  if (writer_.is_open()) {
    StageTimer timer(cpu_clock_, &summary_.total_ms.encode);
    writer_.Close();
  }
  summary_.seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - run_start_).count();
  for (FrameObserver* ob : observers_) ob->OnFinish(summary_);
  return summary_;
}

}  // namespace arreg::pipeline
