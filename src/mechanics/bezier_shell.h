// Cubic Bezier triangle shell elements over frame nodes (6 DOFs per corner):
// membrane (small strain) + Kirchhoff bending in a corotational element frame.
//
// Kinematics (per element, control points p1..p10 as in the seed's fig. 2):
//   corners p_i = x_i; edge points p_j = x_i + R_i R_i0^T R_e0 S3 a_j, attached
//   to their corner frame i (a_j: rest attachment segment in the element's rest
//   frame R_e0; S3 = diag(S, 1) with S the element's in-plane stretch, see
//   below); the central point from the other nine (seed eq. 7, quadratic
//   precision). The element frame R_e is the 2D polar rotation of the corner
//   triangle (seed eq. 31, iterated until the correction is below a tolerance),
//   and S = R_e^T A (2x2, symmetric) its stretch, A the corner triangle's map
//   from rest to current.
// Energy: E = 1/2 xi^T K xi with the 12 deformational coordinates
//   xi = (S11 - 1, S22 - 1, S12, Log(Q_1), Log(Q_2), Log(Q_3)),
//   Q_i = R_e^T R_i R_i0^T R_e0 the corner rotations relative to the element
//   frame. Rigid motions give xi = 0 exactly. K (12 x 12) is the linear
//   stiffness of the element in these coordinates (6-point Gauss):
//   - membrane: small strain of the Bezier surface's in-plane displacement
//     (seed eq. 24-29), the edge points moving in plane with the drilling
//     rotation only (the seed's split, section 3.2; the other two rotations
//     would move a curved element's raised edge points in plane and lock);
//   - Kirchhoff bending: a constant curvature from the boundary integral
//     -(1/A) int sym(grad w (x) n) ds with the normal slope linear between the
//     corner rotations along each edge (shared by neighbours), plus the Bezier
//     curvature's deviation from its element mean.
// Departures from the seed, each for a failed patch test: (1) the edge segment
// follows S: a rigid segment keeps the edge points at 1/3 of the REST edge
// length from their corner, so a uniform stretch gives a non-uniform strain
// along the edge (zero at the corners, 1.5x the mean in the middle; 20 % too
// stiff in extension at any mesh size); neighbours then share edge points only
// up to the difference of their in-plane rotations (non-conforming, passes the
// patch test). (2) The centre point by eq. 7 (quadratic precision), not eq. 10,
// so that a constant curvature is reproduced. (3) The boundary-integral
// constant curvature: the Bezier surface is only C0 across edges and its own
// curvature leaves an interior-node residual (~11 % of the boundary forces on
// a patch), which converges plates 3-4 % too soft.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "mechanics/generalised_state.h"

