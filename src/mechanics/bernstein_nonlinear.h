// Strain-stiffening elasticity of Bernstein-Bezier tetrahedra (seed 003, Roth et al.:
// Young's modulus growing with a scalar strain measure, small displacements, solved by
// incremental Newton-Raphson), as a generalised energy term with quadrature.
//
// Material. The seed states E as a function of the strain norm, reducing to linear
// elasticity for vanishing strain or nonlinearity A = 0; its exact formula is not in the
// text we have, so we take the hyperelastic form
//   W(eps) = psi(eps) (1 + A/2 |eps|^2),  psi = mu eps:eps + lambda/2 tr(eps)^2,
// |eps| the Frobenius norm: in uniaxial strain with nu = 0 it gives the stress
// sigma = E0 (e + A e^3), a secant modulus E0 (1 + A e^2), and being an energy it has a
// symmetric tangent and an exact Newton. Kinematics are geometrically linear as in the
// seed (eps = sym(grad u), u = x - X): no corotation, so large rotations are not
// force-free (use BernsteinTetTerm for those).
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "mechanics/generalised_state.h"
#include "mechanics/high_order_mesh.h"
#include "mechanics/tet_element.h"

namespace arreg::mechanics {

// Points and weights of a tetrahedron quadrature exact for polynomials of degree
// `degree` in L (a collapsed Gauss-Legendre product, Stroud's conical rule): barycentric
// points and weights summing to one (multiply by the volume).
void TetQuadrature(int degree, std::vector<Eigen::Vector4d>* points, std::vector<double>* weights);

struct StiffeningMaterial {
  Material material;        // E0 (relaxed), nu; density unused (static)
  double nonlinearity = 0;  // A (dimensionless, >= 0); 0 is linear elasticity; default 0
  void Check() const;
  // W, sigma = dW/deps and the tangent dsigma = D(eps)[deps] (kPa).
  double Energy(const Eigen::Matrix3d& eps) const;
  Eigen::Matrix3d Stress(const Eigen::Matrix3d& eps) const;
  Eigen::Matrix3d StressIncrement(const Eigen::Matrix3d& eps, const Eigen::Matrix3d& deps) const;
};

// E = sum_e int_e W(eps(x)) dV over Bernstein elements of the mesh's degree, with the
// quadrature exact for the polynomial integrand (degree 4(k - 1)). Gradient and Hessian
// exact (the Hessian can lose definiteness only where W is not convex, far beyond the
// small strains the seed assumes).
class BernsteinStiffeningTerm : public GeneralisedEnergyTerm {
 public:
  // `mesh` must outlive this; node[i]: the state's point node of mesh node i (#N).
  // Throws arreg::Error naming "elements" for an element of non-positive volume.
  BernsteinStiffeningTerm(const HighOrderTetMesh* mesh, std::vector<int> node,
                          const StiffeningMaterial& material);
  std::string name() const override { return "bernstein-stiffening"; }
  void AppendStencils(std::vector<std::vector<int>>* stencils) const override;
  void Update(const GeneralisedState& state) override;
  double Value(const GeneralisedState& state) const override;
  void AddGradient(const GeneralisedState& state, Eigen::VectorXd* gradient) const override;
  void AddHessian(const GeneralisedState& state, double scale, HessianSink* sink) const override;

 private:
  struct Element {
    std::vector<int> nodes;              // state nodes of the control points
    Eigen::MatrixX3d rest;               // X_alpha (n x 3)
    std::vector<Eigen::MatrixX3d> grad;  // per quadrature point: grad B_alpha (n x 3)
    std::vector<double> weight;          // per quadrature point: w_q V (mm^3)
  };
  Eigen::Matrix3d Strain(const GeneralisedState& state, const Element& el, int q) const;

  const HighOrderTetMesh* mesh_;
  std::vector<int> node_;
  StiffeningMaterial material_;
  std::vector<Element> elements_;
  double energy_ = 0;
};

}  // namespace arreg::mechanics
