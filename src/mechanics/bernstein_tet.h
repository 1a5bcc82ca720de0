// Bernstein-Bezier tetrahedra of degree 1, 2 and 3 with corotational linear
// elasticity, as a generalised energy term over point nodes (the control points).
//
// Element: the displacement (and the deformed position) is sum_alpha B_alpha(L) x_alpha
// over the control points x_alpha, B_alpha = k!/(alpha!) L^alpha the Bernstein
// polynomials of degree k in the barycentric coordinates L. The rest geometry is the
// linear tetrahedron (subparametric, as the seed): rest control points at the
// Bezier points sum_i alpha_i/k v_i, so grad L_i = g_i (the P1 shape gradients) is
// constant and grad B_alpha = k sum_i B^{k-1}_{alpha-e_i} g_i.
//
// Integrals are closed-form: int_T L^alpha dV = 6 V alpha! / (|alpha| + 3)!, and a
// product of Bernstein polynomials is one Bernstein polynomial of the summed degree, so
// mass and stiffness need no quadrature.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "mechanics/generalised_state.h"
#include "mechanics/high_order_mesh.h"
#include "mechanics/tet_element.h"

namespace arreg::mechanics {

// int_T L0^a0 L1^a1 L2^a2 L3^a3 dV = 6 V a0! a1! a2! a3! / (a0 + a1 + a2 + a3 + 3)!
// (the multinomial formula), V the tetrahedron's volume.
double BarycentricMonomialIntegral(const std::array<int, 4>& alpha, double volume);
// int_T B_alpha B_beta dV for Bernstein polynomials of the degrees |alpha| and |beta|.
double BernsteinProductIntegral(const std::array<int, 4>& alpha, const std::array<int, 4>& beta,
                                double volume);
// B_alpha(L) of degree |alpha| at barycentric coordinates L.
double BernsteinValue(const std::array<int, 4>& alpha, const Eigen::Vector4d& L);
// grad B_alpha(L) for all alpha of BernsteinIndices(degree), rows in that order
// (BernsteinCount(degree) x 3), with g the rows grad L_i (1/mm).
Eigen::MatrixX3d BernsteinGradients(int degree, const Eigen::Matrix<double, 4, 3>& g,
                                    const Eigen::Vector4d& L);

// Consistent mass matrix rho int B_alpha B_beta dV of one element (scalar, per
// component; BernsteinCount x BernsteinCount), kg.
Eigen::MatrixXd BernsteinMassMatrix(int degree, double volume, double density);
// Row-sum lumped masses: rho int B_alpha dV = rho V / C(k+3, 3) for every control
// point (a tenth of the element's mass at k = 2, a twentieth at k = 3). Positive because
// Bernstein polynomials are non-negative (unlike Lagrange P2, whose vertex row sums are
// negative); it is also the consistent load of a uniform body force, so gravity on these
// masses is exact.
double BernsteinLumpedMass(int degree, double volume, double density);
// Rest stiffness K (3n x 3n, control-point-major: dof 3 alpha + i) of linear
// elasticity, blocks K_ab = lambda G_ab + mu G_ab^T + mu tr(G_ab) I with
// G_ab = int grad B_a grad B_b^T dV in closed form; for k = 1 it is the P1 element's.
Eigen::MatrixXd BernsteinStiffnessMatrix(int degree, const Eigen::Matrix<double, 4, 3>& g,
                                         double volume, double lambda_kpa, double mu_kpa);
// Mixed u-p rest stiffness with a pressure discontinuous across elements, of degree m
// (0 <= m < degree), condensed per element. The energy mu |dev eps|^2 + p tr(eps) -
// p^2/(2 kappa) (kappa = lambda + 2 mu / 3, the bulk modulus) made stationary in p over
// the element's Bernstein polynomials of degree m gives p = kappa P(div u), P the L2
// projection onto them, and the stiffness K_dev + kappa C^T M^-1 C with
// C_q,(alpha,j) = int B_q d_j B_alpha and M_qr = int B_q B_r: the volumetric energy sees
// only the projected divergence, which frees the element from the incompressibility
// constraints that lock it when nu -> 0.5. Exact condensation of the saddle point for
// nu < 0.5 (kappa finite); at degree 1 (m = 0) div u is constant and K is the
// displacement element's.
Eigen::MatrixXd BernsteinMixedStiffnessMatrix(int degree, int pressure_degree,
                                              const Eigen::Matrix<double, 4, 3>& g, double volume,
                                              double lambda_kpa, double mu_kpa);
// Mean gradients c_alpha = 1/V int grad B_alpha dV = k/C(k+2,3) sum_{i: alpha_i > 0} g_i
// (n x 3): the volume-averaged deformation gradient is sum_alpha x_alpha c_alpha^T.
Eigen::MatrixX3d BernsteinMeanGradients(int degree, const Eigen::Matrix<double, 4, 3>& g);

struct BernsteinTetOptions {
  Material material;               // E, nu, density (SI, tet_element.h); default soft tissue
  int polar_max_iterations = 20;   // cap of the polar iteration per element; default 20
  double polar_tolerance = 1e-12;  // stop when the rotation update angle (rad) is below; 1e-12
  // -1: displacement formulation (default); 0 .. degree - 1: mixed u-p with a pressure
  // of that degree, discontinuous and condensed per element (BernsteinMixedStiffnessMatrix).
  int pressure_degree = -1;
  void Check() const;
};

// Corotational linear elasticity of Bernstein-Bezier tetrahedra:
//   E = sum_e 1/2 u_e^T K_e u_e,  u_alpha = R_e^T x_alpha - X_alpha,
// K_e the closed-form rest stiffness, X the rest control points. One rotation per
// element: the polar rotation of the volume-averaged deformation gradient
// F_e = sum x_alpha c_alpha^T (the centre value for k <= 2, where F is at most linear
// in L). Why one per element and not per quadrature point: K_e stays the precomputed
// closed-form matrix (per-point rotations would need quadrature of R(L) K(L) R(L)^T on
// every update), the warped Hessian is R K R^T block by block as for P1, degree 1 is
// exactly CorotationalElasticity (kLinear volume term), and a rigid motion gives u a
// translation, which K maps to zero. The price: an element that bends within itself
// by a large angle sees one averaged rotation, so elements should stay small against
// the radius of bending.
// Gradient: exact for R_e = R_e(x) (with dR/dx of the polar decomposition: the torque
// tau = sum_alpha y_alpha x f_alpha, y = R^T x, f = K u, adds -R (s x c_alpha) with
// s = (tr(S) I - S)^-1 tau, S = R^T F_e; tau vanishes for k = 1). Hessian: the
// stiffness-warping R K_e R^T (dR/dx neglected, as CorotationalElasticity), positive
// semi-definite. Mass: row-sum lumped (BernsteinLumpedMass).
// Curved rest geometry (control points off the affine Bezier points, e.g. from
// RaiseTetMeshOntoSurface or a curved Gmsh mesh) makes the element isoparametric:
// grad_X B = J^-T grad_xi B, and K_e, c_alpha, the lumped masses rho int B_alpha dV and
// the volume come from quadrature (TetQuadrature of degree 6(k - 1)); cof(J) grad_xi B is
// a polynomial of degree 3(k - 1), integrated exactly, so constant strain still passes the
// patch test. Displacement formulation only.
class BernsteinTetTerm : public GeneralisedEnergyTerm, public InertiaSource {
 public:
  // `mesh` must outlive this; node[i]: the state's point node of mesh node i (#N).
  // Throws arreg::Error naming "elements" for an element of non-positive corner volume,
  // a curved element inverted at a quadrature point, or a curved element with
  // pressure_degree >= 0 (a control point more than 1e-9 of the element's size off its
  // affine Bezier point makes it curved).
  BernsteinTetTerm(const HighOrderTetMesh* mesh, std::vector<int> node,
                   const BernsteinTetOptions& options = {});
  std::string name() const override { return "bernstein-tet"; }
  void AppendStencils(std::vector<std::vector<int>>* stencils) const override;
  // Rotations, energy and gradient at the state's positions; nothing when they are
  // bit for bit those of the last Update of the same state and topology.
  void Update(const GeneralisedState& state) override;
  // The energy at the last Update.
  double Value(const GeneralisedState& state) const override;
  void AddGradient(const GeneralisedState& state, Eigen::VectorXd* gradient) const override;
  void AddHessian(const GeneralisedState& state, double scale, HessianSink* sink) const override;
  void AddNodeInertia(const GeneralisedState& state,
                      std::vector<NodeInertia>* inertia) const override;

