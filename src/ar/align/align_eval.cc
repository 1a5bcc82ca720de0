#include "ar/align/align_eval.h"

#include <ctime>
#include <limits>

#include "ar/align/align_job.h"
#include "core/error.h"

namespace arreg::align {

std::vector<Landmark> SyntheticLandmarks(const ModelSurface& surface, const PinholeCamera& camera,
                                         const ModelPose& truth, const cv::Mat& mask, int count,
                                         double noise_px, std::mt19937_64* rng) {
  // Vertex normals (area-weighted) to keep vertices seen nearly head-on: those are visible on
  // a compact organ and their pixel is well defined.
  const RowMatX3d& v = surface.vertices();
  RowMatX3d normals = RowMatX3d::Zero(v.rows(), 3);
  for (int f = 0; f < surface.faces().rows(); ++f)
    for (int k = 0; k < 3; ++k) normals.row(surface.faces()(f, k)) += surface.face_normals().row(f);
  const Eigen::Vector3d eye = camera.CenterInWorld();
  std::vector<int> candidates;
  std::vector<Eigen::Vector2d> pixels;
  for (int i = 0; i < v.rows(); ++i) {
    const Eigen::Vector3d w = truth.Apply(v.row(i).transpose());
    const Eigen::Vector3d n = (truth.rotation * normals.row(i).transpose()).normalized();
    if (n.dot((eye - w).normalized()) < 0.5) continue;
    const Eigen::Vector2d p = camera.Project(w);
    if (!camera.IsInImage(p, 5.0)) continue;
    if (mask.at<uint8_t>(static_cast<int>(std::lround(p.y())),
                         static_cast<int>(std::lround(p.x()))) == 0)
      continue;
    candidates.push_back(i);
    pixels.push_back(p);
  }
  ARREG_CHECK_INPUT(static_cast<int>(candidates.size()) >= count, "", "landmarks", "only ",
                    candidates.size(), " model vertices are visible head-on");
  // Farthest-point sampling from the vertex nearest to the mask's centroid.
  std::vector<int> chosen = {0};
  std::vector<double> d2(candidates.size(), std::numeric_limits<double>::infinity());
  while (static_cast<int>(chosen.size()) < count) {
    int next = 0;
    for (size_t i = 0; i < candidates.size(); ++i) {
      d2[i] = std::min(d2[i], (pixels[i] - pixels[chosen.back()]).squaredNorm());
      if (d2[i] > d2[next]) next = static_cast<int>(i);
    }
    chosen.push_back(next);
  }
  std::normal_distribution<double> noise(0.0, noise_px);
  std::vector<Landmark> out;
  for (int c : chosen) {
    Landmark l;
    l.point_in_model = v.row(candidates[c]).transpose();
    l.pixel = pixels[c] + Eigen::Vector2d(noise(*rng), noise(*rng));
    out.push_back(l);
  }
  return out;
}

TrialResult RunPerturbedTrial(AlignInput input, const AlignOptions& options, const ModelPose& truth,
                              double max_deg, double max_mm, std::mt19937_64* rng) {
  const Eigen::Vector3d c = input.surface->centroid();
  input.initial_pose = PerturbPose(truth, c, max_deg, max_mm, rng);
  const std::clock_t start = std::clock();
  const AlignResult r = Align(input, options);
  const double cpu_seconds = static_cast<double>(std::clock() - start) / CLOCKS_PER_SEC;
  TrialResult t;
  t.rotation_error_deg = RotationErrorDeg(r.pose, truth);
  t.translation_error_mm = PointErrorMm(r.pose, truth, c);
  t.fits = r.fits;
  t.seconds = r.seconds;
  t.cpu_seconds = cpu_seconds;
  return t;
}

AlignInput SceneCase::Input() const {
  AlignInput in;
  in.camera = &scene.camera;
  in.surface = surface.get();
  in.outline = outline.get();
  return in;
}

SceneCase LoadSceneCase(const std::string& dir, double spacing_px) {
  SceneCase c;
  c.dir = dir;
  ReadSceneOptions options;
  options.check_files_exist = false;  // scenes made with --no-video
  c.scene = ReadScene(dir + "/scene.json", options);
  c.surface = std::make_unique<ModelSurface>(LoadModelSurface(c.scene));
  c.outline = std::make_unique<Outline>(
      ReadOutline(dir + "/gt/masks/000000.png", c.scene.camera, spacing_px));
  c.truth = ModelPose::FromRigid(c.scene.world_from_model);
  return c;
}

TrialPair RunTrialPair(const SceneCase& c, const AlignOptions& options, double max_deg,
                       double max_mm, int landmarks, double noise_px, std::mt19937_64* rng) {
  TrialPair p;
  p.outline_only = RunPerturbedTrial(c.Input(), options, c.truth, max_deg, max_mm, rng);
  AlignInput with = c.Input();
  with.landmarks = SyntheticLandmarks(*c.surface, c.scene.camera, c.truth, c.outline->mask,
                                      landmarks, noise_px, rng);
  p.with_landmarks = RunPerturbedTrial(with, options, c.truth, max_deg, max_mm, rng);
  return p;
}

}  // namespace arreg::align
