// Tests of the registration pipeline on small rendered scenes: a static video keeps the model
// in place, a rigid shift is followed, the records are complete and a stop leaves them complete.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <set>
#include <string>
#include <utility>

#include "ar/debug/recorder.h"
#include "ar/pipeline/overlay.h"
#include "ar/pipeline/record_writer.h"
#include "ar/pipeline/registration_pipeline.h"
#include "ar/render/rasterizer.h"
#include "core/camera.h"
#include "core/error.h"
#include "core/geometry.h"
#include "core/json_reader.h"
#include "core/mesh_generators.h"
#include "core/mesh_io.h"
#include "core/mesh_ops.h"
#include "core/scene.h"
#include "test_util.h"
#include "tracking/video_io.h"

namespace arreg::pipeline {
namespace {

// Smooth value noise on a 2.5 mm lattice: blob texture that SURF and LK lock onto.
float Noise(const Eigen::Vector3d& p) {
  auto hash = [](int x, int y) {
    uint32_t h = static_cast<uint32_t>(x) * 73856093u ^ static_cast<uint32_t>(y) * 19349663u;
    h = (h ^ (h >> 13)) * 1274126177u;
    return ((h ^ (h >> 16)) & 0xffff) / 65535.0f;
  };
  const double s = 2.5, x = p.x() / s, y = p.y() / s;
  const int ix = static_cast<int>(std::floor(x)), iy = static_cast<int>(std::floor(y));
  const float fx = static_cast<float>(x - ix), fy = static_cast<float>(y - iy);
  const float sx = fx * fx * (3 - 2 * fx), sy = fy * fy * (3 - 2 * fy);
  const float a = hash(ix, iy), b = hash(ix + 1, iy), c = hash(ix, iy + 1),
              d = hash(ix + 1, iy + 1);
  return (a * (1 - sx) + b * sx) * (1 - sy) + (c * (1 - sx) + d * sx) * sy;
}

// A 60 x 60 x 10 mm box (centred on the z axis, top face at z = 0) seen from 200 mm, filmed
// while each point p moves to motion(p, frame).
struct BoxScene {
  std::string dir;
  Scene scene;
};

using BoxMotion = std::function<Eigen::RowVector3d(const Eigen::RowVector3d&, int)>;

// The tests' camera: 320 x 256 px, 200 mm above the origin looking down -z.
PinholeCamera TestCamera() {
  PinholeCamera camera;
  camera.width = 320;
  camera.height = 256;
  camera.fx = camera.fy = 300;
  camera.cx = 159.5;
  camera.cy = 127.5;
  camera.LookAt(Eigen::Vector3d(0, 0, 200), Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(0, 1, 0));
  return camera;
}

// Renders `surface` (textured by its rest position) moving by `motion` to dir/video.mp4;
// `paint`, if given, draws over each rendered frame (an occluder) before it is encoded.
void RenderVideo(const std::string& dir, const PinholeCamera& camera, const SurfaceMesh& surface,
                 int frames, const BoxMotion& motion,
                 const std::function<void(int, cv::Mat*)>& paint = {}) {
  const render::RasterCamera raster = ToRasterCamera(camera);
  VideoWriter writer;
  VideoWriterOptions wo;
  wo.crf = 0;
  writer.Open(dir + "/video.mp4", camera.width, camera.height, 25.0, wo);
  for (int f = 0; f < frames; ++f) {
    RowMatX3d moved = surface.vertices;
    for (int i = 0; i < moved.rows(); ++i) moved.row(i) = motion(surface.vertices.row(i), f);
    const RowMatX3d& rest = surface.vertices;
    const RowMatX3i& faces = surface.faces;
    render::RenderTarget target(raster, 2);
    target.Clear(Eigen::Vector3f(0.1f, 0.05f, 0.05f));
    target.Draw(moved, faces, RowMatX3d(), [&](const render::Fragment& fr) {
      Eigen::Vector3d p = Eigen::Vector3d::Zero();
      for (int k = 0; k < 3; ++k) p += fr.barycentric[k] * rest.row(faces(fr.face, k)).transpose();
      const float g = 0.2f + 0.7f * Noise(p);
      return Eigen::Vector3f(g, 0.8f * g, 0.7f * g);
    });
    cv::Mat image = target.ResolveBgr();
    if (paint) paint(f, &image);
    writer.Write(image);
  }
  writer.Close();
}

BoxScene MakeMovingBoxScene(const std::string& name, int frames, const BoxMotion& motion,
                            const std::function<void(int, cv::Mat*)>& paint = {}) {
  BoxScene b;
  b.dir = testing::ScratchDir(name);
  TetMesh mesh = MakeBoxTetMesh(Eigen::Vector3d(60, 60, 10), Eigen::Vector3i(6, 6, 1));
  for (int i = 0; i < mesh.vertices.rows(); ++i)
    mesh.vertices.row(i) -= Eigen::RowVector3d(30, 30, 10);  // top face at z = 0
  WriteTetMesh(b.dir + "/model.vtk", mesh);
  const PinholeCamera camera = TestCamera();
  RenderVideo(b.dir, camera, ExtractBoundary(mesh), frames, motion, paint);

  nlohmann::json j;
  j["model"] = "model.vtk";
  j["camera"] = CameraToJson(camera);
  j["video"] = "video.mp4";
  j["material"] = {{"youngs_modulus_pa", 5000.0}};
  std::ofstream(b.dir + "/scene.json") << j.dump(2);
  b.scene = ReadScene(b.dir + "/scene.json");
  return b;
}

// The box shifted by shift_mm(frame) in x.
BoxScene MakeBoxScene(const std::string& name, int frames,
                      const std::function<double(int)>& shift_mm) {
  return MakeMovingBoxScene(name, frames, [&](const Eigen::RowVector3d& p, int f) {
    return Eigen::RowVector3d(p + Eigen::RowVector3d(shift_mm(f), 0, 0));
  });
}

class StopAfter : public FrameObserver {
 public:
  StopAfter(int frame, std::atomic<bool>* flag) : frame_(frame), flag_(flag) {}
  void OnFrame(const FrameState& f) override {
    if (f.frame == frame_) flag_->store(true);
    last_mean_mm = f.stats.spring_length_mean_mm;
    max_mean_mm = std::max(max_mean_mm, f.stats.spring_length_mean_mm);
    alive = f.stats.features_alive;
    if (f.is_last) {
      centroid = f.state->positions().colwise().mean().transpose();
      rest_centroid = f.state->rest_positions().colwise().mean().transpose();
    }
  }
  int frame_;
  std::atomic<bool>* flag_;
  double last_mean_mm = 0, max_mean_mm = 0;
  int alive = 0;
  Eigen::Vector3d centroid, rest_centroid;
};

std::vector<nlohmann::json> ReadJsonl(const std::string& path) {
  std::vector<nlohmann::json> lines;
  std::ifstream in(path);
  std::string line;
  while (std::getline(in, line)) lines.push_back(ParseJsonText(line, path));
  return lines;
}

TEST(Pipeline, StaticVideoKeepsModelInPlaceAndRecordsAreComplete) {
  const BoxScene b = MakeBoxScene("pipeline_static", 8, [](int) { return 0.0; });
  PipelineOptions o = ReadPipelineOptions(b.scene);
  std::atomic<bool> never{false};
  StopAfter probe(-1, &never);
  const std::string out = b.dir + "/run";
  RecordWriter records(out, false);
  RegistrationPipeline pipe(b.scene, o);
  pipe.AddObserver(&probe);
  pipe.AddObserver(&records);
  RunOptions run;
  run.overlay_video_path = out + "/overlay.mp4";
  run.save_every = 3;
  const RunSummary s = pipe.Run(run);
  EXPECT_EQ(s.frames, 8);
  EXPECT_FALSE(s.interrupted);
  EXPECT_EQ(s.cut_events, 0);  // nothing moves: no cut may be detected
  EXPECT_GT(probe.alive, 30);
  // Tracking noise on a lossless still video is well below a pixel (0.67 mm at 200 mm).
  EXPECT_LT(probe.max_mean_mm, 0.05);
  EXPECT_LT((probe.centroid - probe.rest_centroid).norm(), 0.05);

  const auto lines = ReadJsonl(out + "/frames.jsonl");
  ASSERT_EQ(lines.size(), 8u);
  for (size_t i = 0; i < lines.size(); ++i) {
    EXPECT_EQ(lines[i].at("frame").get<int>(), static_cast<int>(i));
    for (const char* key :
         {"features_alive", "outliers", "spring_length_mean_mm", "spring_length_max_mm",
          "feature_error_mean_mm", "feature_error_max_mm", "cut_events", "ms"})
      EXPECT_TRUE(lines[i].contains(key)) << key;
    EXPECT_LE(lines[i].at("spring_length_mean_mm").get<double>(),
              lines[i].at("spring_length_max_mm").get<double>());
  }
  // Meshes at frames 0, 3, 6 and the last one (7).
  namespace fs = std::filesystem;
  for (int f : {0, 3, 6, 7}) {
    char name[16];
    std::snprintf(name, sizeof(name), "%06d", f);
    EXPECT_TRUE(fs::exists(out + "/surface/" + name + ".obj")) << f;
    EXPECT_TRUE(fs::exists(out + "/mesh/" + name + ".vtk")) << f;
  }
  EXPECT_FALSE(fs::exists(out + "/surface/000001.obj"));
  const nlohmann::json run_json = ParseJsonFile(out + "/run.json");
  EXPECT_EQ(run_json.at("frames").get<int>(), 8);
  EXPECT_FALSE(run_json.at("interrupted").get<bool>());
  EXPECT_TRUE(run_json.at("topology").get<bool>());
  // The resolved spring stiffness is recorded: kappa x E x V / (A x N) with V the box's
  // 36,000 mm^3, A its 60 x 60 mm top face (the only one facing the camera) and N the attached
  // features.
  const nlohmann::json& mech = run_json.at("options").at("mechanics");
  const int attached = run_json.at("features").at("attached").get<int>();
  EXPECT_NEAR(mech.at("spring_model_volume_mm3").get<double>(), 36000.0, 1e-6);
  EXPECT_NEAR(mech.at("spring_visible_area_mm2").get<double>(), 3600.0, 1e-6);
  EXPECT_NEAR(mech.at("spring_stiffness_resolved_n_per_m").get<double>(),
              170.0 * 5000.0 * 10.0 / attached * 1e-3, 1e-9);
  EXPECT_GE(mech.at("out_of_view_tethered_vertices").get<int>(), 0);
  VideoReader overlay;
  overlay.Open(out + "/overlay.mp4");
  EXPECT_EQ(overlay.frame_count(), 8);
  // The saved surface is the model's boundary at rest: a closed box of 60 x 60 x 10 mm.
  const SurfaceMesh last = ReadSurfaceMesh(out + "/surface/000007.obj");
  EXPECT_NEAR(last.vertices.col(0).maxCoeff() - last.vertices.col(0).minCoeff(), 60.0, 0.1);
}

TEST(Pipeline, FollowsARigidShift) {
  // 6 mm to the right over 12 frames, then held.
  const BoxScene b =
      MakeBoxScene("pipeline_shift", 16, [](int f) { return 0.5 * std::min(f, 12); });
  PipelineOptions o = ReadPipelineOptions(b.scene);
  o.render.enabled = false;
  std::atomic<bool> never{false};
  StopAfter probe(-1, &never);
  RegistrationPipeline pipe(b.scene, o);
  pipe.AddObserver(&probe);
  const RunSummary s = pipe.Run();
  EXPECT_EQ(s.frames, 16);
  const Eigen::Vector3d moved = probe.centroid - probe.rest_centroid;
  EXPECT_NEAR(moved.x(), 6.0, 0.3);
  EXPECT_NEAR(moved.y(), 0.0, 0.3);
  EXPECT_NEAR(moved.z(), 0.0, 0.3);
  EXPECT_LT(probe.last_mean_mm, 0.3);
}

// A video with random bytes over a stretch in its middle: the damaged frames are not tracked
// (the reader stands the last good frame in for them), they are listed in run.json and marked in
// frames.jsonl, no feature is lost on them, and the run processes every frame and follows the
// shift. (The frames after them up to the next key frame decode smeared without an error flag;
// the tracker's own checks drop most features there.)
TEST(Pipeline, DamagedFramesAreSkippedAndReported) {
  const BoxScene b =
      MakeBoxScene("pipeline_damaged", 40, [](int f) { return 0.25 * std::min(f, 32); });
  {
    namespace fs = std::filesystem;
    const std::string video = b.dir + "/video.mp4";
    std::fstream f(video, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(static_cast<std::streamoff>(fs::file_size(video) * 6 / 10));
    std::mt19937 rng(5);
    for (int i = 0; i < 3000; ++i) f.put(static_cast<char>(rng() & 0xff));
  }
  PipelineOptions o = ReadPipelineOptions(b.scene);
  o.render.enabled = false;
  std::atomic<bool> never{false};
  StopAfter probe(-1, &never);
  const std::string out = b.dir + "/run";
  RecordWriter records(out, false);
  RegistrationPipeline pipe(b.scene, o);
  pipe.AddObserver(&probe);
  pipe.AddObserver(&records);
  const RunSummary s = pipe.Run();
  EXPECT_EQ(s.frames, 40);
  ASSERT_FALSE(s.damaged_frames.empty());
  EXPECT_GT(s.damaged_frames.front(), 5);
  const Eigen::Vector3d moved = probe.centroid - probe.rest_centroid;
  EXPECT_NEAR(moved.x(), 8.0, 0.4);
  EXPECT_NEAR(moved.y(), 0.0, 0.4);

  const nlohmann::json run_json = ParseJsonFile(out + "/run.json");
  EXPECT_EQ(run_json.at("damaged_frames").get<std::vector<int>>(), s.damaged_frames);
  std::vector<int> marked;
  for (const nlohmann::json& line : ReadJsonl(out + "/frames.jsonl"))
    if (line.value("damaged", false)) {
      marked.push_back(line.at("frame").get<int>());
      EXPECT_EQ(line.at("lost").get<int>(), 0) << "a damaged frame is not tracked";
    }
  EXPECT_EQ(marked, s.damaged_frames);
}

// Features that join later (tracking.redetect_every_frames): a flat occluder hides a quarter
// of the box for six frames while it slides; the tracker fills the hole it leaves, the new
// features are attached after their probation, embedded where the model is then (not where it
// was at rest): the box's rigid shift is followed and their springs stay as short as the
// others'.
TEST(Pipeline, FeaturesDetectedLaterAreEmbeddedWhereTheModelIs) {
  const BoxScene b = MakeMovingBoxScene(
      "pipeline_late_features", 24,
      [](const Eigen::RowVector3d& p, int f) {
        return Eigen::RowVector3d(p + Eigen::RowVector3d(0.4 * std::min(f, 15), 0, 0));
      },
      [](int f, cv::Mat* image) {
        if (f >= 3 && f < 9) (*image)(cv::Rect(160, 128, 50, 50)).setTo(cv::Scalar(60, 60, 60));
      });
  Scene scene = b.scene;
  scene.tracking = {{"redetect_every_frames", 1}, {"attach_after_frames", 2}};
  PipelineOptions o = ReadPipelineOptions(scene);
  o.render.enabled = false;
  struct LateProbe : FrameObserver {
    void OnFrame(const FrameState& f) override {
      if (f.frame == 0) first = static_cast<int>(f.features->size());
      added += f.stats.added;
      if (!f.is_last) return;
      centroid = f.state->positions().colwise().mean().transpose();
      rest_centroid = f.state->rest_positions().colwise().mean().transpose();
      for (size_t r = 0; r < f.features->size(); ++r) {
        const FeatureView& v = (*f.features)[r];
        if (!v.alive) continue;
        double& worst = static_cast<int>(r) < first ? worst_first_mm : worst_late_mm;
        worst = std::max(worst, v.spring_length_mm);
        late_alive += static_cast<int>(r) >= first;
      }
    }
    int first = 0, added = 0, late_alive = 0;
    double worst_first_mm = 0, worst_late_mm = 0;
    Eigen::Vector3d centroid, rest_centroid;
  } probe;
  RegistrationPipeline pipe(scene, o);
  pipe.AddObserver(&probe);
  pipe.Run();
  EXPECT_GT(probe.added, 3);
  EXPECT_GT(probe.late_alive, 3);
  const Eigen::Vector3d moved = probe.centroid - probe.rest_centroid;
  EXPECT_NEAR(moved.x(), 6.0, 0.3);
  EXPECT_NEAR(moved.y(), 0.0, 0.3);
  // An embedding off by the shift at attachment (4-6 mm) or by the motion since detection
  // would show here.
  EXPECT_LT(probe.worst_late_mm, std::max(0.5, 2 * probe.worst_first_mm));
  std::printf(
      "late features: %d added, %d alive at the end; worst spring %.3f mm (frame-0 ones "
      "%.3f mm)\n",
      probe.added, probe.late_alive, probe.worst_late_mm, probe.worst_first_mm);
}

// Records, per frame, the shown configuration and the dynamic model.
class ConfigurationProbe : public FrameObserver {
 public:
  void OnFrame(const FrameState& f) override {
    shown.push_back(*f.positions);
    dynamic.push_back(f.state->positions());
    surface_matches = surface_matches && f.surface->vertices == *f.positions;
    fit_status.push_back(f.stats.output_fit_status);
  }
  std::vector<RowMatX3d> shown, dynamic;
  std::vector<std::string> fit_status;
  bool surface_matches = true;
};

// The top face (z = 0) of a size x size x 10 mm box mesh of n x n cells, centred on the z
// axis and raised by `lift_mm`: a flat sheet, counter-clockwise seen from +z.
SurfaceMesh TopSheet(double size_mm, int n, double lift_mm) {
  TetMesh box = MakeBoxTetMesh(Eigen::Vector3d(size_mm, size_mm, 10), Eigen::Vector3i(n, n, 1));
  for (int i = 0; i < box.vertices.rows(); ++i)
    box.vertices.row(i) -= Eigen::RowVector3d(size_mm / 2, size_mm / 2, 10);
  SurfaceMesh boundary = ExtractBoundary(box);
  SurfaceMesh sheet;
  sheet.vertices = boundary.vertices;
  std::vector<Eigen::RowVector3i> top;
  for (int f = 0; f < boundary.num_faces(); ++f) {
    bool on_top = true;
    for (int k = 0; k < 3; ++k)
      on_top &= std::abs(boundary.vertices(boundary.faces(f, k), 2)) < 1e-9;
    if (on_top) top.push_back(boundary.faces.row(f));
  }
  sheet.faces.resize(static_cast<int>(top.size()), 3);
  for (size_t f = 0; f < top.size(); ++f) sheet.faces.row(f) = top[f];
  RemoveUnreferencedVertices(&sheet);
  sheet.vertices.col(2).array() += lift_mm;
  return sheet;
}

// Keeps the thin structures' centroid of the last frame.
class ThinProbe : public FrameObserver {
 public:
  void OnStart(const RunStart& start) override {
    on_thin = start.features_on_thin;
    attached = start.features_attached;
  }
  void OnFrame(const FrameState& f) override {
    ASSERT_NE(f.thin, nullptr);
    if (f.frame == 0) rest = Centroid(*f.thin);
    if (f.is_last) {
      last = Centroid(*f.thin);
      organ = f.state->num_vertices() > 0
                  ? Eigen::Vector3d(f.state->positions().colwise().mean().transpose() -
                                    f.state->rest_positions().colwise().mean().transpose())
                  : Eigen::Vector3d::Zero();
    }
  }
  static Eigen::Vector3d Centroid(const std::vector<SurfaceMesh>& meshes) {
    return meshes.at(0).vertices.colwise().mean().transpose();
  }
  Eigen::Vector3d rest = Eigen::Vector3d::Zero(), last = Eigen::Vector3d::Zero(),
                  organ = Eigen::Vector3d::Zero();
  int on_thin = 0, attached = 0;
};

// A scene of one membrane (a 60 x 60 mm sheet, no organ model) filmed while it shifts 6 mm:
// features are lifted onto the shell, its springs pull it along (a rigid shift costs no
// elastic energy, so the tolerance is the box test's), and the records hold the sheet.
TEST(Pipeline, MembraneOnlySceneFollowsARigidShift) {
  const std::string dir = testing::ScratchDir("pipeline_membrane");
  const SurfaceMesh sheet = TopSheet(60, 6, 0.0);
  WriteSurfaceMesh(dir + "/sheet.obj", sheet);
  const PinholeCamera camera = TestCamera();
  RenderVideo(dir, camera, sheet, 16, [](const Eigen::RowVector3d& p, int f) {
    return Eigen::RowVector3d(p + Eigen::RowVector3d(0.5 * std::min(f, 12), 0, 0));
  });
  nlohmann::json j;
  j["camera"] = CameraToJson(camera);
  j["video"] = "video.mp4";
  j["thin_structures"] = {{{"name", "sheet"},
                           {"type", "shell"},
                           {"mesh", "sheet.obj"},
                           {"thickness_mm", 1.0},
                           {"material", {{"youngs_modulus_pa", 20000.0}, {"poisson_ratio", 0.3}}}}};
  std::ofstream(dir + "/scene.json") << j.dump(2);
  const Scene scene = ReadScene(dir + "/scene.json");
  PipelineOptions o = ReadPipelineOptions(scene);
  o.render.enabled = false;
  RegistrationPipeline pipe(scene, o);
  ThinProbe probe;
  RecordWriter records(dir + "/out", false);
  debug::DebugRecorderOptions ro;
  ro.run_dir = dir + "/out";
  debug::DebugRecorder recorder(ro);
  pipe.AddObserver(&probe);
  pipe.AddObserver(&records);
  pipe.AddObserver(&recorder);
  const RunSummary s = pipe.Run();
  EXPECT_EQ(s.frames, 16);
  // The debug records resolve the detector's pairs to the features on the sheet (the
  // detector's features are those attached to the organ or to a thin structure), which carry
  // their target and model points.
  {
    const nlohmann::json rec = ParseJsonFile(debug::FrameRecordPath(dir + "/out", 15));
    std::set<int> on_sheet;
    for (const auto& f : rec["features"])
      if (f.contains("target_mm") && f.contains("model_mm")) on_sheet.insert(f["id"].get<int>());
    EXPECT_EQ(static_cast<int>(on_sheet.size()), probe.on_thin);
    ASSERT_FALSE(rec["detection"].is_null());
    ASSERT_FALSE(rec["detection"]["pairs"].empty());
    for (const auto& p : rec["detection"]["pairs"]) {
      EXPECT_EQ(on_sheet.count(p[0].get<int>()), 1u);
      EXPECT_EQ(on_sheet.count(p[1].get<int>()), 1u);
    }
  }
  const Eigen::Vector3d moved = probe.last - probe.rest;
  EXPECT_NEAR(moved.x(), 6.0, 0.3);
  EXPECT_NEAR(moved.y(), 0.0, 0.3);
  EXPECT_NEAR(moved.z(), 0.0, 0.3);
  // Records: thin/ and surface/ hold the sheet, no tetrahedral mesh, run.json names it.
  const nlohmann::json run = ParseJsonFile(dir + "/out/run.json");
  EXPECT_EQ(run["thin_structures"], nlohmann::json::array({"sheet"}));
  EXPECT_GT(run["thin"]["features_attached"].get<int>(), 20);
  EXPECT_EQ(run["thin"]["features_attached"], run["features"]["attached"]);
  const SurfaceMesh thin = ReadSurfaceMesh(dir + "/out/thin/000015.obj");
  EXPECT_EQ(thin.num_faces(), sheet.num_faces());
  EXPECT_NEAR(thin.vertices.col(0).mean() - sheet.vertices.col(0).mean(), 6.0, 0.3);
  EXPECT_EQ(ReadSurfaceMesh(dir + "/out/surface/000015.obj").num_faces(), sheet.num_faces());
  EXPECT_FALSE(std::filesystem::exists(dir + "/out/mesh/000015.vtk"));
}

// The box with a 40 x 40 mm shell lying 0.3 mm above its top face, tied to it
// (attach: "model"): features on the shell and on the box's rim pull one system; both follow
// the 6 mm shift.
TEST(Pipeline, ShellTiedToTheOrganFollowsItsShift) {
  BoxScene b = MakeBoxScene("pipeline_tied_shell", 16, [](int f) { return 0.5 * std::min(f, 12); });
  WriteSurfaceMesh(b.dir + "/shell.obj", TopSheet(40, 4, 0.3));
  nlohmann::json j = ParseJsonFile(b.dir + "/scene.json");
  j["thin_structures"] = {{{"name", "shell"},
                           {"type", "shell"},
                           {"mesh", "shell.obj"},
                           {"thickness_mm", 0.5},
                           {"attach", "model"},
                           {"attach_distance_mm", 1.0}}};
  std::ofstream(b.dir + "/scene.json") << j.dump(2);
  const Scene scene = ReadScene(b.dir + "/scene.json");
  PipelineOptions o = ReadPipelineOptions(scene);
  o.render.enabled = false;
  RegistrationPipeline pipe(scene, o);
  ThinProbe probe;
  pipe.AddObserver(&probe);
  EXPECT_EQ(pipe.Run().frames, 16);
  // The shell covers the middle of the box's top: features on both.
  EXPECT_GT(probe.on_thin, 10);
  EXPECT_GT(probe.attached - probe.on_thin, 10);
  const Eigen::Vector3d shell = probe.last - probe.rest;
  EXPECT_NEAR(shell.x(), 6.0, 0.3);
  EXPECT_NEAR(shell.y(), 0.0, 0.3);
  EXPECT_NEAR(shell.z(), 0.0, 0.3);
  EXPECT_NEAR(probe.organ.x(), 6.0, 0.3);
  EXPECT_NEAR(probe.organ.y(), 0.0, 0.3);
}

TEST(Pipeline, OutputFitChangesWhatIsShownOnly) {
  // The box is stretched along x by 1 % a frame for 12 frames, then held. The output fit
  // (docs/springs.md, "Output fit") moves what is drawn and saved; the dynamic model, which
  // detection and lifting use, is the same as without it. With the fit off (factor 0) the
  // dynamic model is shown. (That the fit follows the targets more closely is tested in
  // tests/mechanics/quasi_static_fit_test.cc, its effect on accuracy in tests/e2e.)
  const int frames = 14;
  const BoxScene b =
      MakeMovingBoxScene("pipeline_fit", frames, [](const Eigen::RowVector3d& p, int f) {
        return Eigen::RowVector3d(p.x() * (1.0 + 0.01 * std::min(f, 12)), p.y(), p.z());
      });
  const std::string out = b.dir + "/run";
  auto run = [&](double factor, bool record) {
    PipelineOptions o = ReadPipelineOptions(b.scene);
    o.render.enabled = false;
    o.mechanics.output_spring_factor = factor;
    ConfigurationProbe probe;
    RecordWriter records(out, false);
    RegistrationPipeline pipe(b.scene, o);
    pipe.AddObserver(&probe);
    if (record) pipe.AddObserver(&records);
    RunOptions ro;
    ro.save_every = 100;
    EXPECT_EQ(pipe.Run(ro).frames, frames);
    return probe;
  };
  const ConfigurationProbe fit = run(6.0, true), off = run(0.0, false);
  EXPECT_TRUE(fit.surface_matches);
  EXPECT_TRUE(off.surface_matches);
  for (int f = 1; f < frames; ++f) {
    EXPECT_EQ(fit.fit_status[f], "converged") << f;
    EXPECT_TRUE(off.fit_status[f].empty()) << f;
    EXPECT_EQ(off.shown[f], off.dynamic[f]) << f;
    EXPECT_LT((fit.dynamic[f] - off.dynamic[f]).cwiseAbs().maxCoeff(), 1e-9) << f;
    EXPECT_GT((fit.shown[f] - fit.dynamic[f]).cwiseAbs().maxCoeff(), 1e-3) << f;
  }
  // The saved meshes are the shown configuration.
  const TetMesh saved = ReadTetMesh(out + "/mesh/" + "000013.vtk");
  EXPECT_LT((saved.vertices - fit.shown.back()).cwiseAbs().maxCoeff(), 1e-5);
}

// model.degree 2 (docs/higher-order.md, "In the registration"): the box bent in its plane
// (y += c x^2, growing over 10 frames, then held). The organ runs as straight-raised quadratic
// Bernstein tetrahedra: what is shown and saved is the curved boundary's tessellation, which
// at rest lies on the straight faces and after the bend leaves them (the edge control points
// moved off the chords); it follows the bend as the linear model does. Degree 1 on the same
// video shows its linear boundary. Topology changes are refused up front.
class SurfaceProbe : public FrameObserver {
 public:
  void OnFrame(const FrameState& f) override {
    surfaces.push_back(*f.surface);
    linear.push_back(ExtractBoundary(f.state->CurrentMesh()));
    spring_mean_mm.push_back(f.stats.spring_length_mean_mm);
  }
  std::vector<SurfaceMesh> surfaces, linear;
  std::vector<double> spring_mean_mm;
};

// Largest distance of `points` from the triangles of `mesh` (brute force).
double LargestDistance(const RowMatX3d& points, const SurfaceMesh& mesh) {
  double worst = 0;
  for (int i = 0; i < points.rows(); ++i) {
    const Eigen::Vector3d p = points.row(i).transpose();
    double best = std::numeric_limits<double>::infinity();
    for (int t = 0; t < mesh.num_faces(); ++t) {
      const Eigen::Vector3d q =
          ClosestPointOnTriangle(p, mesh.vertices.row(mesh.faces(t, 0)).transpose(),
                                 mesh.vertices.row(mesh.faces(t, 1)).transpose(),
                                 mesh.vertices.row(mesh.faces(t, 2)).transpose());
      best = std::min(best, (q - p).norm());
    }
    worst = std::max(worst, best);
  }
  return worst;
}

TEST(Pipeline, DegreeTwoShowsTheCurvedBoundaryAndFollowsABend) {
  const int frames = 16;
  BoxScene b =
      MakeMovingBoxScene("pipeline_degree", frames, [](const Eigen::RowVector3d& p, int f) {
        return Eigen::RowVector3d(p.x(), p.y() + 0.008 * p.x() * p.x() * std::min(f, 10) / 10.0,
                                  p.z());
      });
  auto run = [&](int degree) {
    Scene scene = b.scene;
    scene.model_degree = degree;
    PipelineOptions o = ReadPipelineOptions(scene);
    o.render.enabled = false;
    o.cutting.enabled = false;
    o.mechanics.output_spring_factor = 0;  // degree 1 shows its dynamic state too
    SurfaceProbe probe;
    RegistrationPipeline pipe(scene, o);
    pipe.AddObserver(&probe);
    EXPECT_EQ(pipe.Run().frames, frames);
    return probe;
  };
  const SurfaceProbe p2 = run(2), p1 = run(1);
  // Degree 1 shows its linear boundary; degree 2 a finer tessellation (16 triangles a face).
  EXPECT_EQ(p1.surfaces.back().vertices, p1.linear.back().vertices);
  EXPECT_EQ(p2.surfaces.back().num_faces(), 16 * p2.linear.back().num_faces());
  // At rest on the straight faces; bent, off them: the sagitta of a 10 mm edge under the
  // 7.2 mm bend at x = 30 is 0.008 * 5^2 = 0.2 mm.
  EXPECT_LT(LargestDistance(p2.surfaces.front().vertices, p2.linear.front()), 1e-9);
  const double off = LargestDistance(p2.surfaces.back().vertices, p2.linear.back());
  EXPECT_GT(off, 0.05);
  EXPECT_LT(off, 1.0);
  // Both follow the bend: springs short at the end.
  EXPECT_LT(p2.spring_mean_mm.back(), 0.5);
  EXPECT_LT(p1.spring_mean_mm.back(), 0.5);

  Scene scene = b.scene;
  scene.model_degree = 3;
  PipelineOptions o = ReadPipelineOptions(scene);
  o.cutting.enabled = true;
  try {
    RegistrationPipeline pipe(scene, o);
    ADD_FAILURE() << "a degree-3 run with topology changes was accepted";
  } catch (const Error& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("model.degree"), std::string::npos) << msg;
    EXPECT_NE(msg.find("--no-topology"), std::string::npos) << msg;
  }
}

TEST(Pipeline, StopFlagEndsTheRunWithCompleteOutputs) {
  const BoxScene b = MakeBoxScene("pipeline_stop", 10, [](int f) { return 0.2 * f; });
  PipelineOptions o = ReadPipelineOptions(b.scene);
  std::atomic<bool> stop{false};
  StopAfter probe(3, &stop);
  const std::string out = b.dir + "/run";
  RecordWriter records(out, false);
  RegistrationPipeline pipe(b.scene, o);
  pipe.AddObserver(&probe);
  pipe.AddObserver(&records);
  RunOptions run;
  run.overlay_video_path = out + "/overlay.mp4";
  run.stop = &stop;
  run.save_every = 100;
  const RunSummary s = pipe.Run(run);
  EXPECT_TRUE(s.interrupted);
  // Raised while frame 3 was being recorded, the flag is seen when frame 4 is complete (as
  // a Ctrl-C arriving then): frames 0..4 are done.
  EXPECT_EQ(s.frames, 5);
  EXPECT_EQ(ReadJsonl(out + "/frames.jsonl").size(), 5u);
  const nlohmann::json run_json = ParseJsonFile(out + "/run.json");
  EXPECT_TRUE(run_json.at("interrupted").get<bool>());
  EXPECT_EQ(run_json.at("frames").get<int>(), 5);
  // The last processed frame is a record frame; the video holds exactly the frames done.
  EXPECT_TRUE(std::filesystem::exists(out + "/surface/000004.obj"));
  VideoReader overlay;
  overlay.Open(out + "/overlay.mp4");
  EXPECT_EQ(overlay.frame_count(), 5);
  // No temporary files are left behind.
  for (const auto& e : std::filesystem::directory_iterator(out))
    EXPECT_EQ(e.path().filename().string().find(".tmp"), std::string::npos) << e.path();
}

TEST(Pipeline, OptionsRejectUnknownKeysAndBadValues) {
  Scene scene;
  scene.path = "scene.json";
  scene.mechanics = {{"sprng_stiffness", 3.0}};
  EXPECT_THROW(ReadPipelineOptions(scene), Error);
  scene.mechanics = {{"spring_stiffness_n_per_m", -1.0}};
  EXPECT_THROW(ReadPipelineOptions(scene), Error);
  scene.mechanics = nlohmann::json::object();
  scene.render = {{"organ_opacity", 0.5}, {"wireframe", true}};
  const PipelineOptions o = ReadPipelineOptions(scene);
  EXPECT_DOUBLE_EQ(o.render.organ_opacity, 0.5);
  EXPECT_TRUE(o.render.wireframe);
  EXPECT_EQ(o.tracking.max_features, 500);
  // weaker points fill a weakly textured organ up to 350 features.
  EXPECT_EQ(o.tracking.min_features, 350);
  EXPECT_DOUBLE_EQ(o.tracking.min_hessian_threshold, 0.5);
  scene.tracking = {{"min_features", 0}, {"min_hessian_threshold", 2.0}};
  EXPECT_EQ(ReadPipelineOptions(scene).tracking.min_features, 0);
  EXPECT_DOUBLE_EQ(ReadPipelineOptions(scene).tracking.min_hessian_threshold, 2.0);
  scene.tracking = {{"min_features", -5}};
  EXPECT_THROW(ReadPipelineOptions(scene), Error);
  scene.tracking = {{"min_hessian_threshold", -1.0}};
  EXPECT_THROW(ReadPipelineOptions(scene), Error);
  scene.tracking = nlohmann::json::object();
  // The cutting section's keys are read and checked.
  EXPECT_TRUE(o.cutting.keep_connected);
  EXPECT_DOUBLE_EQ(o.cutting.detector.bridge_radius_factor, 2.0);
  scene.cutting = {{"keep_connected", false},
                   {"bridge_radius_factor", 0.0},
                   {"bridge_cone_half_angle_deg", 20.0}};
  const PipelineOptions c = ReadPipelineOptions(scene);
  EXPECT_FALSE(c.cutting.keep_connected);
  EXPECT_DOUBLE_EQ(c.cutting.detector.bridge_radius_factor, 0.0);
  EXPECT_DOUBLE_EQ(c.cutting.detector.bridge_cone_half_angle_deg, 20.0);
  scene.cutting = {{"bridge_cone_half_angle_deg", 95.0}};
  EXPECT_THROW(ReadPipelineOptions(scene), Error);
  scene.cutting = {{"keep_connected", 1.5}};
  EXPECT_THROW(ReadPipelineOptions(scene), Error);
  // the first event's depth foresees the polyline reaching the outline.
  EXPECT_TRUE(o.cutting.first_event_foresight);
  scene.cutting = {{"first_event_foresight", false}};
  EXPECT_FALSE(ReadPipelineOptions(scene).cutting.first_event_foresight);
  scene.cutting = {{"first_event_foresight", 3}};
  EXPECT_THROW(ReadPipelineOptions(scene), Error);
  // segments that would split the model are refused.
  EXPECT_TRUE(o.cutting.refuse_splitting_segments);
  scene.cutting = {{"refuse_splitting_segments", false}};
  EXPECT_FALSE(ReadPipelineOptions(scene).cutting.refuse_splitting_segments);
  scene.cutting = {{"refuse_splitting_segments", "yes"}};
  EXPECT_THROW(ReadPipelineOptions(scene), Error);
  // a star does not start a polyline.
  EXPECT_TRUE(o.cutting.detector.reject_star_starts);
  scene.cutting = {{"reject_star_starts", false}};
  EXPECT_FALSE(ReadPipelineOptions(scene).cutting.detector.reject_star_starts);
  scene.cutting = {{"reject_star_starts", 1}};
  EXPECT_THROW(ReadPipelineOptions(scene), Error);
  // the outlier floor in pixels.
  EXPECT_EQ(o.cutting.min_outlier_measure_px, 1.0);
  scene.cutting = {{"min_outlier_measure_px", 0.5}};
  EXPECT_EQ(ReadPipelineOptions(scene).cutting.min_outlier_measure_px, 0.5);
  scene.cutting = {{"min_outlier_measure_px", -1}};
  EXPECT_THROW(ReadPipelineOptions(scene), Error);
  // the scale of tau: the plain mean unless the mean of the inliers is asked for.
  EXPECT_FALSE(o.cutting.detector.mean_of_inliers);
  scene.cutting = {{"mean_of_inliers", true}};
  EXPECT_TRUE(ReadPipelineOptions(scene).cutting.detector.mean_of_inliers);
  scene.cutting = {{"mean_of_inliers", 1}};
  EXPECT_THROW(ReadPipelineOptions(scene), Error);
  // conservative starts, opt-in.
  EXPECT_FALSE(o.cutting.detector.confirm_starts_with_model_measure);
  scene.cutting = {{"confirm_starts_with_model_measure", true}};
  EXPECT_TRUE(ReadPipelineOptions(scene).cutting.detector.confirm_starts_with_model_measure);
  scene.cutting = {{"confirm_starts_with_model_measure", "no"}};
  EXPECT_THROW(ReadPipelineOptions(scene), Error);
  // where S is cut.
  EXPECT_EQ(o.cutting.cut_configuration, CutConfiguration::kRest);
  scene.cutting = {{"cut_configuration", "current"}};
  EXPECT_EQ(ReadPipelineOptions(scene).cutting.cut_configuration, CutConfiguration::kCurrent);
  scene.cutting = {{"cut_configuration", "deformed"}};
  EXPECT_THROW(ReadPipelineOptions(scene), Error);
  // the growth probe.
  EXPECT_DOUBLE_EQ(o.cutting.detector.probe_length_factor, 2.0);
  EXPECT_DOUBLE_EQ(o.cutting.detector.probe_pair_length_factor, 3.0);
  EXPECT_DOUBLE_EQ(o.cutting.detector.probe_outlier_factor, 12.0);
  EXPECT_DOUBLE_EQ(o.cutting.detector.probe_max_lead_factor, 1.0);
  scene.cutting = {{"probe_length_factor", 0.0},
                   {"probe_pair_length_factor", 2.5},
                   {"probe_outlier_factor", 15.0},
                   {"probe_max_lead_factor", 1.5}};
  const PipelineOptions p = ReadPipelineOptions(scene);
  EXPECT_DOUBLE_EQ(p.cutting.detector.probe_length_factor, 0.0);
  EXPECT_DOUBLE_EQ(p.cutting.detector.probe_pair_length_factor, 2.5);
  EXPECT_DOUBLE_EQ(p.cutting.detector.probe_outlier_factor, 15.0);
  EXPECT_DOUBLE_EQ(p.cutting.detector.probe_max_lead_factor, 1.5);
  scene.cutting = {{"probe_outlier_factor", -1.0}};
  EXPECT_THROW(ReadPipelineOptions(scene), Error);
  // the balance bound of a cluster of bridges.
  EXPECT_DOUBLE_EQ(o.cutting.detector.min_opening_balance_bridges, 1.0 / 3.0);
  scene.cutting = {{"min_opening_balance_bridges", 0.25}};
  EXPECT_DOUBLE_EQ(ReadPipelineOptions(scene).cutting.detector.min_opening_balance_bridges, 0.25);
  EXPECT_DOUBLE_EQ(
      PipelineOptionsToJson(ReadPipelineOptions(scene))["cutting"]["min_opening_balance_bridges"]
          .get<double>(),
      0.25);
  scene.cutting = {{"min_opening_balance_bridges", 1.5}};
  EXPECT_THROW(ReadPipelineOptions(scene), Error);
  // ... and of a lone point's growth.
  EXPECT_DOUBLE_EQ(o.cutting.detector.min_lone_growth_balance, 0.0);
  scene.cutting = {{"min_lone_growth_balance", -1.0}};
  EXPECT_DOUBLE_EQ(
      PipelineOptionsToJson(ReadPipelineOptions(scene))["cutting"]["min_lone_growth_balance"]
          .get<double>(),
      -1.0);
  scene.cutting = {{"min_lone_growth_balance", 2.0}};
  EXPECT_THROW(ReadPipelineOptions(scene), Error);
  // internal structures split and capped, or their crossing triangles deleted.
  EXPECT_TRUE(o.cutting.internal_caps);
  scene.cutting = {{"internal_caps", false}};
  EXPECT_FALSE(ReadPipelineOptions(scene).cutting.internal_caps);
  scene.cutting = {{"internal_caps", "yes"}};
  EXPECT_THROW(ReadPipelineOptions(scene), Error);
}

TEST(Overlay, DrawsOnlyOverTheOrganAndBlendsByOpacity) {
  PinholeCamera camera;
  camera.width = 160;
  camera.height = 128;
  camera.fx = camera.fy = 150;
  camera.cx = 79.5;
  camera.cy = 63.5;
  camera.LookAt(Eigen::Vector3d(0, 0, 200), Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(0, 1, 0));
  const TetMesh box = MakeBoxTetMesh(Eigen::Vector3d(40, 40, 10), Eigen::Vector3i(2, 2, 1));
  SurfaceMesh surface = ExtractBoundary(box);
  surface.vertices.rowwise() -= Eigen::RowVector3d(20, 20, 10);
  const cv::Mat frame(camera.height, camera.width, CV_8UC3, cv::Scalar(40, 60, 80));
  const cv::Mat silhouette =
      render::RenderMask(ToRasterCamera(camera), surface.vertices, surface.faces);
  for (double opacity : {0.0, 0.35, 1.0}) {
    RenderStageOptions o;
    o.style = OverlayStyle::kTint;  // the translucent surface (the contour style draws none)
    o.legend = false;
    o.organ_opacity = opacity;
    OverlayRenderer overlay(camera, o);
    cv::Mat out = frame.clone();
    overlay.Render(surface.vertices, surface.faces, {}, OverlayLayers(), &out);
    int changed_outside = 0, changed_inside = 0, inside = 0;
    for (int y = 0; y < out.rows; ++y)
      for (int x = 0; x < out.cols; ++x) {
        const cv::Vec3b d = out.at<cv::Vec3b>(y, x), f = frame.at<cv::Vec3b>(y, x);
        const int diff = std::abs(d[0] - f[0]) + std::abs(d[1] - f[1]) + std::abs(d[2] - f[2]);
        // Interior pixels: away from the silhouette's anti-aliased edge.
        bool interior = true;
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const int yy = std::clamp(y + dy, 0, out.rows - 1),
                      xx = std::clamp(x + dx, 0, out.cols - 1);
            interior = interior && silhouette.at<uint8_t>(yy, xx) > 0;
          }
        bool exterior = true;
        for (int dy = -2; dy <= 2; ++dy)
          for (int dx = -2; dx <= 2; ++dx) {
            const int yy = std::clamp(y + dy, 0, out.rows - 1),
                      xx = std::clamp(x + dx, 0, out.cols - 1);
            exterior = exterior && silhouette.at<uint8_t>(yy, xx) == 0;
          }
        if (exterior && diff > 0) ++changed_outside;
        if (interior) {
          ++inside;
          if (diff > 6) ++changed_inside;
        }
      }
    EXPECT_EQ(changed_outside, 0) << opacity;  // the frame is kept exactly off the organ
    ASSERT_GT(inside, 100);
    if (opacity == 0.0)
      EXPECT_EQ(changed_inside, 0);  // fully transparent: the frame shows through unchanged
    else
      EXPECT_EQ(changed_inside, inside) << opacity;  // every interior pixel is tinted
  }
}

// Scene keys reach the options and are written back to run.json; out-of-range values name the key.
TEST(PipelineOptions, TrackingAndDetectorKeysRoundTrip) {
  Scene scene;
  scene.path = "scene.json";
  scene.tracking = {{"appearance_check", true},    {"appearance_min_correlation", 0.7},
                    {"drift_correction", true},    {"drift_window_px", 25},
                    {"drift_every_frames", 1},     {"drift_min_correlation", 0.8},
                    {"drift_max_correction_px", 3}};
  scene.cutting = {{"neighbours_per_feature", 12}, {"outlier_weight_cap", 1.5}};
  const PipelineOptions o = ReadPipelineOptions(scene);
  EXPECT_TRUE(o.tracking.appearance.enabled);
  EXPECT_DOUBLE_EQ(o.tracking.appearance.min_correlation, 0.7);
  EXPECT_TRUE(o.tracking.drift.enabled);
  EXPECT_EQ(o.tracking.drift.window_px, 25);
  EXPECT_EQ(o.tracking.drift.every_frames, 1);
  EXPECT_DOUBLE_EQ(o.tracking.drift.min_correlation, 0.8);
  EXPECT_DOUBLE_EQ(o.tracking.drift.max_correction_px, 3);
  EXPECT_EQ(o.cutting.detector.neighbours_per_feature, 12);
  const nlohmann::json j = PipelineOptionsToJson(o);
  EXPECT_EQ(j["tracking"]["appearance_check"], true);
  EXPECT_DOUBLE_EQ(j["tracking"]["appearance_min_correlation"].get<double>(), 0.7);
  EXPECT_EQ(j["tracking"]["drift_correction"], true);
  EXPECT_EQ(j["tracking"]["drift_window_px"], 25);
  EXPECT_EQ(j["cutting"]["neighbours_per_feature"], 12);
  EXPECT_EQ(j["tracking"]["redetect_every_frames"], 0);  // off by default
  EXPECT_EQ(j["mechanics"]["volume_term"], "jacobian");
  scene.mechanics = {{"volume_term", "linear"}};
  EXPECT_EQ(ReadPipelineOptions(scene).mechanics.volume_term, mechanics::VolumeTerm::kLinear);
  scene.mechanics = {{"volume_term", "neo-hookean"}};
  try {
    ReadPipelineOptions(scene);
    FAIL() << "an unknown volume term was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("volume_term"), std::string::npos) << e.what();
  }
  scene.mechanics = nlohmann::json::object();
  scene.tracking = {{"redetect_every_frames", 5},
                    {"redetect_hole_factor", 1.5},
                    {"attach_after_frames", 3},
                    {"attach_max_misfit_factor", 4}};
  const PipelineOptions late = ReadPipelineOptions(scene);
  EXPECT_EQ(late.tracking.redetect_every_frames, 5);
  EXPECT_DOUBLE_EQ(late.tracking.redetect_hole_factor, 1.5);
  EXPECT_EQ(late.attach_after_frames, 3);
  EXPECT_DOUBLE_EQ(late.attach_max_misfit_factor, 4);
  EXPECT_EQ(PipelineOptionsToJson(late)["attach_after_frames"], 3);
  for (const nlohmann::json& bad :
       {nlohmann::json{{"attach_after_frames", -1}}, nlohmann::json{{"redetect_hole_factor", -1}},
        nlohmann::json{{"attach_max_misfit_factor", 0}}}) {
    scene.tracking = bad;
    try {
      ReadPipelineOptions(scene);
      FAIL() << bad.dump() << " was accepted";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(bad.begin().key()), std::string::npos) << e.what();
    }
  }

