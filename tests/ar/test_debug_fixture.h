// A small synthetic run recorded through the real DebugRecorder: a plane of features seen by a
// pinhole camera, the right half of which opens away (a cut), run through the real CutDetector.
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "ar/debug/recorder.h"
#include "ar/pipeline/pipeline_options.h"
#include "core/mesh_generators.h"
#include "core/mesh_ops.h"
#include "core/scene.h"
#include "cutting/detection.h"

namespace arreg::debug::fixture {

constexpr int kFrames = 8;
constexpr int kWidth = 320, kHeight = 256;
constexpr double kDepthMm = 200.0;
constexpr double kCutXMm = 5.0;  // features right of x = 5 mm drift away
constexpr double kOpeningMmPerFrame = 2.0;
// The uncut model, held by the springs of both sides, lies half-way across the opening: each
// lip's target is half the opening from its model point, as across a real cut (the detector
// asks a new cut of both lips, cutting::CutDetectorOptions::min_opening_balance).
inline double ModelShiftMm(int frame) { return 0.5 * kOpeningMmPerFrame * frame; }
constexpr int kUnattachedRow = 3;  // never attached: detector indices skip it
constexpr int kLostRow = 10;       // lost at frame kLostFrame
constexpr int kLostFrame = 2;
constexpr int kTopologyChangeFrame = 5;  // the model surface changes topology here

inline int IdOfRow(int r) { return 100 + 3 * r; }

inline PinholeCamera MakeCamera() {
  PinholeCamera c;
  c.width = kWidth;
  c.height = kHeight;
  c.fx = c.fy = 300.0;
  c.cx = 160.0;
  c.cy = 128.0;
  return c;
}

// Textured input frame: gradient, circles and the frame number, so screenshots are not blank.
inline cv::Mat MakeImage(int frame) {
  cv::Mat img(kHeight, kWidth, CV_8UC3);
  for (int y = 0; y < kHeight; ++y)
    for (int x = 0; x < kWidth; ++x)
      img.at<cv::Vec3b>(y, x) =
          cv::Vec3b(static_cast<uchar>(60 + x / 4), static_cast<uchar>(40 + y / 4),
                    static_cast<uchar>(90 + ((x + y + 7 * frame) % 40)));
  for (int k = 0; k < 12; ++k)
    cv::circle(img, cv::Point(20 + 25 * k, 40 + 13 * ((k * 5 + frame) % 13)), 6,
               cv::Scalar(30, 160, 200), -1, cv::LINE_AA);
  return img;
}

struct Features {
  std::vector<Eigen::Vector3d> initial_mm;  // p^0 per row (plane z = kDepthMm)
};

inline std::vector<Eigen::Vector3d> InitialPoints() {
  std::vector<Eigen::Vector3d> p;
  for (int iy = 0; iy < 7; ++iy)
    for (int ix = 0; ix < 9; ++ix) p.emplace_back(-40.0 + 10.0 * ix, -30.0 + 10.0 * iy, kDepthMm);
  return p;
}

// Records kFrames frames into run_dir/debug with the real recorder and detector. Returns the
// detection results per frame (for tests that compare against the records).
inline std::vector<cutting::DetectionResult> RecordRun(const std::string& run_dir) {
  const PinholeCamera camera = MakeCamera();
  Scene scene;
  scene.camera = camera;
  pipeline::PipelineOptions options;
  // The fixture's features are laid out for r_F = 15 mm (a few neighbours each), not the
  // default radius from the spacing of a dense field.
  options.cutting.detector.neighbours_per_feature = 0;
  options.cutting.detector.neighbour_radius_mm = 15.0;
  options.cutting.detector.outlier_factor = 4.0;
  options.cutting.detector.min_outliers = 4;
  const std::vector<Eigen::Vector3d> p0 = InitialPoints();
  const int nf = static_cast<int>(p0.size());

  std::vector<pipeline::FeatureView> features(nf);
  std::vector<int> detector_ids;
  for (int r = 0; r < nf; ++r) {
    features[r].id = IdOfRow(r);
    if (r == kUnattachedRow) {
      features[r].lift_status = lift::LiftStatus::kNotAttached;
      continue;
    }
    features[r].spring = static_cast<int>(detector_ids.size());
    features[r].alive = features[r].spring_active = features[r].attached = true;
    features[r].lift_status = lift::LiftStatus::kSurfaceHit;
    detector_ids.push_back(r);
  }
  RowMatX3d p0_attached(detector_ids.size(), 3);
  for (size_t i = 0; i < detector_ids.size(); ++i)
    p0_attached.row(i) = p0[detector_ids[i]].transpose();
  cutting::CutDetector detector(options.cutting.detector);
  detector.Initialize(p0_attached, detector_ids);

  // Model: a box in front of the camera; its surface gains a face at kTopologyChangeFrame.
  TetMesh box = MakeBoxTetMesh(Eigen::Vector3d(80, 60, 20), Eigen::Vector3i(4, 3, 1));
  for (Eigen::Index v = 0; v < box.vertices.rows(); ++v)
    box.vertices.row(v) += Eigen::RowVector3d(-40, -30, kDepthMm);
  SurfaceMesh surface = ExtractBoundary(box);
  std::vector<SurfaceMesh> internal(1);
  internal[0].vertices.resize(4, 3);
  internal[0].vertices << -5, -5, 205, 5, -5, 205, 0, 5, 205, 0, 0, 212;
  internal[0].faces.resize(4, 3);
  internal[0].faces << 0, 2, 1, 0, 1, 3, 1, 2, 3, 0, 3, 2;
  const std::vector<std::string> internal_names = {"tumour"};
  SurfaceMesh cut_surface;
  cut_surface.vertices.resize(4, 3);
  cut_surface.vertices << kCutXMm, -30, 190, kCutXMm, 30, 190, kCutXMm, 30, 215, kCutXMm, -30, 215;
  cut_surface.faces.resize(2, 3);
  cut_surface.faces << 0, 1, 2, 0, 2, 3;

  DebugRecorderOptions ro;
  ro.run_dir = run_dir;
  DebugRecorder recorder(ro);
  pipeline::RunStart start;
  start.scene = &scene;
  start.options = &options;
  start.expected_frames = kFrames;
  start.fps = 10.0;
  start.width = kWidth;
  start.height = kHeight;
  start.features_detected = nf;
  start.features_attached = static_cast<int>(detector_ids.size());
  start.detector = &detector.options();
  recorder.OnStart(start);

  std::vector<cutting::DetectionResult> results;
  RowMatX3d targets(nf, 3), anchors(nf, 3);
  for (int t = 0; t < kFrames; ++t) {
    cutting::FrameFeatures ff;
    std::vector<int> ff_rows;
    for (int r = 0; r < nf; ++r) {
      const double shift = p0[r].x() > kCutXMm ? kOpeningMmPerFrame * t : 0.0;
      const Eigen::Vector3d target = p0[r] + Eigen::Vector3d(shift, 0, 0);
      const Eigen::Vector3d anchor = p0[r] + Eigen::Vector3d(ModelShiftMm(t), 0, 0);
      targets.row(r) = target.transpose();
      anchors.row(r) = anchor.transpose();
      pipeline::FeatureView& v = features[r];
      v.pixel = camera.Project(target);
      if (r == kLostRow && t >= kLostFrame) {
        v.track_status = TrackStatus::kLostFlow;
        v.alive = v.spring_active = false;
        v.lift_status = lift::LiftStatus::kLost;
        v.spring_length_mm = 0;
        v.pixel = camera.Project(
            p0[r] + Eigen::Vector3d(p0[r].x() > kCutXMm ? kOpeningMmPerFrame : 0, 0, 0));
      } else if (v.alive) {
        v.spring_length_mm = (target - anchor).norm();
      }
      if (v.alive) ff_rows.push_back(r);
    }
    // Detector ids are rows; FrameFeatures rows follow ff_rows.
    ff.ids = ff_rows;
    ff.target_mm.resize(ff_rows.size(), 3);
    ff.model_mm.resize(ff_rows.size(), 3);
    for (size_t i = 0; i < ff_rows.size(); ++i) {
      ff.target_mm.row(i) = targets.row(ff_rows[i]);
      ff.model_mm.row(i) = anchors.row(ff_rows[i]);
    }
    cutting::DetectionResult detection;
    detector.Update(ff, &detection);
    results.push_back(detection);

    if (t == kTopologyChangeFrame) {
      // Split the first face into three around its centroid: a new topology.
      const Eigen::RowVector3i f = surface.faces.row(0);
      const Eigen::RowVector3d c =
          (surface.vertices.row(f(0)) + surface.vertices.row(f(1)) + surface.vertices.row(f(2))) /
          3.0;
      const int nv = surface.num_vertices();
      surface.vertices.conservativeResize(nv + 1, 3);
      surface.vertices.row(nv) = c;
      const int nfaces = surface.num_faces();
      surface.faces.conservativeResize(nfaces + 2, 3);
      surface.faces.row(0) << f(0), f(1), nv;
      surface.faces.row(nfaces) << f(1), f(2), nv;
      surface.faces.row(nfaces + 1) << f(2), f(0), nv;
    }
    const cv::Mat image = MakeImage(t);
    std::vector<pipeline::CutEvent> events;
    if (!detection.new_cut_points.empty()) {
      pipeline::CutEvent e;
      e.frame = t;
      e.status = pipeline::CutEventStatus::kNoCrossing;
      e.polyline_points = static_cast<int>(detection.polyline_mm.size());
      events.push_back(e);
    }
    pipeline::FrameState fs;
    fs.frame = t;
    fs.time_s = t / 10.0;
    fs.is_last = t + 1 == kFrames;
    fs.image = &image;
    fs.features = &features;
    fs.targets_mm = &targets;
    fs.anchors_mm = &anchors;
    fs.detection = &detection;
    fs.cut_events = &events;
    fs.cut_surface = t >= 4 ? &cut_surface : nullptr;
    fs.surface = &surface;
    fs.internal = &internal;
    fs.internal_names = &internal_names;
    fs.stats.features_alive = static_cast<int>(ff_rows.size());
    fs.stats.lost = t == kLostFrame ? 1 : 0;
    fs.stats.mechanics_status = "converged";
    fs.ms.track = 1.5 + t;
    fs.ms.mechanics = 2.0;
    recorder.OnFrame(fs);
  }
  pipeline::RunSummary summary;
  summary.frames = kFrames;
  recorder.OnFinish(summary);
  return results;
}

}  // namespace arreg::debug::fixture
