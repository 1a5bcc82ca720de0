#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "core/error.h"
#include "core/json_reader.h"
#include "core/scene.h"
#include "test_util.h"

namespace arreg {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

void Touch(const std::string& path) {
  fs::create_directories(fs::path(path).parent_path());
  std::ofstream(path) << "x\n";
}

template <typename F>
std::string ErrorMessage(F f) {
  try {
    f();
  } catch (const Error& e) {
    return e.what();
  }
  ADD_FAILURE() << "no arreg::Error thrown";
  return "";
}

// A scene folder with every referenced file present and a full scene JSON.
struct SceneFixture {
  std::string dir;
  json scene;

  explicit SceneFixture(const std::string& name) {
    dir = testing::ScratchDir(name);
    Touch(dir + "/meshes/liver.msh");
    Touch(dir + "/meshes/tumour.obj");
    Touch(dir + "/meshes/vessels.obj");
    Touch(dir + "/video/take1.mp4");
    fs::create_directories(dir + "/gt");
    scene = json::parse(R"({
      "units": "m",
      "description": "synthetic liver",
      "model": {"mesh": "meshes/liver.msh",
                "world_from_model": {"rotation": [[0, -1, 0], [1, 0, 0], [0, 0, 1]],
                                     "translation_mm": [1, 2, 3]}},
      "internal_structures": [
        {"name": "tumour", "mesh": "meshes/tumour.obj", "color": [1, 0, 0], "opacity": 0.8},
        {"name": "vessels", "mesh": "meshes/vessels.obj"}
      ],
      "camera": {"width": 640, "height": 480, "fx": 500, "fy": 500, "cx": 319.5, "cy": 239.5,
                 "distortion": [-0.1, 0.01, 0, 0, 0]},
      "video": "video/take1.mp4",
      "ground_truth": "gt",
      "material": {"youngs_modulus_pa": 3000, "poisson_ratio": 0.49},
      "tracking": {"max_features": 400},
      "mechanics": {"solver": "cg"},
      "lifting": {},
      "cutting": {"tau": 8},
      "render": {"organ_opacity": 0.5},
      "output": {"write_meshes": true}
    })");
  }
  std::string Write(const json& j, const std::string& name = "scene.json") const {
    const std::string path = dir + "/" + name;
    std::ofstream(path) << j.dump(2);
    return path;
  }
};

TEST(Scene, FullSceneParses) {
  SceneFixture f("scene_full");
  const Scene s = ReadScene(f.Write(f.scene));
  EXPECT_EQ(s.units, LengthUnit::kMetre);
  EXPECT_EQ(s.mm_per_unit, 1000.0);
  EXPECT_EQ(s.description, "synthetic liver");
  EXPECT_EQ(s.model_mesh_path, fs::weakly_canonical(f.dir + "/meshes/liver.msh").string());
  EXPECT_LT((s.world_from_model * Eigen::Vector3d(1, 0, 0) - Eigen::Vector3d(1, 3, 3)).norm(),
            1e-12);
  ASSERT_EQ(s.internal_structures.size(), 2u);
  EXPECT_EQ(s.internal_structures[0].name, "tumour");
  EXPECT_EQ(s.internal_structures[0].color_rgb, Eigen::Vector3d(1, 0, 0));
  EXPECT_EQ(s.internal_structures[0].opacity, 0.8);
  EXPECT_EQ(s.internal_structures[1].opacity, 1.0);
  EXPECT_EQ(s.camera.width, 640);
  EXPECT_EQ(s.camera.distortion.k1, -0.1);
  EXPECT_TRUE(s.camera_file.empty());
  EXPECT_EQ(s.video_path, fs::weakly_canonical(f.dir + "/video/take1.mp4").string());
  EXPECT_EQ(s.ground_truth_path, fs::weakly_canonical(f.dir + "/gt").string());
  EXPECT_EQ(s.material.youngs_modulus_pa, 3000);
  EXPECT_EQ(s.material.poisson_ratio, 0.49);
  EXPECT_EQ(s.material.density_kg_m3, Material().density_kg_m3);
  EXPECT_EQ(s.tracking["max_features"], 400);
  EXPECT_EQ(s.cutting["tau"], 8);
  EXPECT_TRUE(s.output["write_meshes"].get<bool>());
  // Module sections are parsed later by their modules with the same file and key path.
  JsonObjectReader mech(s.mechanics, s.path, "mechanics");
  std::string solver;
  mech.Required("solver", &solver);
  EXPECT_EQ(solver, "cg");
}

