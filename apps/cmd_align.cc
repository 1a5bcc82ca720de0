// `arreg align`: places the scene's model in the world from one frame's organ outline
// and/or 2D-3D landmarks (Ceres); writes the aligned scene, an overlay and a summary.
#include <cstdio>
#include <string>

#include "ar/align/align_job.h"
#include "commands.h"
#include "option_parser.h"

namespace arreg::cli {

int RunAlign(int argc, char** argv) {
  align::AlignJob job;
  std::string mask, outline;
  bool quiet = false;
  OptionParser parser(
      "arreg align --scene S.json [--frame N] [--mask M.png | --outline O.json] "
      "[--landmarks L.json] [--init-pose P.json|scene] [--scale] --out ALIGNED.json",
      "Estimates the model's world_from_model from one video frame: the organ's outline (its "
      "silhouette against the model's projected occluding contour) and/or landmarks (pixel <-> "
      "model point), with a robust loss, from an initial pose or a search over viewpoints. "
      "Refuses (exit 1, nothing written) when the model does not fit the outline.");
  parser.AddString("scene", &job.scene_path, "S.json", "input scene (not modified)", true);
  parser.AddInt("frame", &job.frame, "N", "frame the outline and landmarks belong to (overlay)");
  parser.AddString("mask", &mask, "M.png", "organ mask of the frame (inside > 127)");
  parser.AddString("outline", &outline, "O.json",
                   "organ outline as polygons: {\"polygons\": [[[u, v], ...], ...]} (px)");
  parser.AddString("landmarks", &job.landmarks_path, "L.json",
                   "{\"landmarks\": [{\"pixel\": [u, v], \"model_point_mm\": [x, y, z]}, ...]}");
  parser.AddString("init-pose", &job.init_pose, "P.json|scene",
                   "initial world_from_model (rigid transform JSON, or 'scene' for the scene's "
                   "own); without it: PnP on 4+ landmarks, else a search over viewpoints");
  parser.AddFlag("scale", &job.options.estimate_scale,
                 "also estimate a uniform scale (model in the wrong units)");
  parser.AddString("out", &job.out_path, "ALIGNED.json", "aligned scene to write", true);
  parser.AddString("overlay", &job.overlay_path, "PNG", "overlay (default: OUT's .overlay.png)");
  parser.AddString("summary", &job.summary_path, "JSON", "summary (default: OUT's .summary.json)");
  std::string loss = align::RobustLossName(job.options.robust_loss);
  parser.AddString("loss", &loss, "huber|cauchy|none", "robust loss");
  parser.AddDouble("loss-scale", &job.options.loss_scale_px, "PX",
                   "where the robust loss leaves the quadratic (px)");
  parser.AddInt("local-starts", &job.options.local_starts, "N",
                "extra starts rotated about the initial pose (agreement, local minima)");
  parser.AddFlag("quiet", &quiet, "print nothing but errors");
  parser.SetEpilog(
      "outputs: OUT (the scene with model.world_from_model set; a scaled copy of the meshes "
      "beside it when --scale finds a scale != 1), OUT's .overlay.png (outline green, model "
      "silhouette yellow, landmarks red/blue), OUT's .summary.json (docs/align.md).\n\n"
      "example: arreg align --scene kidney/scene.json --mask kidney/gt/masks/000000.png "
      "--init-pose scene --out /tmp/aligned.json");
  if (!parser.Parse(argc, argv)) return 0;
  if (!mask.empty() && !outline.empty())
    throw UsageError("--mask/--outline", "give one of them, not both");
  job.outline_path = mask.empty() ? outline : mask;
  job.options.robust_loss = align::ParseRobustLoss(loss, "--loss");

  const align::AlignJobResult out = align::RunAlignJob(job);
  const align::AlignResult& r = out.result;
  if (quiet) return 0;
  const Eigen::Vector3d t = r.pose.translation_mm;
  const Eigen::AngleAxisd aa(r.pose.rotation);
  std::printf("pose: rotation %.3f deg about [%.4f %.4f %.4f], translation [%.3f %.3f %.3f] mm",
              aa.angle() * 180 / M_PI, aa.axis().x(), aa.axis().y(), aa.axis().z(), t.x(), t.y(),
              t.z());
  if (job.options.estimate_scale) std::printf(", scale %.5f", r.pose.scale);
  std::printf("\nfit: IoU %.4f, contour->outline mean %.3f px, outline->contour mean %.3f px",
              r.iou, r.contour_to_outline.mean_px, r.outline_to_contour.mean_px);
  if (r.landmarks.count > 0)
    std::printf(", landmarks RMS %.3f px (%d)", r.landmarks.rms_px, r.landmarks.count);
  const align::StartResult& best = r.starts[r.best_start];
  std::printf("\ncost %.5g -> %.5g, starts %zu, at the optimum %d, %.2f s (Ceres: %s)\n",
              best.cost_before, best.cost_after, r.starts.size(), r.starts_at_optimum, r.seconds,
              r.ceres_termination.c_str());
  if (r.ambiguous) std::printf("warning: %s\n", r.warning.c_str());
  if (!out.video_frame_used) std::printf("note: video frame not readable, overlay on grey\n");
  std::printf("wrote %s, %s, %s\n", job.out_path.c_str(), out.overlay_path.c_str(),
              out.summary_path.c_str());
  return 0;
}

}  // namespace arreg::cli
