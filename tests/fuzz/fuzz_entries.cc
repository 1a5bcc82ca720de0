#include "fuzz/fuzz_entries.h"

#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <stdexcept>

#include "core/camera.h"
#include "core/error.h"
#include "core/mesh_generators.h"
#include "core/mesh_io.h"
#include "core/mesh_ops.h"
#include "core/opencv_yaml.h"
#include "core/run_records.h"
#include "core/scene.h"
#include "tracking/video_io.h"

namespace arreg::fuzz {
namespace {

void ReadTet(const std::string& path) { ReadTetMesh(path); }

// Mesh formats: everything the file holds, then the narrowing the tools do
// (a tetrahedral model or a surface), each of which may reject the file.
void ReadMesh(const std::string& path) {
  ReadMeshFile(path);
  try {
    ReadTet(path);
  } catch (const Error&) {
  }
  ReadSurfaceMesh(path);
}

void ReadSceneFile(const std::string& path) {
  ReadSceneOptions options;
  options.check_files_exist = false;  // the fuzzed scene names files that do not exist
  ReadScene(path, options);
}

void ReadCamera(const std::string& path) { ReadCameraFile(path); }

void ReadYaml(const std::string& path) { ParseOpenCvYamlFile(path); }

// A run folder's records and a ground truth's meta.json, as `arreg eval` reads them.
void ReadRun(const std::string& path) { ReadRunSummary(path); }
void ReadFrames(const std::string& path) { ReadFrameRecords(path, 3); }
void ReadMeta(const std::string& path) { ReadGroundTruthMeta(path); }

// A container and stream read to the end, as `arreg run` does.
void ReadVideo(const std::string& path) {
  VideoReader reader;
  reader.Open(path);
  cv::Mat frame;
  for (int i = 0; i < 64 && reader.Read(&frame); ++i) {
  }
}

std::string TempPath(const Target& target) {
  const char* dir = std::getenv("TMPDIR");
  const std::filesystem::path base = dir != nullptr && *dir != '\0' ? dir : "/tmp";
  return (base /
          ("arreg-fuzz-" + std::to_string(::getpid()) + "-" + target.name + target.extension))
      .string();
}

}  // namespace

const std::vector<Target>& Targets() {
  static const std::vector<Target> targets = {
      {"msh", ".msh", ReadMesh},        {"vtk", ".vtk", ReadMesh},
      {"obj", ".obj", ReadMesh},        {"stl", ".stl", ReadMesh},
      {"off", ".off", ReadMesh},        {"scene", ".json", ReadSceneFile},
      {"camera", ".json", ReadCamera},  {"yaml", ".yaml", ReadYaml},
      {"video", ".mp4", ReadVideo},     {"run", ".json", ReadRun},
      {"frames", ".jsonl", ReadFrames}, {"meta", ".json", ReadMeta},
  };
  return targets;
}

const Target& FindTarget(const std::string& name) {
  for (const Target& t : Targets())
    if (t.name == name) return t;
  throw std::invalid_argument("unknown fuzz target '" + name + "'");
}

int RunOne(const Target& target, const uint8_t* data, size_t size) {
  const std::string path = TempPath(target);
  {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  }
  int accepted = 0;
  try {
    target.read(path);
    accepted = 1;
  } catch (const Error&) {
  }
  std::remove(path.c_str());
  return accepted;
}

int WriteSeeds(const Target& target, const std::string& dir) {
  std::filesystem::create_directories(dir);
  int count = 0;
  const auto text = [&](const std::string& name, const std::string& content) {
    std::ofstream(std::filesystem::path(dir) / name, std::ios::binary) << content;
    ++count;
  };
  const auto seed_path = [&](const std::string& name) {
    ++count;
    return (std::filesystem::path(dir) / name).string();
  };
  if (target.name == "msh" || target.name == "vtk" || target.name == "obj" ||
      target.name == "stl" || target.name == "off") {
    const TetMesh tets = MakeBoxTetMesh({2, 1, 1}, {2, 1, 1});
    const SurfaceMesh surface = ExtractBoundary(tets);
    MeshWriteOptions ascii, binary, v41;
    binary.binary = true;
    v41.msh_version = MshVersion::kV41;
    ascii.precision = binary.precision = v41.precision = 6;  // short numbers leave room to mutate
    const std::string& ext = target.extension;
    if (ext == ".msh" || ext == ".vtk") {
      WriteTetMesh(seed_path("tets-ascii" + ext), tets, ascii);
      WriteTetMesh(seed_path(ext == ".msh" ? "tets-v41.msh" : "tets-binary.vtk"), tets,
                   ext == ".msh" ? v41 : binary);
    }
    WriteSurfaceMesh(seed_path("surface-ascii" + ext), surface, ascii);
    if (ext == ".vtk" || ext == ".stl")
      WriteSurfaceMesh(seed_path("surface-binary" + ext), surface, binary);
    if (ext == ".msh")
      text("v1.msh",
           "$NOD\n4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n$ENDNOD\n$ELM\n1\n1 4 1 1 4 1 2 3 "
           "4\n$ENDELM\n");
    if (ext == ".obj")
      text("quads-uv.obj",
           "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
           "vn 0 0 1\nf 1/1/1 2/2/1 3/3/1 4/4/1\nf -4 -2 -1\n");
  } else if (target.name == "scene") {
    text("minimal.json", R"({"model": "m.msh", "camera": "c.yaml", "video": "v.mp4"})");
    text("full.json", R"({"units": "m", "description": "d", "model": {"mesh": "m.msh",
  "world_from_model": {"rotation": [1, 0, 0, 0], "translation_mm": [0, 0, 120]}},
  "internal_structures": [{"name": "t", "mesh": "t.obj", "color": [1, 0, 0], "opacity": 0.5}],
  "camera": {"width": 640, "height": 480, "fx": 500, "fy": 500, "cx": 320, "cy": 240,
             "distortion": [-0.1, 0.01, 0, 0, 0]},
  "video": "v.mp4", "ground_truth": "gt",
  "material": {"youngs_modulus_pa": 4500, "poisson_ratio": 0.45, "density_kg_m3": 1060,
               "rayleigh_mass_per_s": 0.1, "rayleigh_stiffness_s": 0.01},
  /* comment */ "tracking": {"max_features": 400}, "cutting": {}, "output": {}})");
  } else if (target.name == "camera" || target.name == "yaml") {
    PinholeCamera camera;
    camera.width = 640;
    camera.height = 480;
    camera.fx = camera.fy = 500;
    camera.cx = 320;
    camera.cy = 240;
    if (target.name == "camera") WriteCameraJson(seed_path("camera.json"), camera);
    text("camera.yaml",
         "%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\n"
         "camera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n"
         "   data: [ 500., 0., 320., 0., 500., 240., 0., 0., 1. ]\n"
         "distortion_coefficients: !!opencv-matrix\n   rows: 1\n   cols: 5\n   dt: d\n"
         "   data: [ -0.1, 0.01, 0., 0., 0. ]\n");
    text("ros.yaml",
         "image_width: 640\nimage_height: 480\ncamera_name: c\ncamera_matrix:\n  rows: 3\n"
         "  cols: 3\n  data: [500, 0, 320, 0, 500, 240, 0, 0, 1]\ndistortion_model: plumb_bob\n"
         "distortion_coefficients:\n  rows: 1\n  cols: 5\n  data: [0, 0, 0, 0, 0]\n");
  } else if (target.name == "run") {
    text("run.json", R"({"version": "0.1.0", "scene": "s.json", "camera": {"width": 640,
  "height": 480, "fx": 500, "fy": 500, "cx": 320, "cy": 240}, "frames": 3, "topology": true,
  "interrupted": false, "thin_structures": ["membrane", "vessel"], "cut_events": 0})");
  } else if (target.name == "frames") {
    text("frames.jsonl",
         "{\"frame\": 0, \"feature_error_mean_mm\": 0.5, \"feature_error_max_mm\": 1.5, "
         "\"cut_events\": [], \"ms\": {\"track\": 1.0}}\n"
         "{\"frame\": 1, \"feature_error_mean_mm\": null, \"feature_error_max_mm\": null}\n\n"
         "{\"frame\": 2, \"feature_error_mean_mm\": 1e-3, \"feature_error_max_mm\": 2}\n");
  } else if (target.name == "meta") {
    text("meta.json", R"({"frames": 50, "width": 640, "height": 512, "surface_every_k": 10})");
  }
  // Video seeds come from scripts/fuzz (the ffmpeg command line encodes them).
  return count;
}

}  // namespace arreg::fuzz