TEST(Scene, MinimalSceneUsesDefaults) {
  SceneFixture f("scene_minimal");
  const json j = {
      {"model", "meshes/liver.msh"}, {"camera", f.scene["camera"]}, {"video", "video/take1.mp4"}};
  const Scene s = ReadScene(f.Write(j));
  EXPECT_EQ(s.units, LengthUnit::kMillimetre);
  EXPECT_EQ(s.mm_per_unit, 1.0);
  EXPECT_TRUE(s.world_from_model.isApprox(Eigen::Isometry3d::Identity()));
  EXPECT_TRUE(s.internal_structures.empty());
  EXPECT_TRUE(s.ground_truth_path.empty());
  EXPECT_TRUE(s.tracking.is_object() && s.tracking.empty());
  EXPECT_EQ(s.material.poisson_ratio, Material().poisson_ratio);
}

TEST(Scene, EachMissingRequiredKeyIsNamed) {
  SceneFixture f("scene_missing");
  for (const std::string key : {"model", "camera", "video"}) {
    json j = f.scene;
    j.erase(key);
    const std::string path = f.Write(j);
    const std::string msg = ErrorMessage([&] { ReadScene(path); });
    EXPECT_NE(msg.find("scene.json: " + key + ": required key is missing"), std::string::npos)
        << msg;
  }
  json j = f.scene;
  j["model"].erase("mesh");
  const std::string msg = ErrorMessage([&] { ReadScene(f.Write(j)); });
  EXPECT_NE(msg.find("model.mesh: required key is missing"), std::string::npos) << msg;
}

TEST(Scene, UnknownKeysAreNamed) {
  SceneFixture f("scene_unknown");
  json j = f.scene;
  j["tracknig"] = json::object();
  std::string msg = ErrorMessage([&] { ReadScene(f.Write(j)); });
  EXPECT_NE(msg.find("scene.json: tracknig: unknown key"), std::string::npos) << msg;
  EXPECT_NE(msg.find("tracking"), std::string::npos) << msg;

  j = f.scene;
  j["camera"]["fxx"] = 1;
  msg = ErrorMessage([&] { ReadScene(f.Write(j)); });
  EXPECT_NE(msg.find("camera.fxx: unknown key"), std::string::npos) << msg;

  j = f.scene;
  j["internal_structures"][1]["colour"] = {0, 1, 0};
  msg = ErrorMessage([&] { ReadScene(f.Write(j)); });
  EXPECT_NE(msg.find("internal_structures[1].colour: unknown key"), std::string::npos) << msg;

  j = f.scene;
  j["material"]["youngs_modulus"] = 1;
  msg = ErrorMessage([&] { ReadScene(f.Write(j)); });
  EXPECT_NE(msg.find("material.youngs_modulus: unknown key"), std::string::npos) << msg;
}