  scene.tracking = {{"appearance_min_correlation", 1.5}};
  try {
    ReadPipelineOptions(scene);
    FAIL() << "a correlation above 1 was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("min_correlation"), std::string::npos) << e.what();
  }
  scene.tracking = {{"drift_window_px", 24}};
  try {
    ReadPipelineOptions(scene);
    FAIL() << "an even drift window was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("window_px"), std::string::npos) << e.what();
  }
}

// Instrument rejection is on by default in the pipeline (off in the tracker); its keys reach the
// options and run.json, and a bad value names its key.
TEST(PipelineOptions, InstrumentRejectionKeysRoundTrip) {
  Scene scene;
  scene.path = "scene.json";
  EXPECT_FALSE(FeatureTrackerOptions().instruments.enabled);
  EXPECT_TRUE(ReadPipelineOptions(scene).tracking.instruments.enabled);
  scene.tracking = {{"instrument_rejection", false},     {"instrument_seed_max_warmth", 1.0},
                    {"instrument_grow_max_warmth", 7.0}, {"instrument_min_area_fraction", 0.01},
                    {"instrument_margin_px", 6},         {"instrument_motion", false}};
  const PipelineOptions o = ReadPipelineOptions(scene);
  EXPECT_FALSE(o.tracking.instruments.enabled);
  EXPECT_DOUBLE_EQ(o.tracking.instruments.mask.seed_max_warmth, 1.0);
  EXPECT_DOUBLE_EQ(o.tracking.instruments.mask.grow_max_warmth, 7.0);
  EXPECT_DOUBLE_EQ(o.tracking.instruments.mask.min_area_fraction, 0.01);
  EXPECT_EQ(o.tracking.instruments.mask.margin_px, 6);
  EXPECT_FALSE(o.tracking.instruments.motion.enabled);
  const nlohmann::json j = PipelineOptionsToJson(o);
  EXPECT_EQ(j["tracking"]["instrument_rejection"], false);
  EXPECT_DOUBLE_EQ(j["tracking"]["instrument_grow_max_warmth"].get<double>(), 7.0);
  EXPECT_EQ(j["tracking"]["instrument_margin_px"], 6);
  EXPECT_EQ(j["tracking"]["instrument_motion"], false);
  scene.tracking = {{"instrument_seed_max_warmth", 11.0}};  // above grow_max_warmth (10)
  try {
    ReadPipelineOptions(scene);
    FAIL() << "a seed threshold above the growth threshold was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("seed_max_warmth"), std::string::npos) << e.what();
  }
}