namespace arreg::mechanics {

struct ShellMaterial {
  double youngs_modulus_kpa = 3.0;     // kPa (= mN/mm^2); > 0
  double poisson_ratio = 0.45;         // [0, 0.5)
  double thickness_mm = 1.0;           // > 0
  double density_kg_per_mm3 = 1.0e-6;  // kg/mm^3 (water: 1e-6); >= 0
  void Check() const;                  // throws arreg::Error naming the field
};

enum class ShellHessian {
  kGaussNewton,     // B^T K B (B = d xi / d(x, phi)): positive semi-definite; drops the
                    // geometric part sum_k (K xi)_k d2 xi_k, which is indefinite
  kExact,           // the full Hessian (second-order forward differentiation, ~100x slower)
  kExactProjected,  // the full Hessian with negative eigenvalues of each 18x18 block set to 0
};

struct BezierShellOptions {
  ShellMaterial material;
  ShellHessian hessian = ShellHessian::kGaussNewton;
  // Iterated 2D polar correction of the element frame (seed section 3.4): stop
  // when the correction angle is below polar_tolerance_rad (rad, default 1e-13)
  // or after polar_max_iterations (default 5). With the exact kinematics the
  // corner triangle's 2D gradient turns as F -> Q^T F with the frame, so the
  // exact polar angle converges in one iteration; the second one checks it.
  int polar_max_iterations = 5;
  double polar_tolerance_rad = 1e-13;
  void Check() const;
};

// Bernstein weights n_1..n_10 of the cubic Bezier triangle at (xi1, xi2)
// (xi3 = 1 - xi1 - xi2), seed eq. 5.
Eigen::Matrix<double, 10, 1> BezierTriangleWeights(double xi1, double xi2);

// Rest rotations for shell nodes on a triangle mesh: z axis = the area-weighted
// vertex normal, x axis = the first incident edge projected on the tangent plane.
// positions: (#V x 3); triangles: (#T x 3) vertex indices, counter-clockwise
// seen from the normal side. Throws arreg::Error for an index out of range or a
// vertex without a non-degenerate triangle.
std::vector<Eigen::Matrix3d> ShellVertexRotations(const RowMatX3d& positions,
                                                  const std::vector<Eigen::Vector3i>& triangles);

// Positions and rotations of a state, to recognise it again (derivative caches).
struct StateSnapshot {
  RowMatX3d positions;
  std::vector<Eigen::Matrix3d> rotations;
  void Take(const GeneralisedState& state);
  bool Matches(const GeneralisedState& state) const;  // exact equality
};

class BezierShell : public GeneralisedEnergyTerm, public InertiaSource {
 public:
  // triangles: (#T x 3) frame-node indices of `state`, counter-clockwise about
  // the rest normals (the z axes of the nodes' rest rotations). Builds the rest
  // control nets (seed section 2.2) and the element stiffnesses. Throws
  // arreg::Error for invalid options, an index that is not a frame node, a
  // degenerate triangle, or a rest normal that does not define edge points.
  BezierShell(const GeneralisedState& state, const std::vector<Eigen::Vector3i>& triangles,
              const BezierShellOptions& options);

  // After a topology change (mechanics/shell_cutting.h): the element list
  // becomes `triangles`; element e with reuse[e] set keeps its rest data (its
  // corners may be replaced by nodes of the same rest position and rotation,
  // else arreg::Error), the others are built as by the constructor. Call the
  // solver's InvalidatePattern() afterwards.
  void ReplaceElements(const GeneralisedState& state, const std::vector<Eigen::Vector3i>& triangles,
                       const std::vector<char>& reuse);

  std::string name() const override { return "bezier_shell"; }
  void AppendStencils(std::vector<std::vector<int>>* stencils) const override;
  // The first of AddGradient / AddHessian at a state computes every element's
  // gradient and Hessian, and the energy; the other, repeats and Value at the
  // same positions and rotations reuse them. Update only drops them.
  void Update(const GeneralisedState& state) override;
  double Value(const GeneralisedState& state) const override;
  void AddGradient(const GeneralisedState& state, Eigen::VectorXd* gradient) const override;
  // Hessian per options().hessian (default: Gauss-Newton, positive semi-definite).
  void AddHessian(const GeneralisedState& state, double scale, HessianSink* sink) const override;

  // Lumped mass: each Gauss point's mass rho t w |J| goes to the corners with
  // its barycentric weights. Rotational inertia of corner i (body axes of the
  // node): the same Gauss masses' second moment about the corner,
  // sum lambda_i m_g (|r|^2 I - r r^T), r = rest position - corner, plus the
  // through-thickness term m t^2/12 about the in-plane axes.
  void AddNodeInertia(const GeneralisedState& state,
                      std::vector<NodeInertia>* inertia) const override;

  int num_elements() const { return static_cast<int>(elements_.size()); }
  const Eigen::Vector3i& triangle(int element) const { return elements_[element].nodes; }
  const BezierShellOptions& options() const { return options_; }
  // Rest area of the element's Bezier surface (projected on its rest plane), mm^2.
  double rest_area(int element) const { return elements_[element].area; }
  // The 12 x 12 stiffness in the deformational coordinates xi (mN mm / unit^2).
  const Eigen::Matrix<double, 12, 12>& local_stiffness(int element) const {
    return elements_[element].k;
  }