TEST(Scene, InvalidValuesAreNamed) {
  SceneFixture f("scene_invalid");
  const std::vector<std::pair<std::string, std::string>> cases = {
      {R"({"units": "cm"})", "units: \"cm\" is not one of \"mm\", \"m\""},
      {R"({"video": "video/missing.mp4"})", "video: \"video/missing.mp4\" does not exist"},
      {R"({"ground_truth": "video/take1.mp4"})",
       "ground_truth: \"video/take1.mp4\" is not a directory"},
      {R"({"model": "meshes"})", "model: \"meshes\" is a directory"},
      {R"({"material": {"poisson_ratio": 0.5}})", "material.poisson_ratio: must be in (-1, 0.5)"},
      {R"({"material": {"youngs_modulus_pa": -2}})",
       "material.youngs_modulus_pa: must be positive"},
      {R"({"camera": {"width": 640, "height": 480, "fx": 0, "fy": 500, "cx": 1, "cy": 1}})",
       "camera.fx: focal length must be positive"},
      {R"({"tracking": [1, 2]})", "tracking: expected a JSON object"},
      {R"({"internal_structures": [{"name": "a", "mesh": "meshes/tumour.obj", "color": [255, 0, 0]}]})",
       "internal_structures[0].color: RGB components must be in [0, 1]"},
      {R"({"internal_structures": [{"name": "a", "mesh": "meshes/tumour.obj"},
                                   {"name": "a", "mesh": "meshes/vessels.obj"}]})",
       "internal_structures[1].name: duplicate structure name"},
      {R"({"video": 3})", "video: expected a string"},
  };
  for (const auto& [patch, expected] : cases) {
    json j = f.scene;
    j.merge_patch(json::parse(patch));
    const std::string msg = ErrorMessage([&] { ReadScene(f.Write(j)); });
    EXPECT_NE(msg.find("scene.json: " + expected), std::string::npos) << patch << " -> " << msg;
  }
}

TEST(Scene, RelativePathsResolveAgainstTheSceneFolder) {
  SceneFixture f("scene_paths");
  Scene s;
  s.directory = "/data/scenes/liver";
  EXPECT_EQ(s.ResolvePath("meshes/liver.msh"), "/data/scenes/liver/meshes/liver.msh");
  EXPECT_EQ(s.ResolvePath("../shared/video.mp4"), "/data/scenes/shared/video.mp4");
  EXPECT_EQ(s.ResolvePath("/abs/video.mp4"), "/abs/video.mp4");
  EXPECT_EQ(s.ResolvePath(""), "");

  // A scene in a subfolder referring to files one level up, read through a
  // relative path from another working directory.
  fs::create_directories(f.dir + "/scenes");
  json j = f.scene;
  j["model"]["mesh"] = "../meshes/liver.msh";
  j["internal_structures"] = json::array();
  j["video"] = "../video/take1.mp4";
  j["ground_truth"] = "../gt";
  const std::string path = f.Write(j, "scenes/scene.json");
  const fs::path old_cwd = fs::current_path();
  fs::current_path(f.dir + "/video");
  Scene read;
  EXPECT_NO_THROW(read = ReadScene("../scenes/scene.json"));
  fs::current_path(old_cwd);
  EXPECT_EQ(read.model_mesh_path, fs::weakly_canonical(f.dir + "/meshes/liver.msh").string());
  EXPECT_EQ(read.directory, fs::weakly_canonical(f.dir + "/scenes").string());
  (void)path;
}

TEST(Scene, CameraFromCalibrationFile) {
  SceneFixture f("scene_camera_file");
  std::ofstream(f.dir + "/calib.yaml") << "%YAML:1.0\nimage_width: 320\nimage_height: 240\n"
                                          "camera_matrix: !!opencv-matrix\n  rows: 3\n  cols: 3\n  "
                                          "dt: d\n  data: [300, 0, 160, 0, 300, 120, 0, 0, 1]\n";
  json j = f.scene;
  j["camera"] = "calib.yaml";
  const Scene s = ReadScene(f.Write(j));
  EXPECT_EQ(s.camera.width, 320);
  EXPECT_EQ(s.camera.fx, 300);
  EXPECT_EQ(s.camera_file, fs::weakly_canonical(f.dir + "/calib.yaml").string());

  std::ofstream(f.dir + "/calib.yaml")
      << "image_width: 320\ncamera_matrix: [300, 0, 160, 0, 300, 120, 0, 0, 1]\n";
  const std::string msg = ErrorMessage([&] { ReadScene(f.Write(j)); });
  EXPECT_NE(msg.find("scene.json: camera: in calibration file:"), std::string::npos) << msg;
  EXPECT_NE(msg.find("calib.yaml: image_height"), std::string::npos) << msg;

  j["camera"] = "missing.yaml";
  const std::string msg2 = ErrorMessage([&] { ReadScene(f.Write(j)); });
  EXPECT_NE(msg2.find("camera: \"missing.yaml\" does not exist"), std::string::npos) << msg2;
}