// The relative stiffness and the absolute override reach the options and run.json; bad values
// name their key.
TEST(PipelineOptions, SpringStiffnessKeysRoundTrip) {
  Scene scene;
  scene.path = "scene.json";
  PipelineOptions o = ReadPipelineOptions(scene);
  EXPECT_DOUBLE_EQ(o.mechanics.spring_stiffness_relative, 170.0);
  EXPECT_DOUBLE_EQ(o.mechanics.spring_stiffness_n_per_m, 0.0);  // no override
  scene.mechanics = {{"spring_stiffness_relative", 40.0}, {"spring_stiffness_n_per_m", 800.0}};
  o = ReadPipelineOptions(scene);
  EXPECT_DOUBLE_EQ(o.mechanics.spring_stiffness_relative, 40.0);
  EXPECT_DOUBLE_EQ(o.mechanics.spring_stiffness_n_per_m, 800.0);
  const nlohmann::json j = PipelineOptionsToJson(o);
  EXPECT_DOUBLE_EQ(j["mechanics"]["spring_stiffness_relative"].get<double>(), 40.0);
  EXPECT_DOUBLE_EQ(j["mechanics"]["spring_stiffness_n_per_m"].get<double>(), 800.0);
  EXPECT_DOUBLE_EQ(o.mechanics.output_spring_factor, 6.0);
  scene.mechanics = {{"output_spring_factor", 0.0}};
  EXPECT_DOUBLE_EQ(ReadPipelineOptions(scene).mechanics.output_spring_factor, 0.0);
  scene.mechanics = {{"output_spring_factor", 12.0}};
  EXPECT_DOUBLE_EQ(
      PipelineOptionsToJson(ReadPipelineOptions(scene))["mechanics"]["output_spring_factor"]
          .get<double>(),
      12.0);
  EXPECT_DOUBLE_EQ(o.mechanics.out_of_view_tether, 1.0);
  scene.mechanics = {{"out_of_view_tether", 0.0}};
  EXPECT_DOUBLE_EQ(ReadPipelineOptions(scene).mechanics.out_of_view_tether, 0.0);
  EXPECT_DOUBLE_EQ(
      PipelineOptionsToJson(ReadPipelineOptions(scene))["mechanics"]["out_of_view_tether"]
          .get<double>(),
      0.0);
  EXPECT_TRUE(o.mechanics.line_search);
  scene.mechanics = {{"line_search", false}};
  EXPECT_FALSE(ReadPipelineOptions(scene).mechanics.line_search);
  EXPECT_FALSE(
      PipelineOptionsToJson(ReadPipelineOptions(scene))["mechanics"]["line_search"].get<bool>());
  scene.mechanics = {{"line_search", "yes"}};
  try {
    ReadPipelineOptions(scene);
    FAIL() << "line_search = \"yes\" was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("line_search"), std::string::npos) << e.what();
  }

  for (const auto& [key, value] : {std::pair<const char*, double>{"spring_stiffness_relative", 0.0},
                                   {"spring_stiffness_relative", -1.0},
                                   {"spring_stiffness_relative", std::nan("")},
                                   {"spring_stiffness_n_per_m", -500.0},
                                   {"output_spring_factor", -1.0},
                                   {"output_spring_factor", std::nan("")},
                                   {"out_of_view_tether", -1.0},
                                   {"out_of_view_tether", std::nan("")}}) {
    scene.mechanics = {{key, value}};
    try {
      ReadPipelineOptions(scene);
      FAIL() << key << " = " << value << " was accepted";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(key), std::string::npos) << e.what();
    }
  }
}

