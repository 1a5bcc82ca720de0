// The scene file: one JSON document naming the organ model, internal structures,
// camera, video and per-module settings of a registration run (docs/scene-format.md).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/camera.h"
#include "core/enum_names.h"

namespace arreg {

// Tissue parameters shared by mechanics and cutting.
struct Material {
  double youngs_modulus_pa = 5000.0;  // Pa; soft liver/kidney parenchyma is a few kPa
  double poisson_ratio = 0.45;        // dimensionless, in (-1, 0.5)
  double density_kg_m3 = 1000.0;      // kg/m^3
  // Rayleigh damping D = alpha M + beta K.
  double rayleigh_mass_per_s = 0.1;    // alpha, 1/s
  double rayleigh_stiffness_s = 0.01;  // beta, s
  // Throws arreg::Error(file, "<prefix>.<field>") on the first invalid field.
  void Check(const std::string& file = "", const std::string& prefix = "material") const;
};

struct InternalStructure {
  std::string name;                                            // unique within the scene
  std::string mesh_path;                                       // resolved (see Scene::ResolvePath)
  Eigen::Vector3d color_rgb = Eigen::Vector3d(1.0, 1.0, 0.0);  // each in [0, 1]
  double opacity = 1.0;                                        // in [0, 1]
};

// A thin structure registered with (or instead of) the organ: a shell (a triangle
// mid-surface with a thickness, src/mechanics/bezier_shell.h) or a vessel (a
// centreline tree with a radius, src/mechanics/vessel.h). docs/scene-format.md.
enum class ThinStructureType { kShell, kVessel };
// The spelling in scene files: "shell", "vessel".
inline constexpr EnumName<ThinStructureType> kThinStructureTypeNames[] = {
    {ThinStructureType::kShell, "shell"}, {ThinStructureType::kVessel, "vessel"}};
const char* ThinStructureTypeName(ThinStructureType type);
// kModel: tied to the tet model by proximity.
enum class ThinAttachment { kNone, kModel };
// The spelling in scene files: "none", "model".
inline constexpr EnumName<ThinAttachment> kThinAttachmentNames[] = {
    {ThinAttachment::kNone, "none"}, {ThinAttachment::kModel, "model"}};
const char* ThinAttachmentName(ThinAttachment attachment);

struct ThinStructure {
  std::string name;  // unique among thin and internal structures
  ThinStructureType type = ThinStructureType::kShell;
  std::string mesh_path;            // shell: triangle mid-surface (resolved), model frame and units
  std::string visual_mesh_path;     // shell, optional: finer surface drawn and scored, "" if none
  std::string centreline_path;      // vessel: OBJ with v lines and l polylines (resolved)
  double thickness_mm = 0.0;        // shell: > 0, mm
  double radius_mm = 0.0;           // vessel: > 0, mm
  Material material;                // default: the scene's top-level material
  std::vector<int> fixed_vertices;  // indices into mesh / centreline vertices, held clamped
  ThinAttachment attach = ThinAttachment::kNone;
  double attach_distance_mm = 1.0;  // >= 0, mm: shell vertices this close to the model surface
  Eigen::Vector3d color = Eigen::Vector3d(1.0, 1.0, 0.0);  // RGB, each in [0, 1]
  double opacity = 1.0;                                    // in [0, 1]
};

// Unit of the coordinates in a scene's mesh files; "mm" and "m" in scene files.
enum class LengthUnit { kMillimetre, kMetre };
inline constexpr EnumName<LengthUnit> kLengthUnitNames[] = {{LengthUnit::kMillimetre, "mm"},
                                                            {LengthUnit::kMetre, "m"}};

struct Scene {
  std::string path;       // the scene file as given to ReadScene ("" for in-memory scenes)
  std::string directory;  // folder that relative paths are resolved against

  // Unit of the coordinates in the referenced mesh files. arreg works in
  // millimetres; loaders multiply mesh coordinates by mm_per_unit.
  LengthUnit units = LengthUnit::kMillimetre;
  double mm_per_unit = 1.0;  // 1 for millimetres, 1000 for metres
  std::string description;   // free text, optional

  // Tetrahedral mesh of the organ (resolved); "" for a scene of thin structures only.
  std::string model_mesh_path;
  // Rigid placement of the model mesh (after unit scaling) in the world frame,
  // translation in mm. Identity when absent. Applies to thin structures too.
  Eigen::Isometry3d world_from_model = Eigen::Isometry3d::Identity();
  // Polynomial degree of the organ's tetrahedra (`model.degree`): 1 (linear, the default),
  // 2 or 3 (Bernstein-Bezier, docs/higher-order.md).
  int model_degree = 1;
  std::vector<InternalStructure> internal_structures;
  std::vector<ThinStructure> thin_structures;

  PinholeCamera camera;
  std::string camera_file;  // calibration file the camera came from, "" if inline

  std::string video_path;         // recorded (or synthetic) laparoscopic video (resolved)
  std::string ground_truth_path;  // optional evaluation folder (resolved), "" if none

  Material material;

  // Module sections, parsed by their modules with JsonObjectReader (file = path,
  // key path "tracking", ...). Empty objects when absent.
  nlohmann::json tracking = nlohmann::json::object();
  nlohmann::json mechanics = nlohmann::json::object();
  nlohmann::json lifting = nlohmann::json::object();
  nlohmann::json cutting = nlohmann::json::object();
  nlohmann::json render = nlohmann::json::object();
  nlohmann::json output = nlohmann::json::object();

  // `relative` joined to `directory` (unchanged when absolute or empty).
  std::string ResolvePath(const std::string& relative) const;
};

struct ReadSceneOptions {
  // Fail when a referenced file or folder (model, internal structures, camera
  // file, video, ground truth) does not exist. Off for tools that create them.
  bool check_files_exist = true;  // default true
};

// Reads and validates a scene file. Required keys: camera, video, and model
// unless thin_structures is non-empty; unknown top-level keys (and unknown keys
// in model, camera, material, internal_structures, thin_structures) are errors
// naming them. Every error names the file and key.
Scene ReadScene(const std::string& path, const ReadSceneOptions& options = {});
// Same for JSON already parsed; `path` places the scene (relative paths, messages).
Scene ParseScene(const nlohmann::json& json, const std::string& path,
                 const ReadSceneOptions& options = {});

// Sets one option of a module section from "SECTION.KEY=VALUE" (e.g.
// "tracking.redetect_every_frames=5", "cutting.detector=separation"): VALUE is
// read as JSON (number, true/false, null, array, object, quoted string) and as
// a plain string otherwise; "SECTION.A.B=..." sets a nested key. The module
// validates the value when it reads its section. Throws arreg::Error naming
// `where` (e.g. "--set") for a malformed assignment or an unknown section.
void SetSceneOption(Scene* scene, const std::string& assignment, const std::string& where);

// The JSON that ParseScene reads back to an equal scene. Paths are written
// relative to `directory` when they lie under it, otherwise absolute. The camera
// is written inline.
nlohmann::json SceneToJson(const Scene& scene, const std::string& directory);
// Writes SceneToJson(scene, folder of `path`) atomically.
void WriteScene(const std::string& path, const Scene& scene);

}  // namespace arreg