TEST(Scene, WriteThenReadGivesTheSameScene) {
  SceneFixture f("scene_write");
  const Scene original = ReadScene(f.Write(f.scene));
  const std::string out = f.dir + "/written.json";
  WriteScene(out, original);
  // Paths under the scene folder are written relative.
  const json written = ParseJsonFile(out);
  EXPECT_EQ(written["model"]["mesh"], "meshes/liver.msh");
  EXPECT_EQ(written["video"], "video/take1.mp4");
  const Scene s = ReadScene(out);
  EXPECT_EQ(s.model_mesh_path, original.model_mesh_path);
  EXPECT_EQ(s.video_path, original.video_path);
  EXPECT_EQ(s.ground_truth_path, original.ground_truth_path);
  EXPECT_EQ(s.units, original.units);
  EXPECT_TRUE(s.world_from_model.isApprox(original.world_from_model, 1e-14));
  ASSERT_EQ(s.internal_structures.size(), 2u);
  EXPECT_EQ(s.internal_structures[0].mesh_path, original.internal_structures[0].mesh_path);
  EXPECT_EQ(s.camera.distortion.ToVector(), original.camera.distortion.ToVector());
  EXPECT_EQ(s.material.poisson_ratio, 0.49);
  EXPECT_EQ(s.tracking, original.tracking);
  EXPECT_EQ(s.render, original.render);
  // Files outside the folder are written as absolute paths.
  Scene moved = original;
  fs::create_directories(f.dir + "/sub");
  WriteScene(f.dir + "/sub/scene.json", moved);
  const json sub = ParseJsonFile(f.dir + "/sub/scene.json");
  EXPECT_EQ(sub["video"], original.video_path);
  EXPECT_EQ(ReadScene(f.dir + "/sub/scene.json").video_path, original.video_path);
}

TEST(Scene, ModelDegreeParsesRoundTripsAndIsChecked) {
  SceneFixture f("scene_degree");
  EXPECT_EQ(ReadScene(f.Write(f.scene)).model_degree, 1);
  // The default is not written, so degree-1 scenes stay as they were.
  WriteScene(f.dir + "/d1.json", ReadScene(f.Write(f.scene)));
  EXPECT_FALSE(ParseJsonFile(f.dir + "/d1.json")["model"].contains("degree"));
  for (int degree : {2, 3}) {
    json j = f.scene;
    j["model"]["degree"] = degree;
    const Scene s = ReadScene(f.Write(j));
    EXPECT_EQ(s.model_degree, degree);
    WriteScene(f.dir + "/written.json", s);
    EXPECT_EQ(ParseJsonFile(f.dir + "/written.json")["model"]["degree"], degree);
    EXPECT_EQ(ReadScene(f.dir + "/written.json").model_degree, degree);
  }
  const std::vector<std::pair<json, std::string>> cases = {
      {0, "scene.json: model.degree: must be 1, 2 or 3, got 0"},
      {4, "scene.json: model.degree: must be 1, 2 or 3, got 4"},
      {2.5, "scene.json: model.degree: expected an integer"},
      {"2", "scene.json: model.degree: expected an integer"},
  };
  for (const auto& [value, expected] : cases) {
    json j = f.scene;
    j["model"]["degree"] = value;
    const std::string msg = ErrorMessage([&] { ReadScene(f.Write(j)); });
    EXPECT_NE(msg.find(expected), std::string::npos) << value << " -> " << msg;
  }
}