// The tether of tissue out of view: exactly the vertices projecting outside the image (or
// behind the camera) are held, each with its share of the rest volume: a model seen nowhere
// gets factor x N k in all; held vertices are left out; linear in the factor.
TEST(OutOfViewTethers, HoldsTheVerticesOutsideTheImageByTheirVolumeShare) {
  TetMesh mesh = MakeBoxTetMesh({100, 50, 10}, {10, 5, 2});
  mesh.vertices.rowwise() += Eigen::RowVector3d(-50, -25, 200);
  PinholeCamera camera;
  camera.width = 640;
  camera.height = 480;
  camera.fx = camera.fy = 2000.0;  // 64 x 48 mm seen at 200 mm: the box's sides are out of view
  camera.cx = 319.5;
  camera.cy = 239.5;
  const double total = 500.0, factor = 0.5;
  const std::vector<VertexTether> tethers = OutOfViewTethers(mesh, camera, factor, total, {});
  std::vector<char> tethered(mesh.num_vertices(), 0);
  for (const VertexTether& t : tethers) {
    tethered[t.vertex] = 1;
    EXPECT_GT(t.stiffness_n_per_m, 0.0);
  }
  int outside = 0;
  for (int v = 0; v < mesh.num_vertices(); ++v) {
    const bool in_image = camera.IsInImage(camera.Project(mesh.vertices.row(v).transpose()));
    EXPECT_EQ(tethered[v] != 0, !in_image) << "vertex " << v;
    outside += in_image ? 0 : 1;
  }
  EXPECT_GT(outside, 0);
  EXPECT_LT(outside, mesh.num_vertices());
  // Behind the camera nothing is seen: every vertex is tethered, the stiffnesses sum to
  // factor x total (the volume shares sum to the volume).
  TetMesh behind = mesh;
  behind.vertices.col(2).array() -= 400.0;
  const std::vector<VertexTether> all = OutOfViewTethers(behind, camera, factor, total, {});
  ASSERT_EQ(static_cast<int>(all.size()), behind.num_vertices());
  double sum = 0;
  for (const VertexTether& t : all) sum += t.stiffness_n_per_m;
  EXPECT_NEAR(sum, factor * total, 1e-9);
  // Held vertices are left out; twice the factor, twice each stiffness; 0 is off.
  const std::vector<VertexTether> without_first =
      OutOfViewTethers(behind, camera, factor, total, {0, 1});
  EXPECT_EQ(without_first.size(), all.size() - 2);
  EXPECT_EQ(without_first.front().vertex, 2);
  const std::vector<VertexTether> twice = OutOfViewTethers(behind, camera, 2 * factor, total, {});
  for (size_t i = 0; i < all.size(); ++i)
    EXPECT_NEAR(twice[i].stiffness_n_per_m, 2 * all[i].stiffness_n_per_m, 1e-12);
  EXPECT_TRUE(OutOfViewTethers(behind, camera, 0.0, total, {}).empty());
}

