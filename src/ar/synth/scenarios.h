// The synthetic benchmark scenarios (thesis experiments 7.7, 7.8): shapes,
// meshes, grip motions, cuts and camera of each, built from a few options.
#pragma once

#include <Eigen/Core>
#include <cstdint>
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
// displacement (mm) that follows a timeline, or by `motion` when it is set.
struct Grip {
  std::string name;
  std::function<bool(const Eigen::Vector3d& rest_mm)> selects;
  Timeline displacement_mm;
  // Optional rigid motion (rest position, normalised time) -> position (mm), for grips that
  // also rotate; overrides displacement_mm.
  std::function<Eigen::Vector3d(const Eigen::Vector3d& rest_mm, double t)> motion;
  Eigen::Vector3d Target(const Eigen::Vector3d& rest_mm, double t) const {
    return motion ? motion(rest_mm, t) : Eigen::Vector3d(rest_mm + displacement_mm.At(t));
  }
};

// A membrane: the truth is a thin slab of tetrahedra with a vertex layer on its mid-plane
// z = mid_z (rest); the registration gets a shell on a coarse mid-surface triangle mesh.
struct MembraneSpec {
  std::string name = "membrane";
  double thickness_mm = 1.5;
  double mid_z_mm = 0.75;                 // rest z of the mid-surface vertex layer
  SurfaceMesh model_mid_surface;          // coarse shell mesh given to the registration (world)
  std::vector<int> model_fixed_vertices;  // its vertices on the supports
};

// A vessel tree embedded in the organ, following the truth's tetrahedra.
struct VesselSpec {
  std::string name = "vessel";
  double radius_mm = 1.5;
  RowMatX3d nodes;                          // (#N x 3) centreline nodes at rest (mm), ~1 mm apart
  std::vector<std::vector<int>> polylines;  // branches over `nodes` (a tree: shared ids)
  double model_spacing_mm = 5.0;            // node spacing of the centreline given to the run
};

// Tear by stress: a notch (the CutSchedule's first notch_mm, open from frame 0) whose
// extension advances one step whenever the mean largest principal Cauchy stress of the
// tetrahedra ahead of the tip exceeds the strength (docs/synth.md).
struct TearSpec {
  double notch_mm = 8;             // notch length (mm), along the cut path from the free edge
  double strength_pa = 0;          // tensile strength (Pa)
  double step_mm = 2.5;            // advance per step (mm), one truth cell
  double max_steps_per_frame = 1;  // bounded crack speed (steps per frame)
  double max_length_mm = 0;        // the tear stops here (mm along the path)
  double process_zone_mm = 5;      // stress averaged over tets within this radius ahead of the tip
  Eigen::Vector3d notch_tip;       // rest position of the notch tip (mm)
  Eigen::Vector3d notch_dir;       // rest direction of the notch (unit, in the sheet plane)
  Eigen::Vector3d plane_normal = Eigen::Vector3d::UnitZ();  // the sheet's normal at rest
};

struct CutSchedule {
  CutSurfaceSpec surface;
  ProgressiveCutOptions options;  // snapping of the truth mesh onto the cut surface
  Timeline advance_mm;            // x component: how far the cut has advanced at time t (mm)
  double length_mm = 0;           // final length of the cut along its path (mm)
  bool precut = false;            // already open at frame 0
  std::string description;
};

struct ScenarioOptions {
  double fine_cell_mm = 5.0;    // grid spacing of the band truth meshes in-plane (mm), default 5
                                // (membranes: half of it)
  double kidney_cell_mm = 2.6;  // circumradius bound of the kidney truth mesh (mm), default 2.6
  // Grid spacing of the membranes' model shell (the registration's mid-surface, mm), in [2, 10];
  // default 5.
  double membrane_cell_mm = 5.0;
  double amplitude = 1.0;  // scales every grip motion (1 = the scenario's nominal speed/stretch)
  int width = 640, height = 512;  // image size (px)
  // Focal length relative to the scenarios' 60-degree horizontal field of view, from the same
  // camera position (2 = twice the focal length, the organ covers 4x the pixels). Default 1.
  double zoom = 1.0;
  uint64_t seed = 1;  // membrane sizes, pull and cut position; vessel tree (others ignore it)
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
  bool has_model = true;         // false: a scene of thin structures only (no tet model)
  std::optional<MembraneSpec> membrane;
  std::optional<VesselSpec> vessel;
  // With a tear, `cut` holds the path (level set, progress) and the notch; advance_mm is unused.
  std::optional<TearSpec> tear;
};

struct ScenarioInfo {
  std::string name;
  std::string description;
};
const std::vector<ScenarioInfo>& ListScenarios();
// The path of a tear (TearSpec): the notch from the free edge to notch_tip, then a straight
// crack from the tip along `crack_dir` (rest, in the sheet plane) up to max_length_mm along the
// whole path. Progress: distance along the path from the free edge.
CutSurfaceSpec TearPath(const TearSpec& tear, const Eigen::Vector3d& crack_dir);

// Throws arreg::Error naming `name` when it is not a scenario.
Scenario BuildScenario(const std::string& name, const ScenarioOptions& options);

}  // namespace arreg::synth
