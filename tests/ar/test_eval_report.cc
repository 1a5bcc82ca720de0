// End-to-end `arreg eval` on hand-built run and ground-truth folders whose
// metrics are known in closed form, plus the input errors it must name.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <utility>
#include <vector>

#include "ar/eval/color_map.h"
#include "ar/eval/dice.h"
#include "ar/eval/evaluation.h"
#include "core/camera.h"
#include "core/error.h"
#include "core/file_util.h"
#include "core/json_reader.h"
#include "core/mesh_io.h"
#include "test_eval_fixtures.h"
#include "test_util.h"

namespace arreg::eval {
namespace {

using namespace fixtures;  // test_eval_fixtures.h

EvalOptions FastOptions() {
  EvalOptions o;
  o.hausdorff.sampling.min_random_samples = 2000;
  return o;
}

TEST(EvalReport, MetricsOfAHandBuiltRunMatchTheClosedForm) {
  const Folders f = MakeFolders("eval_report_metrics");
  EvalOptions options = FastOptions();
  std::vector<std::pair<int, int>> progress;
  options.progress = [&](int done, int total) { progress.emplace_back(done, total); };
  const RunEvaluation ev = EvaluateRun(f.run.string(), f.gt.string(), options);
  const std::vector<std::pair<int, int>> expected_progress = {{1, 3}, {2, 3}, {3, 3}};
  EXPECT_EQ(progress, expected_progress);
  ASSERT_EQ(ev.frames.size(), 3u);
  EXPECT_DOUBLE_EQ(*ev.frames[0].dice, 1.0);
  EXPECT_DOUBLE_EQ(*ev.frames[1].dice, 0.75);
  EXPECT_DOUBLE_EQ(*ev.frames[2].dice, 6.0 / 7.0);
  EXPECT_DOUBLE_EQ(ev.dice_final, 6.0 / 7.0);
  EXPECT_NEAR(ev.dice_mean, (1.0 + 0.75 + 6.0 / 7.0) / 3.0, 1e-15);

  EXPECT_FALSE(ev.frames[1].surface.has_value());
  ASSERT_TRUE(ev.frames[2].surface.has_value());
  EXPECT_NEAR(ev.frames[0].surface->max, 0.0, 1e-12);
  EXPECT_NEAR(ev.frames[2].surface->mean_model_to_gt, 3.0, 1e-9);
  EXPECT_NEAR(ev.frames[2].surface->max_gt_to_model, 3.0, 1e-9);
  ASSERT_TRUE(ev.surface.has_value());
  EXPECT_NEAR(ev.surface->mean_model_to_gt, 1.5, 1e-9);  // mean over frames 0 and 2
  EXPECT_NEAR(ev.surface->mean_gt_to_model, 1.5, 1e-9);
  EXPECT_NEAR(ev.surface->max_model_to_gt, 3.0, 1e-9);  // largest over frames
  EXPECT_NEAR(ev.surface->max, 3.0, 1e-9);
  ASSERT_TRUE(ev.internal.has_value());
  EXPECT_NEAR(ev.internal->mean_model_to_gt, 0.25, 1e-9);
  EXPECT_NEAR(ev.internal->max, 0.5, 1e-9);

  EXPECT_DOUBLE_EQ(*ev.feature_error_mean_mm, 1.5);  // frame 2 logged null
  EXPECT_DOUBLE_EQ(*ev.feature_error_max_mm, 4.0);
  EXPECT_FALSE(ev.frames[2].feature_error_mean_mm.has_value());

  // Colour maps at frame 2, both directions, surface and internal structures.
  ASSERT_EQ(ev.distance_fields.size(), 4u);
  EXPECT_EQ(ev.distance_fields[0].name, "surface_model_to_gt");
  EXPECT_EQ(ev.distance_fields[0].frame, 2);
  EXPECT_NEAR(ev.distance_fields[0].distances.maxCoeff(), 3.0, 1e-9);
  EXPECT_NEAR(ev.distance_fields[0].scale_max_mm, 3.0, 1e-9);
  EXPECT_EQ(ev.distance_fields[2].mesh.num_faces(), 4);  // two objects of the internal OBJ
}

TEST(EvalReport, WritesJsonCsvHtmlAndColourMaps) {
  const Folders f = MakeFolders("eval_report_files");
  const EvalOptions o = FastOptions();
  const RunEvaluation run = EvaluateRun(f.run.string(), f.gt.string(), o);
  const RunEvaluation base = EvaluateRun(f.baseline.string(), f.gt.string(), o);
  WriteEvalReport(f.out.string(), f.gt.string(), run, &base, o);

  const nlohmann::json report = ParseJsonFile((f.out / "report.json").string());
  EXPECT_DOUBLE_EQ(report.at("dice_final").get<double>(), 6.0 / 7.0);
  for (const char* key : {"hausdorff_surface", "hausdorff_internal"})
    for (const char* part :
         {"mean_model_to_gt", "mean_gt_to_model", "max_model_to_gt", "max_gt_to_model", "max"})
      EXPECT_TRUE(report.at(key).at(part).is_number()) << key << "." << part;
  EXPECT_NEAR(report.at("hausdorff_surface").at("max").get<double>(), 3.0, 1e-9);
  EXPECT_DOUBLE_EQ(report.at("feature_error_mm").at("mean").get<double>(), 1.5);
  EXPECT_DOUBLE_EQ(report.at("feature_error_mm").at("max").get<double>(), 4.0);
  ASSERT_EQ(report.at("frames").size(), 3u);
  EXPECT_DOUBLE_EQ(report.at("frames")[1].at("dice").get<double>(), 0.75);
  EXPECT_TRUE(report.at("frames")[1].at("hausdorff_surface").is_null());
  EXPECT_FALSE(report.at("baseline").at("topology").get<bool>());
  // A run without thin structures keeps its keys and columns.
  EXPECT_FALSE(report.contains("thin_structures"));
  EXPECT_FALSE(report.at("frames")[0].contains("thin"));

  std::istringstream csv(ReadFileToString((f.out / "report.csv").string()));
  std::string line;
  int rows = 0;
  std::getline(csv, line);
  EXPECT_EQ(line.rfind("run,frame,dice,hausdorff_surface_mean_model_to_gt", 0), 0u);
  while (std::getline(csv, line)) {
    ++rows;
    EXPECT_EQ(std::count(line.begin(), line.end(), ','), 14) << line;
  }
  EXPECT_EQ(rows, 6);  // 3 frames x (run, baseline)

  const std::string html = ReadFileToString((f.out / "report.html").string());
  EXPECT_NE(html.find("<svg class=\"plot\" id=\"plot-dice\""), std::string::npos);
  EXPECT_NE(html.find("with topology"), std::string::npos);
  EXPECT_NE(html.find("without topology"), std::string::npos);
  EXPECT_NE(html.find("data:image/png;base64,"), std::string::npos);
  EXPECT_EQ(html.find("<script"), std::string::npos);
  EXPECT_EQ(html.find("http://"),
            html.find("http://www.w3.org/2000/svg"));  // only the SVG namespace

  // Colour-map mesh: vertices carry the colour of their distance (3 mm = top of the scale).
  const std::string obj =
      ReadFileToString((f.out / "colormaps" / "surface_model_to_gt_000002.obj").string());
  std::istringstream in(obj);
  int coloured_vertices = 0;
  const Eigen::Vector3f top = ViridisColor(1.0);
  while (std::getline(in, line)) {
    if (line.rfind("v ", 0) != 0) continue;
    std::istringstream v(line.substr(2));
    double x, y, z, r, g, b;
    ASSERT_TRUE(v >> x >> y >> z >> r >> g >> b) << line;
    EXPECT_NEAR(r, top[0], 1e-3);
    EXPECT_NEAR(g, top[1], 1e-3);
    EXPECT_NEAR(b, top[2], 1e-3);
    ++coloured_vertices;
  }
  EXPECT_EQ(coloured_vertices, 4);
  const cv::Mat image =
      cv::imread((f.out / "colormaps" / "surface_model_to_gt_000002.png").string());
  ASSERT_FALSE(image.empty());
  EXPECT_EQ(image.rows, 120);
  EXPECT_GT(image.cols, 160);  // view plus legend
  EXPECT_TRUE(fs::exists(f.out / "colormaps" / "baseline_internal_gt_to_model_000002.png"));
  EXPECT_EQ(report.at("overlap_images").size(), 0u);  // off by default
  EXPECT_FALSE(fs::exists(f.out / "overlap"));
}

// With overlap images, one PNG per frame with a Dice for each run, listed in report.json; its
// grey pixels are the Dice's intersection.
TEST(EvalReport, WritesOverlapImagesWhenAsked) {
  const Folders f = MakeFolders("eval_report_overlap");
  EvalOptions o = FastOptions();
  o.color_maps = false;
  o.overlap_images = true;
  const RunEvaluation run = EvaluateRun(f.run.string(), f.gt.string(), o);
  const RunEvaluation base = EvaluateRun(f.baseline.string(), f.gt.string(), o);
  WriteEvalReport(f.out.string(), f.gt.string(), run, &base, o);
  const nlohmann::json report = ParseJsonFile((f.out / "report.json").string());
  const size_t frames_with_dice = run.overlap_pngs.size();
  ASSERT_EQ(frames_with_dice, 3u);
  EXPECT_EQ(report.at("overlap_images").size(), frames_with_dice + base.overlap_pngs.size());
  EXPECT_EQ(report.at("overlap_images")[0].get<std::string>(), "overlap/000000.png");
  EXPECT_TRUE(fs::exists(f.out / "overlap" / "baseline_000002.png"));
  const cv::Mat image = cv::imread((f.out / "overlap" / "000001.png").string());
  ASSERT_FALSE(image.empty());
  EXPECT_EQ(image.cols, run.camera.width);
  EXPECT_EQ(image.rows, run.camera.height);
  int both = 0, differ = 0;
  for (int y = 0; y < image.rows; ++y)
    for (int x = 0; x < image.cols; ++x) {
      both += image.at<cv::Vec3b>(y, x) == kOverlapBoth;
      differ += image.at<cv::Vec3b>(y, x) == kOverlapTruthOnly ||
                image.at<cv::Vec3b>(y, x) == kOverlapModelOnly;
    }
  ASSERT_GT(both + differ, 0);
  EXPECT_DOUBLE_EQ(2.0 * both / (2.0 * both + differ), 0.75);  // frame 1's Dice
}

TEST(EvalReport, ErrorsNameTheOffendingFile) {
  const Folders f = MakeFolders("eval_report_errors");
  const auto expect_error_naming = [&](const fs::path& run, const std::string& needle) {
    try {
      EvaluateRun(run.string(), f.gt.string(), FastOptions());
      ADD_FAILURE() << "no error, expected one naming " << needle;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  expect_error_naming(f.root / "missing", "run.json");

  // frames.jsonl shorter than run.json's frame count.
  const fs::path short_log = f.root / "short_log";
  MakeRun(short_log, true);
  WriteText(short_log / "frames.jsonl", "{\"frame\": 0}\n{\"frame\": 1}\n");
  expect_error_naming(short_log, "frames.jsonl");

  // More frames than the ground truth has.
  const fs::path too_long = f.root / "too_long";
  MakeRun(too_long, true);
  nlohmann::json j = ParseJsonFile((too_long / "run.json").string());
  j["frames"] = 4;
  WriteText(too_long / "run.json", j.dump());
  expect_error_naming(too_long, "run.json");

  // A corrupt mask.
  WriteText(f.gt / "masks" / (Name(1) + ".png"), "not a png");
  expect_error_naming(f.run, "masks/000001.png");
  WriteMask(f.gt / "masks" / (Name(1) + ".png"), cv::Rect(70, 40, 40, 40));

  // A mask of the wrong size.
  cv::imwrite((f.gt / "masks" / (Name(2) + ".png")).string(), cv::Mat::zeros(60, 80, CV_8U));
  expect_error_naming(f.run, "masks/000002.png");
}

TEST(EvalReport, InterruptedRunIsEvaluatedOnItsFrames) {
  const Folders f = MakeFolders("eval_report_interrupted");
  nlohmann::json j = ParseJsonFile((f.run / "run.json").string());
  j["frames"] = 2;
  WriteText(f.run / "run.json", j.dump());
  WriteText(f.run / "frames.jsonl", "{\"frame\": 0}\n{\"frame\": 1}\n");
  EXPECT_THROW(EvaluateRun(f.run.string(), f.gt.string(), FastOptions()), Error);
  j["interrupted"] = true;
  WriteText(f.run / "run.json", j.dump());
  const RunEvaluation ev = EvaluateRun(f.run.string(), f.gt.string(), FastOptions());
  EXPECT_EQ(ev.frames.size(), 2u);
  EXPECT_DOUBLE_EQ(ev.dice_final, 0.75);
  EXPECT_FALSE(ev.feature_error_mean_mm.has_value());
}

TEST(EvalReport, FramesWithoutARunSurfaceAreSummarisedInOneWarning) {
  const Folders f = MakeFolders("eval_report_missing_surfaces");
  // The truth has surfaces at frames 0 and 2; the run keeps only frame 1's.
  fs::remove(f.run / "surface" / (Name(0) + ".obj"));
  fs::remove(f.run / "surface" / (Name(2) + ".obj"));
  ::testing::internal::CaptureStderr();
  const RunEvaluation ev = EvaluateRun(f.run.string(), f.gt.string(), FastOptions());
  const std::string err = ::testing::internal::GetCapturedStderr();
  EXPECT_EQ(std::count(err.begin(), err.end(), '\n'), 1) << err;
  EXPECT_NE(err.find("no surface at 2 frames"), std::string::npos) << err;
  EXPECT_NE(err.find("(first 0, last 2)"), std::string::npos) << err;
  EXPECT_TRUE(ev.frames[1].dice.has_value());
  EXPECT_FALSE(ev.frames[0].dice.has_value());
  EXPECT_FALSE(ev.surface.has_value());

  // A single such frame is named.
  WriteText(f.run / "surface" / (Name(2) + ".obj"), SquareObj(-10, -10, 100, 20));
  ::testing::internal::CaptureStderr();
  EvaluateRun(f.run.string(), f.gt.string(), FastOptions());
  const std::string one = ::testing::internal::GetCapturedStderr();
  EXPECT_EQ(std::count(one.begin(), one.end(), '\n'), 1) << one;
  EXPECT_NE(one.find("no surface at frame 0 "), std::string::npos) << one;
}

// Thin structures (run.json `thin_structures`): two sheets, "a" identical to the truth and "b"
// 10 mm farther from the camera than the true one at frame 1, beside the organ square.
// Per structure: Dice 1 and Hausdorff 0 for "a"; Hausdorff exactly d (parallel sheets with
// the same outline offset along their normal) for "b" at frame 1. The union silhouette of the
// identical frame 0 has Dice 1 exactly (the mask is the union rasterised with the same camera).
TEST(EvalReport, ThinStructuresGetUnionAndPerStructureFigures) {
  const fs::path root = ::arreg::testing::ScratchDir("eval_report_thin");
  const fs::path gt = root / "gt", run = root / "run", out = root / "report";
  const PinholeCamera camera = TestCamera();
  WriteText(gt / "meta.json", R"({"units": "mm", "frames": 2, "width": 160, "height": 120})");
  const std::string organ = SquareObj(-10, -10, 100, 12);
  const double d = 10.0;
  for (int frame = 0; frame < 2; ++frame) {
    const std::string gt_thin = SquareObj(3, -8, 100, 6, 0, "a") + SquareObj(-9, 4, 105, 5, 4, "b");
    WriteText(gt / "thin" / (Name(frame) + ".obj"), gt_thin);
    WriteText(gt / "surface" / (Name(frame) + ".obj"), organ);
    cv::Mat mask = RenderSilhouette(
        camera, ReadSurfaceMesh((gt / "surface" / (Name(frame) + ".obj")).string()));
    for (const auto& [name, mesh] : ReadObjObjects((gt / "thin" / (Name(frame) + ".obj")).string()))
      cv::bitwise_or(mask, RenderSilhouette(camera, mesh), mask);
    fs::create_directories(gt / "masks");
    ASSERT_TRUE(cv::imwrite((gt / "masks" / (Name(frame) + ".png")).string(), mask));
    WriteText(run / "surface" / (Name(frame) + ".obj"), organ);
    // The run's file lists the objects in another order than run.json (matched by name).
    WriteText(run / "thin" / (Name(frame) + ".obj"),
              SquareObj(-9, 4, 105 + (frame == 1 ? d : 0.0), 5, 0, "b") +
                  SquareObj(3, -8, 100, 6, 4, "a"));
  }
  nlohmann::json j;
  j["camera"] = CameraToJson(camera);
  j["frames"] = 2;
  j["thin_structures"] = {"a", "b"};
  WriteText(run / "run.json", j.dump(2));
  WriteText(run / "frames.jsonl", "{\"frame\": 0}\n{\"frame\": 1}\n");

  const EvalOptions o = FastOptions();
  const RunEvaluation ev = EvaluateRun(run.string(), gt.string(), o);
  ASSERT_EQ(ev.thin.size(), 2u);
  EXPECT_EQ(ev.thin[0].name, "a");
  ASSERT_TRUE(ev.frames[0].dice && ev.frames[1].dice);
  EXPECT_DOUBLE_EQ(*ev.frames[0].dice, 1.0);
  EXPECT_LT(*ev.frames[1].dice, 1.0);
  for (int frame = 0; frame < 2; ++frame) {
    const ThinFrameFigures& a = ev.frames[frame].thin[0];
    ASSERT_TRUE(a.dice && a.hausdorff);
    EXPECT_DOUBLE_EQ(*a.dice, 1.0);
    EXPECT_NEAR(a.hausdorff->max, 0.0, 1e-9);
  }
  const ThinFrameFigures& b1 = ev.frames[1].thin[1];
  ASSERT_TRUE(b1.dice && b1.hausdorff);
  EXPECT_LT(*b1.dice, 1.0);  // farther: a smaller silhouette
  EXPECT_GT(*b1.dice, 0.7);
  EXPECT_NEAR(b1.hausdorff->max, d, 1e-9);
  EXPECT_NEAR(b1.hausdorff->mean_model_to_gt, d, 1e-9);
  EXPECT_NEAR(b1.hausdorff->mean_gt_to_model, d, 1e-9);
  ASSERT_TRUE(ev.thin[1].hausdorff && ev.thin[1].dice_mean);
  EXPECT_NEAR(ev.thin[1].hausdorff->max, d, 1e-9);
  EXPECT_NEAR(ev.thin[1].hausdorff->mean_model_to_gt, d / 2, 1e-9);  // 0 and d over two frames
  EXPECT_DOUBLE_EQ(*ev.thin[1].dice_final, *b1.dice);
  EXPECT_DOUBLE_EQ(*ev.thin[1].dice_mean, (1.0 + *b1.dice) / 2);

  WriteEvalReport(out.string(), gt.string(), ev, nullptr, o);
  const nlohmann::json report = ParseJsonFile((out / "report.json").string());
  ASSERT_EQ(report.at("thin_structures").size(), 2u);
  EXPECT_EQ(report.at("thin_structures")[1].at("name"), "b");
  EXPECT_NEAR(report.at("thin_structures")[1].at("hausdorff").at("max").get<double>(), d, 1e-9);
  EXPECT_DOUBLE_EQ(report.at("frames")[0].at("thin").at("a").at("dice").get<double>(), 1.0);
  const std::string csv = ReadFileToString((out / "report.csv").string());
  EXPECT_NE(csv.find(",thin_a_dice,"), std::string::npos);
  EXPECT_NE(csv.find(",thin_b_hausdorff_max"), std::string::npos);
  const std::string html = ReadFileToString((out / "report.html").string());
  EXPECT_NE(html.find("id=\"thin-structures\""), std::string::npos);
  EXPECT_NE(html.find("id=\"plot-thin-dice\""), std::string::npos);

  // A structure run.json lists but the OBJ lacks: one error naming the file and the object.
  WriteText(run / "thin" / (Name(1) + ".obj"), SquareObj(3, -8, 100, 6, 0, "a"));
  try {
    EvaluateRun(run.string(), gt.string(), o);
    FAIL() << "missing object accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("thin/000001.obj"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("o b"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace arreg::eval
