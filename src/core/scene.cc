#include "core/scene.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <set>

#include "core/error.h"
#include "core/file_util.h"
#include "core/json_reader.h"

namespace arreg {
namespace fs = std::filesystem;

const char* ThinStructureTypeName(ThinStructureType type) {
  return NameOf(kThinStructureTypeNames, type);
}

const char* ThinAttachmentName(ThinAttachment attachment) {
  return NameOf(kThinAttachmentNames, attachment);
}

namespace {

const std::vector<std::string> kModuleSections = {"tracking", "mechanics", "lifting",
                                                  "cutting",  "render",    "output"};

nlohmann::json* ModuleSection(Scene* scene, const std::string& name) {
  if (name == "tracking") return &scene->tracking;
  if (name == "mechanics") return &scene->mechanics;
  if (name == "lifting") return &scene->lifting;
  if (name == "cutting") return &scene->cutting;
  if (name == "render") return &scene->render;
  return &scene->output;
}

const nlohmann::json& ModuleSection(const Scene& scene, const std::string& name) {
  return *ModuleSection(const_cast<Scene*>(&scene), name);
}

enum class PathKind { kFile, kDirectory, kFileOrDirectory };

// Resolves a path read from the scene and, when asked, checks that it exists.
std::string CheckedPath(const std::string& value, const std::string& file,
                        const std::string& key_path, const Scene& scene, bool check_exists,
                        PathKind kind) {
  if (value.empty()) throw Error(file, key_path, "path is empty");
  std::string resolved = scene.ResolvePath(value);
  if (check_exists) {
    std::error_code ec;
    const fs::file_status status = fs::status(resolved, ec);
    if (!fs::exists(status))
      throw Error(file, key_path,
                  "\"" + value + "\" does not exist (resolved to " + resolved + ")");
    if (kind == PathKind::kDirectory && !fs::is_directory(status))
      throw Error(file, key_path, "\"" + value + "\" is not a directory");
    if (kind == PathKind::kFile && fs::is_directory(status))
      throw Error(file, key_path, "\"" + value + "\" is a directory, expected a file");
  }
  return resolved;
}

// Reads a path-valued key; "" when optional and absent.
std::string ReadPath(JsonObjectReader& reader, const std::string& key, const Scene& scene,
                     bool required, bool check_exists, PathKind kind) {
  std::string value;
  if (required) {
    reader.Required(key, &value);
  } else if (!reader.Optional(key, &value)) {
    return "";
  }
  return CheckedPath(value, reader.file(), reader.KeyPath(key), scene, check_exists, kind);
}

// Reads a material object; absent keys keep the values of `defaults`.
Material ReadMaterial(JsonObjectReader& r, const Material& defaults = Material()) {
  Material m = defaults;
  r.Optional("youngs_modulus_pa", &m.youngs_modulus_pa);
  r.Optional("poisson_ratio", &m.poisson_ratio);
  r.Optional("density_kg_m3", &m.density_kg_m3);
  r.Optional("rayleigh_mass_per_s", &m.rayleigh_mass_per_s);
  r.Optional("rayleigh_stiffness_s", &m.rayleigh_stiffness_s);
  r.Finish();
  m.Check(r.file(), r.path());
  return m;
}

nlohmann::json MaterialToJson(const Material& m) {
  return {{"youngs_modulus_pa", m.youngs_modulus_pa},
          {"poisson_ratio", m.poisson_ratio},
          {"density_kg_m3", m.density_kg_m3},
          {"rayleigh_mass_per_s", m.rayleigh_mass_per_s},
          {"rayleigh_stiffness_s", m.rayleigh_stiffness_s}};
}

// Keys that belong to one type only are errors on the other ("radius_mm" on a shell).
void RejectKeys(JsonObjectReader& r, const std::vector<std::string>& keys,
                const std::string& type) {
  for (const std::string& key : keys)
    if (r.Has(key)) r.Fail(key, "not a key of a " + type + " (see docs/scene-format.md)");
}

ThinStructure ReadThinStructure(JsonObjectReader& r, const Scene& scene, bool check) {
  ThinStructure t;
  r.Required("name", &t.name);
  if (t.name.empty()) r.Fail("name", "must not be empty");
  r.RequiredEnum("type", kThinStructureTypeNames, &t.type);
  if (t.type == ThinStructureType::kShell) {
    RejectKeys(r, {"centreline", "radius_mm"}, "shell");
    t.mesh_path = ReadPath(r, "mesh", scene, true, check, PathKind::kFile);
    t.visual_mesh_path = ReadPath(r, "visual_mesh", scene, false, check, PathKind::kFile);
    r.Required("thickness_mm", &t.thickness_mm);
    r.CheckPositive("thickness_mm", t.thickness_mm);
  } else {
    RejectKeys(r, {"mesh", "visual_mesh", "thickness_mm"}, "vessel");
    t.centreline_path = ReadPath(r, "centreline", scene, true, check, PathKind::kFile);
    r.Required("radius_mm", &t.radius_mm);
    r.CheckPositive("radius_mm", t.radius_mm);
  }
  if (!std::isfinite(t.thickness_mm) || !std::isfinite(t.radius_mm))
    r.Fail(t.type == ThinStructureType::kShell ? "thickness_mm" : "radius_mm", "must be finite");
  t.material = scene.material;
  if (auto material = r.OptionalObject("material"))
    t.material = ReadMaterial(*material, scene.material);
  r.Optional("fixed_vertices", &t.fixed_vertices);
  std::set<int> fixed;
  for (int v : t.fixed_vertices) {
    if (v < 0) r.Fail("fixed_vertices", "vertex indices must be >= 0, got " + std::to_string(v));
    if (!fixed.insert(v).second)
      r.Fail("fixed_vertices", "vertex " + std::to_string(v) + " is listed twice");
  }
  r.OptionalEnum("attach", kThinAttachmentNames, &t.attach);
  r.Optional("attach_distance_mm", &t.attach_distance_mm);
  r.CheckNonNegative("attach_distance_mm", t.attach_distance_mm);
  if (!std::isfinite(t.attach_distance_mm)) r.Fail("attach_distance_mm", "must be finite");
  if (r.Optional("color", &t.color)) {
    for (int i = 0; i < 3; ++i)
      if (!(t.color[i] >= 0.0 && t.color[i] <= 1.0))
        r.Fail("color", "RGB components must be in [0, 1] (divide 0-255 values by 255)");
  }
  r.Optional("opacity", &t.opacity);
  r.CheckInRange("opacity", t.opacity, 0.0, 1.0);
  r.Finish();
  return t;
}

std::string PathForWriting(const std::string& path, const std::string& directory) {
  if (path.empty()) return path;
  const fs::path p = fs::absolute(path).lexically_normal();
  const fs::path dir = fs::absolute(directory.empty() ? "." : directory).lexically_normal();
  const fs::path rel = p.lexically_relative(dir);
  if (rel.empty() || *rel.begin() == "..") return p.string();
  return rel.string();
}

}  // namespace

void Material::Check(const std::string& file, const std::string& prefix) const {
  const auto field = [&](const char* name) { return prefix.empty() ? name : prefix + "." + name; };
  ARREG_CHECK_INPUT(youngs_modulus_pa > 0.0 && std::isfinite(youngs_modulus_pa), file,
                    field("youngs_modulus_pa"), "must be positive, got ", youngs_modulus_pa);
  ARREG_CHECK_INPUT(poisson_ratio > -1.0 && poisson_ratio < 0.5, file, field("poisson_ratio"),
                    "must be in (-1, 0.5), got ", poisson_ratio);
  ARREG_CHECK_INPUT(density_kg_m3 > 0.0 && std::isfinite(density_kg_m3), file,
                    field("density_kg_m3"), "must be positive, got ", density_kg_m3);
  ARREG_CHECK_INPUT(rayleigh_mass_per_s >= 0.0 && std::isfinite(rayleigh_mass_per_s), file,
                    field("rayleigh_mass_per_s"), "must be >= 0, got ", rayleigh_mass_per_s);
  ARREG_CHECK_INPUT(rayleigh_stiffness_s >= 0.0 && std::isfinite(rayleigh_stiffness_s), file,
                    field("rayleigh_stiffness_s"), "must be >= 0, got ", rayleigh_stiffness_s);
}

std::string Scene::ResolvePath(const std::string& relative) const {
  if (relative.empty()) return relative;
  const fs::path p(relative);
  if (p.is_absolute() || directory.empty()) return p.lexically_normal().string();
  return (fs::path(directory) / p).lexically_normal().string();
}

Scene ParseScene(const nlohmann::json& json, const std::string& path,
                 const ReadSceneOptions& options) {
  Scene scene;
  scene.path = path;
  scene.directory = path.empty()
                        ? fs::current_path().string()
                        : fs::absolute(fs::path(path)).parent_path().lexically_normal().string();
  const bool check = options.check_files_exist;

  JsonObjectReader root(json, path, "");
  if (root.OptionalEnum("units", kLengthUnitNames, &scene.units)) {
    scene.mm_per_unit = scene.units == LengthUnit::kMetre ? 1000.0 : 1.0;
  }
  root.Optional("description", &scene.description);

  // The top-level material first: thin structures default to it.
  if (auto material = root.OptionalObject("material")) scene.material = ReadMaterial(*material);

  // model: "mesh path" or {"mesh": ..., "world_from_model": {...}}; optional when the
  // scene has thin structures (a membrane-only scene).
  const bool has_thin = root.Has("thin_structures") && !json["thin_structures"].empty();
  if (!has_thin || root.Has("model")) {
    nlohmann::json model;
    if (!root.Has("model"))
      throw Error(path, "model",
                  "required key is missing (a scene needs a model or at least one thin "
                  "structure)");
    root.Required("model", &model);
    if (model.is_string()) {
      scene.model_mesh_path =
          CheckedPath(model.get<std::string>(), path, "model", scene, check, PathKind::kFile);
    } else {
      JsonObjectReader r = root.Object("model");
      scene.model_mesh_path = ReadPath(r, "mesh", scene, !has_thin, check, PathKind::kFile);
      if (auto placement = r.OptionalObject("world_from_model"))
        scene.world_from_model = ReadRigidTransformJson(*placement);
      if (r.Optional("degree", &scene.model_degree)) {
        if (scene.model_degree < 1 || scene.model_degree > 3)
          r.Fail("degree", "must be 1, 2 or 3, got " + std::to_string(scene.model_degree));
        if (scene.model_mesh_path.empty())
          r.Fail("degree", "needs a model mesh (the degree is that of its tetrahedra)");
      }
      r.Finish();
    }
  }

  std::set<std::string> names;
  for (JsonObjectReader& r : root.ObjectArray("internal_structures")) {
    InternalStructure s;
    r.Required("name", &s.name);
    if (s.name.empty()) r.Fail("name", "must not be empty");
    if (!names.insert(s.name).second) r.Fail("name", "duplicate structure name \"" + s.name + "\"");
    s.mesh_path = ReadPath(r, "mesh", scene, true, check, PathKind::kFile);
    if (r.Optional("color", &s.color_rgb)) {
      for (int i = 0; i < 3; ++i)
        if (!(s.color_rgb[i] >= 0.0 && s.color_rgb[i] <= 1.0))
          r.Fail("color", "RGB components must be in [0, 1] (divide 0-255 values by 255)");
    }
    r.Optional("opacity", &s.opacity);
    r.CheckInRange("opacity", s.opacity, 0.0, 1.0);
    r.Finish();
    scene.internal_structures.push_back(std::move(s));
  }
  for (JsonObjectReader& r : root.ObjectArray("thin_structures")) {
    ThinStructure t = ReadThinStructure(r, scene, check);
    if (!names.insert(t.name).second) r.Fail("name", "duplicate structure name \"" + t.name + "\"");
    scene.thin_structures.push_back(std::move(t));
  }

  // camera: inline object or calibration file path.
  {
    nlohmann::json camera;
    root.Required("camera", &camera);
    if (camera.is_string()) {
      scene.camera_file = ReadPath(root, "camera", scene, true, true, PathKind::kFile);
      try {
        scene.camera = ReadCameraFile(scene.camera_file);
      } catch (const Error& e) {
        throw Error(path, "camera", std::string("in calibration file: ") + e.what());
      }
    } else {
      JsonObjectReader r = root.Object("camera");
      scene.camera = ReadCameraJson(r);
    }
  }

  // Image folders are accepted as videos too (tracking's VideoReader reads them).
  scene.video_path = ReadPath(root, "video", scene, true, check, PathKind::kFileOrDirectory);
  scene.ground_truth_path =
      ReadPath(root, "ground_truth", scene, false, check, PathKind::kDirectory);

  for (const std::string& name : kModuleSections) {
    if (auto section = root.OptionalObject(name)) *ModuleSection(&scene, name) = section->json();
  }
  root.Finish();
  return scene;
}

void SetSceneOption(Scene* scene, const std::string& assignment, const std::string& where) {
  const size_t eq = assignment.find('=');
  const std::string key = assignment.substr(0, eq);
  if (eq == std::string::npos || key.empty())
    throw Error("", where, "expected SECTION.KEY=VALUE, got \"" + assignment + "\"");
  std::vector<std::string> parts;
  for (size_t begin = 0;;) {
    const size_t dot = key.find('.', begin);
    parts.push_back(key.substr(begin, dot == std::string::npos ? std::string::npos : dot - begin));
    if (parts.back().empty()) throw Error("", where, "empty key component in \"" + key + "\"");
    if (dot == std::string::npos) break;
    begin = dot + 1;
  }
  if (parts.size() < 2 ||
      std::find(kModuleSections.begin(), kModuleSections.end(), parts[0]) == kModuleSections.end())
    throw Error("", where,
                "\"" + key +
                    "\" must be SECTION.KEY with SECTION one of tracking, mechanics, "
                    "lifting, cutting, render, output");
  const std::string text = assignment.substr(eq + 1);
  nlohmann::json value = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (value.is_discarded()) value = text;
  nlohmann::json* node = ModuleSection(scene, parts[0]);
  for (size_t i = 1; i + 1 < parts.size(); ++i) {
    nlohmann::json& child = (*node)[parts[i]];
    if (!child.is_object() && !child.is_null())
      throw Error("", where, "\"" + parts[i] + "\" in \"" + key + "\" is not an object");
    node = &child;
  }
  (*node)[parts.back()] = value;
}

Scene ReadScene(const std::string& path, const ReadSceneOptions& options) {
  const nlohmann::json json = ParseJsonFile(path);
  return ParseScene(json, path, options);
}

nlohmann::json SceneToJson(const Scene& scene, const std::string& directory) {
  nlohmann::json j;
  j["units"] = NameOf(kLengthUnitNames, scene.units);
  if (!scene.description.empty()) j["description"] = scene.description;
  const bool identity = scene.world_from_model.matrix() == Eigen::Matrix4d::Identity();
  if (!scene.model_mesh_path.empty()) {
    nlohmann::json model = {{"mesh", PathForWriting(scene.model_mesh_path, directory)}};
    if (!identity) model["world_from_model"] = RigidTransformToJson(scene.world_from_model);
    if (scene.model_degree != 1) model["degree"] = scene.model_degree;
    j["model"] = model;
  } else if (!identity) {
    // Without a model mesh the placement still applies to the thin structures.
    j["model"] = {{"world_from_model", RigidTransformToJson(scene.world_from_model)}};
  }
  if (!scene.internal_structures.empty()) {
    nlohmann::json list = nlohmann::json::array();
    for (const InternalStructure& s : scene.internal_structures) {
      list.push_back({{"name", s.name},
                      {"mesh", PathForWriting(s.mesh_path, directory)},
                      {"color", {s.color_rgb.x(), s.color_rgb.y(), s.color_rgb.z()}},
                      {"opacity", s.opacity}});
    }
    j["internal_structures"] = list;
  }
  if (!scene.thin_structures.empty()) {
    nlohmann::json list = nlohmann::json::array();
    for (const ThinStructure& t : scene.thin_structures) {
      nlohmann::json o = {{"name", t.name}, {"type", ThinStructureTypeName(t.type)}};
      if (t.type == ThinStructureType::kShell) {
        o["mesh"] = PathForWriting(t.mesh_path, directory);
        if (!t.visual_mesh_path.empty())
          o["visual_mesh"] = PathForWriting(t.visual_mesh_path, directory);
        o["thickness_mm"] = t.thickness_mm;
      } else {
        o["centreline"] = PathForWriting(t.centreline_path, directory);
        o["radius_mm"] = t.radius_mm;
      }
      o["material"] = MaterialToJson(t.material);
      if (!t.fixed_vertices.empty()) o["fixed_vertices"] = t.fixed_vertices;
      o["attach"] = ThinAttachmentName(t.attach);
      o["attach_distance_mm"] = t.attach_distance_mm;
      o["color"] = {t.color.x(), t.color.y(), t.color.z()};
      o["opacity"] = t.opacity;
      list.push_back(o);
    }
    j["thin_structures"] = list;
  }
  j["camera"] = CameraToJson(scene.camera);
  j["video"] = PathForWriting(scene.video_path, directory);
  if (!scene.ground_truth_path.empty())
    j["ground_truth"] = PathForWriting(scene.ground_truth_path, directory);
  j["material"] = MaterialToJson(scene.material);
  for (const std::string& name : kModuleSections) {
    const nlohmann::json& section = ModuleSection(scene, name);
    if (!section.is_null() && !section.empty()) j[name] = section;
  }
  return j;
}

void WriteScene(const std::string& path, const Scene& scene) {
  ARREG_CHECK_INPUT(!scene.model_mesh_path.empty() || !scene.thin_structures.empty(), path,
                    "model.mesh", "scene has neither a model mesh nor a thin structure");
  for (size_t i = 0; i < scene.thin_structures.size(); ++i) {
    const ThinStructure& t = scene.thin_structures[i];
    const std::string key = "thin_structures[" + std::to_string(i) + "]";
    ARREG_CHECK_INPUT(!t.name.empty(), path, key + ".name", "must not be empty");
    const bool shell = t.type == ThinStructureType::kShell;
    ARREG_CHECK_INPUT(!(shell ? t.mesh_path : t.centreline_path).empty(), path,
                      key + (shell ? ".mesh" : ".centreline"), "path is empty");
    const double size = shell ? t.thickness_mm : t.radius_mm;
    ARREG_CHECK_INPUT(size > 0.0 && std::isfinite(size), path,
                      key + (shell ? ".thickness_mm" : ".radius_mm"), "must be positive, got ",
                      size);
    t.material.Check(path, key + ".material");
  }
  ARREG_CHECK_INPUT(!scene.video_path.empty(), path, "video", "scene has no video path");
  scene.camera.Check(path, "camera");
  scene.material.Check(path, "material");
  const std::string directory = fs::absolute(fs::path(path)).parent_path().string();
  const std::string text = SceneToJson(scene, directory).dump(2) + "\n";
  WriteFileAtomic(path, [&](std::ostream& os) { os << text; });
}

}  // namespace arreg
