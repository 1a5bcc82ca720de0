#include "ar/synth/generator.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "ar/render/rasterizer.h"
#include "ar/synth/scenarios.h"
#include "ar/synth/tissue_texture.h"
#include "core/error.h"
#include "core/file_util.h"
#include "core/mesh_io.h"
#include "core/mesh_ops.h"
#include "core/scene.h"
#include "core/version.h"
#include "tracking/video_io.h"

namespace arreg::synth {

void SynthOptions::Check() const {
  ARREG_CHECK_INPUT(!out_dir.empty(), "", "out", "an output folder is required");
  ARREG_CHECK_INPUT(frames >= 2 && frames <= 100000, "", "frames", "must be in [2, 100000], got ",
                    frames);
  ARREG_CHECK_INPUT(fps > 0 && fps <= 1000, "", "fps", "must be in (0, 1000]");
  ARREG_CHECK_INPUT(surface_every_k >= 1, "", "surface_every_k", "must be >= 1");
  ARREG_CHECK_INPUT(noise_sigma >= 0 && noise_sigma <= 50, "", "noise_sigma", "must be in [0, 50]");
  ARREG_CHECK_INPUT(blur_sigma_px >= 0 && blur_sigma_px <= 20, "", "blur_sigma_px",
                    "must be in [0, 20]");
  ARREG_CHECK_INPUT(supersampling >= 1 && supersampling <= 4, "", "supersampling",
                    "must be in [1, 4]");
  ARREG_CHECK_INPUT(crf >= 0 && crf <= 51, "", "crf", "must be in [0, 51]");
  ARREG_CHECK_INPUT(width % 2 == 0 && height % 2 == 0, "", "size",
                    "width and height must be even (H.264 4:2:0), got ", width, "x", height);
}

namespace {

std::string FrameName(int frame, const char* ext) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%06d.%s", frame, ext);
  return buf;
}

// Compact surface (only referenced vertices) of `faces` over `positions`.
SurfaceMesh CompactSurface(const RowMatX3d& positions, const RowMatX3i& faces) {
  SurfaceMesh mesh;
  mesh.vertices = positions;
  mesh.faces = faces;
  RemoveUnreferencedVertices(&mesh);
  return mesh;
}

void WriteJson(const std::string& path, const nlohmann::json& json) {
  WriteFileAtomic(path, [&](std::ostream& os) { os << json.dump(2) << "\n"; });
}

void WritePng(const std::string& path, const cv::Mat& image) {
  const std::string tmp = TemporaryPathFor(path);
  if (!cv::imwrite(tmp, image)) {
    std::remove(tmp.c_str());
    throw Error(path, "", "cannot write PNG");
  }
  CommitTemporaryFile(tmp, path);
}

// The simulated truth: current split topology, positions and solver.
struct Truth {
  RowMatX3d rest;            // (#V' x 3) rest positions of the split vertices
  RowMatX4i tets;            // (#T x 4) over split vertices
  std::vector<int> origin;   // per split vertex: vertex of the unsplit mesh
  RowMatX3d x;               // (#V' x 3) current positions
  std::vector<int> grip_of;  // per split vertex: grip index or -1
  std::unique_ptr<NeoHookeanEnergy> energy;
  std::unique_ptr<QuasiStaticSolver> solver;
};

// Per vertex of the unsplit mesh that the cut split: the largest distance between two of
// its copies (mm); 0 while the copies coincide.
std::map<int, double> CopySeparations(const Truth& truth) {
  std::map<int, std::vector<int>> copies;
  for (size_t v = 0; v < truth.origin.size(); ++v)
    copies[truth.origin[v]].push_back(static_cast<int>(v));
  std::map<int, double> separation;
  for (const auto& kv : copies) {
    if (kv.second.size() < 2) continue;
    double sep = 0;
    for (size_t i = 0; i < kv.second.size(); ++i)
      for (size_t j = i + 1; j < kv.second.size(); ++j)
        sep = std::max(sep, (truth.x.row(kv.second[i]) - truth.x.row(kv.second[j])).norm());
    separation[kv.first] = sep;
  }
  return separation;
}

// How far the cut has opened anywhere: the largest separation over all split vertices.
double LargestSeparation(const Truth& truth) {
  double largest = 0;
  for (const auto& kv : CopySeparations(truth)) largest = std::max(largest, kv.second);
  return largest;
}

void Rebuild(const Scenario& s, const RowMatX3d& original_rest, const ProgressiveCut::Split& split,
             Truth* truth) {
  RowMatX3d new_x(split.origin.size(), 3);
  if (truth->x.rows() > 0) {
    for (int t = 0; t < split.tetrahedra.rows(); ++t)
      for (int c = 0; c < 4; ++c)
        new_x.row(split.tetrahedra(t, c)) = truth->x.row(truth->tets(t, c));
  } else {
    for (size_t v = 0; v < split.origin.size(); ++v)
      new_x.row(v) = original_rest.row(split.origin[v]);
  }
  truth->x = new_x;
  truth->tets = split.tetrahedra;
  truth->origin = split.origin;
  truth->rest.resize(split.origin.size(), 3);
  truth->grip_of.assign(split.origin.size(), -1);
  std::vector<bool> fixed(split.origin.size(), false);
  for (size_t v = 0; v < split.origin.size(); ++v) {
    truth->rest.row(v) = original_rest.row(split.origin[v]);
    const Eigen::Vector3d p = truth->rest.row(v).transpose();
    for (size_t g = 0; g < s.grips.size(); ++g)
      if (s.grips[g].selects(p)) {
        truth->grip_of[v] = static_cast<int>(g);
        fixed[v] = true;
        break;
      }
  }
  truth->solver.reset();
  truth->energy = std::make_unique<NeoHookeanEnergy>(truth->rest, truth->tets, s.truth_material);
  truth->solver = std::make_unique<QuasiStaticSolver>(truth->energy.get(), fixed);
}

// Static background: dark, reddish abdominal wall with soft blotches.
std::vector<Eigen::Vector3f> MakeBackground(const TissueTexture& texture, int width, int height) {
  std::vector<Eigen::Vector3f> bg(static_cast<size_t>(width) * height);
  for (int v = 0; v < height; ++v)
    for (int u = 0; u < width; ++u) {
      const Eigen::Vector3d p(u / 60.0, v / 60.0, 0.5);
      const double n = 0.7 * texture.Noise(p, 11) + 0.3 * texture.Noise(2.3 * p, 12);
      const double vignette = 1.0 - 0.6 * (std::pow((u - width / 2.0) / width, 2) +
                                           std::pow((v - height / 2.0) / height, 2));
      bg[static_cast<size_t>(v) * width + u] =
          static_cast<float>(vignette) * Eigen::Vector3f(0.20f + 0.16f * static_cast<float>(n),
                                                         0.07f + 0.05f * static_cast<float>(n),
                                                         0.06f + 0.04f * static_cast<float>(n));
    }
  return bg;
}

// An instrument shaft with a two-jaw tip entering from the lower right corner.
void DrawOccluder(cv::Mat* bgr, double t, uint64_t seed) {
  const double w = bgr->cols, h = bgr->rows;
  const double phase = static_cast<double>(seed % 1000) * 0.001 * 2 * M_PI;
  const cv::Point2d tip(w * (0.55 + 0.15 * std::sin(2 * M_PI * t + phase)),
                        h * (0.55 + 0.12 * std::cos(2 * M_PI * 0.7 * t + phase)));
  const cv::Point2d base(w * 1.1, h * 1.15);
  cv::Point2d dir = tip - base;
  dir /= std::hypot(dir.x, dir.y);
  const cv::Point2d normal(-dir.y, dir.x);
  const double radius = 0.035 * w;
  const int steps = 12;
  for (int i = 0; i < steps; ++i) {  // shade across the shaft like a metal cylinder
    const double a0 = -1 + 2.0 * i / steps, a1 = -1 + 2.0 * (i + 1) / steps;
    const double shade = 0.35 + 0.55 * std::pow(std::cos(0.5 * M_PI * (0.5 * (a0 + a1) - 0.3)), 3);
    const cv::Point pts[4] = {base + normal * radius * a0, tip + normal * radius * a0,
                              tip + normal * radius * a1, base + normal * radius * a1};
    const int g = static_cast<int>(255 * shade);
    cv::fillConvexPoly(*bgr, pts, 4, cv::Scalar(g, g, g * 0.95), cv::LINE_AA);
  }
  const double open = 0.25 + 0.2 * std::sin(2 * M_PI * 1.5 * t);
  for (int side = -1; side <= 1; side += 2) {
    const cv::Point2d jaw_dir = dir * std::cos(open) + normal * (side * std::sin(open));
    const cv::Point pts[3] = {tip + normal * (radius * 0.8 * side), tip + jaw_dir * (radius * 3.0),
                              tip - normal * (radius * 0.2 * side)};
    cv::fillConvexPoly(*bgr, pts, 3, cv::Scalar(70, 70, 75), cv::LINE_AA);
  }
}

}  // namespace

