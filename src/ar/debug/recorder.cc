#include "ar/debug/recorder.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <ostream>
#include <utility>

#include "ar/pipeline/pipeline_options.h"
#include "core/error.h"
#include "core/file_util.h"

namespace arreg::debug {

namespace {

const char* LiftStatusName(lift::LiftStatus s) {
  switch (s) {
    case lift::LiftStatus::kNotAttached:
      return "not-attached";
    case lift::LiftStatus::kLost:
      return "lost";
    case lift::LiftStatus::kSurfaceHit:
      return "surface-hit";
    case lift::LiftStatus::kPlaneHit:
      return "plane-hit";
    case lift::LiftStatus::kIntercept:
      return "intercept";
    case lift::LiftStatus::kCarriedDepth:
      return "carried-depth";
  }
  return "unknown";
}

double Round(double v, double scale) { return std::round(v * scale) / scale; }

// [u, v] of a world point, or null when it lies behind the camera (no meaningful pixel).
nlohmann::json PixelOf(const PinholeCamera& camera, const Eigen::Vector3d& p, double scale) {
  const Eigen::Vector3d uvz = camera.ProjectWithDepth(p);
  if (!(uvz.z() > 0) || !uvz.allFinite()) return nullptr;
  return nlohmann::json::array({Round(uvz.x(), scale), Round(uvz.y(), scale)});
}

nlohmann::json Point3(const Eigen::Vector3d& p) {
  return nlohmann::json::array({Round(p.x(), 1e4), Round(p.y(), 1e4), Round(p.z(), 1e4)});
}

// Flattened [u0, v0, u1, v1, ...]; points behind the camera get NaN-free sentinels (null).
nlohmann::json ProjectRows(const PinholeCamera& camera, const RowMatX3d& points, double scale) {
  nlohmann::json out = nlohmann::json::array();
  for (Eigen::Index i = 0; i < points.rows(); ++i) {
    const Eigen::Vector3d uvz = camera.ProjectWithDepth(points.row(i).transpose());
    if (uvz.z() > 0 && uvz.allFinite()) {
      out.push_back(Round(uvz.x(), scale));
      out.push_back(Round(uvz.y(), scale));
    } else {
      out.push_back(nullptr);
      out.push_back(nullptr);
    }
  }
  return out;
}

nlohmann::json Polyline(const PinholeCamera& camera, const std::vector<Eigen::Vector3d>& points,
                        double scale, nlohmann::json* pixels) {
  nlohmann::json mm = nlohmann::json::array();
  *pixels = nlohmann::json::array();
  for (const Eigen::Vector3d& p : points) {
    mm.push_back(Point3(p));
    pixels->push_back(PixelOf(camera, p, scale));
  }
  return mm;
}

nlohmann::json TimesJson(const pipeline::StageTimes& t) {
  return {{"decode", t.decode},       {"track", t.track},     {"lift", t.lift},
          {"mechanics", t.mechanics}, {"cutting", t.cutting}, {"render", t.render},
          {"encode", t.encode},       {"record", t.record},   {"total", t.Total()}};
}

nlohmann::json CameraJson(const PinholeCamera& c) {
  nlohmann::json rows = nlohmann::json::array();
  const Eigen::Matrix4d m = c.camera_from_world.matrix();
  for (int r = 0; r < 4; ++r) rows.push_back({m(r, 0), m(r, 1), m(r, 2), m(r, 3)});
  return {{"width", c.width}, {"height", c.height},       {"fx", c.fx}, {"fy", c.fy}, {"cx", c.cx},
          {"cy", c.cy},       {"camera_from_world", rows}};
}

nlohmann::json DetectorJson(const cutting::CutDetectorOptions& d) {
  return {{"neighbour_radius_mm", d.neighbour_radius_mm},
          {"outlier_factor", d.outlier_factor},
          {"min_outliers", d.min_outliers},
          {"cut_point_radius_mm", d.cut_point_radius_mm},
          {"min_outlier_measure_mm", d.min_outlier_measure_mm},
          {"measure", NameOf(cutting::kCutMeasureNames, d.measure)}};
}

void WriteJson(const std::string& path, const nlohmann::json& j) {
  WriteFileAtomic(path, [&](std::ostream& os) { os << j.dump() << '\n'; });
}

}  // namespace

void DebugRecorderOptions::Check() const {
  ARREG_CHECK_INPUT(!run_dir.empty(), "", "debug.run_dir", "must name the run folder");
  ARREG_CHECK_INPUT(jpeg_quality >= 1 && jpeg_quality <= 100, "", "debug.jpeg_quality",
                    "must lie in [1, 100], got ", jpeg_quality);
  ARREG_CHECK_INPUT(pixel_decimals >= 0 && pixel_decimals <= 6, "", "debug.pixel_decimals",
                    "must lie in [0, 6], got ", pixel_decimals);
}

std::string FrameName(int frame) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%06d", frame);
  return buf;
}
std::string DebugDir(const std::string& run_dir) { return run_dir + "/debug"; }
std::string FrameRecordPath(const std::string& run_dir, int frame) {
  return DebugDir(run_dir) + "/" + FrameName(frame) + ".json";
}
std::string FrameImagePath(const std::string& run_dir, int frame) {
  return DebugDir(run_dir) + "/frames/" + FrameName(frame) + ".jpg";
}
std::string TopologyRecordPath(const std::string& run_dir, int topology_id) {
  return DebugDir(run_dir) + "/topology/" + FrameName(topology_id) + ".json";
}

