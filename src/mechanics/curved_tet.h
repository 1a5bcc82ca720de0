// Curved (Bezier) geometry of a HighOrderTetMesh: the map x(L) of an element and
// its Jacobian, the inverse map by Newton, points embedded so that they follow the
// control points, the tessellated boundary, and raising a linear mesh onto a smooth
// surface with the interior control points relaxed by a linear elastic solve.
//
// An element of degree k maps barycentric coordinates L to x(L) = sum_alpha
// B_alpha(L) P_alpha over its control points P_alpha (BernsteinIndices(k) order).
// Reference coordinates xi = (L1, L2, L3), L0 = 1 - L1 - L2 - L3.
#pragma once

#include <Eigen/Core>
#include <functional>
#include <vector>

#include "core/mesh.h"
#include "mechanics/high_order_mesh.h"

namespace arreg::mechanics {

// B_alpha(L) for every alpha of BernsteinIndices(degree), in that order
// (BernsteinCount(degree)); they sum to one when L does. Any degree 0 .. 12 (the
// Jacobian determinant of a degree-k element has degree 3(k - 1)).
Eigen::VectorXd BernsteinValues(int degree, const Eigen::Vector4d& L);

// Control points of element e (BernsteinCount x 3, mm) gathered from the node
// positions `nodes` (#N x 3: the mesh's rest nodes or a deformed copy).
Eigen::MatrixX3d ElementControlPoints(const HighOrderTetMesh& mesh, const RowMatX3d& nodes, int e);

// x(L) of an element of `degree` with control points `control` (BernsteinCount x 3).
Eigen::Vector3d BezierTetPoint(int degree, const Eigen::MatrixX3d& control,
                               const Eigen::Vector4d& L);
// dx/dxi (columns dx/dL_j - dx/dL_0, j = 1..3), dx/dL_i = k sum_{alpha_i > 0}
// B^{k-1}_{alpha - e_i}(L) P_alpha.
Eigen::Matrix3d BezierTetJacobian(int degree, const Eigen::MatrixX3d& control,
                                  const Eigen::Vector4d& L);

// The Jacobian determinant of an element of degree k is a polynomial of degree
// d = 3(k - 1) in L; its Bernstein coefficients (from its values at the d-lattice
// points) bound it from below over the whole element (Bernstein polynomials are
// non-negative and sum to one). min_coefficient > 0 certifies that the element is not
// inverted anywhere; min_sampled < 0 proves that it is; in between it is undecided
// (a subdivision would decide, not done here).
struct JacobianBounds {
  double min_sampled = 0;      // min det J over the lattice points of degree max(d, 1) (mm^3)
  double min_coefficient = 0;  // min Bernstein coefficient of det J (mm^3)
};
JacobianBounds BezierTetJacobianBounds(int degree, const Eigen::MatrixX3d& control);

// Node positions (#N x 3) whose element maps interpolate f at every element's lattice
// points: the new x(alpha/k) = f(x(alpha/k)) for every alpha of BernsteinIndices(k),
// x the map of `nodes` (#N x 3), by solving the Bernstein collocation system per
// element (a lattice point on a shared face or edge is interpolated by that face's or
// edge's control points alone, so neighbours agree). Exact, x_new = f o x, when f o x is
// a polynomial of degree <= k: f quadratic on straight elements of degree >= 2.
RowMatX3d InterpolateMap(const HighOrderTetMesh& mesh, const RowMatX3d& nodes,
                         const std::function<Eigen::Vector3d(const Eigen::Vector3d&)>& f);

struct InverseMapOptions {
  // Newton stops when |x(L) - p| falls below relative_tolerance times the diagonal
  // of the control points' bounding box (dimensionless); default 1e-13.
  double relative_tolerance = 1e-13;
  int max_iterations = 30;  // Newton iterations; default 30
  // A converged point is inside when every L_i >= -inside_tolerance; default 1e-9.
  double inside_tolerance = 1e-9;
  // Newton gives up (not converged) once some L_i < -max_extrapolation: the point is
  // far outside, where the polynomial map says nothing about it; default 1.
  double max_extrapolation = 1.0;
  void Check() const;
};

struct InverseMapResult {
  bool converged = false;  // |x(L) - p| below the tolerance
  bool inside = false;     // converged and every L_i >= -inside_tolerance
  Eigen::Vector4d barycentric = Eigen::Vector4d::Zero();
  double residual_mm = 0;  // |x(L) - p| at the end
  int iterations = 0;
};

// Solves x(L) = p by Newton's method from the linear tetrahedron's barycentric
// coordinates of p (the four vertex control points), each step halved until the
// residual falls (at most 20 times). A singular Jacobian, a step that cannot reduce
// the residual or L beyond max_extrapolation end it unconverged: the status says so,
// nothing throws.
InverseMapResult InvertBezierTet(int degree, const Eigen::MatrixX3d& control,
                                 const Eigen::Vector3d& p, const InverseMapOptions& options = {});

struct HighOrderEmbeddingOptions {
  InverseMapOptions inverse;  // per-element Newton
  // A point inside no element is extrapolated from the element where Newton converged
  // with the largest min_i L_i when that is >= -max_outside (dimensionless, a fraction
  // of the element); farther points make Embed throw. Default 0.05.
  double max_outside = 0.05;
  void Check() const;
};

// Points carried by the curved elements: point i = sum_alpha B_alpha(L_i) P_alpha of
// its element, so it follows the control points exactly for any deformation of them
// (a polynomial displacement of degree <= k moves it exactly with the field).
class HighOrderEmbedding {
 public:
  HighOrderEmbedding() = default;
  // Locates `points` (#P x 3, mm) in `mesh` with node positions `nodes`: candidates are
  // the elements whose control-point bounding box (which holds the curved element, a
  // convex combination of its control points) contains the point, padded by max_outside
  // of its size; each is inverted by Newton and the one with the largest min_i L_i
  // wins. Throws arreg::Error naming "points" for a point outside every element by
  // more than max_outside, with its index and position.
  static HighOrderEmbedding Embed(const HighOrderTetMesh& mesh, const RowMatX3d& nodes,
                                  const RowMatX3d& points,
                                  const HighOrderEmbeddingOptions& options = {});
  // Points given directly by element and barycentric coordinates (#P each).
  static HighOrderEmbedding FromCoordinates(const HighOrderTetMesh& mesh, std::vector<int> elements,
                                            std::vector<Eigen::Vector4d> barycentric);

  // Positions (#P x 3) for node positions `nodes` (#N x 3).
  RowMatX3d Positions(const RowMatX3d& nodes) const;

  int size() const { return static_cast<int>(elements_.size()); }
  int element(int i) const { return elements_[i]; }
  const Eigen::Vector4d& barycentric(int i) const { return barycentric_[i]; }
  // Points located by extrapolation (inside no element).
  int num_outside() const { return num_outside_; }

 private:
  int count_ = 0;                             // control points per element
  std::vector<int> elements_;                 // #P
  std::vector<Eigen::Vector4d> barycentric_;  // #P
  std::vector<int> nodes_;                    // #P x count_: mesh nodes of the element
  std::vector<double> weights_;               // #P x count_: B_alpha(L)
  int num_outside_ = 0;
};

}  // namespace arreg::mechanics
