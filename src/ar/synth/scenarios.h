// The synthetic benchmark scenarios (thesis experiments 7.7, 7.8): shapes,
// meshes, grip motions, cuts and camera of each, built from a few options.
#pragma once

#include <Eigen/Core>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "ar/synth/neo_hookean.h"
#include "ar/synth/progressive_cut.h"
#include "ar/synth/shapes.h"
#include "core/camera.h"

namespace arreg::synth {

// Piecewise-linear function of normalised time t in [0, 1] (constant outside the keys).
struct Timeline {
  std::vector<std::pair<double, Eigen::Vector3d>> keys;  // (t, value), t increasing
  Eigen::Vector3d At(double t) const;
};

// A set of vertices held by an instrument or a fixation, moved rigidly by a
// displacement (mm) that follows a timeline.
struct Grip {
  std::string name;
  std::function<bool(const Eigen::Vector3d& rest_mm)> selects;
  Timeline displacement_mm;
};

struct CutSchedule {
  CutSurfaceSpec surface;
  Timeline advance_mm;   // x component: how far the cut has advanced at time t (mm)
  double length_mm = 0;  // final length of the cut along its path (mm)
  bool precut = false;   // already open at frame 0
  std::string description;
};

struct ScenarioOptions {
  double fine_cell_mm = 5.0;    // grid spacing of the band truth meshes in-plane (mm), default 5
  double kidney_cell_mm = 2.6;  // circumradius bound of the kidney truth mesh (mm), default 2.6
  double amplitude = 1.0;  // scales every grip motion (1 = the scenario's nominal speed/stretch)
  int width = 640, height = 512;  // image size (px)
  // Focal length relative to the scenarios' 60-degree horizontal field of view, from the same
  // camera position (2 = twice the focal length, the organ covers 4x the pixels). Default 1.
  double zoom = 1.0;
  void Check() const;
};

struct Scenario {
  std::string name;
  std::string description;
  LabeledTetMesh truth;  // fine mesh (labels 1 organ, 2 internal structure)
  LabeledTetMesh model;  // coarse mesh given to the registration (uncut, frame-0 pose)
  std::vector<Grip> grips;
  std::optional<CutSchedule> cut;
  NeoHookeanMaterial truth_material;
  double model_youngs_modulus_pa = 0;  // default parameter written to scene.json
  double model_poisson_ratio = 0.45;
  PinholeCamera camera;
  bool has_internal_structure = false;
  double nominal_stretch = 1.0;  // largest length ratio the grips impose (for reports)
};

struct ScenarioInfo {
  std::string name;
  std::string description;
};
const std::vector<ScenarioInfo>& ListScenarios();
// Throws arreg::Error naming `name` when it is not a scenario.
Scenario BuildScenario(const std::string& name, const ScenarioOptions& options);

}  // namespace arreg::synth