  int degree() const { return mesh_->degree; }
  int num_elements() const { return static_cast<int>(elements_.size()); }
  const HighOrderTetMesh& mesh() const { return *mesh_; }
  const std::vector<int>& node() const { return node_; }
  const Eigen::MatrixXd& element_stiffness(int e) const { return elements_[e].stiffness; }
  double element_volume(int e) const { return elements_[e].volume; }
  const Eigen::Matrix<double, 4, 3>& element_shape_gradients(int e) const { return elements_[e].g; }
  const Eigen::Matrix3d& rotation(int e) const { return rotations_[e]; }
  // Deformed position and deformation gradient inside element e at barycentric L.
  Eigen::Vector3d Position(const GeneralisedState& state, int e, const Eigen::Vector4d& L) const;
  Eigen::Matrix3d DeformationGradientAt(const GeneralisedState& state, int e,
                                        const Eigen::Vector4d& L) const;

 private:
  struct Element {
    std::vector<int> nodes;           // state nodes of the control points
    Eigen::MatrixX3d rest;            // X_alpha (n x 3)
    Eigen::MatrixX3d mean_gradients;  // c_alpha (n x 3)
    Eigen::Matrix<double, 4, 3> g;    // grad L_i of the corner tetrahedron
    Eigen::MatrixXd stiffness;        // K (3n x 3n)
    std::vector<double> lumped_mass;  // rho int B_alpha dV (kg)
    double volume = 0;                // mm^3 (of the curved element when curved)
    bool curved = false;              // rest control points off the affine Bezier points
  };
  // Stiffness, mean gradients, masses and volume of a curved element by quadrature.
  void InitCurvedElement(int e, double lambda_kpa, double mu_kpa);
  // grad_X B_alpha at L in the rest geometry (n x 3).
  Eigen::MatrixX3d RestGradients(int e, const Eigen::Vector4d& L) const;
  const HighOrderTetMesh* mesh_;
  std::vector<int> node_;
  BernsteinTetOptions options_;
  std::vector<std::array<int, 4>> indices_;
  std::vector<Element> elements_;
  // Per element at the last Update: rotation (and its quaternion warm start), gradient.
  std::vector<Eigen::Matrix3d> rotations_;
  std::vector<Eigen::Quaterniond> quaternions_;
  std::vector<Eigen::MatrixX3d> gradients_;  // dE/dx_alpha (n x 3, world)
  double energy_ = 0;
  const GeneralisedState* updated_state_ = nullptr;
  std::uint64_t updated_version_ = 0;
  RowMatX3d updated_positions_;
};

// Appends one point node per node of `mesh` (rest = current = mesh position);
// returns mesh node -> state node.
std::vector<int> AddHighOrderNodes(const HighOrderTetMesh& mesh, GeneralisedState* state);

// Constant forces on nodes: E = -sum_n f_n . x_n (mN, mm). Zero Hessian.
class NodalForceTerm : public GeneralisedEnergyTerm {
 public:
  // forces: (#nodes x 3) mN, one row per state node.
  explicit NodalForceTerm(RowMatX3d forces_mn) : forces_(std::move(forces_mn)) {}
  std::string name() const override { return "nodal-forces"; }
  void AppendStencils(std::vector<std::vector<int>>*) const override {}
  double Value(const GeneralisedState& state) const override;
  void AddGradient(const GeneralisedState& state, Eigen::VectorXd* gradient) const override;
  void AddHessian(const GeneralisedState&, double, HessianSink*) const override {}
  const RowMatX3d& forces() const { return forces_; }

 private:
  RowMatX3d forces_;
};

// Consistent nodal loads (#mesh nodes x 3, mN) of a uniform traction t (mN/mm^2 = kPa)
// on the boundary faces (faces of one element only) whose three corner positions pass
// `select`: each control point of such a face gets t int_face B_alpha dA =
// t 2 A / ((k+1)(k+2)), A the face area.
RowMatX3d UniformTractionLoads(
    const HighOrderTetMesh& mesh,
    const std::function<bool(const Eigen::Vector3d&, const Eigen::Vector3d&,
                             const Eigen::Vector3d&)>& select,
    const Eigen::Vector3d& traction_kpa);

}  // namespace arreg::mechanics
