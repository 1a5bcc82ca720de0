// Per-vertex distance colour maps of the accuracy evaluation: a perceptual
// colour scale, OBJ meshes with vertex colours and rendered images with a legend.
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <string>

#include "core/camera.h"
#include "core/mesh.h"

namespace arreg::eval {

// Viridis colour scale (dark blue -> green -> yellow) at t in [0, 1] (clamped),
// linear RGB in [0, 1]; readable in grey-scale and by colour-blind readers.
Eigen::Vector3f ViridisColor(double t);

// Copy of `mesh` with `colors` set from per-vertex distances (#V) mapped by
// ViridisColor(distance / max_distance). max_distance must be > 0.
SurfaceMesh ColorByDistance(const SurfaceMesh& mesh, const Eigen::VectorXd& distances,
                            double max_distance);

// Writes an OBJ with per-vertex colours ("v x y z r g b", the extension read by
// MeshLab, Blender and CloudCompare) and the faces, through core's mesh writer
// (atomic). Throws arreg::Error when `path` is not .obj or colours are missing.
void WriteColoredObj(const std::string& path, const SurfaceMesh& colored_mesh);

struct ColorMapImageOptions {
  double max_distance = 1.0;  // distance at the top of the scale (scene units, mm); default 1
  std::string title;          // drawn at the top left; default empty
  int supersampling = 2;      // anti-aliasing factor of the rasterizer, 1..8; default 2
  int legend_width_px = 150;  // width of the colour-bar panel added on the right; default 150
  void Check() const;
};

// The mesh rendered by `camera` (lens distortion as in RenderSilhouette), each
// fragment coloured by its interpolated distance and lit from the camera, on a
// dark background, with a colour bar (0, max/2, max, in mm) on the right.
// 8-bit BGR, (width + legend_width_px) x height.
cv::Mat RenderDistanceImage(const PinholeCamera& camera, const SurfaceMesh& mesh,
                            const Eigen::VectorXd& distances, const ColorMapImageOptions& options);

}  // namespace arreg::eval
