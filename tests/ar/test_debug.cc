// Debug records, the annotated PNG and the viewer folder, written from a synthetic run through
// the real recorder and cut detector (test_debug_fixture.h).
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "ar/debug/frame_render.h"
#include "ar/debug/recorder.h"
#include "ar/debug/viewer.h"
#include "core/error.h"
#include "core/file_util.h"
#include "test_debug_fixture.h"
#include "test_util.h"

namespace arreg::debug {
namespace {

namespace fs = std::filesystem;

nlohmann::json ReadJson(const std::string& path) {
  return nlohmann::json::parse(ReadFileToString(path));
}

struct Recorded {
  std::string run;
  std::vector<cutting::DetectionResult> detections;
};

const Recorded& RecordedRun() {
  static const Recorded r = [] {
    Recorded x;
    // One folder per test: ctest runs the tests of this file as parallel processes.
    x.run = ::arreg::testing::ScratchDir(
        std::string("debug_run_") +
        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    x.detections = fixture::RecordRun(x.run);
    return x;
  }();
  return r;
}

TEST(UniqueEdges, ClosedSurfaceHasThreeHalvesEdgesPerFace) {
  SurfaceMesh tet;
  tet.faces.resize(4, 3);
  tet.faces << 0, 2, 1, 0, 1, 3, 1, 2, 3, 0, 3, 2;
  const std::vector<int> e = UniqueEdges(tet.faces);
  EXPECT_EQ(e.size(), 2u * 6u);
  const TetMesh box = MakeBoxTetMesh(Eigen::Vector3d(3, 2, 1), Eigen::Vector3i(3, 2, 1));
  const SurfaceMesh s = ExtractBoundary(box);
  EXPECT_EQ(UniqueEdges(s.faces).size(), 2u * (3u * s.faces.rows() / 2u));
  for (size_t k = 0; k < e.size(); k += 2) EXPECT_LT(e[k], e[k + 1]);
}

TEST(DebugRecorder, OptionsAreChecked) {
  DebugRecorderOptions o;
  EXPECT_THROW(o.Check(), Error);
  o.run_dir = "x";
  o.jpeg_quality = 0;
  EXPECT_THROW(o.Check(), Error);
  o.jpeg_quality = 90;
  o.pixel_decimals = 9;
  EXPECT_THROW(o.Check(), Error);
}

TEST(DebugRecorder, WritesOneRecordAndImagePerFrameAndMeta) {
  const Recorded& r = RecordedRun();
  const nlohmann::json meta = ReadJson(DebugDir(r.run) + "/meta.json");
  EXPECT_EQ(meta["format"], "arreg-debug");
  EXPECT_EQ(meta["frames"], fixture::kFrames);
  EXPECT_EQ(meta["finished"], true);
  EXPECT_EQ(meta["camera"]["width"], fixture::kWidth);
  EXPECT_DOUBLE_EQ(meta["detector"]["outlier_factor"].get<double>(), 4.0);
  for (int t = 0; t < fixture::kFrames; ++t) {
    EXPECT_TRUE(FileExists(FrameRecordPath(r.run, t))) << t;
    const cv::Mat img = cv::imread(FrameImagePath(r.run, t));
    ASSERT_EQ(img.cols, fixture::kWidth);
    // JPEG of the input: close to the original on average.
    EXPECT_LT(cv::norm(img, fixture::MakeImage(t), cv::NORM_L1) / img.total() / 3, 4.0);
  }
}

TEST(DebugRecorder, ProjectionsMatchTheCamera) {
  const Recorded& r = RecordedRun();
  const PinholeCamera camera = fixture::MakeCamera();
  const auto p0 = fixture::InitialPoints();
  const int t = 6;
  const nlohmann::json rec = ReadJson(FrameRecordPath(r.run, t));
  ASSERT_EQ(rec["features"].size(), p0.size());
  for (size_t row = 0; row < p0.size(); ++row) {
    const auto& f = rec["features"][row];
    EXPECT_EQ(f["id"], fixture::IdOfRow(static_cast<int>(row)));
    EXPECT_EQ(f["window_on_instrument"], false);  // no instrument in this scene
    if (static_cast<int>(row) == fixture::kUnattachedRow) {
      EXPECT_FALSE(f.contains("target_px"));
      EXPECT_EQ(f["lift"], "not-attached");
      continue;
    }
    const double shift = p0[row].x() > fixture::kCutXMm ? fixture::kOpeningMmPerFrame * t : 0.0;
    const Eigen::Vector2d target = camera.Project(p0[row] + Eigen::Vector3d(shift, 0, 0));
    const Eigen::Vector2d model =
        camera.Project(p0[row] + Eigen::Vector3d(fixture::ModelShiftMm(t), 0, 0));
    EXPECT_NEAR(f["target_px"][0].get<double>(), target.x(), 0.006);
    EXPECT_NEAR(f["target_px"][1].get<double>(), target.y(), 0.006);
    EXPECT_NEAR(f["model_px"][0].get<double>(), model.x(), 0.006);
    if (static_cast<int>(row) != fixture::kLostRow) {
      EXPECT_NEAR(f["spring_length_mm"].get<double>(), std::abs(shift - fixture::ModelShiftMm(t)),
                  1e-4);
    }
  }
  EXPECT_EQ(rec["features"][fixture::kLostRow]["status"], "lost-flow");
  EXPECT_EQ(rec["features"][fixture::kLostRow]["alive"], false);
  // Model surface and internal structure vertices: projected with the same camera.
  const auto& s = rec["surface_px"];
  EXPECT_NEAR(s[0].get<double>(), camera.Project(Eigen::Vector3d(-40, -30, 200)).x(), 0.006);
  const auto& in = rec["internal"][0];
  EXPECT_EQ(in["name"], "tumour");
  EXPECT_NEAR(in["px"][6].get<double>(), camera.Project(Eigen::Vector3d(0, 0, 212)).x(), 0.006);
}

// Pair indices of the detector refer to the attached features only; the record resolves them to
// ids. A wrong mapping (off by the unattached feature) would pair features farther than r_F.
TEST(DebugRecorder, PairsNameNeighboursByIdAndFlagOutliersAboveTauMean) {
  const Recorded& r = RecordedRun();
  const auto p0 = fixture::InitialPoints();
  std::map<int, Eigen::Vector3d> initial_of_id;
  for (size_t row = 0; row < p0.size(); ++row)
    initial_of_id[fixture::IdOfRow(static_cast<int>(row))] = p0[row];
  int frames_with_outliers = 0, cut_points = 0, bridged = 0;
  for (int t = 0; t < fixture::kFrames; ++t) {
    const nlohmann::json rec = ReadJson(FrameRecordPath(r.run, t));
    const auto& det = rec["detection"];
    const cutting::DetectionResult& d = r.detections[t];
    ASSERT_EQ(det["pairs_bridged"].get<int>(), d.pairs_bridged);
    ASSERT_EQ(det["probe_pairs"].get<int>(), d.probe_pairs);
    ASSERT_EQ(det["probe_outliers"].get<int>(), d.probe_outliers);
    for (size_t i = 0; i < d.new_cut_points.size(); ++i)
      ASSERT_EQ(det["new_cut_points"][i]["probe"].get<bool>(), d.new_cut_points[i].probe);
    bridged += d.pairs_bridged;
    ASSERT_EQ(det["pairs"].size(), d.pairs.size());
    EXPECT_NEAR(det["mean_mu"].get<double>(), d.mean_measure, 1e-12);
    const double threshold = det["threshold"].get<double>();
    EXPECT_NEAR(threshold, std::max(4.0 * d.mean_measure, 0.1), 1e-12);
    int outliers = 0;
    for (const auto& p : det["pairs"]) {
      const int a = p[0].get<int>(), b = p[1].get<int>();
      ASSERT_TRUE(initial_of_id.count(a) && initial_of_id.count(b));
      EXPECT_NE(a, fixture::IdOfRow(fixture::kUnattachedRow));
      // C_F's pairs lie within r_F = 15 mm, the bridges of dead pairs within 2 r_F.
      const double d = (initial_of_id[a] - initial_of_id[b]).norm();
      EXPECT_LT(d, 2 * 15.0) << a << " " << b;
      if (d >= 15.0) {
        EXPECT_GT(bridged, 0) << "frame " << t << ": " << a << " " << b;
      }
      const bool outlier = p[3].get<int>() != 0;
      EXPECT_EQ(outlier, p[2].get<double>() > threshold) << "frame " << t;
      outliers += outlier;
      // Outliers straddle the opening at x = 5 mm.
      if (outlier) {
        EXPECT_TRUE((initial_of_id[a].x() - fixture::kCutXMm) *
                        (initial_of_id[b].x() - fixture::kCutXMm) <
                    0);
      }
    }
    EXPECT_EQ(det["outliers"].get<int>(), outliers);
    EXPECT_EQ(det["lone_features"].get<int>(), d.lone_features);
    EXPECT_EQ(det["one_sided_clusters"].get<int>(), d.one_sided_clusters);
    EXPECT_EQ(det["star_starts"].get<int>(), d.star_starts);
    EXPECT_EQ(det["unconfirmed_starts"].get<int>(), d.unconfirmed_starts);
    EXPECT_EQ(det["closing_starts"].get<int>(), d.closing_starts);
    EXPECT_EQ(det["refused_points"].get<int>(), d.refused_points);
    frames_with_outliers += outliers > 0;
    cut_points += static_cast<int>(det["new_cut_points"].size());
    EXPECT_EQ(det["polyline_px"].size(), d.polyline_mm.size());
    for (const auto& c : det["new_cut_points"]) {
      // Barycentres of straddling pairs lie near the opening (projected x of 5 mm + drift).
      EXPECT_NEAR(c["mm"][0].get<double>(), fixture::kCutXMm, 10.0);
    }
  }
  EXPECT_GE(frames_with_outliers, 3);
  EXPECT_GE(cut_points, 1);
}

TEST(DebugRecorder, TopologyFilesOnlyWhenTheSurfaceChanges) {
  const Recorded& r = RecordedRun();
  const nlohmann::json meta = ReadJson(DebugDir(r.run) + "/meta.json");
  EXPECT_EQ(meta["topology_frames"], nlohmann::json({0, fixture::kTopologyChangeFrame}));
  for (int t = 0; t < fixture::kFrames; ++t)
    EXPECT_EQ(ReadJson(FrameRecordPath(r.run, t))["topology"].get<int>(),
              t < fixture::kTopologyChangeFrame ? 0 : fixture::kTopologyChangeFrame);
  const nlohmann::json t0 = ReadJson(TopologyRecordPath(r.run, 0));
  const nlohmann::json t5 = ReadJson(TopologyRecordPath(r.run, fixture::kTopologyChangeFrame));
  // Splitting one triangle into three adds three edges.
  EXPECT_EQ(t5["surface_edges"].size(), t0["surface_edges"].size() + 6);
  EXPECT_EQ(t0["internal_edges"][0].size(), 12u);
  EXPECT_FALSE(fs::exists(TopologyRecordPath(r.run, 1)));
}

TEST(RenderDebugFrame, DrawsTheLayersOverTheRecordedFrame) {
  const Recorded& r = RecordedRun();
  const std::string dir = ::arreg::testing::ScratchDir("debug_png");
  const std::string none = dir + "/none.png", all = dir + "/all.png", feat = dir + "/feat.png";
  RenderDebugFrame(r.run, 6, DebugLayers::Parse("none"), none);
  RenderDebugFrame(r.run, 6, DebugLayers::Parse("all"), all);
  RenderDebugFrame(r.run, 6, DebugLayers::Parse("features"), feat);
  const cv::Mat a = cv::imread(none), b = cv::imread(all), f = cv::imread(feat);
  ASSERT_FALSE(a.empty());
  // No layers: the recorded JPEG unchanged.
  EXPECT_EQ(cv::norm(a, cv::imread(FrameImagePath(r.run, 6)), cv::NORM_INF), 0.0);
  EXPECT_GT(cv::norm(a, b, cv::NORM_L1), 1000.0);
  // An alive feature is a filled green disc at its pixel.
  const nlohmann::json rec = ReadJson(FrameRecordPath(r.run, 6));
  const auto& px = rec["features"][0]["px"];
  const cv::Vec3b c = f.at<cv::Vec3b>(cvRound(px[1].get<double>()), cvRound(px[0].get<double>()));
  EXPECT_GT(c[1], 180);
  EXPECT_LT(c[0], 60);
  EXPECT_LT(c[2], 60);
  // Outlier layer only: red segments exist where outlier pairs are.
  const std::string out = dir + "/outliers.png";
  RenderDebugFrame(r.run, 6, DebugLayers::Parse("outliers"), out);
  cv::Mat red;
  cv::inRange(cv::imread(out), cv::Scalar(0, 0, 200), cv::Scalar(60, 60, 255), red);
  EXPECT_GT(cv::countNonZero(red), 20);
}

// The instrument mask's outline goes into the record (within the 1.5 px of its simplification)
// and is drawn in orange by the instruments layer only; without a mask the list is empty.
TEST(DebugRecorder, InstrumentOutlinesAreRecordedAndDrawn) {
  cv::Mat mask(120, 160, CV_8UC1, cv::Scalar(0));
  cv::rectangle(mask, cv::Rect(40, 30, 60, 50), cv::Scalar(255), cv::FILLED);
  pipeline::FrameState frame;
  frame.instrument_mask = &mask;
  const PinholeCamera camera = fixture::MakeCamera();
  nlohmann::json rec = MakeFrameRecord(frame, camera, cutting::CutDetectorOptions(), 0);
  ASSERT_EQ(rec["instruments"].size(), 1u);
  const auto& outline = rec["instruments"][0];
  std::vector<cv::Point> poly;
  for (size_t k = 0; k + 1 < outline.size(); k += 2)
    poly.emplace_back(outline[k].get<int>(), outline[k + 1].get<int>());
  const cv::Rect box = cv::boundingRect(poly);
  EXPECT_NEAR(box.x, 40, 1.5);
  EXPECT_NEAR(box.y, 30, 1.5);
  EXPECT_NEAR(box.br().x, 100, 1.5);
  EXPECT_NEAR(box.br().y, 80, 1.5);
  rec["features"] = nlohmann::json::array();
  rec["detection"] = nullptr;
  rec["cut_surface"] = nullptr;
  cv::Mat drawn(120, 160, CV_8UC3, cv::Scalar(0, 0, 0)), none = drawn.clone();
  DrawDebugLayers(rec, nullptr, DebugLayers::Parse("instruments"), &drawn);
  DrawDebugLayers(rec, nullptr, DebugLayers::Parse("features"), &none);
  cv::Mat orange;
  cv::inRange(drawn, cv::Scalar(0, 100, 200), cv::Scalar(60, 180, 255), orange);
  EXPECT_GT(cv::countNonZero(orange), 150);  // the rectangle's perimeter is 220 px
  EXPECT_EQ(cv::countNonZero(orange(cv::Rect(50, 40, 40, 30))), 0);  // an outline, not filled
  EXPECT_EQ(cv::norm(none, cv::NORM_INF), 0.0);
  frame.instrument_mask = nullptr;
  EXPECT_TRUE(
      MakeFrameRecord(frame, camera, cutting::CutDetectorOptions(), 0)["instruments"].empty());
}

TEST(RenderDebugFrame, BadLayerAndMissingFrameAreClearErrors) {
  try {
    DebugLayers::Parse("features,sprngs");
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("sprngs"), std::string::npos);
  }
  const Recorded& r = RecordedRun();
  EXPECT_THROW(RenderDebugFrame(r.run, 99, DebugLayers(), r.run + "/x.png"), Error);
  EXPECT_FALSE(fs::exists(r.run + "/x.png"));
}

TEST(DebugViewer, WritesAFolderWithLazyFrameScriptsAndTracks) {
  const Recorded& r = RecordedRun();
  const std::string out = ::arreg::testing::ScratchDir("debug_viewer") + "/viewer";
  const ViewerSummary s = WriteDebugViewer(r.run, out);
  EXPECT_EQ(s.frames, fixture::kFrames);
  EXPECT_EQ(s.features, static_cast<int>(fixture::InitialPoints().size()));
  EXPECT_EQ(s.topology_files, 2);
  for (const char* f : {"index.html", "viewer.js", "viewer.css", "data/meta.js", "data/tracks.js",
                        "data/topology_000000.js", "frames/000007.jpg"})
    EXPECT_TRUE(fs::exists(out + "/" + f)) << f;
  // Each frame script hands the record unchanged to the viewer.
  const std::string js = ReadFileToString(out + "/data/frame_000003.js");
  const std::string prefix = "window.arregFrame(3, ";
  ASSERT_EQ(js.substr(0, prefix.size()), prefix);
  const std::string body = js.substr(prefix.size(), js.rfind(");") - prefix.size());
  EXPECT_EQ(nlohmann::json::parse(body), ReadJson(FrameRecordPath(r.run, 3)));
  // Tracks: a lost feature keeps its last pixel, so its track ends before the frame it was lost
  // in; the others span every frame.
  const std::string tj = ReadFileToString(out + "/data/tracks.js");
  const std::string tprefix = "window.arregTracks(";
  const nlohmann::json tracks =
      nlohmann::json::parse(tj.substr(tprefix.size(), tj.rfind(");") - tprefix.size()));
  EXPECT_EQ(tracks[std::to_string(fixture::IdOfRow(0))]["f"].size(), size_t(fixture::kFrames));
  EXPECT_EQ(tracks[std::to_string(fixture::IdOfRow(fixture::kLostRow))]["f"].size(),
            size_t(fixture::kLostFrame));
  // No network references: everything is relative.
  std::string html = ReadFileToString(out + "/index.html") + ReadFileToString(out + "/viewer.js");
  const std::string svg_namespace = "http://www.w3.org/2000/svg";  // a name, never fetched
  for (size_t at; (at = html.find(svg_namespace)) != std::string::npos;)
    html.erase(at, svg_namespace.size());
  EXPECT_EQ(html.find("http://"), std::string::npos);
  EXPECT_EQ(html.find("https://"), std::string::npos);
  EXPECT_EQ(html.find("fetch("), std::string::npos);
  // Rewriting replaces the folder whole and leaves no temporaries beside it.
  fs::create_directories(out + "/stale");
  WriteDebugViewer(r.run, out);
  EXPECT_FALSE(fs::exists(out + "/stale"));
  int siblings = 0;
  for (const auto& e : fs::directory_iterator(fs::path(out).parent_path())) (void)e, ++siblings;
  EXPECT_EQ(siblings, 1);
}

TEST(DebugViewer, RunWithoutRecordsIsAClearError) {
  const std::string dir = ::arreg::testing::ScratchDir("debug_viewer_empty");
  try {
    WriteDebugViewer(dir, dir + "/viewer");
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("--debug"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(dir + "/viewer"));
}

}  // namespace
}  // namespace arreg::debug