SynthSummary GenerateSyntheticScene(const SynthOptions& options) {
  options.Check();
  const auto start = std::chrono::steady_clock::now();
  ScenarioOptions scenario_options;
  scenario_options.width = options.width;
  scenario_options.height = options.height;
  scenario_options.amplitude = options.amplitude;
  scenario_options.zoom = options.zoom;
  scenario_options.fine_cell_mm = options.fine_cell_mm;
  scenario_options.kidney_cell_mm = options.kidney_cell_mm;
  Scenario s = BuildScenario(options.scenario, scenario_options);
  ARREG_CHECK_INPUT(s.truth.mesh.num_tetrahedra() >= 4 * s.model.mesh.num_tetrahedra(), "",
                    "fine_cell_mm", "the truth mesh needs at least 4x the model's tetrahedra (",
                    s.truth.mesh.num_tetrahedra(), " vs ", s.model.mesh.num_tetrahedra(),
                    "); use a finer truth mesh");
  SynthSummary summary;
  summary.frames = options.frames;
  summary.truth_tetrahedra = s.truth.mesh.num_tetrahedra();
  summary.truth_vertices = s.truth.mesh.num_vertices();
  summary.model_tetrahedra = s.model.mesh.num_tetrahedra();
  summary.model_vertices = s.model.mesh.num_vertices();

  const std::string dir = options.out_dir;
  const std::string gt = dir + "/gt";
  CreateDirectories(gt + "/masks");
  CreateDirectories(gt + "/surface");
  if (s.has_internal_structure) CreateDirectories(gt + "/internal");

  // Cut: conforming faces in the truth mesh (snapping moves rest vertices).
  std::unique_ptr<ProgressiveCut> cut;
  if (s.cut) {
    cut = std::make_unique<ProgressiveCut>(&s.truth.mesh, s.cut->surface);
    summary.snapped_vertices = cut->num_snapped_vertices();
  }
  const RowMatX3d original_rest = s.truth.mesh.vertices;
  Truth truth;
  ProgressiveCut::Split split;
  if (cut) {
    cut->Advance(s.cut->advance_mm.At(0).x());
    split = cut->ComputeSplit();
  } else {
    split.tetrahedra = s.truth.mesh.tetrahedra;
    split.origin.resize(original_rest.rows());
    for (int v = 0; v < original_rest.rows(); ++v) split.origin[v] = v;
  }
  Rebuild(s, original_rest, split, &truth);
  std::vector<int> face_open_frame(cut ? cut->num_faces() : 0, -1);
  std::vector<bool> internal_tet(s.truth.labels.size());
  for (int t = 0; t < s.truth.labels.size(); ++t) internal_tet[t] = s.truth.labels[t] == 2;

  const render::RasterCamera raster_camera = render::ToRasterCamera(s.camera);
  TissueTextureOptions texture_options;
  texture_options.seed = options.seed;
  const TissueTexture texture(texture_options);
  std::vector<Eigen::Vector3f> background;
  VideoWriter video;
  const std::string video_path = dir + "/video.mp4";
  if (options.write_video) {
    background = MakeBackground(texture, options.width, options.height);
    VideoWriterOptions video_options;
    video_options.crf = options.crf;
    video_options.encode_threads = 1;
    video.Open(video_path, options.width, options.height, options.fps, video_options);
  }
  render::RenderTarget target(raster_camera, options.supersampling);
  render::ShadingOptions shading;

  for (int frame = 0; frame < options.frames; ++frame) {
    const double t = static_cast<double>(frame) / (options.frames - 1);
    if (cut) {
      const std::vector<bool> was_open = cut->FaceOpen();
      if (cut->Advance(s.cut->advance_mm.At(t).x())) {
        const std::vector<bool> now_open = cut->FaceOpen();
        for (size_t f = 0; f < now_open.size(); ++f)
          if (now_open[f] && !was_open[f]) face_open_frame[f] = frame;
        Rebuild(s, original_rest, cut->ComputeSplit(), &truth);
      } else if (frame == 0) {
        const std::vector<bool> now_open = cut->FaceOpen();
        for (size_t f = 0; f < now_open.size(); ++f)
          if (now_open[f]) face_open_frame[f] = 0;
      }
    }
    RowMatX3d targets = truth.x;
    for (int v = 0; v < truth.x.rows(); ++v)
      if (truth.grip_of[v] >= 0)
        targets.row(v) =
            truth.rest.row(v) + s.grips[truth.grip_of[v]].displacement_mm.At(t).transpose();
    const QuasiStaticSummary solve = truth.solver->Solve(targets, &truth.x);
    summary.newton_iterations += solve.iterations;
    if (!solve.converged) ++summary.unconverged_frames;
    const Eigen::VectorXd ratios = truth.energy->VolumeRatios(truth.x);
    double volume = 0, rest_volume = 0;
    for (int k = 0; k < truth.tets.rows(); ++k) {
      const double v0 = SignedVolume(truth.rest.row(truth.tets(k, 0)).transpose(),
                                     truth.rest.row(truth.tets(k, 1)).transpose(),
                                     truth.rest.row(truth.tets(k, 2)).transpose(),
                                     truth.rest.row(truth.tets(k, 3)).transpose());
      rest_volume += v0;
      volume += v0 * ratios[k];
    }
    summary.volume_ratio.push_back(volume / rest_volume);
    if (cut) summary.opening_mm.push_back(LargestSeparation(truth));
    summary.max_volume_change =
        std::max(summary.max_volume_change, std::abs(volume / rest_volume - 1));

    // Surfaces of this frame.
    const RowMatX3i faces = BoundaryFaces(truth.tets);
    const cv::Mat mask = render::RenderMask(raster_camera, truth.x, faces);
    WritePng(gt + "/masks/" + FrameName(frame, "png"), mask);
    const bool save_surface = frame % options.surface_every_k == 0 || frame == options.frames - 1;
    if (save_surface) {
      WriteSurfaceMesh(gt + "/surface/" + FrameName(frame, "obj"), CompactSurface(truth.x, faces));
      if (s.has_internal_structure)
        WriteSurfaceMesh(gt + "/internal/" + FrameName(frame, "obj"),
                         CompactSurface(truth.x, BoundaryFaces(truth.tets, internal_tet)));
    }
    if (options.write_video) {
      target.ClearWith([&](double u, double v) {
        const int iu = std::clamp(static_cast<int>(std::lround(u)), 0, options.width - 1);
        const int iv = std::clamp(static_cast<int>(std::lround(v)), 0, options.height - 1);
        return background[static_cast<size_t>(iv) * options.width + iu];
      });
      const RowMatX3d normals = render::VertexNormals(truth.x, faces);
      target.Draw(truth.x, faces, normals, [&](const render::Fragment& f) {
        const Eigen::Vector3d rest =
            f.barycentric[0] * truth.rest.row(faces(f.face, 0)).transpose() +
            f.barycentric[1] * truth.rest.row(faces(f.face, 1)).transpose() +
            f.barycentric[2] * truth.rest.row(faces(f.face, 2)).transpose();
        return render::ShadeBlinnPhong(texture.Albedo(rest), f, shading);
      });
      cv::Mat image = target.ResolveBgr();
      if (options.occluder) DrawOccluder(&image, t, options.seed);
      if (options.blur_sigma_px > 0)
        cv::GaussianBlur(image, image, cv::Size(), options.blur_sigma_px);
      if (options.noise_sigma > 0) {
        cv::Mat noise(image.size(), CV_32FC3);
        cv::RNG rng(options.seed * 1000003ULL + static_cast<uint64_t>(frame));
        rng.fill(noise, cv::RNG::NORMAL, 0.0, options.noise_sigma);
        cv::Mat noisy;
        image.convertTo(noisy, CV_32FC3);
        noisy += noise;
        noisy.convertTo(image, CV_8UC3);  // saturating
      }
      video.Write(image);
    }
    if (options.progress) options.progress(frame + 1, options.frames);
  }
  if (options.write_video) video.Close();
  summary.final_truth_vertices = static_cast<int>(truth.x.rows());

  // Cut ground truth and the opening at the last frame.
  nlohmann::json cut_json = {{"cut", nullptr}};
  if (cut) {
    const RowMatX3i cut_faces = cut->FaceTriangles();
    const std::vector<double> progress = cut->FaceProgress();
    SurfaceMesh cut_surface;
    cut_surface.vertices = original_rest;
    cut_surface.faces = cut_faces;
    Eigen::VectorXi old_to_new;
    RemoveUnreferencedVertices(&cut_surface, &old_to_new);
    WriteSurfaceMesh(gt + "/cut_surface.obj", cut_surface);
    for (int f : face_open_frame) {
      if (f < 0) continue;
      summary.cut_first_frame =
          summary.cut_first_frame < 0 ? f : std::min(summary.cut_first_frame, f);
      summary.cut_last_frame = std::max(summary.cut_last_frame, f);
    }
    // Separation of the copies of each split vertex, binned along the cut path.
    double opened_length = 0;
    const std::vector<bool> open = cut->FaceOpen();
    for (size_t f = 0; f < open.size(); ++f)
      if (open[f]) opened_length = std::max(opened_length, progress[f]);
    const double bin_mm = 5.0;
    const int bins = std::max(1, static_cast<int>(std::ceil(opened_length / bin_mm)));
    std::vector<double> bin_opening(bins, 0.0);
    for (const auto& [origin, sep] : CopySeparations(truth)) {
      summary.max_cut_opening_mm = std::max(summary.max_cut_opening_mm, sep);
      const double p = s.cut->surface.progress_mm(original_rest.row(origin).transpose());
      if (!std::isfinite(p)) continue;
      const int b = std::clamp(static_cast<int>(p / bin_mm), 0, bins - 1);
      bin_opening[b] = std::max(bin_opening[b], sep);
    }
    int open_bins = 0;
    for (double o : bin_opening) open_bins += o > 2.0;
    summary.cut_open_fraction = opened_length > 0 ? static_cast<double>(open_bins) / bins : 0.0;
    nlohmann::json face_frames = nlohmann::json::array();
    for (int f : face_open_frame) face_frames.push_back(f);
    nlohmann::json opening = nlohmann::json::array();
    for (double o : summary.opening_mm) opening.push_back(o);
    cut_json["cut"] = {
        {"surface", "cut_surface.obj"},
        {"open_frames", {summary.cut_first_frame, summary.cut_last_frame}},
        {"description", s.cut->description},
        {"precut", s.cut->precut},
        {"length_mm", s.cut->length_mm},
        {"coordinates", "rest pose = world frame at frame 0 (model frame of scene.json)"},
        {"face_open_frame", face_frames},
        {"opening_mm", opening},
        {"final_opening",
         {{"fraction_of_length_over_2mm", summary.cut_open_fraction},
          {"max_separation_mm", summary.max_cut_opening_mm},
          {"bin_mm", bin_mm}}}};
  }
  WriteJson(gt + "/cut.json", cut_json);

  // Registration inputs: coarse model, internal structure at rest, scene file.
  WriteTetMesh(dir + "/model.vtk", s.model.mesh);
  Scene scene;
  scene.description = "arreg synth " + s.name + ": " + s.description;
  scene.model_mesh_path = dir + "/model.vtk";
  if (s.has_internal_structure) {
    std::vector<bool> model_internal(s.truth.labels.size());
    for (int k = 0; k < s.truth.labels.size(); ++k) model_internal[k] = s.truth.labels[k] == 2;
    WriteSurfaceMesh(
        dir + "/internal.obj",
        CompactSurface(original_rest, BoundaryFaces(s.truth.mesh.tetrahedra, model_internal)));
    InternalStructure internal;
    internal.name = "internal";
    internal.mesh_path = dir + "/internal.obj";
    internal.color_rgb = Eigen::Vector3d(1.0, 0.85, 0.1);
    scene.internal_structures.push_back(internal);
  }
  scene.camera = s.camera;
  scene.video_path = video_path;
  scene.ground_truth_path = gt;
  scene.material.youngs_modulus_pa = s.model_youngs_modulus_pa;
  scene.material.poisson_ratio = s.model_poisson_ratio;

  nlohmann::json volume = nlohmann::json::array();
  for (double r : summary.volume_ratio) volume.push_back(r);
  WriteJson(
      gt + "/meta.json",
      {{"units", "mm"},
       {"frames", options.frames},
       {"surface_every_k", options.surface_every_k},
       {"width", options.width},
       {"height", options.height},
       {"fps", options.fps},
       {"seed", options.seed},
       {"scenario", s.name},
       {"description", s.description},
       {"version", kVersion},
       {"generator",
        {{"amplitude", options.amplitude},
         {"zoom", options.zoom},
         {"nominal_stretch", s.nominal_stretch},
         {"fine_cell_mm", options.fine_cell_mm},
         {"kidney_cell_mm", options.kidney_cell_mm},
         {"noise_sigma", options.noise_sigma},
         {"blur_sigma_px", options.blur_sigma_px},
         {"occluder", options.occluder},
         {"supersampling", options.supersampling},
         {"crf", options.crf},
         {"video", options.write_video}}},
       {"truth",
        {{"material", "compressible neo-Hookean (Bonet-Wood), quasi-static Newton"},
         {"youngs_modulus_pa", s.truth_material.youngs_modulus_pa},
         {"poisson_ratio", s.truth_material.poisson_ratio},
         {"tetrahedra", summary.truth_tetrahedra},
         {"vertices", summary.truth_vertices},
         {"vertices_after_cut", summary.final_truth_vertices},
         {"newton_iterations", summary.newton_iterations},
         {"unconverged_frames", summary.unconverged_frames},
         {"volume_ratio", volume}}},
       {"model", {{"tetrahedra", summary.model_tetrahedra}, {"vertices", summary.model_vertices}}},
       {"mask",
        "organ silhouette of gt/surface rasterised with the scene camera; the "
        "occluder is not part of it"}});
  // Written last: a scene file means the folder is complete (without --no-video
  // the video it names is absent).
  WriteScene(dir + "/scene.json", scene);
  summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return summary;
}

}  // namespace arreg::synth