TEST(Scene, FileChecksCanBeTurnedOff) {
  SceneFixture f("scene_nocheck");
  json j = f.scene;
  j["video"] = "not_yet_rendered.mp4";
  ReadSceneOptions options;
  options.check_files_exist = false;
  const Scene s = ReadScene(f.Write(j), options);
  EXPECT_EQ(s.video_path, fs::weakly_canonical(f.dir).string() + "/not_yet_rendered.mp4");
  EXPECT_THROW(ReadScene(f.Write(j)), Error);
}

// A scene with a shell and a vessel beside the organ.
json WithThinStructures(SceneFixture& f) {
  Touch(f.dir + "/meshes/membrane.obj");
  Touch(f.dir + "/meshes/membrane_fine.obj");
  Touch(f.dir + "/meshes/artery.obj");
  json j = f.scene;
  j["thin_structures"] = json::parse(R"([
    {"name": "membrane", "type": "shell", "mesh": "meshes/membrane.obj",
     "visual_mesh": "meshes/membrane_fine.obj", "thickness_mm": 0.5,
     "material": {"youngs_modulus_pa": 20000}, "fixed_vertices": [0, 7],
     "attach": "model", "attach_distance_mm": 2, "color": [0.9, 0.6, 0.5], "opacity": 0.7},
    {"name": "artery", "type": "vessel", "centreline": "meshes/artery.obj", "radius_mm": 1.5}
  ])");
  return j;
}

TEST(Scene, ThinStructuresParse) {
  SceneFixture f("scene_thin");
  const Scene s = ReadScene(f.Write(WithThinStructures(f)));
  ASSERT_EQ(s.thin_structures.size(), 2u);
  const ThinStructure& shell = s.thin_structures[0];
  EXPECT_EQ(shell.name, "membrane");
  EXPECT_EQ(shell.type, ThinStructureType::kShell);
  EXPECT_EQ(shell.mesh_path, fs::weakly_canonical(f.dir + "/meshes/membrane.obj").string());
  EXPECT_EQ(shell.visual_mesh_path,
            fs::weakly_canonical(f.dir + "/meshes/membrane_fine.obj").string());
  EXPECT_TRUE(shell.centreline_path.empty());
  EXPECT_EQ(shell.thickness_mm, 0.5);
  // Material keys absent from the structure's own object come from the top-level material.
  EXPECT_EQ(shell.material.youngs_modulus_pa, 20000);
  EXPECT_EQ(shell.material.poisson_ratio, 0.49);
  EXPECT_EQ(shell.fixed_vertices, (std::vector<int>{0, 7}));
  EXPECT_EQ(shell.attach, ThinAttachment::kModel);
  EXPECT_EQ(shell.attach_distance_mm, 2.0);
  EXPECT_EQ(shell.color, Eigen::Vector3d(0.9, 0.6, 0.5));
  EXPECT_EQ(shell.opacity, 0.7);
  const ThinStructure& vessel = s.thin_structures[1];
  EXPECT_EQ(vessel.type, ThinStructureType::kVessel);
  EXPECT_EQ(vessel.centreline_path, fs::weakly_canonical(f.dir + "/meshes/artery.obj").string());
  EXPECT_EQ(vessel.radius_mm, 1.5);
  EXPECT_EQ(vessel.material.youngs_modulus_pa, 3000);  // the top-level material
  EXPECT_TRUE(vessel.fixed_vertices.empty());
  EXPECT_EQ(vessel.attach, ThinAttachment::kNone);
  EXPECT_EQ(vessel.attach_distance_mm, 1.0);
  EXPECT_EQ(vessel.opacity, 1.0);
}

