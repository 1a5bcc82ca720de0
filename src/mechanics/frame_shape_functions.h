// Shape functions of 6-DOF frame models: where the material samples sit, what
// volume each stands for, and the weights w_i and gradients grad w_i of the
// frames that skin it. Mesh-based (barycentric in tetrahedra, trilinear in
// hexahedra) and meshless (moving least squares with a linear basis).
#pragma once

#include <Eigen/Core>
#include <vector>

#include "core/mesh.h"

namespace arreg::mechanics {

// One material sample: rest position X_s, volume V_s and, per frame it sees,
// w_i(X_s) and grad w_i(X_s). Every kind here has sum w_i = 1, sum grad w_i = 0
// and, except Shepard MLS, reproduces linear fields (sum w_i x_i = X,
// sum x_i grad w_i^T = I).
struct FrameSample {
  Eigen::Vector3d rest_position = Eigen::Vector3d::Zero();  // X_s in mm
  double volume_mm3 = 0;                                    // V_s in mm^3, > 0
  std::vector<int> frames;                                  // frame indices i
  std::vector<double> weights;                              // w_i(X_s), one per frame
  std::vector<Eigen::Vector3d> weight_gradients;            // grad w_i(X_s) in 1/mm
};

// Frames (rest positions, one per row) and the samples that they skin.
struct FrameSampling {
  RowMatX3d frame_positions;  // (#F x 3) rest positions in mm
  std::vector<FrameSample> samples;
};

// Linear hexahedral mesh; corner order per hexahedron: (x-,y-,z-), (x+,y-,z-),
// (x+,y+,z-), (x-,y+,z-), then the same four at z+ (reference cube [-1,1]^3).
struct HexMesh {
  RowMatX3d vertices;  // (#V x 3) rest positions in mm
  RowMatXi hexahedra;  // (#H x 8) vertex indices, 0-based
};

// Box [0, size] split into cells.x() x cells.y() x cells.z() hexahedra.
HexMesh MakeBoxHexMesh(const Eigen::Vector3d& size_mm, const Eigen::Vector3i& cells);

// Frames at the vertices of `mesh`, `points_per_tet` samples per tetrahedron
// (1: centroid; 4: the degree-2 Gauss rule), barycentric weights. Throws
// arreg::Error for a degenerate or inverted tetrahedron or another point count.
FrameSampling SampleTetMesh(const TetMesh& mesh, int points_per_tet);

// Frames at the vertices of `mesh`, gauss_per_axis^3 Gauss-Legendre samples
// per hexahedron (1 to 3 per axis), trilinear (isoparametric) weights. Throws
// arreg::Error for a hexahedron with det J <= 0 at a sample.
FrameSampling SampleHexMesh(const HexMesh& mesh, int gauss_per_axis);

struct MlsOptions {
  // Support radius h of each frame's kernel in mm (Wendland C2,
  // phi(r) = (1 - r/h)^4 (4 r/h + 1) for r < h); default 0 = must be set.
  double support_radius_mm = 0;
  // A sample whose moment matrix has reciprocal condition below this (frames
  // in its support nearly coplanar) is rejected; default 1e-8.
  double min_reciprocal_condition = 1e-8;
  // 1: linear basis [1, x, y, z] (reproduces linear fields, so a uniform
  // stretch is exact); 0: constant basis (Shepard weights, a partition of
  // unity only: no extra zero-energy frame-rotation modes, see frame_model.h).
  // Default 1.
  int basis_order = 1;
  void Check() const;
};

// Moving-least-squares weights (basis of MlsOptions::basis_order) of the frames at
// `frame_positions` evaluated at `point`, written into sample->frames /
// weights / weight_gradients (position and volume untouched). Throws
// arreg::Error when fewer frames than basis functions cover the point or the
// moment matrix is singular (linear basis: frames coplanar).
void EvaluateMls(const RowMatX3d& frame_positions, const Eigen::Vector3d& point,
                 const MlsOptions& options, FrameSample* sample);

// Meshless sampling: the given frames, one sample per row of
// `sample_positions` with the volume `sample_volumes_mm3[s]`, MLS weights.
FrameSampling SampleMls(const RowMatX3d& frame_positions, const RowMatX3d& sample_positions,
                        const Eigen::VectorXd& sample_volumes_mm3, const MlsOptions& options);

// Sample points at the centres of an n.x() x n.y() x n.z() grid of cells over
// the box [0, size] (each with its cell volume), for meshless models.
void BoxCellCentres(const Eigen::Vector3d& size_mm, const Eigen::Vector3i& n, RowMatX3d* positions,
                    Eigen::VectorXd* volumes_mm3);

}  // namespace arreg::mechanics
