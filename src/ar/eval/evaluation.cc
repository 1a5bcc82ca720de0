#include "ar/eval/evaluation.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <tuple>

#include "ar/eval/dice.h"
#include "core/error.h"
#include "core/file_util.h"
#include "core/json_reader.h"
#include "core/log.h"
#include "core/mesh_io.h"
#include "core/run_records.h"

namespace arreg::eval {

namespace fs = std::filesystem;

void EvalOptions::Check() const {
  hausdorff.Check();
  ARREG_CHECK_INPUT(std::isfinite(color_map_max_mm) && color_map_max_mm >= 0.0, "",
                    "color_map_max_mm", "must be finite and >= 0 (0 = automatic), got ",
                    color_map_max_mm);
  ARREG_CHECK_INPUT(color_map_supersampling >= 1 && color_map_supersampling <= 8, "",
                    "color_map_supersampling", "must be in [1, 8], got ", color_map_supersampling);
}

namespace {

std::string FramePath(const std::string& dir, const std::string& sub, int frame,
                      const std::string& ext) {
  char name[32];
  std::snprintf(name, sizeof(name), "%06d", frame);
  return (fs::path(dir) / sub / (name + ext)).string();
}

// Frame indices of the files NNNNNN<ext> in dir/sub (sorted); empty when the
// folder does not exist.
std::vector<int> ListFrames(const std::string& dir, const std::string& sub,
                            const std::string& ext) {
  std::vector<int> frames;
  const fs::path folder = fs::path(dir) / sub;
  std::error_code ec;
  if (!fs::is_directory(folder, ec)) return frames;
  for (const auto& entry : fs::directory_iterator(folder)) {
    const std::string name = entry.path().filename().string();
    if (name.size() != 6 + ext.size() || name.compare(6, ext.size(), ext) != 0) continue;
    if (!std::all_of(name.begin(), name.begin() + 6, [](char c) { return c >= '0' && c <= '9'; }))
      continue;
    frames.push_back(std::stoi(name.substr(0, 6)));
  }
  std::sort(frames.begin(), frames.end());
  return frames;
}

cv::Mat ReadMask(const std::string& path, const PinholeCamera& camera) {
  ARREG_CHECK_INPUT(FileExists(path), path, "", "ground-truth mask is missing");
  cv::Mat image = cv::imread(path, cv::IMREAD_UNCHANGED);
  ARREG_CHECK_INPUT(!image.empty(), path, "", "cannot decode the PNG (corrupt or not an image)");
  ARREG_CHECK_INPUT(image.depth() == CV_8U, path, "", "mask must be 8-bit");
  if (image.channels() == 3)
    cv::cvtColor(image, image, cv::COLOR_BGR2GRAY);
  else if (image.channels() == 4)
    cv::cvtColor(image, image, cv::COLOR_BGRA2GRAY);
  ARREG_CHECK_INPUT(image.channels() == 1, path, "", "mask must have 1, 3 or 4 channels");
  ARREG_CHECK_INPUT(image.cols == camera.width && image.rows == camera.height, path, "", "mask is ",
                    image.cols, "x", image.rows, " but the run camera is ", camera.width, "x",
                    camera.height);
  cv::Mat binary;
  cv::threshold(image, binary, 127, 255, cv::THRESH_BINARY);
  return binary;
}

SurfaceMesh ReadMesh(const std::string& path) {
  SurfaceMesh mesh = ReadSurfaceMesh(path);
  ARREG_CHECK_INPUT(mesh.num_faces() > 0, path, "", "surface has no triangles");
  for (int v = 0; v < mesh.num_vertices(); ++v)
    ARREG_CHECK_INPUT(mesh.vertices.row(v).allFinite(), path, internal::Concat("vertex ", v + 1),
                      "non-finite coordinates");
  return mesh;
}

HausdorffFigures Figures(const HausdorffResult& r) {
  return {r.mean_model_to_gt, r.mean_gt_to_model, r.max_model_to_gt, r.max_gt_to_model, r.max};
}

std::optional<HausdorffFigures> Aggregate(const std::vector<FrameEvaluation>& frames,
                                          std::optional<HausdorffFigures> FrameEvaluation::*field) {
  HausdorffFigures sum;
  int count = 0;
  for (const FrameEvaluation& f : frames) {
    const auto& h = f.*field;
    if (!h) continue;
    ++count;
    sum.mean_model_to_gt += h->mean_model_to_gt;
    sum.mean_gt_to_model += h->mean_gt_to_model;
    sum.max_model_to_gt = std::max(sum.max_model_to_gt, h->max_model_to_gt);
    sum.max_gt_to_model = std::max(sum.max_gt_to_model, h->max_gt_to_model);
    sum.max = std::max(sum.max, h->max);
  }
  if (count == 0) return std::nullopt;
  sum.mean_model_to_gt /= count;
  sum.mean_gt_to_model /= count;
  return sum;
}

RunSummaryRecord ReadRunJson(const std::string& run_dir) {
  const std::string path = (fs::path(run_dir) / "run.json").string();
  ARREG_CHECK_INPUT(FileExists(path), path, "", "run summary is missing (is '", run_dir,
                    "' an `arreg run --out` directory?)");
  return ReadRunSummary(path);
}

// Per-frame feature errors from frames.jsonl (one object per processed frame).
void ReadFramesJsonl(const std::string& run_dir, int num_frames,
                     std::vector<FrameEvaluation>* frames) {
  const std::string path = (fs::path(run_dir) / "frames.jsonl").string();
  ARREG_CHECK_INPUT(FileExists(path), path, "", "per-frame log is missing");
  const std::vector<FrameRecord> records = ReadFrameRecords(path, num_frames);
  for (size_t f = 0; f < records.size(); ++f) {
    (*frames)[f].feature_error_mean_mm = records[f].feature_error_mean_mm;
    (*frames)[f].feature_error_max_mm = records[f].feature_error_max_mm;
  }
}

// The objects `names` of the OBJ at `path`, in that order; throws naming the file and the
// first missing object.
std::vector<SurfaceMesh> ReadThinObjects(const std::string& path,
                                         const std::vector<std::string>& names) {
  ARREG_CHECK_INPUT(FileExists(path), path, "", "thin-structure surfaces are missing");
  const std::vector<std::pair<std::string, SurfaceMesh>> objects = ReadObjObjects(path);
  std::vector<SurfaceMesh> meshes;
  for (const std::string& name : names) {
    const auto it = std::find_if(objects.begin(), objects.end(),
                                 [&](const auto& o) { return o.first == name; });
    ARREG_CHECK_INPUT(it != objects.end(), path, "o " + name,
                      "no object of this name (run.json lists it in thin_structures)");
    ARREG_CHECK_INPUT(it->second.num_faces() > 0, path, "o " + name, "object has no triangles");
    meshes.push_back(it->second);
  }
  return meshes;
}

std::optional<double> Mean(double sum, int count) {
  return count > 0 ? std::optional(sum / count) : std::nullopt;
}

}  // namespace

std::vector<std::pair<std::string, SurfaceMesh>> ReadObjObjects(const std::string& path) {
  ARREG_CHECK_INPUT(FileExists(path), path, "", "file is missing");
  std::istringstream in(ReadFileToString(path));
  std::vector<Eigen::Vector3d> vertices;
  // Faces per object over the file's vertex indices.
  std::vector<std::pair<std::string, std::vector<Eigen::Vector3i>>> objects;
  std::string line;
  int line_number = 0;
  while (std::getline(in, line)) {
    ++line_number;
    std::istringstream ls(line);
    std::string tag;
    if (!(ls >> tag) || tag[0] == '#') continue;
    const std::string where = "line " + std::to_string(line_number);
    if (tag == "o" || tag == "g") {
      std::string name;
      std::getline(ls >> std::ws, name);
      while (!name.empty() && (name.back() == '\r' || name.back() == ' ')) name.pop_back();
      objects.emplace_back(name, std::vector<Eigen::Vector3i>());
    } else if (tag == "v") {
      Eigen::Vector3d p;
      ARREG_CHECK_INPUT(static_cast<bool>(ls >> p.x() >> p.y() >> p.z()) && p.allFinite(), path,
                        where, "expected `v x y z` with finite numbers");
      vertices.push_back(p);
    } else if (tag == "f") {
      std::vector<int> corners;
      std::string token;
      while (ls >> token) {
        int index = 0;
        try {
          index = std::stoi(token.substr(0, token.find('/')));
        } catch (const std::exception&) {
          throw Error(path, where, "bad face index '" + token + "'");
        }
        if (index < 0) index += static_cast<int>(vertices.size()) + 1;
        ARREG_CHECK_INPUT(index >= 1 && index <= static_cast<int>(vertices.size()), path, where,
                          "face index ", token, " out of range (", vertices.size(),
                          " vertices so far)");
        corners.push_back(index - 1);
      }
      ARREG_CHECK_INPUT(corners.size() >= 3, path, where, "a face needs at least 3 vertices");
      if (objects.empty()) objects.emplace_back("", std::vector<Eigen::Vector3i>());
      for (size_t k = 1; k + 1 < corners.size(); ++k)  // polygons as fans
        objects.back().second.emplace_back(corners[0], corners[k], corners[k + 1]);
    }
  }
  std::vector<std::pair<std::string, SurfaceMesh>> result;
  for (const auto& [name, faces] : objects) {
    std::vector<int> local(vertices.size(), -1);
    SurfaceMesh mesh;
    std::vector<Eigen::Vector3d> used;
    mesh.faces.resize(static_cast<Eigen::Index>(faces.size()), 3);
    for (size_t f = 0; f < faces.size(); ++f)
      for (int c = 0; c < 3; ++c) {
        int& id = local[faces[f][c]];
        if (id < 0) {
          id = static_cast<int>(used.size());
          used.push_back(vertices[faces[f][c]]);
        }
        mesh.faces(static_cast<Eigen::Index>(f), c) = id;
      }
    mesh.vertices.resize(static_cast<Eigen::Index>(used.size()), 3);
    for (size_t v = 0; v < used.size(); ++v)
      mesh.vertices.row(static_cast<Eigen::Index>(v)) = used[v].transpose();
    result.emplace_back(name, std::move(mesh));
  }
  return result;
}

RunEvaluation EvaluateRun(const std::string& run_dir, const std::string& gt_dir,
                          const EvalOptions& options) {
  options.Check();
  const RunSummaryRecord info = ReadRunJson(run_dir);

  const std::string meta_path = (fs::path(gt_dir) / "meta.json").string();
  ARREG_CHECK_INPUT(FileExists(meta_path), meta_path, "", "ground-truth metadata is missing (is '",
                    gt_dir, "' an `arreg synth` output directory?)");
  const GroundTruthMeta meta = ReadGroundTruthMeta(meta_path);
  const int gt_frames = meta.frames;
  for (const auto& [key, value, expected] :
       {std::tuple{"width", meta.width, info.camera.width},
        std::tuple{"height", meta.height, info.camera.height}}) {
    ARREG_CHECK_INPUT(!value || *value == expected, meta_path, key, "ground truth has ", key, " ",
                      value.value_or(0), " but the run camera (", run_dir, "/run.json) has ",
                      expected);
  }
  const std::string run_json = (fs::path(run_dir) / "run.json").string();
  ARREG_CHECK_INPUT(info.frames <= gt_frames, run_json, "frames", "run processed ", info.frames,
                    " frames but the ground truth (", meta_path, ") has only ", gt_frames);
  ARREG_CHECK_INPUT(info.frames == gt_frames || info.interrupted, run_json, "frames",
                    "run processed ", info.frames, " frames but the ground truth (", meta_path,
                    ") has ", gt_frames, " and the run was not interrupted");
  if (info.frames < gt_frames)
    ARREG_LOG_WARNING(run_dir, ": interrupted run, evaluating its ", info.frames, " of ", gt_frames,
                      " frames");

  RunEvaluation ev;
  ev.run_dir = run_dir;
  ev.topology = info.topology;
  ev.interrupted = info.interrupted;
  ev.label = info.topology ? "with topology" : "without topology";
  ev.num_frames = info.frames;
  ev.camera = info.camera;
  ev.frames.resize(info.frames);
  for (int f = 0; f < info.frames; ++f) ev.frames[f].frame = f;
  ReadFramesJsonl(run_dir, info.frames, &ev.frames);

  const std::vector<std::string>& thin_names = info.thin_structures;
  const bool has_thin = !thin_names.empty();
  ev.thin.resize(thin_names.size());
  for (size_t k = 0; k < thin_names.size(); ++k) ev.thin[k].name = thin_names[k];
  // Evaluated frames: those with a saved organ surface and, with thin structures, those with
  // thin/NNNNNN.obj (a scene of thin structures only saves no organ surface).
  std::vector<int> surface_frames;
  for (int f : ListFrames(run_dir, "surface", ".obj"))
    if (f < info.frames) surface_frames.push_back(f);
  std::vector<int> eval_frames = surface_frames;
  if (has_thin) {
    for (int f : ListFrames(run_dir, "thin", ".obj"))
      if (f < info.frames) eval_frames.push_back(f);
    std::sort(eval_frames.begin(), eval_frames.end());
    eval_frames.erase(std::unique(eval_frames.begin(), eval_frames.end()), eval_frames.end());
  }
  ARREG_CHECK_INPUT(!eval_frames.empty(), (fs::path(run_dir) / "surface").string(), "",
                    "the run saved no surface/NNNNNN.obj", has_thin ? " or thin/NNNNNN.obj" : "",
                    " within its ", info.frames, " frames");
  // One line for all such frames: a run saved with a coarser --save-every than
  // the truth misses most of them.
  std::vector<int> missing;
  for (int f : ListFrames(gt_dir, "surface", ".obj"))
    if (f < info.frames && !std::binary_search(eval_frames.begin(), eval_frames.end(), f))
      missing.push_back(f);
  if (missing.size() == 1)
    ARREG_LOG_WARNING(run_dir, ": no surface at frame ", missing.front(),
                      " where the ground truth has one; that frame is not evaluated");
  else if (!missing.empty())
    ARREG_LOG_WARNING(run_dir, ": no surface at ", missing.size(),
                      " frames where the ground truth has one (first ", missing.front(), ", last ",
                      missing.back(), "); those frames are not evaluated");

  int last_gt_surface_frame = -1;
  double dice_sum = 0.0;
  std::vector<double> thin_dice_sum(thin_names.size(), 0.0);
  std::vector<int> thin_dice_count(thin_names.size(), 0);
  for (size_t i = 0; i < eval_frames.size(); ++i) {
    if (options.progress && i > 0)
      options.progress(static_cast<int>(i), static_cast<int>(eval_frames.size()));
    const int f = eval_frames[i];
    FrameEvaluation& fe = ev.frames[f];
    const std::string run_surface = FramePath(run_dir, "surface", f, ".obj");
    std::optional<SurfaceMesh> model;
    if (FileExists(run_surface)) model = ReadMesh(run_surface);
    const cv::Mat truth = ReadMask(FramePath(gt_dir, "masks", f, ".png"), info.camera);
    cv::Mat silhouette = model ? RenderSilhouette(info.camera, *model)
                               : cv::Mat(cv::Mat::zeros(truth.size(), CV_8U));
    if (has_thin) {
      // The union silhouette: the masks of a scene with thin structures hold all of them.
      const std::vector<SurfaceMesh> run_thin =
          ReadThinObjects(FramePath(run_dir, "thin", f, ".obj"), thin_names);
      std::vector<SurfaceMesh> gt_thin;
      const std::string gt_thin_path = FramePath(gt_dir, "thin", f, ".obj");
      if (FileExists(gt_thin_path)) gt_thin = ReadThinObjects(gt_thin_path, thin_names);
      fe.thin.resize(thin_names.size());
      for (size_t k = 0; k < thin_names.size(); ++k) {
        const cv::Mat own = RenderSilhouette(info.camera, run_thin[k]);
        cv::bitwise_or(silhouette, own, silhouette);
        if (gt_thin.empty()) continue;
        const double dice = ComputeDice(own, RenderSilhouette(info.camera, gt_thin[k])).dice;
        fe.thin[k].dice = dice;
        fe.thin[k].hausdorff =
            Figures(ComputeHausdorff(run_thin[k], gt_thin[k], options.hausdorff));
        thin_dice_sum[k] += dice;
        ++thin_dice_count[k];
        ev.thin[k].dice_final = dice;
      }
    }
    fe.dice = ComputeDice(silhouette, truth).dice;
    if (options.overlap_images) {
      std::vector<unsigned char> png;
      ARREG_CHECK_INPUT(cv::imencode(".png", OverlapImage(truth, silhouette), png), run_dir, "",
                        "PNG encoding of the overlap image failed");
      ev.overlap_pngs.emplace_back(f, std::move(png));
    }
    dice_sum += *fe.dice;
    ev.dice_final = *fe.dice;

    const std::string gt_surface = FramePath(gt_dir, "surface", f, ".obj");
    if (!model || !FileExists(gt_surface)) continue;
    fe.surface = Figures(ComputeHausdorff(*model, ReadMesh(gt_surface), options.hausdorff));
    last_gt_surface_frame = f;
    const std::string gt_internal = FramePath(gt_dir, "internal", f, ".obj");
    const std::string run_internal = FramePath(run_dir, "internal", f, ".obj");
    if (FileExists(gt_internal) && FileExists(run_internal))
      fe.internal = Figures(
          ComputeHausdorff(ReadMesh(run_internal), ReadMesh(gt_internal), options.hausdorff));
  }
  if (options.progress)
    options.progress(static_cast<int>(eval_frames.size()), static_cast<int>(eval_frames.size()));
  for (size_t k = 0; k < thin_names.size(); ++k) {
    ev.thin[k].dice_mean = Mean(thin_dice_sum[k], thin_dice_count[k]);
    std::vector<FrameEvaluation> per_structure;  // Aggregate reads FrameEvaluation::surface
    for (const FrameEvaluation& fe : ev.frames) {
      if (fe.thin.size() <= k || !fe.thin[k].hausdorff) continue;
      per_structure.emplace_back();
      per_structure.back().surface = fe.thin[k].hausdorff;
    }
    ev.thin[k].hausdorff = Aggregate(per_structure, &FrameEvaluation::surface);
  }
  ev.dice_mean = dice_sum / eval_frames.size();
  ev.surface = Aggregate(ev.frames, &FrameEvaluation::surface);
  ev.internal = Aggregate(ev.frames, &FrameEvaluation::internal);

  double feature_sum = 0.0;
  int feature_count = 0;
  for (const FrameEvaluation& f : ev.frames) {
    if (f.feature_error_mean_mm) {
      feature_sum += *f.feature_error_mean_mm;
      ++feature_count;
    }
    if (f.feature_error_max_mm)
      ev.feature_error_max_mm =
          std::max(ev.feature_error_max_mm.value_or(0.0), *f.feature_error_max_mm);
  }
  if (feature_count > 0) ev.feature_error_mean_mm = feature_sum / feature_count;

  // Colour maps at the last frame with a ground-truth surface: per-vertex
  // distances of each surface to the other one (both directions).
  if (options.color_maps && last_gt_surface_frame >= 0) {
    const int f = last_gt_surface_frame;
    for (const char* kind : {"surface", "internal"}) {
      const std::string model_path = FramePath(run_dir, kind, f, ".obj");
      const std::string gt_path = FramePath(gt_dir, kind, f, ".obj");
      if (!FileExists(model_path) || !FileExists(gt_path)) continue;
      const SurfaceMesh model = ReadMesh(model_path);
      const SurfaceMesh truth = ReadMesh(gt_path);
      HausdorffOptions vertex_only = options.hausdorff;
      vertex_only.sampling.max_random_samples = vertex_only.sampling.min_random_samples = 0;
      const HausdorffResult h = ComputeHausdorff(model, truth, vertex_only);
      const auto& figures =
          std::string(kind) == "surface" ? ev.frames[f].surface : ev.frames[f].internal;
      double scale = options.color_map_max_mm;
      if (scale <= 0.0) scale = figures ? figures->max : h.max;
      // Identical surfaces (distances at rounding level): any scale shows zero.
      if (!(scale > 1e-9)) scale = 1.0;
      ev.distance_fields.push_back(
          {std::string(kind) + "_model_to_gt", f, model, h.model_vertex_distances, scale});
      ev.distance_fields.push_back(
          {std::string(kind) + "_gt_to_model", f, truth, h.gt_vertex_distances, scale});
    }
  }
  return ev;
}

}  // namespace arreg::eval