TEST(Scene, ModelIsOptionalOnlyWithThinStructures) {
  SceneFixture f("scene_thin_only");
  json j = WithThinStructures(f);
  j.erase("model");
  Scene s = ReadScene(f.Write(j));
  EXPECT_TRUE(s.model_mesh_path.empty());
  EXPECT_EQ(s.thin_structures.size(), 2u);
  // A placement without a mesh still places the thin structures.
  j["model"] = json::parse(R"({"world_from_model": {"translation_mm": [0, 0, 50]}})");
  s = ReadScene(f.Write(j));
  EXPECT_TRUE(s.model_mesh_path.empty());
  EXPECT_EQ(s.world_from_model.translation(), Eigen::Vector3d(0, 0, 50));
  // Without thin structures (absent or empty) the model is required.
  j.erase("model");
  j["thin_structures"] = json::array();
  std::string msg = ErrorMessage([&] { ReadScene(f.Write(j)); });
  EXPECT_NE(msg.find("scene.json: model: required key is missing"), std::string::npos) << msg;
  j = f.scene;
  j["model"].erase("mesh");
  msg = ErrorMessage([&] { ReadScene(f.Write(j)); });
  EXPECT_NE(msg.find("model.mesh: required key is missing"), std::string::npos) << msg;
}

TEST(Scene, ThinStructureErrorsNameTheKeyPath) {
  SceneFixture f("scene_thin_errors");
  const json base = WithThinStructures(f);
  struct Case {
    std::string pointer;  // JSON pointer of the value to set
    json value;           // null: erase the key
    std::string expected;
  };
  const std::vector<Case> cases = {
      {"/thin_structures/0/thikness_mm", 1, "thin_structures[0].thikness_mm: unknown key"},
      {"/thin_structures/0/type", "membrane", "thin_structures[0].type"},
      {"/thin_structures/0/thickness_mm", nullptr,
       "thin_structures[0].thickness_mm: required key is missing"},
      {"/thin_structures/0/thickness_mm", 0, "thin_structures[0].thickness_mm"},
      {"/thin_structures/0/mesh", "meshes/none.obj",
       "thin_structures[0].mesh: \"meshes/none.obj\""},
      {"/thin_structures/0/radius_mm", 1, "thin_structures[0].radius_mm: not a key of a shell"},
      {"/thin_structures/1/thickness_mm", 1,
       "thin_structures[1].thickness_mm: not a key of a vessel"},
      {"/thin_structures/1/radius_mm", -1, "thin_structures[1].radius_mm"},
      {"/thin_structures/1/centreline", nullptr,
       "thin_structures[1].centreline: required key is missing"},
      {"/thin_structures/1/name", "tumour", "thin_structures[1].name: duplicate structure name"},
      {"/thin_structures/1/name", "membrane", "thin_structures[1].name: duplicate structure name"},
      {"/thin_structures/0/fixed_vertices", json::array({3, -1}),
       "thin_structures[0].fixed_vertices: vertex indices must be >= 0"},
      {"/thin_structures/0/fixed_vertices", json::array({3, 3}),
       "thin_structures[0].fixed_vertices: vertex 3 is listed twice"},
      {"/thin_structures/0/attach", "organ", "thin_structures[0].attach"},
      {"/thin_structures/0/attach_distance_mm", -0.1, "thin_structures[0].attach_distance_mm"},
      {"/thin_structures/0/color", json::array({255, 0, 0}), "thin_structures[0].color"},
      {"/thin_structures/0/opacity", 2, "thin_structures[0].opacity"},
      {"/thin_structures/0/material/poisson_ratio", 0.5,
       "thin_structures[0].material.poisson_ratio: must be in (-1, 0.5)"},
      {"/thin_structures/0/material/young", 1, "thin_structures[0].material.young: unknown key"},
  };
  for (const Case& c : cases) {
    json j = base;
    const json::json_pointer ptr(c.pointer);
    if (c.value.is_null())
      j[ptr.parent_pointer()].erase(ptr.back());
    else
      j[ptr] = c.value;
    const std::string path = f.Write(j);
    const std::string msg = ErrorMessage([&] { ReadScene(path); });
    EXPECT_NE(msg.find("scene.json: " + c.expected), std::string::npos) << c.pointer << ": " << msg;
    EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
  }
}

