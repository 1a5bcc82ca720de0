#include "ar/pipeline/record_writer.h"

#include <cstdio>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>

#include "ar/pipeline/pipeline_options.h"
#include "core/error.h"
#include "core/file_util.h"
#include "core/mesh_io.h"
#include "core/mesh_ops.h"
#include "core/version.h"

namespace arreg::pipeline {

namespace {

std::string FramePath(const std::string& dir, const char* sub, int frame, const char* ext) {
  char name[32];
  std::snprintf(name, sizeof(name), "%06d%s", frame, ext);
  return dir + "/" + sub + "/" + name;
}

// JSON numbers must be finite; a non-finite length would make the line unreadable.
nlohmann::json Finite(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(); }

}  // namespace

nlohmann::json FrameRecord(const FrameState& f) {
  nlohmann::json j;
  j["frame"] = f.frame;
  j["features_alive"] = f.stats.features_alive;
  j["features_added"] = f.stats.added;
  j["outliers"] = f.stats.outliers;
  j["lost"] = f.stats.lost;
  if (f.stats.damaged) j["damaged"] = true;
  const bool any = f.stats.features_alive > 0;
  j["spring_length_mean_mm"] = any ? Finite(f.stats.spring_length_mean_mm) : nlohmann::json();
  j["spring_length_max_mm"] = any ? Finite(f.stats.spring_length_max_mm) : nlohmann::json();
  // Zero-length springs: the spring length is the feature error |p_F^t - p_F^1|.
  j["feature_error_mean_mm"] = j["spring_length_mean_mm"];
  j["feature_error_max_mm"] = j["spring_length_max_mm"];
  j["mechanics_status"] = f.stats.mechanics_status;
  j["inverted_elements"] = f.stats.inverted_elements;
  j["linear_iterations"] = f.stats.linear_iterations;
  j["factorizations"] = f.stats.factorizations;
  j["line_search_cuts"] = f.stats.line_search_cuts;
  if (!f.stats.output_fit_status.empty()) j["output_fit_status"] = f.stats.output_fit_status;
  nlohmann::json cuts = nlohmann::json::array();
  if (f.cut_events)
    for (const CutEvent& e : *f.cut_events) cuts.push_back(e.ToJson());
  j["cut_events"] = cuts;
  j["ms"] = f.ms.ToJson();
  return j;
}

RecordWriter::RecordWriter(std::string out_dir, bool write_png)
    : out_dir_(std::move(out_dir)), write_png_(write_png) {}

RecordWriter::~RecordWriter() {
  // Without OnFinish (an exception ended the run) the partial frames.jsonl is removed.
  if (jsonl_.is_open()) {
    jsonl_.close();
    std::error_code ec;
    std::filesystem::remove(jsonl_temporary_, ec);
  }
}

void RecordWriter::OnStart(const RunStart& start) {
  CreateDirectories(out_dir_);
  for (const char* sub : {"mesh", "surface", "internal"}) CreateDirectories(out_dir_ + "/" + sub);
  const Scene& scene = *start.scene;
  if (!scene.thin_structures.empty()) CreateDirectories(out_dir_ + "/thin");
  if (write_png_) CreateDirectories(out_dir_ + "/frames");
  jsonl_temporary_ = TemporaryPathFor(out_dir_ + "/frames.jsonl");
  jsonl_.open(jsonl_temporary_, std::ios::out | std::ios::trunc);
  ARREG_CHECK_INPUT(jsonl_.good(), out_dir_ + "/frames.jsonl", "", "cannot write");
  run_ = nlohmann::json::object();
  run_["version"] = kVersion;
  run_["scene"] = scene.path;
  run_["camera"] = CameraToJson(scene.camera);
  run_["video"] = scene.video_path;
  run_["options"] = PipelineOptionsToJson(*start.options);
  if (start.springs) {
    nlohmann::json& m = run_["options"]["mechanics"];
    m["spring_stiffness_resolved_n_per_m"] = start.springs->n_per_m;
    m["spring_model_volume_mm3"] = start.springs->volume_mm3;
    m["spring_visible_area_mm2"] = start.springs->visible_area_mm2;
    m["out_of_view_tethered_vertices"] = start.tethered_vertices;
  }
  run_["model"] = {{"vertices", start.model_vertices}, {"tetrahedra", start.model_tetrahedra}};
  run_["features"] = {{"detected", start.features_detected}, {"attached", start.features_attached}};
  if (!scene.thin_structures.empty()) {
    nlohmann::json names = nlohmann::json::array();
    for (const ThinStructure& t : scene.thin_structures) names.push_back(t.name);
    run_["thin_structures"] = names;
    run_["thin"] = {{"shell_elements", start.thin_shell_elements},
                    {"nodes", start.thin_nodes},
                    {"features_attached", start.features_on_thin}};
  }
  run_["fps_video"] = start.fps;
}

void RecordWriter::OnFrame(const FrameState& f) {
  jsonl_ << FrameRecord(f).dump() << '\n';
  ARREG_CHECK_INPUT(jsonl_.good(), out_dir_ + "/frames.jsonl", "", "write failed");
  if (f.save_meshes) {
    // A scene of thin structures only has no tetrahedra (thin/ and surface/ hold it).
    if (f.state->num_tetrahedra() > 0) {
      TetMesh mesh = f.state->CurrentMesh();
      if (f.positions) mesh.vertices = *f.positions;
      WriteTetMesh(FramePath(out_dir_, "mesh", f.frame, ".vtk"), mesh);
    }
    SurfaceMesh surface;
    surface.vertices = f.surface->vertices;
    surface.faces = f.surface->faces;
    RemoveUnreferencedVertices(&surface);
    WriteSurfaceMesh(FramePath(out_dir_, "surface", f.frame, ".obj"), surface);
    if (f.internal && !f.internal->empty())
      WriteObjGroups(FramePath(out_dir_, "internal", f.frame, ".obj"), *f.internal,
                     *f.internal_names, "internal structures");
    if (f.thin && !f.thin->empty())
      WriteObjGroups(FramePath(out_dir_, "thin", f.frame, ".obj"), *f.thin, *f.thin_names,
                     "thin structures");
  }
  if (write_png_ && f.overlay && !f.overlay->empty()) {
    const std::string path = FramePath(out_dir_, "frames", f.frame, ".png");
    const std::string tmp = TemporaryPathFor(path);
    ARREG_CHECK_INPUT(cv::imwrite(tmp, *f.overlay), path, "", "cannot write");
    CommitTemporaryFile(tmp, path);
  }
}

void RecordWriter::OnFinish(const RunSummary& s) {
  jsonl_.close();
  CommitTemporaryFile(jsonl_temporary_, out_dir_ + "/frames.jsonl");
  run_["frames"] = s.frames;
  run_["topology"] = s.topology;
  run_["interrupted"] = s.interrupted;
  run_["cut_events"] = s.cut_events;
  run_["cuts_applied"] = s.cuts_applied;
  run_["damaged_frames"] = s.damaged_frames;
  run_["seconds"] = s.seconds;
  nlohmann::json totals = s.total_ms.ToJson();
  nlohmann::json per_stage_fps = nlohmann::json::object();
  for (auto& [stage, total] : totals.items()) {
    const double t = total.get<double>();
    per_stage_fps[stage] = t > 0 ? Finite(1000.0 * s.frames / t) : nlohmann::json();
  }
  run_["totals"] = {
      {"ms", totals},
      {"fps", per_stage_fps},
      {"fps_end_to_end",
       s.total_ms.Total() > 0 ? Finite(1000.0 * s.frames / s.total_ms.Total()) : nlohmann::json()}};
  WriteFileAtomic(out_dir_ + "/run.json", [&](std::ostream& out) { out << run_.dump(2) << '\n'; });
}

}  // namespace arreg::pipeline
