// Hand-built run and ground-truth folders for the `arreg eval` tests: real OBJ,
// PNG and JSON files whose metrics are known in closed form.
#pragma once

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <stdexcept>
#include <string>

#include <nlohmann/json.hpp>

#include "core/camera.h"
#include "test_util.h"

namespace arreg::eval::fixtures {

namespace fs = std::filesystem;

inline void WriteText(const fs::path& path, const std::string& text) {
  fs::create_directories(path.parent_path());
  std::ofstream(path) << text;
}

// Square [x0, x0 + side] x [y0, y0 + side] at depth z as OBJ text (object `name`,
// vertex indices starting after `offset` vertices).
inline std::string SquareObj(double x0, double y0, double z, double side, int offset = 0,
                             const std::string& name = "") {
  std::ostringstream os;
  if (!name.empty()) os << "o " << name << "\n";
  os << "v " << x0 << ' ' << y0 << ' ' << z << "\nv " << x0 + side << ' ' << y0 << ' ' << z
     << "\nv " << x0 + side << ' ' << y0 + side << ' ' << z << "\nv " << x0 << ' ' << y0 + side
     << ' ' << z << "\n";
  os << "f " << offset + 1 << ' ' << offset + 2 << ' ' << offset + 3 << "\nf " << offset + 1 << ' '
     << offset + 3 << ' ' << offset + 4 << "\n";
  return os.str();
}

inline std::string Name(int frame) {
  char s[16];
  std::snprintf(s, sizeof(s), "%06d", frame);
  return s;
}

inline void WriteMask(const fs::path& path, const cv::Rect& inside) {
  cv::Mat mask = cv::Mat::zeros(120, 160, CV_8U);
  mask(inside).setTo(255);
  fs::create_directories(path.parent_path());
  if (!cv::imwrite(path.string(), mask)) throw std::runtime_error("cannot write " + path.string());
}

inline PinholeCamera TestCamera() {
  PinholeCamera c;
  c.width = 160, c.height = 120;
  c.fx = c.fy = 200;
  c.cx = 79.5, c.cy = 59.5;
  return c;
}

// Ground truth: 3 frames, surfaces at 0 and 2. The camera sees the 20 x 20 mm
// model square at 100 mm as pixels 60..99 x 40..79 (40 x 40).
//   frame 0: mask = that square                  -> Dice 1
//   frame 1: mask shifted 10 px right            -> Dice 2*1200/3200 = 0.75
//   frame 2: mask 30 px wide, truth 3 mm farther -> Dice 2*1200/2800 = 6/7, Hausdorff 3
// Internal structures (two squares in one OBJ) coincide at frame 0 and are
// 0.5 mm apart at frame 2.
inline void MakeGroundTruth(const fs::path& gt) {
  WriteText(gt / "meta.json",
            R"({"units": "mm", "frames": 3, "surface_every_k": 2, "width": 160, "height": 120,
                "seed": 1, "scenario": "test", "version": 1})");
  WriteMask(gt / "masks" / (Name(0) + ".png"), cv::Rect(60, 40, 40, 40));
  WriteMask(gt / "masks" / (Name(1) + ".png"), cv::Rect(70, 40, 40, 40));
  WriteMask(gt / "masks" / (Name(2) + ".png"), cv::Rect(60, 40, 30, 40));
  WriteText(gt / "surface" / (Name(0) + ".obj"), SquareObj(-10, -10, 100, 20));
  WriteText(gt / "surface" / (Name(2) + ".obj"), SquareObj(-10, -10, 103, 20));
  WriteText(gt / "internal" / (Name(0) + ".obj"),
            SquareObj(-5, -5, 110, 4, 0, "vessel") + SquareObj(2, 2, 110, 3, 4, "tumour"));
  WriteText(gt / "internal" / (Name(2) + ".obj"),
            SquareObj(-5, -5, 110.5, 4, 0, "vessel") + SquareObj(2, 2, 110.5, 3, 4, "tumour"));
  WriteText(gt / "cut.json", R"({"cut": null})");
}

// A run that saved its surface at every frame; the model does not move.
inline void MakeRun(const fs::path& run, bool topology) {
  nlohmann::json j;
  j["version"] = 1;
  j["scene"] = "scene.json";
  j["camera"] = CameraToJson(TestCamera());
  j["frames"] = 3;
  j["options"] = nlohmann::json::object();
  j["totals"] = nlohmann::json::object();
  j["topology"] = topology;
  j["interrupted"] = false;
  WriteText(run / "run.json", j.dump(2));
  WriteText(run / "frames.jsonl",
            "{\"frame\": 0, \"feature_error_mean_mm\": 1.0, \"feature_error_max_mm\": 2.0}\n"
            "{\"frame\": 1, \"feature_error_mean_mm\": 2.0, \"feature_error_max_mm\": 4.0}\n"
            "{\"frame\": 2, \"feature_error_mean_mm\": null, \"feature_error_max_mm\": null}\n");
  for (int f = 0; f < 3; ++f)
    WriteText(run / "surface" / (Name(f) + ".obj"), SquareObj(-10, -10, 100, 20));
  for (int f : {0, 2})
    WriteText(run / "internal" / (Name(f) + ".obj"),
              SquareObj(-5, -5, 110, 4, 0, "vessel") + SquareObj(2, 2, 110, 3, 4, "tumour"));
}

struct Folders {
  fs::path root, gt, run, baseline, out;
};

inline Folders MakeFolders(const std::string& name) {
  Folders f;
  f.root = ::arreg::testing::ScratchDir(name);
  f.gt = f.root / "gt";
  f.run = f.root / "run";
  f.baseline = f.root / "run_no_topology";
  f.out = f.root / "report";
  MakeGroundTruth(f.gt);
  MakeRun(f.run, true);
  MakeRun(f.baseline, false);
  return f;
}

}  // namespace arreg::eval::fixtures