TEST(Scene, ThinStructuresRoundTrip) {
  SceneFixture f("scene_thin_write");
  for (const bool with_model : {true, false}) {
    json j = WithThinStructures(f);
    if (!with_model) j["model"].erase("mesh");
    const Scene original = ReadScene(f.Write(j));
    const std::string out = f.dir + "/written.json";
    WriteScene(out, original);
    EXPECT_EQ(ParseJsonFile(out)["thin_structures"][0]["mesh"], "meshes/membrane.obj");
    const Scene s = ReadScene(out);
    EXPECT_EQ(s.model_mesh_path, original.model_mesh_path);
    EXPECT_TRUE(s.world_from_model.isApprox(original.world_from_model, 1e-14));
    ASSERT_EQ(s.thin_structures.size(), original.thin_structures.size());
    for (size_t i = 0; i < s.thin_structures.size(); ++i) {
      const ThinStructure& a = original.thin_structures[i];
      const ThinStructure& b = s.thin_structures[i];
      EXPECT_EQ(b.name, a.name);
      EXPECT_EQ(b.type, a.type);
      EXPECT_EQ(b.mesh_path, a.mesh_path);
      EXPECT_EQ(b.visual_mesh_path, a.visual_mesh_path);
      EXPECT_EQ(b.centreline_path, a.centreline_path);
      EXPECT_EQ(b.thickness_mm, a.thickness_mm);
      EXPECT_EQ(b.radius_mm, a.radius_mm);
      EXPECT_EQ(b.material.youngs_modulus_pa, a.material.youngs_modulus_pa);
      EXPECT_EQ(b.material.poisson_ratio, a.material.poisson_ratio);
      EXPECT_EQ(b.material.density_kg_m3, a.material.density_kg_m3);
      EXPECT_EQ(b.material.rayleigh_mass_per_s, a.material.rayleigh_mass_per_s);
      EXPECT_EQ(b.material.rayleigh_stiffness_s, a.material.rayleigh_stiffness_s);
      EXPECT_EQ(b.fixed_vertices, a.fixed_vertices);
      EXPECT_EQ(b.attach, a.attach);
      EXPECT_EQ(b.attach_distance_mm, a.attach_distance_mm);
      EXPECT_EQ(b.color, a.color);
      EXPECT_EQ(b.opacity, a.opacity);
    }
  }
  // WriteScene refuses a scene with neither a model nor a thin structure.
  Scene empty = ReadScene(f.Write(f.scene));
  empty.model_mesh_path.clear();
  EXPECT_THROW(WriteScene(f.dir + "/empty.json", empty), Error);
  EXPECT_FALSE(fs::exists(f.dir + "/empty.json"));
}

TEST(SceneOption, SetsTypedNestedValuesAndNamesBadAssignments) {
  Scene scene;
  SetSceneOption(&scene, "tracking.redetect_every_frames=5", "--set");
  SetSceneOption(&scene, "cutting.enabled=false", "--set");
  SetSceneOption(&scene, "mechanics.volume_term=linear", "--set");
  SetSceneOption(&scene, "output.a.b=[1,2]", "--set");
  EXPECT_EQ(scene.tracking["redetect_every_frames"], 5);
  EXPECT_EQ(scene.cutting["enabled"], false);
  EXPECT_EQ(scene.mechanics["volume_term"], "linear");
  EXPECT_EQ(scene.output["a"]["b"], nlohmann::json::array({1, 2}));
  SetSceneOption(&scene, "tracking.redetect_every_frames=0", "--set");  // the last one wins
  EXPECT_EQ(scene.tracking["redetect_every_frames"], 0);
  for (const char* bad :
       {"tracking.x", "=1", "nosection.key=1", "tracking=1", "tracking..x=1", "output.a.b.c=1"}) {
    try {
      SetSceneOption(&scene, bad, "--set");
      ADD_FAILURE() << bad << " was accepted";
    } catch (const Error& e) {
      EXPECT_EQ(e.where(), "--set") << bad;
    }
  }
}

}  // namespace
}  // namespace arreg