// k = kappa x E x V / (A x N): linear in kappa, E and V, inverse in A and N; the documented
// reference (docs/springs.md): band-stretch, E = 100 kPa, V = 86,400 mm^3, A = 10,960 mm^2
// facing the camera, 232 springs gives 578 N/m at the default kappa 170.
TEST(SpringStiffness, ScalesWithModulusVolumeAreaAndSprings) {
  const MechanicsStageOptions o;
  const double e = 1e5, v = 86400.0, a = 10960.0;
  const int n = 232;
  const SpringStiffness ref = ResolveSpringStiffness(o, e, v, a, n);
  EXPECT_TRUE(ref.relative);
  EXPECT_NEAR(ref.n_per_m, 577.6, 0.05);
  // Ten times stiffer material: ten times stiffer springs (band-cut-s's 1 MPa).
  EXPECT_NEAR(ResolveSpringStiffness(o, 10 * e, v, a, n).n_per_m, 10 * ref.n_per_m, 1e-9);
  EXPECT_NEAR(ResolveSpringStiffness(o, 0.2 * e, v, a, n).n_per_m, 0.2 * ref.n_per_m, 1e-9);
  // Twice as deep under the same seen area: twice; the same body seen over twice the area or
  // held by twice the springs: half each (the total N x k stays kappa x E x V / A).
  EXPECT_NEAR(ResolveSpringStiffness(o, e, 2 * v, a, n).n_per_m, 2 * ref.n_per_m, 1e-9);
  EXPECT_NEAR(ResolveSpringStiffness(o, e, v, 2 * a, n).n_per_m, 0.5 * ref.n_per_m, 1e-9);
  EXPECT_NEAR(ResolveSpringStiffness(o, e, v, a, 2 * n).n_per_m, 0.5 * ref.n_per_m, 1e-9);
  MechanicsStageOptions twice = o;
  twice.spring_stiffness_relative = 340.0;
  EXPECT_NEAR(ResolveSpringStiffness(twice, e, v, a, n).n_per_m, 2 * ref.n_per_m, 1e-9);
  EXPECT_DOUBLE_EQ(ResolveSpringStiffness(o, e, v, a, 0).n_per_m, 0.0);  // nothing attached
  // The absolute override ignores material and geometry.
  MechanicsStageOptions absolute = o;
  absolute.spring_stiffness_n_per_m = 500.0;
  const SpringStiffness fixed = ResolveSpringStiffness(absolute, 10 * e, v, a, n);
  EXPECT_FALSE(fixed.relative);
  EXPECT_DOUBLE_EQ(fixed.n_per_m, 500.0);
  EXPECT_THROW(ResolveSpringStiffness(o, 0.0, v, a, n), Error);
  EXPECT_THROW(ResolveSpringStiffness(o, e, 0.0, a, n), Error);
  EXPECT_THROW(ResolveSpringStiffness(o, e, v, 0.0, n), Error);
}

// Faces count towards A when their outward side faces the eye: the top of a 60 x 60 x 10 mm box
// seen from straight above, three faces seen from far along the diagonal, none from inside.
TEST(SpringStiffness, AreaFacingTheCamera) {
  const SurfaceMesh box =
      ExtractBoundary(MakeBoxTetMesh(Eigen::Vector3d(60, 60, 10), Eigen::Vector3i(6, 6, 1)));
  EXPECT_NEAR(AreaFacing(box, Eigen::Vector3d(30, 30, 200)), 3600.0, 1e-9);
  EXPECT_NEAR(AreaFacing(box, Eigen::Vector3d(1e6, 1e6, 1e6)), 3600.0 + 2 * 600.0, 1e-6);
  EXPECT_NEAR(AreaFacing(box, Eigen::Vector3d(30, 30, 5)), 0.0, 1e-12);
}

}  // namespace
}  // namespace arreg::pipeline