std::vector<int> UniqueEdges(const RowMatX3i& faces) {
  std::vector<std::pair<int, int>> edges;
  edges.reserve(3 * faces.rows());
  for (Eigen::Index f = 0; f < faces.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      const int a = faces(f, k), b = faces(f, (k + 1) % 3);
      edges.emplace_back(std::min(a, b), std::max(a, b));
    }
  std::sort(edges.begin(), edges.end());
  edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
  std::vector<int> flat;
  flat.reserve(2 * edges.size());
  for (const auto& [a, b] : edges) {
    flat.push_back(a);
    flat.push_back(b);
  }
  return flat;
}

nlohmann::json MakeFrameRecord(const pipeline::FrameState& frame, const PinholeCamera& camera,
                               const cutting::CutDetectorOptions& detector, int topology_id,
                               int pixel_decimals) {
  const double scale = std::pow(10.0, pixel_decimals);
  nlohmann::json rec;
  rec["frame"] = frame.frame;
  rec["time_s"] = frame.time_s;
  rec["is_last"] = frame.is_last;
  rec["image"] = "frames/" + FrameName(frame.frame) + ".jpg";

  // Features: pixel, statuses, projected target p^1 and model point p^t.
  nlohmann::json features = nlohmann::json::array();
  std::vector<int> attached_rows;  // detector index -> feature row
  if (frame.features) {
    const auto& fv = *frame.features;
    for (size_t r = 0; r < fv.size(); ++r) {
      const pipeline::FeatureView& v = fv[r];
      if (v.attached) attached_rows.push_back(static_cast<int>(r));
      nlohmann::json f = {{"id", v.id},
                          {"px", {Round(v.pixel.x(), scale), Round(v.pixel.y(), scale)}},
                          {"status", TrackStatusName(v.track_status)},
                          {"lift", LiftStatusName(v.lift_status)},
                          {"alive", v.alive},
                          {"spring_active", v.spring_active},
                          {"spring_length_mm", Round(v.spring_length_mm, 1e4)},
                          {"window_on_instrument", v.window_on_instrument}};
      const bool has_target = v.attached;
      if (has_target && frame.targets_mm &&
          static_cast<Eigen::Index>(r) < frame.targets_mm->rows()) {
        const Eigen::Vector3d t = frame.targets_mm->row(r).transpose();
        f["target_mm"] = Point3(t);
        f["target_px"] = PixelOf(camera, t, scale);
      }
      if (has_target && frame.anchors_mm &&
          static_cast<Eigen::Index>(r) < frame.anchors_mm->rows()) {
        const Eigen::Vector3d a = frame.anchors_mm->row(r).transpose();
        f["model_mm"] = Point3(a);
        f["model_px"] = PixelOf(camera, a, scale);
      }
      features.push_back(std::move(f));
    }
  }
  rec["features"] = std::move(features);

  // Instruments: outlines of the tracker's instrument mask (within 1.5 px).
  nlohmann::json instruments = nlohmann::json::array();
  if (frame.instrument_mask && !frame.instrument_mask->empty()) {
    std::vector<std::vector<cv::Point>> contours;
    cv::findContours(frame.instrument_mask->clone(), contours, cv::RETR_EXTERNAL,
                     cv::CHAIN_APPROX_SIMPLE);
    for (const std::vector<cv::Point>& c : contours) {
      std::vector<cv::Point> outline;
      cv::approxPolyDP(c, outline, 1.5, true);
      nlohmann::json px = nlohmann::json::array();
      for (const cv::Point& p : outline) px.push_back(p.x), px.push_back(p.y);
      instruments.push_back(std::move(px));
    }
  }
  rec["instruments"] = std::move(instruments);

  // Neighbour pairs of C^t with mu and the outlier test mu > tau * mean(mu).
  nlohmann::json detection = nullptr;
  if (frame.detection) {
    const cutting::DetectionResult& d = *frame.detection;
    ARREG_ASSERT(d.measure.size() == d.pairs.size(), "pairs and measures differ in size");
    std::vector<char> outlier(d.pairs.size(), 0);
    for (int i : d.outliers) {
      ARREG_ASSERT(i >= 0 && i < static_cast<int>(d.pairs.size()), "outlier index ", i);
      outlier[i] = 1;
    }
    const int nf = frame.features ? static_cast<int>(frame.features->size()) : 0;
    // Detector indices are the features attached at frame 0 in row order; resolve to ids.
    auto id_of = [&](int index) {
      ARREG_ASSERT(index >= 0 && index < static_cast<int>(attached_rows.size()), "pair index ",
                   index, " beyond the ", attached_rows.size(), " attached features");
      const int row = attached_rows[index];
      ARREG_ASSERT(row < nf, "feature row");
      return (*frame.features)[row].id;
    };
    nlohmann::json pairs = nlohmann::json::array();
    for (size_t i = 0; i < d.pairs.size(); ++i)
      pairs.push_back({id_of(d.pairs[i].first), id_of(d.pairs[i].second), Round(d.measure[i], 1e6),
                       static_cast<int>(outlier[i])});
    const double tau = detector.outlier_factor;
    const double threshold = std::max(tau * d.mean_measure, detector.min_outlier_measure_mm);
    nlohmann::json new_points = nlohmann::json::array();
    for (const cutting::CutPoint& c : d.new_cut_points)
      new_points.push_back({{"mm", Point3(c.position_mm)},
                            {"px", PixelOf(camera, c.position_mm, scale)},
                            {"initial_mm", Point3(c.initial_position_mm)},
                            {"num_outliers", c.num_outliers},
                            {"probe", c.probe}});
    nlohmann::json separation = nlohmann::json::array();
    for (const auto& [initial_mm, t] : d.separation_tests)
      separation.push_back({{"initial_mm", Point3(initial_mm)},
                            {"tested", t.tested},
                            {"separated", t.separated},
                            {"statistic", Round(t.statistic, 1e4)},
                            {"robust_statistic", Round(t.robust_statistic, 1e4)},
                            {"threshold", Round(t.threshold, 1e4)},
                            {"features_side", {t.features_side[0], t.features_side[1]}},
                            {"opening_mm", Round(t.opening_mm, 1e4)},
                            {"jump_mm", Point3(t.jump_mm)}});
    nlohmann::json polyline_px, extended_px;
    nlohmann::json polyline_mm = Polyline(camera, d.polyline_mm, scale, &polyline_px);
    nlohmann::json extended_mm = Polyline(camera, d.extended_polyline_mm, scale, &extended_px);
    detection = {{"pairs", std::move(pairs)},
                 {"mean_mu", d.mean_measure},
                 {"tau", tau},
                 {"threshold", threshold},
                 {"outliers", d.outliers.size()},
                 {"min_outliers", detector.min_outliers},
                 {"pairs_removed_by_cut", d.pairs_removed_by_cut},
                 {"pairs_removed_by_death", d.pairs_removed_by_death},
                 {"pairs_bridged", d.pairs_bridged},
                 {"probe_pairs", d.probe_pairs},
                 {"probe_outliers", d.probe_outliers},
                 {"lone_features", d.lone_features},
                 {"one_sided_clusters", d.one_sided_clusters},
                 {"star_starts", d.star_starts},
                 {"unconfirmed_starts", d.unconfirmed_starts},
                 {"closing_starts", d.closing_starts},
                 {"refused_points", d.refused_points},
                 {"refused_segments", d.refused_segments},
                 {"not_separated", d.not_separated},
                 {"separation_tests", std::move(separation)},
                 {"new_cut_points", std::move(new_points)},
                 {"segment_added", d.segment_added},
                 {"polyline_mm", std::move(polyline_mm)},
                 {"polyline_px", std::move(polyline_px)},
                 {"extended_polyline_mm", std::move(extended_mm)},
                 {"extended_polyline_px", std::move(extended_px)},
                 {"look_ahead_px", d.look_ahead_mm ? PixelOf(camera, *d.look_ahead_mm, scale)
                                                   : nlohmann::json(nullptr)}};
  }
  rec["detection"] = std::move(detection);

  nlohmann::json events = nlohmann::json::array();
  if (frame.cut_events)
    for (const pipeline::CutEvent& e : *frame.cut_events) events.push_back(e.ToJson());
  rec["cut_events"] = std::move(events);

  if (frame.cut_surface && frame.cut_surface->num_faces() > 0) {
    nlohmann::json faces = nlohmann::json::array();
    for (Eigen::Index f = 0; f < frame.cut_surface->faces.rows(); ++f)
      for (int k = 0; k < 3; ++k) faces.push_back(frame.cut_surface->faces(f, k));
    rec["cut_surface"] = {{"px", ProjectRows(camera, frame.cut_surface->vertices, scale)},
                          {"faces", std::move(faces)}};
  } else {
    rec["cut_surface"] = nullptr;
  }

  // Mesh and internal structures: projected vertices here, edges in the topology file.
  rec["topology"] = topology_id;
  rec["surface_px"] =
      frame.surface ? ProjectRows(camera, frame.surface->vertices, scale) : nlohmann::json::array();
  nlohmann::json internal = nlohmann::json::array();
  if (frame.internal)
    for (size_t s = 0; s < frame.internal->size(); ++s) {
      const std::string name = frame.internal_names && s < frame.internal_names->size()
                                   ? (*frame.internal_names)[s]
                                   : "structure " + std::to_string(s);
      internal.push_back(
          {{"name", name}, {"px", ProjectRows(camera, (*frame.internal)[s].vertices, scale)}});
    }
  rec["internal"] = std::move(internal);
  if (frame.state)
    rec["model"] = {{"vertices", frame.state->num_vertices()},
                    {"tetrahedra", frame.state->num_tetrahedra()}};

  const pipeline::FrameStats& s = frame.stats;
  rec["stats"] = {{"features_alive", s.features_alive},
                  {"outliers", s.outliers},
                  {"lost", s.lost},
                  {"spring_length_mean_mm", s.spring_length_mean_mm},
                  {"spring_length_max_mm", s.spring_length_max_mm},
                  {"inverted_elements", s.inverted_elements},
                  {"mechanics_status", s.mechanics_status}};
  rec["ms"] = TimesJson(frame.ms);
  return rec;
}

