#include "ar/pipeline/registration_pipeline.h"

#include "ar/pipeline/frame_loop.h"
#include "core/error.h"
#include "core/mesh_io.h"
#include "core/mesh_ops.h"
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
  // Degree 2 and 3 (docs/higher-order.md, "In the registration"): degree 2 is cut by the
  // quadratic remesher, degree 3 not at all; the thin structures' ties embed in linear
  // tetrahedra.
  if (scene.model_degree > 1) {
    ARREG_CHECK_INPUT(scene.model_degree == 2 || !options.cutting.enabled, scene.path,
                      "model.degree", "degree ", scene.model_degree,
                      " elements cannot be cut (quadratic cutting is degree 2): run with "
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
  FrameLoop loop(impl_->scene, impl_->options, impl_->model, &impl_->reader, run_options,
                 impl_->observers);
  loop.Start();
  for (int frame = 0; frame < loop.num_frames(); ++frame)
    if (!loop.Step(frame)) break;
  return loop.Finish();
}

}  // namespace arreg::pipeline
