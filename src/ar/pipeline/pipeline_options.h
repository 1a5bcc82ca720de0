// Options of the registration pipeline (`arreg run`), one struct per stage, read from the
// scene's module sections (tracking, lifting, mechanics, cutting, render, output) with checks.
#pragma once

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "ar/lift/lifting.h"
#include "core/enum_names.h"
#include "core/mesh.h"
#include "core/scene.h"
#include "cutting/detection.h"
#include "cutting/tet_cutter.h"
#include "mechanics/linear_solver.h"
#include "mechanics/tet_element.h"
#include "tracking/tracker.h"

namespace arreg::pipeline {

// Mechanics stage: zero-length springs from embedded features to lifted targets and one
// implicit Euler step per frame (thesis 7.4.3).
struct MechanicsStageOptions {
  // Relative stiffness kappa of the feature springs (dimensionless, > 0): the springs' total
  // stiffness N x k over the model's elastic stiffness scale E x V / A (E Young's modulus, V
  // rest volume, A area of the surface facing the camera at frame 0, so V / A is the depth of
  // tissue under the seen surface: a slab's thickness, a compact organ's size), i.e. each of
  // the N springs attached at frame 0 gets k = kappa x E x V / (A x N). Default 170: the
  // image coupling dominates the elastic response of the whole organ (the model lags a global
  // target motion by ~1 / (1 + kappa) of it) while elasticity still interpolates between
  // features; it is the median of what the validated 500 N/m was on the 100 kPa band and
  // 20 kPa kidney scenes (144-200), and gives ten times that on the 1 MPa band
  // (docs/springs.md, "Spring stiffness").
  double spring_stiffness_relative = 170.0;
  // Volumetric part of the material (mechanics::CorotationalOptions::volume_term), for the
  // dynamic model and the output fit: "jacobian" lambda/2 (det F - 1)^2 (default) or "linear"
  // lambda/2 tr(eps)^2 (docs/mechanics.md, "Volume term").
  mechanics::VolumeTerm volume_term = mechanics::VolumeTerm::kJacobian;
  // Absolute stiffness of each feature spring [N/m = mN/mm], overriding the relative one when
  // > 0 (`--stiffness`); default 0 (use spring_stiffness_relative).
  double spring_stiffness_n_per_m = 0.0;
  int substeps = 1;  // implicit Euler sub-steps per video frame [count]; default 1
  // Newton iterations per sub-step: 1 is the thesis' one-step scheme; more iterate towards
  // convergence (newton_tolerance_mm 1e-6), each with the line search. Default 2: a cut band's
  // free lips turn by tens of degrees within a frame, and one step of the warped stiffness
  // leaves them hanging across the opened notch.
  int newton_iterations = 2;
  // Rayleigh damping [1/s] and [s]; negative (default) takes the scene's material values.
  double rayleigh_mass_per_s = -1.0;
  double rayleigh_stiffness_s = -1.0;
  // Gravity in the world frame [mm/s^2]; default zero (registration needs none: the image
  // springs carry the motion and the model is registered at frame 0 in its loaded pose).
  Eigen::Vector3d gravity_mm_per_s2 = Eigen::Vector3d::Zero();
  // Model vertices held at their frame-0 position (indices into the model mesh); default none.
  std::vector<int> fixed_vertices;
  // Tether of the tissue out of view (dimensionless, >= 0; 0 off): the model vertices that
  // project outside the image at frame 0 are never observed, yet the tissue there stays
  // attached to the anatomy beyond the view; without a prior the stretched model's elasticity
  // pulls that part into the image. Each such vertex v is held at its frame-0 place by a
  // zero-length spring k_v = out_of_view_tether x N k x V_v / V (N k the feature springs' total
  // stiffness, V_v the vertex's share of the rest volume V): 1 holds the unseen tissue, per
  // unit volume, as firmly as the feature springs hold the whole model. Tet models of degree 1
  // without thin structures (docs/springs.md, "Tissue out of view").
  double out_of_view_tether = 1.0;
  // kCholmodPcg (default, "cholmod-pcg": CG preconditioned by the CHOLMOD factor of an earlier
  // frame's matrix, refactorised when CG slows down), kCholmod ("cholmod": exact, refactorised
  // every step) or kConjugateGradient ("cg": block-Jacobi preconditioned).
  mechanics::LinearSolverType linear_solver = mechanics::LinearSolverType::kCholmodPcg;
  // Line search on the incremental potential along each Newton increment of the frame's step
  // (mechanics::ImplicitEulerOptions::line_search; docs/mechanics.md, "Line search"): without
  // it the free lips of a cut, stretched band swing in depth from frame to frame. The output
  // fit takes its step whole (QuasiStaticFitOptions::line_search). Default true.
  bool line_search = true;
  // What is drawn, saved and evaluated is, per frame, the quasi-static fit of the model to
  // its springs made this many times stiffer (mechanics::QuasiStaticFit: one Newton step from
  // the frame's state, same linear solver); cut detection, lifting and the next frame go on
  // from the dynamic model, whose springs the detector's measure is calibrated on. 0 shows
  // the dynamic model itself. Dimensionless, >= 0; default 6 (docs/springs.md, "Output fit").
  double output_spring_factor = 6.0;
  void Check() const;
};

// Where the cutting stage builds and cuts S (CuttingStageOptions::cut_configuration).
enum class CutConfiguration { kRest, kCurrent };
// The spelling in scene files and run records: "rest", "current".
inline constexpr EnumName<CutConfiguration> kCutConfigurationNames[] = {
    {CutConfiguration::kRest, "rest"}, {CutConfiguration::kCurrent, "current"}};
const char* CutConfigurationName(CutConfiguration configuration);
// Inverse of CutConfigurationName; throws arreg::Error naming `field` for any other name.
CutConfiguration ParseCutConfiguration(const std::string& name, const std::string& field);

// Cutting stage (thesis 7.5): detection every frame, extrusion of the polyline into S,
// remeshing, mechanics follow, re-embedding and spring removal.
struct CuttingStageOptions {
  bool enabled = true;  // false is `--no-topology`; default true
  cutting::CutDetectorOptions detector;
  // [mm] springs whose anchor lies closer than this to S are removed (thesis margin r). Default 4.
  double spring_margin_mm = 4.0;
  // [mm] S extends this far beyond the model's depth range along the rays. Default 10.
  double extrusion_margin_mm = 10.0;
  // Remeshing method: kFlips (default, "flips", thesis 5.1) or kBielser ("bielser").
  cutting::RemeshMethod method = cutting::RemeshMethod::kFlips;
  // Snapping threshold eps (unitless, >= 0): a vertex of a crossed edge moves onto S when its
  // distance to S is below eps x the mean rest edge length (thesis 5.1.3; its figures use
  // 0 to 0.3). Default 0.1.
  double snap_epsilon = 0.1;
  // Vertices closer to S than this x the mean rest edge length count as lying on S (marked
  // for separation, their edges not crossed; unitless, >= 0). Successive events cut with S
  // extruded in a later frame, which passes near, not through, the vertices an earlier event
  // put on the crack; a tolerance of a fraction of an element merges the two instead of
  // cutting slivers next to the crack. Default 0.25.
  double on_surface_tolerance = 0.25;
  // A cut event must not split the model into more pieces: when the S that spans the model's
  // depth along the rays would, S is cut again ending at 3/4, 1/2 and 1/4 of that depth behind
  // the polyline, and the first that keeps the pieces is applied (else the event is rejected).
  // A monocular view does not show how deep a cut goes; S along the rays through the whole
  // depth cuts hidden tissue behind the visible cut, and where the cut runs down the side of a
  // thick organ the rays sweep through its body and cut off a piece the video never shows
  // coming loose (synthetic kidney: Dice 0.946 -> 0.862 once the detector followed the cut
  // down the side). Whether a cut goes through is not seen either: a cut seen crossing the
  // object from outline to outline may be a transection or an incision with a hidden hinge
  // (the kidney's polyline, border extensions included, ends beside the model at both ends).
  // Set false for scenes where a piece is cut off: the full-depth S is applied always.
  // Default true.
  bool keep_connected = true;
  // With keep_connected, the depth of a cut is chosen at its first event as if its polyline
  // already reached the outline where an end is within `foresight_mm` of it (the pipeline
  // passes r_F, the detector's neighbour radius): the S of that foreseen polyline is tried at
  // each depth, and the first depth at which it would not split the model is the event's (1/4
  // at least). Later events of the cut go no deeper. Without it a cut seen early, before its
  // polyline spans the organ, goes through the full depth at its first event, where the next
  // event, one frame later, is held at 1/2 (on most synthetic kidney cuts; the internal
  // structure's mean error rises by a quarter). 0 disables.
  // Set by the pipeline from first_event_foresight, not a scene key.
  double foresight_mm = 0.0;
  // The pipeline sets foresight_mm to r_F (true, default) or 0 (false).
  bool first_event_foresight = true;
  // [px] the outlier test's floor in image pixels: the pipeline converts it to millimetres at
  // the attached features' median frame-0 depth (z / f, the size of a pixel on the organ) and
  // the detector uses the larger of that and `detector.min_outlier_measure_mm`. A misfit
  // difference below about one pixel is tracking precision, whatever the organ's distance
  // (0.1 mm is a third of a pixel on the synthetic kidney, a quarter on the bands). 0 leaves
  // the millimetre floor alone. Default 1 (docs/detection.md, "A floor in pixels").
  double min_outlier_measure_px = 1.0;
  // [px] standard deviation of the tracked positions per image axis: the separation test's noise
  // floor (cutting::SeparationTestOptions::noise_floor_mm), converted to millimetres at the
  // attached features' median frame-0 depth. The drift-corrected tracker keeps synthetic
  // features 0.26-0.40 px (median) from their true positions (docs/tracking.md). Default 0.5.
  double tracking_noise_px = 0.5;
  // With keep_connected, the detector is given the cut handler's verdict before it adds a
  // segment (cutting::CutDetector::SetSegmentCheck): a point whose segment would make an event
  // that keep_connected rejects at every depth is refused, as a point that is no growth of the
  // polyline is. Otherwise the strain concentrations at the two re-entrant corners of a band's
  // stem, 30 mm apart and within the growth radius of each other, were joined into a polyline
  // across the stem on 13 of 41 band-stretch seeds: rejected events, but events of a scene
  // without a cut (docs/detection.md, "Segments that would split the model"). false adds every
  // segment the growth rules allow. Default true.
  bool refuse_splitting_segments = true;
  // Where S is built and cut: kRest (default, "rest") extrudes the polyline of the cut points'
  // frame-0 positions along the frame-0 rays and cuts the rest configuration with the whole
  // polyline at every event, so each event continues the crack exactly where the last one left it;
  // kCurrent ("current") extrudes this frame's polyline and cuts only its new segments (the
  // thesis; the strips of successive frames meet along lines that stay sewn, see
  // docs/cutting.md).
  CutConfiguration cut_configuration = CutConfiguration::kRest;
  // Internal structures S cuts: true (default) splits each surface along the model's crack and,
  // when it is closed, closes each side again with a cap on the crack (cutting::
  // SplitAlongCrack), so a cut tumour is two closed pieces that follow their sides; false
  // deletes the triangles crossing S (thesis eq. 7.12), which leaves a hole where the crack
  // opens.
  bool internal_caps = true;
  // Where an internal structure's split is refused (the event then deletes its triangles
  // crossing S), the split's inputs are written to this folder, when set, so that it can be
  // reproduced with cutting::SplitAlongCrack: NNNNNN_split_K_structure.obj (the structure as
  // loaded) and NNNNNN_split_K_crack.obj (the model's crack), both in rest coordinates [mm], for
  // frame NNNNNN and structure K. Not a scene key: `arreg run --debug` sets it to DIR/debug.
  // Default "" (nothing written).
  std::string refused_split_dir;
  void Check() const;
};

// How the registered organ is drawn (docs/overlay.md).
enum class OverlayStyle {
  kContour,  // its outline and cut edges as lines, the video inside left as it is
  kTint,     // a translucent shaded surface (organ_opacity, organ_color)
};
// The spelling in scene files and run records: "contour", "tint".
inline constexpr EnumName<OverlayStyle> kOverlayStyleNames[] = {{OverlayStyle::kContour, "contour"},
                                                                {OverlayStyle::kTint, "tint"}};

// Overlay rendering (z-buffered, anti-aliased) drawn over the decoded frame.
struct RenderStageOptions {
  bool enabled = true;  // render the overlay at all (bench without); default true
  // "contour" (default): the organ's silhouette and cut edges as anti-aliased lines over the
  // unaltered video, internal structures in their own colour; "tint": the organ as a
  // translucent surface of organ_color at organ_opacity.
  OverlayStyle style = OverlayStyle::kContour;
  // Silhouette line colour, linear RGB in [0, 1]; default bright green (contrasts with tissue).
  Eigen::Vector3d contour_color = Eigen::Vector3d(0.1, 1.0, 0.2);
  // Cut-edge line colour, linear RGB in [0, 1]; default cyan.
  Eigen::Vector3d cut_edge_color = Eigen::Vector3d(0.1, 0.85, 1.0);
  int contour_width_px = 2;  // line width of silhouette and cut edges (px), in [1, 8]; default 2
  // A surface edge whose two faces meet at more than this dihedral angle (degrees) is drawn as
  // a cut edge: a cut's wall meets the organ's surface at its rim at about 90 degrees, while
  // the organ's own surface is smooth at the mesh's resolution. In (0, 180); default 60.
  double cut_edge_angle_deg = 60;
  bool legend = true;         // colour legend in the top-left corner; default true
  bool frame_counter = true;  // "frame N" in the bottom-left corner; default true
  // Anti-aliasing: 1 (default) one sample per pixel with analytic coverage of silhouette edges
  // (render::CoverageLayer, fast); 2..8 the reference rasterizer at that many samples per
  // pixel and axis.
  int supersampling = 1;
  double organ_opacity = 0.35;  // in [0, 1]; default 0.35 (internal structures show through)
  Eigen::Vector3d organ_color = Eigen::Vector3d(0.95, 0.55, 0.45);  // linear RGB in [0, 1]
  bool wireframe = false;      // draw the model's surface edges; default false
  bool show_features = false;  // tracked feature pixels (green); default false
  bool show_targets = false;   // lifted targets projected (blue); default false
  bool show_springs = false;   // anchor-target segments projected (yellow); default false
  void Check() const;
};

// What is written into the run folder (docs/run-format.md).
struct OutputStageOptions {
  bool video = true;  // overlay.mp4; default true
  int crf = 23;       // x264 quality of overlay.mp4 (0..51); x264's own default
  // x264 speed preset of overlay.mp4; default "ultrafast": at CRF 18 the overlay looks the
  // same, the file is larger, and encoding costs a fraction of "veryfast" (docs/pipeline-speed.md).
  std::string preset = "ultrafast";
  // x264 encoder threads; 1 (default) keeps timings single-threaded, 0 lets FFmpeg choose.
  int encode_threads = 1;
  bool png_frames = false;  // also frames/NNNNNN.png; default false
  // Meshes every k-th frame when the scene has no ground truth (else gt's surface_every_k);
  // the last frame is always written. Default 10.
  int save_every = 10;
  void Check() const;
};

struct PipelineOptions {
  FeatureTrackerOptions tracking;
  lift::FeatureLifterOptions lifting;
  MechanicsStageOptions mechanics;
  CuttingStageOptions cutting;
  RenderStageOptions render;
  OutputStageOptions output;
  int max_frames = -1;  // process at most this many frames; -1 (default) = the whole video
  // Dilation [px] of the projected model silhouette used as the tracker's ROI at every frame;
  // -1 (default) uses the silhouette only at frame 0 (detection) and the whole image afterwards.
  int roi_dilation_px = -1;
  // A feature re-detected after frame 0 (tracking.redetect_every_frames) is attached once it
  // has been tracked, without a loss, for this many frames since its detection. Points on the
  // silhouette's edge or a specular rim slide and are dropped by the forward-backward check or
  // the outlier filter within a frame or two; a spring on them would pull the model along the
  // slide. 0 = attach at detection. Default 5.
  int attach_after_frames = 5;
  // ... and only where the model agrees with the image there: the mean spring length of the
  // attached features within 3 frame-0 feature spacings of its attach point is at most this
  // factor times the median spring length of all of them. Where the model lags the tissue
  // (a cut the model has not made yet, tissue its springs cannot reach), the rest point a new
  // feature would be given through the model is wrong, and a spring from there holds the model
  // in place: in the gap of an opening cut the new point is background. A feature with no such
  // neighbour (its whole patch lost) is attached. Default 2.
  double attach_max_misfit_factor = 2.0;
  // Throws arreg::Error naming the field.
  void Check() const;
};

// The feature spring stiffness of a run, resolved at frame 0 (docs/springs.md, "Spring
// stiffness").
struct SpringStiffness {
  double n_per_m = 0;           // per spring [N/m]
  bool relative = true;         // derived from spring_stiffness_relative (else the override)
  double volume_mm3 = 0;        // V: rest volume of the model [mm^3]
  double visible_area_mm2 = 0;  // A: area of the boundary faces facing the camera [mm^2]
  int springs = 0;              // N: springs attached at frame 0
};

// k = spring_stiffness_relative x E x V / (A x N) [Pa mm = 1e-3 N/m], or the absolute override
// when set; 0 when no spring is attached (N = 0). Throws arreg::Error for E <= 0, V <= 0 or
// A <= 0 when k is relative and N > 0.
SpringStiffness ResolveSpringStiffness(const MechanicsStageOptions& mechanics,
                                       double youngs_modulus_pa, double volume_mm3,
                                       double visible_area_mm2, int springs);

// Area [mm^2] of the faces of `surface` whose outward side faces the point `eye_world` (the
// camera centre): every feature attached by a ray from the camera lies on such a face.
double AreaFacing(const SurfaceMesh& surface, const Eigen::Vector3d& eye_world);

// A model vertex held at its frame-0 place by a zero-length spring (MechanicsStageOptions::
// out_of_view_tether).
struct VertexTether {
  int vertex = -1;
  double stiffness_n_per_m = 0;
};

// The tethers of the vertices of `mesh` (rest positions = frame 0) that project outside the
// camera's image or lie behind it: k_v = factor x total_spring_n_per_m x V_v / V, V_v a
// quarter of the rest volume of each tetrahedron at v, V the rest volume. Vertices in `fixed`
// and vertices of no tetrahedron are left out. Empty when factor or total_spring_n_per_m is 0.
std::vector<VertexTether> OutOfViewTethers(const TetMesh& mesh, const PinholeCamera& camera,
                                           double factor, double total_spring_n_per_m,
                                           const std::vector<int>& fixed);

// Reads the options from the scene's module sections (unknown keys are errors naming
// "scene.json: mechanics.sprng_stiffness"); missing keys keep the defaults above, except
// `tracking.max_features`, whose pipeline default is 500.
PipelineOptions ReadPipelineOptions(const Scene& scene);

// Every option as JSON (the `options` object of run.json).
nlohmann::json PipelineOptionsToJson(const PipelineOptions& options);

}  // namespace arreg::pipeline
