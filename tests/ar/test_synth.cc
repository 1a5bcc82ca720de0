// Tests of the synthetic scene generator: truth mechanics (derivatives,
// incompressibility), meshing, cuts as real separations, and the written
// ground truth (determinism, masks vs surfaces, cut opening).
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <set>
#include <sstream>

#include "ar/eval/evaluation.h"
#include "ar/render/rasterizer.h"
#include "ar/synth/generator.h"
#include "ar/synth/neo_hookean.h"
#include "ar/synth/progressive_cut.h"
#include "ar/synth/scenarios.h"
#include "ar/synth/shapes.h"
#include "ar/synth/tissue_texture.h"
#include "core/error.h"
#include "core/file_util.h"
#include "core/json_reader.h"
#include "core/mesh_io.h"
#include "core/mesh_ops.h"
#include "core/scene.h"
#include "test_util.h"

namespace arreg::synth {
namespace {

LabeledTetMesh SmallBox(const Eigen::Vector3d& size, double cell) {
  BoxUnionMeshOptions o;
  o.cell_mm = Eigen::Vector3d::Constant(cell);
  return MeshBoxUnion({Eigen::AlignedBox3d(Eigen::Vector3d::Zero(), size)}, o);
}

// --zoom scales the focal length from the same camera pose; out-of-range values name the field.
TEST(Scenarios, ZoomScalesTheFocalLengthFromTheSamePose) {
  ScenarioOptions o;
  const Scenario base = BuildScenario("band-stretch", o);
  o.zoom = 2.0;
  const Scenario zoomed = BuildScenario("band-stretch", o);
  EXPECT_NEAR(zoomed.camera.fx, 2.0 * base.camera.fx, 1e-9 * base.camera.fx);
  EXPECT_NEAR(zoomed.camera.fy, 2.0 * base.camera.fy, 1e-9 * base.camera.fy);
  EXPECT_DOUBLE_EQ(zoomed.camera.cx, base.camera.cx);
  EXPECT_TRUE(zoomed.camera.camera_from_world.isApprox(base.camera.camera_from_world, 1e-12));
  // A point on the optical axis stays put; one off the axis moves twice as far from the centre.
  const Eigen::Vector3d p(20, 60, 4);
  const Eigen::Vector2d c(base.camera.cx, base.camera.cy);
  EXPECT_NEAR((zoomed.camera.Project(p) - c).norm(), 2.0 * (base.camera.Project(p) - c).norm(),
              1e-6);
  o.zoom = 5.0;
  try {
    BuildScenario("band-stretch", o);
    FAIL() << "zoom 5 was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("zoom"), std::string::npos) << e.what();
  }
}

TEST(NeoHookean, GradientAndHessianMatchFiniteDifferences) {
  const LabeledTetMesh box = SmallBox({10, 10, 10}, 5);
  NeoHookeanMaterial m;
  m.poisson_ratio = 0.45;
  const NeoHookeanEnergy e(box.mesh.vertices, box.mesh.tetrahedra, m);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-0.6, 0.6);
  RowMatX3d x = box.mesh.vertices;
  for (int i = 0; i < x.rows(); ++i)
    for (int c = 0; c < 3; ++c) x(i, c) += u(rng) + 0.1 * x(i, c) * (c == 0);
  const Eigen::VectorXd g = e.Gradient(x);
  const Eigen::SparseMatrix<double> h = e.Hessian(x);
  const double step = 1e-5;
  double max_g_err = 0, max_g = 0, max_h_err = 0, max_h = 0;
  for (int d = 0; d < 3 * x.rows(); ++d) {
    RowMatX3d xp = x, xm = x;
    xp(d / 3, d % 3) += step;
    xm(d / 3, d % 3) -= step;
    const double fd = (e.Value(xp) - e.Value(xm)) / (2 * step);
    max_g_err = std::max(max_g_err, std::abs(fd - g[d]));
    max_g = std::max(max_g, std::abs(g[d]));
    const Eigen::VectorXd fd_col = (e.Gradient(xp) - e.Gradient(xm)) / (2 * step);
    const Eigen::VectorXd col = h.col(d);
    max_h_err = std::max(max_h_err, (fd_col - col).cwiseAbs().maxCoeff());
    max_h = std::max(max_h, col.cwiseAbs().maxCoeff());
  }
  EXPECT_LT(max_g_err, 1e-6 * max_g);
  EXPECT_LT(max_h_err, 1e-6 * max_h);
  // The Hessian is symmetric.
  EXPECT_LT((Eigen::MatrixXd(h) - Eigen::MatrixXd(h).transpose()).cwiseAbs().maxCoeff(),
            1e-9 * max_h);
}

TEST(NeoHookean, RigidMotionsAreFreeOfEnergyAndForce) {
  const LabeledTetMesh box = SmallBox({10, 5, 5}, 2.5);
  const NeoHookeanEnergy e(box.mesh.vertices, box.mesh.tetrahedra, NeoHookeanMaterial());
  const Eigen::Matrix3d r =
      Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  RowMatX3d x = (box.mesh.vertices * r.transpose()).rowwise() + Eigen::RowVector3d(4, -2, 9);
  EXPECT_NEAR(e.Value(x), 0.0, 1e-6);
  EXPECT_LT(e.Gradient(x).cwiseAbs().maxCoeff(), 1e-6);
}

TEST(NeoHookean, KeepsVolumeWithinTwoPercentAt186PercentStretch) {
  const LabeledTetMesh bar = SmallBox({20, 20, 4}, 2);
  const NeoHookeanEnergy e(bar.mesh.vertices, bar.mesh.tetrahedra, NeoHookeanMaterial());
  std::vector<bool> fixed(bar.mesh.num_vertices());
  for (int v = 0; v < bar.mesh.num_vertices(); ++v)
    fixed[v] = bar.mesh.vertices(v, 1) <= 1e-9 || bar.mesh.vertices(v, 1) >= 20 - 1e-9;
  QuasiStaticSolver solver(&e, fixed);
  RowMatX3d x = bar.mesh.vertices;
  for (int step = 1; step <= 10; ++step) {
    RowMatX3d targets = bar.mesh.vertices;
    for (int v = 0; v < targets.rows(); ++v)
      if (targets(v, 1) >= 20 - 1e-9) targets(v, 1) += 0.086 * step * 20;
    const QuasiStaticSummary s = solver.Solve(targets, &x);
    ASSERT_TRUE(s.converged) << "step " << step << ": " << s.message;
  }
  const Eigen::VectorXd j = e.VolumeRatios(x);
  const Eigen::VectorXd v0 = TetVolumes(bar.mesh);
  const double ratio = j.dot(v0) / v0.sum();
  EXPECT_NEAR(ratio, 1.0, 0.02);
  EXPECT_GT(j.minCoeff(), 0.5);
  // The middle of the bar narrows (Poisson effect): it is really stretched.
  double min_x = 1e9, max_x = -1e9;
  for (int v = 0; v < x.rows(); ++v)
    if (std::abs(bar.mesh.vertices(v, 1) - 10) < 1e-9) {
      min_x = std::min(min_x, x(v, 0));
      max_x = std::max(max_x, x(v, 0));
    }
  EXPECT_LT(max_x - min_x, 20 * 0.85);
}

TEST(Shapes, BoxUnionIsAClosedMeshOfTheRightVolume) {
  for (int per_cell : {5, 6}) {
    BoxUnionMeshOptions o;
    o.cell_mm = Eigen::Vector3d(5, 5, 4);
    o.tets_per_cell = per_cell;
    const LabeledTetMesh band =
        MeshBoxUnion({Eigen::AlignedBox3d(Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(100, 100, 8)),
                      Eigen::AlignedBox3d(Eigen::Vector3d(30, -20, 0), Eigen::Vector3d(70, 0, 8))},
                     o);
    EXPECT_EQ(band.mesh.num_tetrahedra(), per_cell * (20 * 20 * 2 + 8 * 4 * 2));
    const Eigen::VectorXd volumes = TetVolumes(band.mesh);
    EXPECT_GT(volumes.minCoeff(), 0);
    EXPECT_NEAR(volumes.sum(), 100 * 100 * 8 + 40 * 20 * 8, 1e-6);
    SurfaceMesh boundary;
    boundary.vertices = band.mesh.vertices;
    boundary.faces = BoundaryFaces(band.mesh.tetrahedra);
    EXPECT_NEAR(EnclosedVolume(boundary), volumes.sum(), 1e-6);  // closed and outward
  }
}

TEST(Shapes, KidneyMeshHasTheOrganAndTheInternalStructure) {
  const KidneyShape shape;
  KidneyMeshOptions o;
  o.cell_size_mm = o.facet_size_mm = 5;
  o.facet_distance_mm = 0.8;
  const LabeledTetMesh kidney = MeshKidney(shape, o);
  const Eigen::VectorXd volumes = TetVolumes(kidney.mesh);
  EXPECT_GT(volumes.minCoeff(), 0);
  double internal = 0;
  for (int t = 0; t < kidney.labels.size(); ++t) internal += kidney.labels[t] == 2 ? volumes[t] : 0;
  const double ellipsoid = 4.0 / 3.0 * M_PI * 27.5 * 5.5 * 13.5;
  EXPECT_NEAR(internal / ellipsoid, 1.0, 0.12);
  // Extent of the organ along its axes.
  const Eigen::Vector3d extent =
      kidney.mesh.vertices.colwise().maxCoeff() - kidney.mesh.vertices.colwise().minCoeff();
  EXPECT_NEAR(extent.x(), 100, 4);
  EXPECT_NEAR(extent.y(), 27, 3);
  EXPECT_GT(extent.z(), 50);
  EXPECT_LT(extent.z(), 70);
}

TEST(ProgressiveCut, PartialCutDuplicatesOnlyTheVerticesBehindTheFront) {
  LabeledTetMesh box = SmallBox({20, 20, 10}, 5);
  CutSurfaceSpec spec;
  spec.level_set = [](const Eigen::Vector3d& p) { return p.y() - 10; };
  spec.progress_mm = [](const Eigen::Vector3d& p) {
    return p.x() <= 20 ? p.x() : std::numeric_limits<double>::infinity();
  };
  ProgressiveCut cut(&box.mesh, spec);
  EXPECT_EQ(cut.num_faces(), 4 * 2 * 2);  // 4 x 2 grid squares on the plane, 2 triangles each
  EXPECT_EQ(cut.ComputeSplit().origin.size(), static_cast<size_t>(box.mesh.num_vertices()));
  // Half way: the plane's vertices at x = 0 and 5 split (2 x 3 of them); x = 10 is the front.
  EXPECT_TRUE(cut.Advance(10));
  ProgressiveCut::Split half = cut.ComputeSplit();
  EXPECT_EQ(half.origin.size(), static_cast<size_t>(box.mesh.num_vertices() + 6));
  TetMesh half_mesh{box.mesh.vertices, half.tetrahedra, {}, {}};
  half_mesh.vertices.resize(half.origin.size(), 3);
  for (size_t v = 0; v < half.origin.size(); ++v)
    half_mesh.vertices.row(v) = box.mesh.vertices.row(half.origin[v]);
  EXPECT_EQ(ConnectedComponents(half_mesh, Adjacency::kVertex).maxCoeff(), 0);
  // All the way through: two pieces, every vertex of the plane duplicated.
  EXPECT_TRUE(cut.Advance(100));
  EXPECT_FALSE(cut.Advance(100));
  ProgressiveCut::Split full = cut.ComputeSplit();
  EXPECT_EQ(full.origin.size(), static_cast<size_t>(box.mesh.num_vertices() + 15));
  TetMesh full_mesh{RowMatX3d(full.origin.size(), 3), full.tetrahedra, {}, {}};
  for (size_t v = 0; v < full.origin.size(); ++v)
    full_mesh.vertices.row(v) = box.mesh.vertices.row(full.origin[v]);
  EXPECT_EQ(ConnectedComponents(full_mesh, Adjacency::kVertex).maxCoeff(), 1);
}

TEST(ProgressiveCut, SnapsVerticesOntoACurvedSurface) {
  LabeledTetMesh box = SmallBox({40, 40, 8}, 4);
  CutSurfaceSpec spec;
  spec.level_set = [](const Eigen::Vector3d& p) {
    return p.y() - 20 - 5 * std::sin(2 * M_PI * p.x() / 40);
  };
  spec.progress_mm = [](const Eigen::Vector3d& p) { return p.x(); };
  const RowMatX3d before = box.mesh.vertices;
  ProgressiveCut cut(&box.mesh, spec);
  EXPECT_GT(cut.num_snapped_vertices(), 10);
  // The staircase of faces between the two sides moves towards the surface: the
  // snapped vertices lie on it and the mean distance drops by more than a quarter.
  const RowMatX3i faces = cut.FaceTriangles();
  double before_sum = 0, after_sum = 0;
  std::set<int> on_surface;
  for (int f = 0; f < faces.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      before_sum += std::abs(spec.level_set(before.row(faces(f, k)).transpose()));
      const double phi = spec.level_set(box.mesh.vertices.row(faces(f, k)).transpose());
      after_sum += std::abs(phi);
      if (std::abs(phi) < 1e-6) on_surface.insert(faces(f, k));
    }
  EXPECT_GE(static_cast<int>(on_surface.size()), cut.num_snapped_vertices());
  EXPECT_LT(after_sum, 0.75 * before_sum);
  EXPECT_GT(TetVolumes(box.mesh).minCoeff(), 0);
}

TEST(TissueTexture, IsDeterministicPerSeedAndVaries) {
  TissueTextureOptions o;
  o.seed = 7;
  const TissueTexture a(o), b(o);
  o.seed = 8;
  const TissueTexture c(o);
  int differ = 0;
  double min_lum = 1, max_lum = 0;
  for (int i = 0; i < 200; ++i) {
    const Eigen::Vector3d p(1.37 * i, 0.71 * i, 0.3 * i);
    EXPECT_EQ(a.Albedo(p), b.Albedo(p));
    differ += (a.Albedo(p) - c.Albedo(p)).norm() > 1e-3;
    min_lum = std::min(min_lum, static_cast<double>(a.Albedo(p).sum()));
    max_lum = std::max(max_lum, static_cast<double>(a.Albedo(p).sum()));
  }
  EXPECT_GT(differ, 100);
  EXPECT_GT(max_lum - min_lum, 0.5);  // contrast for tracking
}

std::string Slurp(const std::string& path) { return ReadFileToString(path); }

SynthOptions SmallRun(const std::string& scenario, const std::string& dir) {
  SynthOptions o;
  o.scenario = scenario;
  o.out_dir = dir;
  o.frames = 11;
  o.width = 160;
  o.height = 128;
  o.surface_every_k = 5;
  o.supersampling = 1;
  return o;
}

TEST(Generator, SameSeedGivesIdenticalGroundTruthAndMasksMatchSurfaces) {
  const std::string d1 = testing::ScratchDir("synth_det_1"),
                    d2 = testing::ScratchDir("synth_det_2");
  const SynthSummary s1 = GenerateSyntheticScene(SmallRun("band-stretch", d1));
  const SynthSummary s2 = GenerateSyntheticScene(SmallRun("band-stretch", d2));
  EXPECT_EQ(s1.unconverged_frames, 0);
  EXPECT_GE(s1.truth_tetrahedra, 4 * s1.model_tetrahedra);
  for (const std::string rel : {"gt/meta.json", "gt/cut.json", "gt/surface/000005.obj",
                                "gt/surface/000010.obj", "gt/masks/000005.png", "model.vtk"})
    EXPECT_EQ(Slurp(d1 + "/" + rel), Slurp(d2 + "/" + rel)) << rel;
  // Truth keeps its volume through the 186 % stretch (frame 5 is the peak).
  EXPECT_LT(s1.max_volume_change, 0.02);
  EXPECT_NEAR(s1.volume_ratio[5], 1.0, 0.02);
  // The scene file reads back and its camera rasterises the GT surface into the GT mask.
  const Scene scene = ReadScene(d1 + "/scene.json");
  EXPECT_EQ(scene.camera.width, 160);
  const TetMesh model = ReadTetMesh(scene.model_mesh_path);
  EXPECT_EQ(model.num_tetrahedra(), s1.model_tetrahedra);
  for (int frame : {0, 5, 10}) {
    char name[32];
    std::snprintf(name, sizeof(name), "%06d", frame);
    const SurfaceMesh surface = ReadSurfaceMesh(d1 + "/gt/surface/" + name + ".obj");
    render::RasterCamera rc;
    rc.width = scene.camera.width;
    rc.height = scene.camera.height;
    rc.fx = scene.camera.fx;
    rc.fy = scene.camera.fy;
    rc.cx = scene.camera.cx;
    rc.cy = scene.camera.cy;
    rc.camera_from_world = scene.camera.camera_from_world;
    const cv::Mat expected = render::RenderMask(rc, surface.vertices, surface.faces);
    const cv::Mat mask = cv::imread(d1 + "/gt/masks/" + name + ".png", cv::IMREAD_UNCHANGED);
    ASSERT_EQ(mask.type(), CV_8U);
    EXPECT_EQ(cv::countNonZero(mask != expected), 0) << "frame " << frame;
    EXPECT_GT(cv::countNonZero(mask), 500) << "frame " << frame;
  }
  // Stretching makes the silhouette taller between frames 0 and 5 (186 % peak).
  const cv::Mat m0 = cv::imread(d1 + "/gt/masks/000000.png", cv::IMREAD_UNCHANGED);
  const cv::Mat m5 = cv::imread(d1 + "/gt/masks/000005.png", cv::IMREAD_UNCHANGED);
  EXPECT_GT(cv::boundingRect(m5).height, 1.4 * cv::boundingRect(m0).height);
  EXPECT_TRUE(FileExists(d1 + "/video.mp4"));
}

TEST(Generator, PrecutOpensOverMostOfItsLength) {
  const std::string d = testing::ScratchDir("synth_precut");
  SynthOptions o = SmallRun("band-precut-side", d);
  o.write_video = false;
  o.frames = 6;  // the pull reaches its peak at t = 0.6 and is held to the last frame
  const SynthSummary s = GenerateSyntheticScene(o);
  EXPECT_EQ(s.unconverged_frames, 0);
  EXPECT_EQ(s.cut_first_frame, 0);
  EXPECT_GE(s.cut_open_fraction, 0.5);
  // Held at 186 % to the last frame (thesis 7.7.1), the slit gapes wide open at the end.
  EXPECT_GT(s.max_cut_opening_mm, 30.0);
  // The opening per frame: closed at rest in frame 0, the final separation at the last frame.
  ASSERT_EQ(s.opening_mm.size(), 6u);
  EXPECT_NEAR(s.opening_mm.front(), 0.0, 1e-9);
  EXPECT_DOUBLE_EQ(s.opening_mm.back(), s.max_cut_opening_mm);
  EXPECT_GT(s.opening_mm[3], 2.0);
  EXPECT_GT(s.final_truth_vertices, s.truth_vertices);
  EXPECT_LT(s.max_volume_change, 0.02);
  const std::string cut = Slurp(d + "/gt/cut.json");
  EXPECT_NE(cut.find("cut_surface.obj"), std::string::npos);
  const SurfaceMesh surface = ReadSurfaceMesh(d + "/gt/cut_surface.obj");
  EXPECT_NEAR(SurfaceArea(surface), 40 * 8, 1e-6);  // the slit: 40 mm x 8 mm
}

TEST(Generator, CutWhileFilmedOpensProgressively) {
  const std::string d = testing::ScratchDir("synth_cut_v");
  SynthOptions o = SmallRun("band-cut-v", d);
  o.write_video = false;
  o.frames = 21;
  const SynthSummary s = GenerateSyntheticScene(o);
  EXPECT_EQ(s.unconverged_frames, 0);
  // The cut starts at t = 0.3 and the tear ends at t = 0.9.
  EXPECT_GE(s.cut_first_frame, 6);
  EXPECT_LE(s.cut_last_frame, 18);
  EXPECT_GT(s.cut_last_frame, s.cut_first_frame + 5);
  EXPECT_GE(s.cut_open_fraction, 0.5);
  // Torn while pulled to 180 %, the halves splay into a V (thesis 7.7.2): ~80 mm at the top.
  EXPECT_GT(s.max_cut_opening_mm, 60.0);
  // Closed before the cut starts, open once its faces have opened.
  ASSERT_EQ(s.opening_mm.size(), 21u);
  for (int f = 0; f < s.cut_first_frame; ++f) EXPECT_EQ(s.opening_mm[f], 0.0) << "frame " << f;
  EXPECT_GT(s.opening_mm.back(), 60.0);
}

// The objects of an OBJ written with `o name` groups (gt/thin), by name.
std::map<std::string, SurfaceMesh> ThinObjects(const std::string& path) {
  std::map<std::string, SurfaceMesh> out;
  for (auto& [name, mesh] : eval::ReadObjObjects(path)) out[name] = mesh;
  return out;
}

// A tear's path: the notch up to its tip, then the crack in the given direction; the level set
// vanishes on both, progress is the length along the path.
TEST(Scenarios, TearPathFollowsTheNotchThenTheCrack) {
  TearSpec tear;
  tear.notch_mm = 8;
  tear.notch_dir = Eigen::Vector3d::UnitY();
  tear.notch_tip = Eigen::Vector3d(40, 8, 0);
  tear.max_length_mm = 50;
  const Eigen::Vector3d dir = Eigen::Vector3d(1, 2, 0).normalized();
  const CutSurfaceSpec path = TearPath(tear, dir);
  EXPECT_NEAR(path.level_set(Eigen::Vector3d(40, 3, 0.5)), 0, 1e-12);
  EXPECT_NEAR(path.progress_mm(Eigen::Vector3d(40, 3, 0.5)), 3, 1e-12);
  const Eigen::Vector3d on_crack = tear.notch_tip + 10 * dir;
  EXPECT_NEAR(path.level_set(on_crack), 0, 1e-12);
  EXPECT_NEAR(path.progress_mm(on_crack), 18, 1e-12);
  EXPECT_TRUE(std::isinf(path.progress_mm(tear.notch_tip + 45 * dir)));  // beyond max length
  // The two sides keep their sign across the tip (a continuous level set).
  EXPECT_GT(
      path.level_set(Eigen::Vector3d(45, 7.9, 0)) * path.level_set(Eigen::Vector3d(45, 8.1, 0)), 0);
}

// membrane-cut: a scene of one shell and no tet model; the truth's mid-surface is the sheet
// (area L x W at rest), the mask its silhouette, and the scissor cut opens it while pulled.
TEST(Generator, MembraneCutWritesAShellSceneAndTheTrueMidSurface) {
  const std::string d = testing::ScratchDir("synth_membrane_cut");
  SynthOptions o = SmallRun("membrane-cut", d);
  o.write_video = false;
  o.seed = 3;
  const SynthSummary s = GenerateSyntheticScene(o);
  EXPECT_EQ(s.unconverged_frames, 0);
  EXPECT_EQ(s.model_tetrahedra, 0);
  EXPECT_GE(s.cut_first_frame, 3);  // the scissors start at t = 0.3
  EXPECT_GT(s.max_cut_opening_mm, 2.0);
  const Scene scene = ReadScene(d + "/scene.json", {false});
  EXPECT_TRUE(scene.model_mesh_path.empty());
  ASSERT_EQ(scene.thin_structures.size(), 1u);
  const ThinStructure& shell = scene.thin_structures[0];
  EXPECT_EQ(shell.type, ThinStructureType::kShell);
  EXPECT_GE(shell.thickness_mm, 1.0);
  EXPECT_LE(shell.thickness_mm, 2.0);
  const SurfaceMesh model = ReadSurfaceMesh(shell.mesh_path);
  const double length = model.vertices.col(0).maxCoeff(), width = model.vertices.col(1).maxCoeff();
  EXPECT_GE(length, 80);
  EXPECT_LE(length, 100);
  EXPECT_GE(width, 50);
  EXPECT_LE(width, 70);
  // Held: the static support x = 0, all of it; the pulled support x = L moves and is free.
  int on_static_support = 0;
  for (int v = 0; v < model.num_vertices(); ++v) on_static_support += model.vertices(v, 0) < 1e-9;
  EXPECT_EQ(static_cast<int>(shell.fixed_vertices.size()), on_static_support);
  for (int v : shell.fixed_vertices) EXPECT_LT(model.vertices(v, 0), 1e-9) << v;
  const auto rest = ThinObjects(d + "/gt/thin/000000.obj");
  ASSERT_EQ(rest.count("membrane"), 1u);
  // Snaps onto the cut move free-edge vertices slightly off the edge: the area within 0.1 %.
  EXPECT_NEAR(SurfaceArea(rest.at("membrane")), length * width, 1e-3 * length * width);
  for (int v = 0; v < rest.at("membrane").num_vertices(); ++v)
    EXPECT_NEAR(rest.at("membrane").vertices(v, 2), shell.thickness_mm / 2, 1e-9);
  // At the end the cut has split mid-surface vertices; the mask is the sheet's silhouette.
  const auto last = ThinObjects(d + "/gt/thin/000010.obj");
  EXPECT_GT(last.at("membrane").num_vertices(), rest.at("membrane").num_vertices());
  const cv::Mat mask = cv::imread(d + "/gt/masks/000010.png", cv::IMREAD_UNCHANGED);
  const cv::Mat sheet = render::RenderMask(render::ToRasterCamera(scene.camera),
                                           last.at("membrane").vertices, last.at("membrane").faces);
  // The slab's silhouette differs from its mid-surface's by its thickness at the rims only.
  EXPECT_LT(cv::countNonZero(mask != sheet), 0.05 * cv::countNonZero(mask));
}

// membrane-tear: the notch is open from frame 0; the crack starts once the pull loads its tip
// beyond the strength, runs roughly perpendicular to the pull (x), one step per frame at most.
TEST(Generator, MembraneTearAdvancesFromTheNotchTip) {
  const std::string d = testing::ScratchDir("synth_membrane_tear");
  SynthOptions o = SmallRun("membrane-tear", d);
  o.write_video = false;
  o.frames = 21;
  o.fine_cell_mm = 8;  // 4 mm truth cells in-plane: a quicker test, the same model
  const SynthSummary s = GenerateSyntheticScene(o);
  EXPECT_EQ(s.unconverged_frames, 0);
  EXPECT_EQ(s.cut_first_frame, 0);
  const nlohmann::json tear = ParseJsonFile(d + "/gt/cut.json").at("cut").at("tear");
  const std::vector<double> advance = tear.at("advance_mm").get<std::vector<double>>();
  const std::vector<double> stress = tear.at("tip_stress_pa").get<std::vector<double>>();
  const double strength = tear.at("strength_pa").get<double>();
  const double step = tear.at("step_mm").get<double>();
  ASSERT_EQ(advance.size(), 21u);
  EXPECT_DOUBLE_EQ(advance.front(), 8.0);  // at rest the notch does not grow
  EXPECT_LT(stress.front(), strength);
  EXPECT_GT(advance.back(), 8.0 + 3 * step);  // it tears
  for (size_t f = 1; f < advance.size(); ++f) {
    EXPECT_GE(advance[f], advance[f - 1]);
    EXPECT_LE(advance[f] - advance[f - 1], step + 1e-9);  // bounded crack speed
    // A frame where it did not advance (and could) had its tip below the strength.
    if (advance[f] == advance[f - 1] &&
        advance[f] + step <= tear.at("max_length_mm").get<double>()) {
      EXPECT_LE(stress[f], strength) << "frame " << f;
    }
  }
  const Eigen::Vector3d dir(tear.at("direction")[0].get<double>(),
                            tear.at("direction")[1].get<double>(),
                            tear.at("direction")[2].get<double>());
  EXPECT_GT(dir.y(), std::cos(30 * M_PI / 180));  // perpendicular to the pull, within 30 degrees
  EXPECT_GT(s.max_cut_opening_mm, 2.0);
}

// vessel-cut: the kidney's tets plus a vessel tree attached to them; the true tube loses the
// segment the cut crosses once the cut has passed it, and the mask holds organ and vessel.
TEST(Generator, VesselCutSeversTheBranchItCrosses) {
  const std::string d = testing::ScratchDir("synth_vessel_cut");
  SynthOptions o = SmallRun("vessel-cut", d);
  o.write_video = false;
  o.kidney_cell_mm = 4.0;
  const SynthSummary s = GenerateSyntheticScene(o);
  EXPECT_EQ(s.unconverged_frames, 0);
  const Scene scene = ReadScene(d + "/scene.json", {false});
  EXPECT_FALSE(scene.model_mesh_path.empty());
  ASSERT_EQ(scene.thin_structures.size(), 1u);
  const ThinStructure& vessel = scene.thin_structures[0];
  EXPECT_EQ(vessel.type, ThinStructureType::kVessel);
  EXPECT_EQ(vessel.attach, ThinAttachment::kModel);
  EXPECT_GT(vessel.radius_mm, 0);
  std::istringstream centreline(Slurp(vessel.centreline_path));
  int polylines = 0;
  for (std::string line; std::getline(centreline, line);) polylines += line.rfind("l ", 0) == 0;
  EXPECT_EQ(polylines, 4);  // trunk + 3 branches
  const auto rest = ThinObjects(d + "/gt/thin/000000.obj");
  const auto last = ThinObjects(d + "/gt/thin/000010.obj");
  ASSERT_EQ(rest.count("vessel"), 1u);
  // Ring of 10 vertices per node, 20 triangles per segment: one segment fewer after the cut.
  EXPECT_EQ(rest.at("vessel").num_faces() - last.at("vessel").num_faces(), 20);
  const cv::Mat mask = cv::imread(d + "/gt/masks/000010.png", cv::IMREAD_UNCHANGED);
  const SurfaceMesh organ = ReadSurfaceMesh(d + "/gt/surface/000010.obj");
  const cv::Mat organ_mask =
      render::RenderMask(render::ToRasterCamera(scene.camera), organ.vertices, organ.faces);
  EXPECT_EQ(cv::countNonZero(organ_mask & ~mask), 0);  // the union holds the organ
}

TEST(Generator, RejectsUnknownScenarioAndBadOptions) {
  SynthOptions o;
  o.out_dir = testing::ScratchDir("synth_bad");
  o.scenario = "liver-explode";
  EXPECT_THROW(GenerateSyntheticScene(o), Error);
  o.scenario = "band-stretch";
  o.frames = 1;
  EXPECT_THROW(GenerateSyntheticScene(o), Error);
  o.frames = 10;
  o.width = 641;
  EXPECT_THROW(GenerateSyntheticScene(o), Error);
}

}  // namespace
}  // namespace arreg::synth
