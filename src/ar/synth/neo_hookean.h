// Ground-truth mechanics of the synthetic scenes: a compressible neo-Hookean
// solid (nearly incompressible by default) on linear tetrahedra, solved
// quasi-statically by Newton's method with prescribed (Dirichlet) grip motions.
#pragma once

#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <memory>
#include <string>
#include <vector>

#include "core/mesh.h"

namespace arreg::synth {

// Energy density (Bonet & Wood): psi = mu/2 (tr(F^T F) - 3) - mu ln J + lambda/2 (ln J)^2.
struct NeoHookeanMaterial {
  double youngs_modulus_pa = 1.0e5;  // Young's modulus (Pa), default 100 kPa (soft silicone)
  double poisson_ratio = 0.495;      // default 0.495: volume kept within ~1 % at 186 % stretch
  void Check() const;
  double mu() const;      // shear modulus (Pa)
  double lambda() const;  // first Lame parameter (Pa)
};

// Value / gradient / Hessian of the elastic energy of a tetrahedral body.
// Positions are (#V x 3) in mm, so energies are in Pa mm^3 (= 1e-9 J).
class NeoHookeanEnergy {
 public:
  // `rest` gives rest positions and positively oriented tetrahedra; throws
  // arreg::Error when a tetrahedron is degenerate or inverted at rest.
  NeoHookeanEnergy(const RowMatX3d& rest_positions, const RowMatX4i& tetrahedra,
                   const NeoHookeanMaterial& material);

  // +infinity when some tetrahedron is inverted or flat (J <= 0).
  double Value(const RowMatX3d& positions) const;
  // dE/dx (3 #V), vertex-major (x0, y0, z0, x1, ...).
  Eigen::VectorXd Gradient(const RowMatX3d& positions) const;
  // Per-element 12 x 12 Hessian (vertex-major over the element's 4 vertices).
  Eigen::Matrix<double, 12, 12> ElementHessian(int tet, const RowMatX3d& positions) const;
  // Full sparse Hessian (3 #V x 3 #V), for tests.
  Eigen::SparseMatrix<double> Hessian(const RowMatX3d& positions) const;

  // Ratio current / rest volume per tetrahedron (J).
  Eigen::VectorXd VolumeRatios(const RowMatX3d& positions) const;
  double RestVolume() const { return rest_volume_.sum(); }

  const RowMatX4i& tetrahedra() const { return tets_; }
  int num_vertices() const { return num_vertices_; }
  int num_tetrahedra() const { return static_cast<int>(tets_.rows()); }

 private:
  Eigen::Matrix3d DeformationGradient(int tet, const RowMatX3d& x) const;
  RowMatX4i tets_;
  int num_vertices_;
  double mu_, lambda_;
  std::vector<Eigen::Matrix3d> rest_inverse_;  // Dm^-1 per tetrahedron
  Eigen::VectorXd rest_volume_;                // mm^3 per tetrahedron
};

struct QuasiStaticOptions {
  int max_iterations = 25;  // Newton iterations per solve, default 25
  // Converged when |grad_free| <= this * mean|diag(H)| * 1 mm * sqrt(#free DOF),
  // i.e. a residual force that would move a typical vertex by this many mm; default 1e-8.
  double relative_force_tolerance = 1e-8;
  double step_tolerance_mm = 1e-7;  // or when the largest step is below this (mm), default 1e-7
  double armijo = 1e-4;             // sufficient-decrease constant of the line search, default 1e-4
  int max_line_search_steps = 30;   // step halvings, default 30
  double min_volume_ratio = 0.05;   // steps creating J below this are shortened, default 0.05
  void Check() const;
};

struct QuasiStaticSummary {
  bool converged = false;
  int iterations = 0;
  int regularised_factorisations = 0;  // Hessians that needed a diagonal shift to factorise
  double final_gradient_norm = 0;      // |grad_free| (Pa mm^2)
  double energy = 0;                   // Pa mm^3
  std::string message;
};

// Newton solver with Dirichlet vertices. Keeps the sparsity pattern and the
// symbolic factorisation (CHOLMOD supernodal LLT) between solves on one topology.
class QuasiStaticSolver {
 public:
  QuasiStaticSolver(const NeoHookeanEnergy* energy, const std::vector<bool>& fixed_vertex,
                    const QuasiStaticOptions& options = {});
  ~QuasiStaticSolver();

  // Moves the fixed vertices to `targets` (rows of fixed vertices are read,
  // others ignored) and finds the equilibrium of the free vertices, starting
  // from `positions` (#V x 3), which is updated in place.
  QuasiStaticSummary Solve(const RowMatX3d& targets, RowMatX3d* positions);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace arreg::synth