  // The 12 deformational coordinates xi of an element (see the top of the file).
  Eigen::Matrix<double, 12, 1> DeformationalCoordinates(const GeneralisedState& state,
                                                        int element) const;
  // Current control points (10 x 3, rows p1..p10) and, when `jacobian` is set,
  // their derivative (30 x 18: rows p1.x, p1.y, p1.z, p2.x, ...; columns per
  // corner (x, y, z, phi_x, phi_y, phi_z), phi a spatial rotation increment).
  void ControlPoints(const GeneralisedState& state, int element,
                     Eigen::Matrix<double, 10, 3>* points,
                     Eigen::Matrix<double, 30, 18>* jacobian = nullptr) const;
  // Element energy, gradient (18) and Hessian (18 x 18) per options().hessian.
  double ElementEnergy(const GeneralisedState& state, int element,
                       Eigen::Matrix<double, 18, 1>* gradient = nullptr,
                       Eigen::Matrix<double, 18, 18>* hessian = nullptr) const;

  // Internal per-element data (public so the implementation's helpers see it).
  // clang-tidy flags the array index (__i0) of the implicit copy of the array members.
  // NOLINTNEXTLINE(bugprone-reserved-identifier)
  struct Element {
    Eigen::Vector3i nodes;
    Eigen::Matrix3d rest_frame;               // R_e0 (columns: element axes in world)
    Eigen::Matrix2d rest_edges_inverse;       // E0^-1, E0 = rest local [x2-x1, x3-x1]
    Eigen::Matrix3d corner_link[3];           // C_i = R_i0^T R_e0
    Eigen::Vector3d attachment[6];            // a_j (rest local), edge points p4..p9
    Eigen::Matrix<double, 10, 3> rest_local;  // rest control points, local, centroid origin
    Eigen::Matrix<double, 12, 12> k;          // stiffness in xi
    double area = 0;
    Eigen::Matrix<double, 3, 3> lumped_inertia[3];  // rest-local rotational inertia per corner
    double lumped_mass[3] = {0, 0, 0};
  };

 private:
  // Whether the caches below hold `state`.
  bool CacheHolds(const GeneralisedState& state) const;
  // Fills the caches below for `state` unless they hold it already.
  void CacheDerivatives(const GeneralisedState& state) const;

  BezierShellOptions options_;
  std::vector<Element> elements_;
  // Element derivatives and the total energy at cached_state_ (its positions and rotations).
  mutable double cached_energy_ = 0;
  mutable std::vector<Eigen::Matrix<double, 18, 1>> cached_gradient_;
  mutable std::vector<Eigen::Matrix<double, 18, 18>> cached_hessian_;
  mutable StateSnapshot cached_state_;
};

// Supports and loads that node-level fixed masks cannot express, for shell
// problems: one translation or rotation component of a node held along a unit
// direction (symmetry planes, diaphragms), as a stiff penalty
//   1/2 k (a . (x - x_rest))^2,  1/2 k (a . Log(R R_rest^T))^2,
// and dead point forces -f . x. The rotation penalty's Hessian is its
// Gauss-Newton part k J_l^-T a a^T J_l^-1 (positive semi-definite; exact where
// the held component is zero). With k ~1e6 times the structure's stiffness the
// held component is zero to ~1e-6 of the free motion.
class ShellSupportTerm : public GeneralisedEnergyTerm {
 public:
  std::string name() const override { return "shell_supports"; }
  // Throw arreg::Error for a zero direction or a non-positive stiffness.
  void HoldTranslation(int node, const Eigen::Vector3d& direction, double stiffness_n_per_m);
  void HoldRotation(int node, const Eigen::Vector3d& direction, double stiffness_nmm_per_rad2);
  void AddForce(int node, const Eigen::Vector3d& force_mn);

  void AppendStencils(std::vector<std::vector<int>>* stencils) const override;
  double Value(const GeneralisedState& state) const override;
  void AddGradient(const GeneralisedState& state, Eigen::VectorXd* gradient) const override;
  void AddHessian(const GeneralisedState& state, double scale, HessianSink* sink) const override;

 private:
  struct Hold {
    int node;
    bool rotation;
    Eigen::Vector3d direction;
    double stiffness;
  };
  std::vector<Hold> holds_;
  std::vector<std::pair<int, Eigen::Vector3d>> forces_;
};

}  // namespace arreg::mechanics
