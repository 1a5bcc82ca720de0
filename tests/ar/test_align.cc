// align: outline distance transform and boundary, the model's projected contour, pose
// recovery on masks rendered from the model itself (with lens distortion, with scale), PnP
// on landmarks, and a fixed subset of the perturbation trials on the synthetic scenes.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>

#include "ar/align/align_eval.h"
#include "ar/align/align_job.h"
#include "core/error.h"
#include "core/file_util.h"
#include "test_align_fixture.h"

namespace arreg::align {
namespace {

using testing::GetAlignScene;

PinholeCamera TestCamera() { return PinholeCamera::FromFieldOfView(640, 512, 60.0); }

TEST(AlignOptions, RobustLossNamesRoundTripAndOthersAreErrors) {
  for (RobustLoss loss : {RobustLoss::kHuber, RobustLoss::kCauchy, RobustLoss::kNone})
    EXPECT_EQ(ParseRobustLoss(RobustLossName(loss), "--loss"), loss);
  EXPECT_EQ(AlignOptions().robust_loss, RobustLoss::kHuber);
  try {
    ParseRobustLoss("Huber", "--loss");
    FAIL() << "'Huber' was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("--loss"), std::string::npos) << e.what();
  }
}

TEST(AlignOutline, DiskSignedDistanceAndBoundary) {
  const PinholeCamera camera = TestCamera();
  cv::Mat mask = cv::Mat::zeros(512, 640, CV_8U);
  const Eigen::Vector2d c(320.0, 256.0);
  const double radius = 80.0;
  for (int y = 0; y < 512; ++y)
    for (int x = 0; x < 640; ++x)
      if ((Eigen::Vector2d(x, y) - c).norm() <= radius) mask.at<uint8_t>(y, x) = 255;
  const Outline o = OutlineFromMask(mask, camera, 3.0, "disk");
  EXPECT_NEAR(o.area_px, M_PI * radius * radius, 2 * M_PI * radius);
  EXPECT_NEAR((o.centroid_px - c).norm(), 0.0, 0.05);
  // The zero level lies half a pixel beyond the last inside centre: on the circle within
  // the binarisation's error.
  EXPECT_NEAR(o.signed_distance_px.at<double>(256, 320), -radius, 0.75);
  EXPECT_NEAR(o.signed_distance_px.at<double>(256, 320 + 100), 100 - radius, 0.75);
  ASSERT_GT(o.boundary_px.rows(), 100);  // ~2 pi r / 3
  for (int i = 0; i < o.boundary_px.rows(); ++i) {
    const Eigen::Vector2d p = o.boundary_px.row(i).transpose();
    EXPECT_NEAR((p - c).norm(), radius, 0.75);
    EXPECT_GT(o.normals.row(i).dot((p - c).normalized().transpose()), 0.9);
  }
}

TEST(AlignOutline, ImageBorderIsNoOutline) {
  const PinholeCamera camera = TestCamera();
  cv::Mat mask = cv::Mat::zeros(512, 640, CV_8U);
  mask(cv::Rect(0, 100, 200, 200)).setTo(255);  // touches the left border
  const Outline o = OutlineFromMask(mask, camera, 2.0, "left");
  // Points near the left border belong to the top and bottom edges only.
  for (int i = 0; i < o.boundary_px.rows(); ++i)
    if (o.boundary_px(i, 0) < 2.0) {
      EXPECT_NEAR(std::fabs(o.boundary_px(i, 1) - 199.5), 100.0, 0.75) << o.boundary_px.row(i);
    }
  // Inside pixels next to the border measure to the real boundary only.
  EXPECT_NEAR(o.signed_distance_px.at<double>(200, 0), -99.5, 0.75);
}

TEST(AlignOutline, PolygonJsonEqualsItsMask) {
  const PinholeCamera camera = TestCamera();
  const std::string dir = testing::ScratchDir("align_polygon");
  {
    std::ofstream f(dir + "/outline.json");
    f << R"({"polygons": [[[100, 100], [300, 100], [300, 250], [100, 250]]]})";
  }
  const Outline o = ReadOutline(dir + "/outline.json", camera, 3.0);
  EXPECT_NEAR(o.area_px, 200.0 * 150.0, 2 * (200 + 150) + 4);
  {
    std::ofstream f(dir + "/bad.json");
    f << R"({"polygons": [[[100, 100], [300, 100]]]})";
  }
  try {
    ReadOutline(dir + "/bad.json", camera, 3.0);
    FAIL() << "a two-point polygon was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("polygons[0]"), std::string::npos) << e.what();
  }
  cv::imwrite(dir + "/small.png", cv::Mat::zeros(100, 100, CV_8U));
  EXPECT_THROW(ReadOutline(dir + "/small.png", camera, 3.0), Error);
}

TEST(AlignLandmarks, ReadAndErrors) {
  const std::string dir = testing::ScratchDir("align_landmarks");
  {
    std::ofstream f(dir + "/l.json");
    f << R"({"landmarks": [{"pixel": [10, 20], "model_point_mm": [1, 2, 3]}]})";
  }
  const std::vector<Landmark> l = ReadLandmarks(dir + "/l.json");
  ASSERT_EQ(l.size(), 1u);
  EXPECT_EQ(l[0].pixel, Eigen::Vector2d(10, 20));
  EXPECT_EQ(l[0].point_in_model, Eigen::Vector3d(1, 2, 3));
  {
    std::ofstream f(dir + "/bad.json");
    f << R"({"landmarks": [{"pixel": [10, 20], "model_point": [1, 2, 3]}]})";
  }
  try {
    ReadLandmarks(dir + "/bad.json");
    FAIL() << "a misspelt key was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("landmarks[0]"), std::string::npos) << e.what();
  }
}

// A camera with strong lens distortion: the solver must project exactly as PinholeCamera.
PinholeCamera DistortedCamera(const PinholeCamera& c) {
  PinholeCamera d = c;
  d.distortion = Distortion::FromVector({-0.25, 0.08, 1e-3, -5e-4, 0.0});
  return d;
}

TEST(AlignContour, SamplesLieOnTheSilhouetteBoundary) {
  const testing::AlignScene& s = GetAlignScene("band-stretch");
  const PinholeCamera camera = DistortedCamera(s.scene.camera);
  const ProjectedModel p = ProjectModel(*s.surface, camera, s.truth, 3.0);
  ASSERT_TRUE(p.valid);
  ASSERT_GT(p.contour.pixels.rows(), 100);
  const Outline own = OutlineFromMask(p.mask, camera, 3.0, "own");
  for (int i = 0; i < p.contour.pixels.rows(); ++i) {
    const int x = static_cast<int>(std::lround(p.contour.pixels(i, 0)));
    const int y = static_cast<int>(std::lround(p.contour.pixels(i, 1)));
    EXPECT_LE(std::fabs(own.signed_distance_px.at<double>(y, x)), 1.5) << i;
    // The sample is the projection of its model point.
    const Eigen::Vector2d q =
        camera.Project(s.truth.Apply(p.contour.points_in_model.row(i).transpose()));
    EXPECT_NEAR((q - p.contour.pixels.row(i).transpose()).norm(), 0.0, 1e-6);
  }
}

TEST(Align, RecoversThePoseOfItsOwnSilhouetteWithDistortion) {
  const testing::AlignScene& s = GetAlignScene("band-stretch");
  const PinholeCamera camera = DistortedCamera(s.scene.camera);
  const Outline outline =
      OutlineFromMask(ProjectModel(*s.surface, camera, s.truth, 3.0).mask, camera, 3.0, "own");
  AlignInput in;
  in.camera = &camera;
  in.surface = s.surface.get();
  in.outline = &outline;
  for (uint64_t seed = 1; seed <= 4; ++seed) {
    std::mt19937_64 rng(seed);
    const TrialResult t = RunPerturbedTrial(in, AlignOptions(), s.truth, 20.0, 20.0, &rng);
    EXPECT_TRUE(t.fits) << seed;
    EXPECT_LT(t.rotation_error_deg, 0.2) << seed;
    EXPECT_LT(t.translation_error_mm, 0.2) << seed;
  }
}

TEST(Align, EstimatesAUniformScale) {
  const testing::AlignScene& s = GetAlignScene("band-stretch");
  const PinholeCamera& camera = s.scene.camera;
  const Outline outline =
      OutlineFromMask(ProjectModel(*s.surface, camera, s.truth, 3.0).mask, camera, 3.0, "own");
  // The same model in units 0.8 times too small (e.g. a mesh exported in the wrong unit).
  SurfaceMesh shrunk;
  shrunk.vertices = 0.8 * s.surface->vertices();
  shrunk.faces = s.surface->faces();
  const ModelSurface small(shrunk);
  AlignInput in;
  in.camera = &camera;
  in.surface = &small;
  in.outline = &outline;
  // Start at the true distance, moved sideways and turned.
  const Eigen::Vector3d true_centroid = s.truth.Apply(s.surface->centroid());
  const double true_depth = (camera.camera_from_world * true_centroid).z();
  ModelPose start = s.truth;
  start.rotation = Eigen::AngleAxisd(0.1, Eigen::Vector3d(1, 1, 0).normalized()) * start.rotation;
  start.translation_mm += true_centroid - start.Apply(small.centroid()) +
                          camera.camera_from_world.linear().transpose() * Eigen::Vector3d(6, -4, 0);
  in.initial_pose = start;
  // Rigid, the smaller model fits by coming nearer: 0.8 of the distance.
  const AlignResult rigid = Align(in, AlignOptions());
  EXPECT_NEAR((camera.camera_from_world * rigid.pose.Apply(small.centroid())).z() / true_depth, 0.8,
              0.02);
  AlignOptions scaled;
  scaled.estimate_scale = true;
  const AlignResult with = Align(in, scaled);
  EXPECT_TRUE(with.fits) << with.failure;
  EXPECT_NEAR(with.pose.scale, 1.25, 0.005);
  EXPECT_LT(RotationErrorDeg(with.pose, s.truth), 0.2);
  EXPECT_LT((with.pose.Apply(small.centroid()) - true_centroid).norm(), 0.3);
}

TEST(Align, LandmarksAloneByPnp) {
  const testing::AlignScene& s = GetAlignScene("band-stretch");
  std::mt19937_64 rng(3);
  AlignInput in;
  in.camera = &s.scene.camera;
  in.surface = s.surface.get();
  in.landmarks =
      SyntheticLandmarks(*s.surface, s.scene.camera, s.truth, s.outline->mask, 6, 0.0, &rng);
  const AlignResult r = Align(in, AlignOptions());
  EXPECT_TRUE(r.fits) << r.failure;
  EXPECT_LT(RotationErrorDeg(r.pose, s.truth), 0.01);
  EXPECT_LT(PointErrorMm(r.pose, s.truth, s.surface->centroid()), 0.01);
  EXPECT_LT(r.landmarks.rms_px, 1e-3);
}

// The fixed subset of `arreg bench align` (100 runs in test_align_slow): the outline alone
// within 2 deg / 2 mm in 90 % of the runs, with 4 landmarks within 1 deg / 1 mm in all.
void CheckPerturbed(const std::string& scenario, int runs) {
  const testing::AlignScene& s = GetAlignScene(scenario);
  int outline_ok = 0, landmarks_ok = 0;
  for (int k = 0; k < runs; ++k) {
    std::mt19937_64 rng(1000 + k);
    const TrialPair t = RunTrialPair(s, AlignOptions(), 20, 20, 4, 0.25, &rng);
    const TrialResult &a = t.outline_only, &b = t.with_landmarks;
    outline_ok += a.fits && a.rotation_error_deg <= 2 && a.translation_error_mm <= 2;
    EXPECT_TRUE(b.fits && b.rotation_error_deg <= 1 && b.translation_error_mm <= 1)
        << scenario << " run " << k << ": " << b.rotation_error_deg << " deg, "
        << b.translation_error_mm << " mm";
    landmarks_ok += b.fits && b.rotation_error_deg <= 1 && b.translation_error_mm <= 1;
  }
  EXPECT_GE(outline_ok, 0.9 * runs) << scenario;
  EXPECT_EQ(landmarks_ok, runs) << scenario;
}

TEST(AlignScenes, KidneyPerturbedSubset) { CheckPerturbed("kidney-cut", 10); }
TEST(AlignScenes, BandPerturbedSubset) { CheckPerturbed("band-stretch", 10); }

TEST(AlignScenes, WrongOrganIsRefused) {
  const testing::AlignScene& kidney = GetAlignScene("kidney-cut");
  const testing::AlignScene& band = GetAlignScene("band-stretch");
  for (const auto& [model, other] : {std::pair{&kidney, &band}, std::pair{&band, &kidney}}) {
    const Outline wrong = OutlineFromMask(other->outline->mask, model->scene.camera, 3.0, "wrong");
    AlignInput in = model->Input();
    in.outline = &wrong;
    in.initial_pose = model->truth;
    const AlignResult r = Align(in, AlignOptions());
    EXPECT_FALSE(r.fits) << "IoU " << r.iou;
    EXPECT_NE(r.failure.find("does not fit"), std::string::npos) << r.failure;
  }
}

// Without an initial pose the search must find the truth or say that it may be elsewhere:
// both organs have near-symmetric outlines in their views.
TEST(AlignScenes, SearchFindsThePoseOrReportsTheAmbiguity) {
  for (const std::string scenario : {"kidney-cut", "band-stretch"}) {
    const testing::AlignScene& s = GetAlignScene(scenario);
    const AlignResult r = Align(s.Input(), AlignOptions());
    EXPECT_TRUE(r.fits) << scenario << ": " << r.failure;
    const bool found = RotationErrorDeg(r.pose, s.truth) <= 2 &&
                       PointErrorMm(r.pose, s.truth, s.surface->centroid()) <= 2;
    EXPECT_TRUE(found || r.ambiguous)
        << scenario << ": " << RotationErrorDeg(r.pose, s.truth) << " deg off";
    // The pose near the truth is among the starts' results.
    bool near_truth = false;
    for (const StartResult& start : r.starts)
      near_truth |= start.valid && RotationErrorDeg(start.final, s.truth) <= 2 &&
                    PointErrorMm(start.final, s.truth, s.surface->centroid()) <= 2;
    EXPECT_TRUE(near_truth) << scenario;
  }
}

TEST(AlignScenes, JobWritesOutputsOrNothing) {
  const testing::AlignScene& band = GetAlignScene("band-stretch");
  const testing::AlignScene& kidney = GetAlignScene("kidney-cut");
  const std::string dir = testing::ScratchDir("align_job");
  // A perturbed copy of the scene as input (the input must stay untouched).
  Scene perturbed = band.scene;
  std::mt19937_64 rng(5);
  perturbed.world_from_model =
      PerturbPose(band.truth, band.surface->centroid(), 15, 15, &rng).Rigid();
  WriteScene(dir + "/in.json", perturbed);
  const std::string before = ReadFileToString(dir + "/in.json");
  AlignJob job;
  job.scene_path = dir + "/in.json";
  job.outline_path = band.dir + "/gt/masks/000000.png";
  job.init_pose = "scene";
  job.out_path = dir + "/out.json";
  const AlignJobResult r = RunAlignJob(job);
  EXPECT_EQ(ReadFileToString(dir + "/in.json"), before);
  ASSERT_TRUE(FileExists(dir + "/out.json"));
  EXPECT_TRUE(FileExists(dir + "/out.overlay.png"));
  EXPECT_TRUE(FileExists(dir + "/out.summary.json"));
  const Scene out = ReadScene(dir + "/out.json", ReadSceneOptions{false});
  const ModelPose got = ModelPose::FromRigid(out.world_from_model);
  EXPECT_LT(RotationErrorDeg(got, band.truth), 0.5);
  EXPECT_LT(PointErrorMm(got, band.truth, band.surface->centroid()), 0.5);
  const nlohmann::json summary = nlohmann::json::parse(ReadFileToString(dir + "/out.summary.json"));
  EXPECT_TRUE(summary["fits"].get<bool>());
  EXPECT_LT(summary["cost_after"].get<double>(), summary["cost_before"].get<double>());
  EXPECT_EQ(summary["starts"].size(), 3u);

  job.outline_path = kidney.dir + "/gt/masks/000000.png";
  job.out_path = dir + "/refused.json";
  try {
    RunAlignJob(job);
    FAIL() << "the kidney's outline was accepted for the band";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("refused"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(FileExists(dir + "/refused.json"));
  EXPECT_FALSE(FileExists(dir + "/refused.overlay.png"));
  EXPECT_FALSE(FileExists(dir + "/refused.summary.json"));
  job.out_path = job.scene_path;
  EXPECT_THROW(RunAlignJob(job), Error);  // never overwrites its input
}

}  // namespace
}  // namespace arreg::align
