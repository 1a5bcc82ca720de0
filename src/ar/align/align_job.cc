#include "ar/align/align_job.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/file_util.h"
#include "core/json_reader.h"
#include "core/log.h"
#include "core/mesh_io.h"
#include "core/mesh_ops.h"
#include "tracking/video_io.h"

namespace arreg::align {

namespace fs = std::filesystem;

namespace {

// `path` with a trailing ".json" replaced by `suffix` (appended otherwise).
std::string Beside(const std::string& path, const std::string& suffix) {
  const std::string ext = ".json";
  if (path.size() > ext.size() && path.compare(path.size() - ext.size(), ext.size(), ext) == 0)
    return path.substr(0, path.size() - ext.size()) + suffix;
  return path + suffix;
}

bool SameFile(const std::string& a, const std::string& b) {
  std::error_code ec;
  return fs::exists(a, ec) && fs::exists(b, ec) && fs::equivalent(a, b, ec);
}

nlohmann::json StatsJson(const TermStats& s) {
  return {{"count", s.count}, {"rms_px", s.rms_px}, {"mean_px", s.mean_px}, {"max_px", s.max_px}};
}

// Frame `index` of the scene's video (BGR), or an empty image when it cannot be read.
cv::Mat ReadVideoFrame(const Scene& scene, int index) {
  if (scene.video_path.empty() || !FileExists(scene.video_path)) return {};
  try {
    VideoReader reader;
    reader.Open(scene.video_path);
    cv::Mat frame;
    for (int i = 0; i <= index; ++i)
      if (!reader.Read(&frame)) return {};
    return frame;
  } catch (const Error&) {
    return {};
  }
}

}  // namespace

void AlignJob::Check() const {
  ARREG_CHECK_INPUT(!scene_path.empty(), "", "--scene", "is required");
  ARREG_CHECK_INPUT(!out_path.empty(), "", "--out", "is required");
  ARREG_CHECK_INPUT(frame >= 0, "", "--frame", "must be >= 0, got ", frame);
  ARREG_CHECK_INPUT(!outline_path.empty() || !landmarks_path.empty(), "", "align",
                    "give an outline (--mask or --outline) and/or --landmarks");
  ARREG_CHECK_INPUT(!SameFile(scene_path, out_path), out_path, "--out",
                    "is the input scene; the input is never overwritten");
  options.Check();
}

ModelSurface LoadModelSurface(const Scene& scene) {
  ARREG_CHECK_INPUT(!scene.model_mesh_path.empty(), scene.path, "model.mesh",
                    "align needs a tetrahedral model");
  TetMesh mesh = ReadTetMesh(scene.model_mesh_path);
  mesh.vertices *= scene.mm_per_unit;
  return ModelSurface(ExtractBoundary(mesh));
}

void WriteAlignedScene(const Scene& input, const ModelPose& pose, const std::string& out_path) {
  Scene scene = input;
  scene.world_from_model = pose.Rigid();
  if (pose.scale != 1.0) {
    // The scene format holds a rigid pose and a unit; other scales go into the meshes.
    const std::string stem = Beside(out_path, "");
    const double factor = pose.scale * scene.mm_per_unit;
    TetMesh mesh = ReadTetMesh(input.model_mesh_path);
    mesh.vertices *= factor;
    scene.model_mesh_path = fs::absolute(stem + ".model.vtk").string();
    WriteTetMesh(scene.model_mesh_path, mesh);
    for (size_t i = 0; i < scene.internal_structures.size(); ++i) {
      SurfaceMesh s = ReadSurfaceMesh(input.internal_structures[i].mesh_path);
      s.vertices *= factor;
      scene.internal_structures[i].mesh_path =
          fs::absolute(stem + ".structure" + std::to_string(i) + ".obj").string();
      WriteSurfaceMesh(scene.internal_structures[i].mesh_path, s);
    }
    scene.units = LengthUnit::kMillimetre;
    scene.mm_per_unit = 1.0;
  }
  WriteScene(out_path, scene);
}

cv::Mat DrawAlignOverlay(const cv::Mat& background, const PinholeCamera& camera,
                         const ModelSurface& surface, const ModelPose& pose, const Outline* outline,
                         const std::vector<Landmark>& landmarks, const AlignResult& result) {
  cv::Mat image;
  if (background.empty() || background.cols != camera.width || background.rows != camera.height)
    image = cv::Mat(camera.height, camera.width, CV_8UC3, cv::Scalar(64, 64, 64));
  else
    image = background.clone();
  std::vector<std::vector<cv::Point>> contours;
  if (outline) {
    cv::findContours(outline->mask, contours, cv::RETR_LIST, cv::CHAIN_APPROX_NONE);
    cv::drawContours(image, contours, -1, cv::Scalar(0, 220, 0), 1, cv::LINE_AA);
  }
  const ProjectedModel projected = ProjectModel(surface, camera, pose, 1.0, 1.0, false);
  if (projected.valid) {
    contours.clear();
    cv::findContours(projected.mask, contours, cv::RETR_LIST, cv::CHAIN_APPROX_NONE);
    cv::drawContours(image, contours, -1, cv::Scalar(0, 230, 255), 1, cv::LINE_AA);
  }
  for (const Landmark& l : landmarks) {
    const cv::Point target(static_cast<int>(std::lround(l.pixel.x())),
                           static_cast<int>(std::lround(l.pixel.y())));
    cv::circle(image, target, 4, cv::Scalar(0, 0, 255), 1, cv::LINE_AA);
    const Eigen::Vector3d pc = camera.camera_from_world * pose.Apply(l.point_in_model);
    if (pc.z() <= 0) continue;
    const Eigen::Vector2d p = camera.ProjectFromCamera(pc);
    const cv::Point projected_point(static_cast<int>(std::lround(p.x())),
                                    static_cast<int>(std::lround(p.y())));
    cv::drawMarker(image, projected_point, cv::Scalar(255, 80, 0), cv::MARKER_CROSS, 8, 1);
    cv::line(image, target, projected_point, cv::Scalar(255, 80, 0), 1, cv::LINE_AA);
  }
  char text[160];
  int n = std::snprintf(text, sizeof text, "align:");
  if (outline)
    n += std::snprintf(
        text + n, sizeof text - n, " IoU %.3f, contour %.2f px", result.iou,
        0.5 * (result.contour_to_outline.mean_px + result.outline_to_contour.mean_px));
  if (!landmarks.empty())
    n +=
        std::snprintf(text + n, sizeof text - n, " landmarks RMS %.2f px", result.landmarks.rms_px);
  if (result.ambiguous) std::snprintf(text + n, sizeof text - n, " AMBIGUOUS");
  cv::putText(image, text, cv::Point(8, 18), cv::FONT_HERSHEY_SIMPLEX, 0.45,
              cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
  return image;
}

nlohmann::json AlignSummaryJson(const AlignResult& r, const Eigen::Vector3d& centroid) {
  nlohmann::json starts = nlohmann::json::array();
  for (const StartResult& s : r.starts) {
    nlohmann::json j = {{"valid", s.valid},
                        {"cost_before", s.cost_before},
                        {"cost_after", s.cost_after},
                        {"outer_iterations", s.outer_iterations},
                        {"inner_iterations", s.inner_iterations}};
    if (s.valid && r.best_start >= 0) {
      j["rotation_from_best_deg"] = RotationErrorDeg(s.final, r.pose);
      j["distance_from_best_mm"] = PointErrorMm(s.final, r.pose, centroid);
    }
    starts.push_back(j);
  }
  const StartResult* best = r.best_start >= 0 ? &r.starts[r.best_start] : nullptr;
  return {
      {"fits", r.fits},
      {"failure", r.failure},
      {"world_from_model", RigidTransformToJson(r.pose.Rigid())},
      {"scale", r.pose.scale},
      {"cost_before", best ? best->cost_before : 0.0},
      {"cost_after", best ? best->cost_after : 0.0},
      {"iou", r.iou},
      {"residuals",
       {{"contour_to_outline", StatsJson(r.contour_to_outline)},
        {"outline_to_contour", StatsJson(r.outline_to_contour)},
        {"landmarks", StatsJson(r.landmarks)}}},
      {"starts", starts},
      {"best_start", r.best_start},
      {"starts_at_optimum", r.starts_at_optimum},
      {"ambiguous", r.ambiguous},
      {"warning", r.warning},
      {"ceres",
       {{"minimizer", r.ceres_minimizer},
        {"termination", r.ceres_termination},
        {"message", r.ceres_message},
        {"iterations", r.ceres_iterations},
        {"residuals", r.ceres_residuals},
        {"effective_parameters", r.ceres_parameters},
        {"initial_cost", r.ceres_initial_cost},
        {"final_cost", r.ceres_final_cost},
        {"time_s", r.ceres_time_s}}},
      {"seconds", r.seconds},
  };
}

AlignJobResult RunAlignJob(const AlignJob& job) {
  job.Check();
  ReadSceneOptions read_options;
  read_options.check_files_exist = false;  // the video is only the overlay's background
  const Scene scene = ReadScene(job.scene_path, read_options);
  const ModelSurface surface = LoadModelSurface(scene);
  std::optional<Outline> outline;
  if (!job.outline_path.empty())
    outline = ReadOutline(job.outline_path, scene.camera, job.options.contour_spacing_px);
  AlignInput input;
  input.camera = &scene.camera;
  input.surface = &surface;
  input.outline = outline ? &*outline : nullptr;
  if (!job.landmarks_path.empty()) input.landmarks = ReadLandmarks(job.landmarks_path);
  if (job.init_pose == "scene") {
    input.initial_pose = ModelPose::FromRigid(scene.world_from_model);
  } else if (!job.init_pose.empty()) {
    const nlohmann::json json = ParseJsonFile(job.init_pose);
    JsonObjectReader reader(json, job.init_pose, "");
    input.initial_pose = ModelPose::FromRigid(ReadRigidTransformJson(reader));
  }

  AlignJobResult out;
  out.result = Align(input, job.options);
  const AlignResult& r = out.result;
  if (!r.fits)
    throw Error(job.outline_path.empty() ? job.landmarks_path : job.outline_path, "",
                "refused: " + r.failure);

  out.overlay_path =
      job.overlay_path.empty() ? Beside(job.out_path, ".overlay.png") : job.overlay_path;
  out.summary_path =
      job.summary_path.empty() ? Beside(job.out_path, ".summary.json") : job.summary_path;
  const cv::Mat frame = ReadVideoFrame(scene, job.frame);
  out.video_frame_used = !frame.empty();
  const cv::Mat overlay =
      DrawAlignOverlay(frame, scene.camera, surface, r.pose, input.outline, input.landmarks, r);
  const std::string temporary = TemporaryPathFor(out.overlay_path);
  ARREG_CHECK_INPUT(cv::imwrite(temporary, overlay), out.overlay_path, "", "cannot write the PNG");
  CommitTemporaryFile(temporary, out.overlay_path);

  nlohmann::json summary = AlignSummaryJson(r, surface.centroid());
  summary["scene"] = fs::absolute(job.scene_path).string();
  summary["frame"] = job.frame;
  summary["inputs"] = {{"outline", job.outline_path},
                       {"landmarks", job.landmarks_path},
                       {"init_pose", job.init_pose.empty() ? "search" : job.init_pose},
                       {"estimate_scale", job.options.estimate_scale},
                       {"robust_loss", RobustLossName(job.options.robust_loss)}};
  summary["overlay"] = out.overlay_path;
  summary["video_frame_used"] = out.video_frame_used;
  WriteFileAtomic(out.summary_path, [&](std::ostream& os) { os << summary.dump(2) << "\n"; });
  WriteAlignedScene(scene, r.pose, job.out_path);  // last: its presence means the job finished
  return out;
}

}  // namespace arreg::align