nlohmann::json MakeTopologyRecord(const pipeline::FrameState& frame) {
  nlohmann::json t;
  t["surface_edges"] = frame.surface ? UniqueEdges(frame.surface->faces) : std::vector<int>{};
  nlohmann::json internal = nlohmann::json::array();
  if (frame.internal)
    for (const SurfaceMesh& m : *frame.internal) internal.push_back(UniqueEdges(m.faces));
  t["internal_edges"] = std::move(internal);
  return t;
}

DebugRecorder::DebugRecorder(const DebugRecorderOptions& options) : options_(options) {
  options_.Check();
  debug_dir_ = DebugDir(options_.run_dir);
  CreateDirectories(debug_dir_ + "/frames");
  CreateDirectories(debug_dir_ + "/topology");
}

void DebugRecorder::OnStart(const pipeline::RunStart& start) {
  ARREG_CHECK_INPUT(start.scene != nullptr, "", "debug recorder", "OnStart needs the scene");
  camera_ = start.scene->camera;
  if (start.detector) {
    detector_ = *start.detector;
  } else if (start.options) {
    detector_ = start.options->cutting.detector;
  }
  start_json_ = {{"expected_frames", start.expected_frames},
                 {"fps", start.fps},
                 {"width", start.width},
                 {"height", start.height},
                 {"model_vertices", start.model_vertices},
                 {"model_tetrahedra", start.model_tetrahedra},
                 {"features_detected", start.features_detected},
                 {"features_attached", start.features_attached}};
  started_ = true;
  frames_recorded_ = 0;
  topology_id_ = -1;
  topology_frames_.clear();
  WriteMeta(false, nullptr);
}

bool DebugRecorder::TopologyChanged(const pipeline::FrameState& frame) const {
  if (topology_id_ < 0) return true;
  const RowMatX3i empty;
  const RowMatX3i& faces = frame.surface ? frame.surface->faces : empty;
  if (faces.rows() != last_surface_faces_.rows() || faces != last_surface_faces_) return true;
  const size_t n = frame.internal ? frame.internal->size() : 0;
  if (n != last_internal_faces_.size()) return true;
  for (size_t s = 0; s < n; ++s) {
    const RowMatX3i& f = (*frame.internal)[s].faces;
    if (f.rows() != last_internal_faces_[s].rows() || f != last_internal_faces_[s]) return true;
  }
  return false;
}

void DebugRecorder::OnFrame(const pipeline::FrameState& frame) {
  ARREG_CHECK_INPUT(started_, "", "debug recorder", "OnFrame before OnStart");
  if (TopologyChanged(frame)) {
    topology_id_ = frame.frame;
    topology_frames_.push_back(frame.frame);
    WriteJson(TopologyRecordPath(options_.run_dir, topology_id_), MakeTopologyRecord(frame));
    last_surface_faces_ = frame.surface ? frame.surface->faces : RowMatX3i();
    last_internal_faces_.clear();
    if (frame.internal)
      for (const SurfaceMesh& m : *frame.internal) last_internal_faces_.push_back(m.faces);
  }
  if (frame.image && !frame.image->empty()) {
    const std::string path = FrameImagePath(options_.run_dir, frame.frame);
    const std::string tmp = TemporaryPathFor(path);
    ARREG_CHECK_INPUT(
        cv::imwrite(tmp, *frame.image, {cv::IMWRITE_JPEG_QUALITY, options_.jpeg_quality}), path,
        "frame " + std::to_string(frame.frame), "cannot write the JPEG");
    CommitTemporaryFile(tmp, path);
  }
  WriteJson(FrameRecordPath(options_.run_dir, frame.frame),
            MakeFrameRecord(frame, camera_, detector_, topology_id_, options_.pixel_decimals));
  ++frames_recorded_;
  last_frame_ = frame.frame;
}

void DebugRecorder::OnFinish(const pipeline::RunSummary& summary) {
  if (!started_) return;
  WriteMeta(true, &summary);
}

void DebugRecorder::WriteMeta(bool finished, const pipeline::RunSummary* summary) const {
  nlohmann::json meta = {{"format", "arreg-debug"},       {"version", 1},
                         {"camera", CameraJson(camera_)}, {"detector", DetectorJson(detector_)},
                         {"start", start_json_},          {"frames", frames_recorded_},
                         {"last_frame", last_frame_},     {"topology_frames", topology_frames_},
                         {"finished", finished}};
  if (summary)
    meta["summary"] = {{"frames", summary->frames},
                       {"interrupted", summary->interrupted},
                       {"topology", summary->topology},
                       {"cut_events", summary->cut_events},
                       {"cuts_applied", summary->cuts_applied},
                       {"seconds", summary->seconds},
                       {"total_ms", TimesJson(summary->total_ms)}};
  WriteJson(debug_dir_ + "/meta.json", meta);
}

}  // namespace arreg::debug
