#include "mechanics/bernstein_tet.h"

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <map>

#include "core/error.h"
#include "mechanics/bernstein_nonlinear.h"
#include "mechanics/curved_tet.h"

namespace arreg::mechanics {

namespace {

double Factorial(int n) {
  double f = 1.0;
  for (int i = 2; i <= n; ++i) f *= i;
  return f;
}

int Degree(const std::array<int, 4>& alpha) { return alpha[0] + alpha[1] + alpha[2] + alpha[3]; }

// k! / (a0! a1! a2! a3!)
double Multinomial(const std::array<int, 4>& alpha) {
  double m = Factorial(Degree(alpha));
  for (int a : alpha) m /= Factorial(a);
  return m;
}

std::array<int, 4> Lowered(const std::array<int, 4>& alpha, int i) {
  std::array<int, 4> out = alpha;
  --out[i];
  return out;
}

// [v]x w = v x w
Eigen::Matrix3d Skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d s;
  s << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return s;
}

}  // namespace

double BarycentricMonomialIntegral(const std::array<int, 4>& alpha, double volume) {
  double f = 6.0 * volume;
  for (int a : alpha) f *= Factorial(a);
  return f / Factorial(Degree(alpha) + 3);
}

double BernsteinProductIntegral(const std::array<int, 4>& alpha, const std::array<int, 4>& beta,
                                double volume) {
  const std::array<int, 4> sum = {alpha[0] + beta[0], alpha[1] + beta[1], alpha[2] + beta[2],
                                  alpha[3] + beta[3]};
  return Multinomial(alpha) * Multinomial(beta) * BarycentricMonomialIntegral(sum, volume);
}

double BernsteinValue(const std::array<int, 4>& alpha, const Eigen::Vector4d& L) {
  double v = Multinomial(alpha);
  for (int i = 0; i < 4; ++i) v *= std::pow(L[i], alpha[i]);
  return v;
}

Eigen::MatrixX3d BernsteinGradients(int degree, const Eigen::Matrix<double, 4, 3>& g,
                                    const Eigen::Vector4d& L) {
  const std::vector<std::array<int, 4>> indices = BernsteinIndices(degree);
  Eigen::MatrixX3d out = Eigen::MatrixX3d::Zero(static_cast<int>(indices.size()), 3);
  for (size_t a = 0; a < indices.size(); ++a)
    for (int i = 0; i < 4; ++i)
      if (indices[a][i] > 0)
        out.row(a) += degree * BernsteinValue(Lowered(indices[a], i), L) * g.row(i);
  return out;
}

Eigen::MatrixXd BernsteinMassMatrix(int degree, double volume, double density) {
  const std::vector<std::array<int, 4>> indices = BernsteinIndices(degree);
  const int n = static_cast<int>(indices.size());
  Eigen::MatrixXd m(n, n);
  for (int a = 0; a < n; ++a)
    for (int b = 0; b < n; ++b)
      m(a, b) = density * BernsteinProductIntegral(indices[a], indices[b], volume);
  return m;
}

double BernsteinLumpedMass(int degree, double volume, double density) {
  return density * volume / BernsteinCount(degree);  // C(k+3,3) = BernsteinCount(k)
}

Eigen::MatrixXd BernsteinStiffnessMatrix(int degree, const Eigen::Matrix<double, 4, 3>& g,
                                         double volume, double lambda_kpa, double mu_kpa) {
  const std::vector<std::array<int, 4>> indices = BernsteinIndices(degree);
  const int n = static_cast<int>(indices.size());
  Eigen::MatrixXd k(3 * n, 3 * n);
  for (int a = 0; a < n; ++a) {
    for (int b = 0; b < n; ++b) {
      // G_ab = k^2 sum_ij g_i g_j^T int B^{k-1}_{a-e_i} B^{k-1}_{b-e_j}
      Eigen::Matrix3d G = Eigen::Matrix3d::Zero();
      for (int i = 0; i < 4; ++i) {
        if (indices[a][i] == 0) continue;
        for (int j = 0; j < 4; ++j) {
          if (indices[b][j] == 0) continue;
          G += BernsteinProductIntegral(Lowered(indices[a], i), Lowered(indices[b], j), volume) *
               g.row(i).transpose() * g.row(j);
        }
      }
      G *= static_cast<double>(degree * degree);
      Eigen::Matrix3d block = lambda_kpa * G + mu_kpa * G.transpose();
      block.diagonal().array() += mu_kpa * G.trace();
      k.block<3, 3>(3 * a, 3 * b) = block;
    }
  }
  return k;
}

Eigen::MatrixXd BernsteinMixedStiffnessMatrix(int degree, int pressure_degree,
                                              const Eigen::Matrix<double, 4, 3>& g, double volume,
                                              double lambda_kpa, double mu_kpa) {
  ARREG_CHECK_INPUT(pressure_degree >= 0 && pressure_degree < degree, "", "pressure_degree",
                    "must lie in [0, ", degree - 1, "] for degree ", degree, ", got ",
                    pressure_degree);
  const double kappa = lambda_kpa + 2.0 * mu_kpa / 3.0;
  // Deviatoric part: lambda' = -2 mu / 3 leaves mu |dev eps|^2.
  Eigen::MatrixXd k = BernsteinStiffnessMatrix(degree, g, volume, -2.0 * mu_kpa / 3.0, mu_kpa);
  const std::vector<std::array<int, 4>> u_indices = BernsteinIndices(degree);
  const std::vector<std::array<int, 4>> p_indices = BernsteinIndices(pressure_degree);
  const int nu = static_cast<int>(u_indices.size()), np = static_cast<int>(p_indices.size());
  Eigen::MatrixXd c = Eigen::MatrixXd::Zero(np, 3 * nu);
  for (int q = 0; q < np; ++q)
    for (int a = 0; a < nu; ++a)
      for (int i = 0; i < 4; ++i)
        if (u_indices[a][i] > 0)  // d B_a = k sum_i B^{k-1}_{a-e_i} g_i
          c.block<1, 3>(q, 3 * a) +=
              degree * BernsteinProductIntegral(p_indices[q], Lowered(u_indices[a], i), volume) *
              g.row(i);
  Eigen::MatrixXd m(np, np);
  for (int q = 0; q < np; ++q)
    for (int r = 0; r < np; ++r)
      m(q, r) = BernsteinProductIntegral(p_indices[q], p_indices[r], volume);
  k += kappa * c.transpose() * m.llt().solve(c);
  return k;
}

Eigen::MatrixX3d BernsteinMeanGradients(int degree, const Eigen::Matrix<double, 4, 3>& g) {
  const std::vector<std::array<int, 4>> indices = BernsteinIndices(degree);
  Eigen::MatrixX3d c = Eigen::MatrixX3d::Zero(static_cast<int>(indices.size()), 3);
  // 1/V int B^{k-1}_beta dV = 1 / C(k+2, 3) = 1 / BernsteinCount(k - 1)
  const double weight = static_cast<double>(degree) / BernsteinCount(degree - 1);
  for (size_t a = 0; a < indices.size(); ++a)
    for (int i = 0; i < 4; ++i)
      if (indices[a][i] > 0) c.row(a) += weight * g.row(i);
  return c;
}

void BernsteinTetOptions::Check() const {
  material.Check();
  ARREG_CHECK_INPUT(polar_max_iterations >= 1, "", "polar_max_iterations",
                    "must be at least 1, got ", polar_max_iterations);
  ARREG_CHECK_INPUT(std::isfinite(polar_tolerance) && polar_tolerance > 0, "", "polar_tolerance",
                    "must be positive and finite, got ", polar_tolerance);
  ARREG_CHECK_INPUT(pressure_degree >= -1 && pressure_degree <= 2, "", "pressure_degree",
                    "must be -1 (displacement) or a degree in [0, 2], got ", pressure_degree);
}

BernsteinTetTerm::BernsteinTetTerm(const HighOrderTetMesh* mesh, std::vector<int> node,
                                   const BernsteinTetOptions& options)
    : mesh_(mesh), node_(std::move(node)), options_(options) {
  options_.Check();
  ARREG_CHECK_INPUT(static_cast<int>(node_.size()) == mesh_->num_nodes(), "", "node", "has ",
                    node_.size(), " entries for ", mesh_->num_nodes(), " mesh nodes");
  const int k = mesh_->degree;
  indices_ = BernsteinIndices(k);
  const int n = static_cast<int>(indices_.size());
  ARREG_CHECK_INPUT(options_.pressure_degree < k, "", "pressure_degree",
                    "must be below the degree ", k, ", got ", options_.pressure_degree);
  ARREG_CHECK_INPUT(mesh_->elements.cols() == n, "", "elements", "has ", mesh_->elements.cols(),
                    " control points per element, degree ", k, " needs ", n);
  const double lambda = options_.material.LameLambdaKpa();
  const double mu = options_.material.LameMuKpa();
  elements_.resize(mesh_->num_elements());
  for (int e = 0; e < mesh_->num_elements(); ++e) {
    Element& el = elements_[e];
    el.nodes.resize(n);
    el.rest.resize(n, 3);
    for (int a = 0; a < n; ++a) {
      const int m = mesh_->elements(e, a);
      ARREG_CHECK_INPUT(m >= 0 && m < mesh_->num_nodes(), "", "elements", "element ", e,
                        " has node index ", m, " out of range");
      el.nodes[a] = node_[m];
      el.rest.row(a) = mesh_->nodes.row(m);
    }
    TetRestData rest;
    const bool ok = ComputeTetRestData(el.rest.row(0), el.rest.row(1), el.rest.row(2),
                                       el.rest.row(3), options_.material, &rest);
    ARREG_CHECK_INPUT(ok, "", "elements", "element ", e, " has non-positive volume ",
                      rest.volume_mm3, " mm^3");
    el.g = rest.shape_gradients;
    el.volume = rest.volume_mm3;
    // The closed-form integrals hold for the affine rest map (constant Jacobian); a
    // control point off its affine Bezier point makes the element curved (isoparametric).
    const double size = (el.rest.row(1) - el.rest.row(0)).norm();
    el.curved = false;
    for (int a = 4; a < n; ++a) {
      Eigen::RowVector3d affine = Eigen::RowVector3d::Zero();
      for (int i = 0; i < 4; ++i) affine += indices_[a][i] * el.rest.row(i) / k;
      if ((affine - el.rest.row(a)).norm() > 1e-9 * size) el.curved = true;
    }
    if (el.curved) {
      ARREG_CHECK_INPUT(options_.pressure_degree < 0, "", "elements", "element ", e,
                        " is curved: the mixed u-p formulation needs straight elements");
      InitCurvedElement(e, lambda, mu);
      continue;
    }
    el.mean_gradients = BernsteinMeanGradients(k, el.g);
    el.lumped_mass.assign(n, options_.material.DensityKgPerMm3() * el.volume / BernsteinCount(k));
    el.stiffness = options_.pressure_degree < 0
                       ? BernsteinStiffnessMatrix(k, el.g, el.volume, lambda, mu)
                       : BernsteinMixedStiffnessMatrix(k, options_.pressure_degree, el.g, el.volume,
                                                       lambda, mu);
  }
  rotations_.assign(elements_.size(), Eigen::Matrix3d::Identity());
  quaternions_.assign(elements_.size(), Eigen::Quaterniond::Identity());
  gradients_.assign(elements_.size(), Eigen::MatrixX3d::Zero(n, 3));
}

void BernsteinTetTerm::AppendStencils(std::vector<std::vector<int>>* stencils) const {
  for (const Element& el : elements_) stencils->push_back(el.nodes);
}

void BernsteinTetTerm::Update(const GeneralisedState& state) {
  if (updated_state_ == &state && updated_version_ == state.topology_version() &&
      updated_positions_.rows() == state.positions().rows() &&
      updated_positions_ == state.positions())
    return;
  const int n = static_cast<int>(indices_.size());
  energy_ = 0;
  Eigen::MatrixX3d x(n, 3), y(n, 3);
  Eigen::VectorXd u(3 * n), f(3 * n);
  for (size_t e = 0; e < elements_.size(); ++e) {
    const Element& el = elements_[e];
    for (int a = 0; a < n; ++a) {
      ARREG_ASSERT(!state.is_frame(el.nodes[a]), "Bernstein control points are point nodes");
      x.row(a) = state.positions().row(el.nodes[a]);
    }
    const Eigen::Matrix3d F = x.transpose() * el.mean_gradients;
    Eigen::Matrix3d R;
    PolarRotation(F, &quaternions_[e], &R, options_.polar_max_iterations, options_.polar_tolerance);
    rotations_[e] = R;
    y = x * R;  // rows (R^T x_alpha)^T
    for (int a = 0; a < n; ++a) u.segment<3>(3 * a) = (y.row(a) - el.rest.row(a)).transpose();
    f.noalias() = el.stiffness * u;
    energy_ += 0.5 * u.dot(f);
    // dR/dx: E changes by -omega . tau with omega the rotation increment (R^T dR = [omega]x),
    // tau = sum y x f, and (tr(S) I - S) omega = axial(R^T dF - dF^T R), S = R^T F.
    Eigen::Vector3d tau = Eigen::Vector3d::Zero();
    for (int a = 0; a < n; ++a) tau += y.row(a).transpose().cross(f.segment<3>(3 * a));
    Eigen::Matrix3d S = R.transpose() * F;
    S = 0.5 * (S + S.transpose()).eval();
    const Eigen::Matrix3d A = S.trace() * Eigen::Matrix3d::Identity() - S;
    Eigen::Vector3d s = Eigen::Vector3d::Zero();
    // A is singular only when two singular values of F sum to zero (a degenerate or
    // inverted element); the rotation is then not differentiable and the term is dropped.
    if (std::abs(A.determinant()) > 1e-12 * std::pow(std::max(S.trace(), 1e-300), 3))
      s = A.inverse() * tau;
    const Eigen::Matrix3d Rs = R * Skew(s);
    Eigen::MatrixX3d& grad = gradients_[e];
    for (int a = 0; a < n; ++a)
      grad.row(a) =
          (R * f.segment<3>(3 * a) - Rs * el.mean_gradients.row(a).transpose()).transpose();
  }
  updated_state_ = &state;
  updated_version_ = state.topology_version();
  updated_positions_ = state.positions();
}

double BernsteinTetTerm::Value(const GeneralisedState& state) const { return energy_; }

void BernsteinTetTerm::AddGradient(const GeneralisedState& state, Eigen::VectorXd* gradient) const {
  const int n = static_cast<int>(indices_.size());
  for (size_t e = 0; e < elements_.size(); ++e)
    for (int a = 0; a < n; ++a)
      gradient->segment<3>(state.dof_offset(elements_[e].nodes[a])) +=
          gradients_[e].row(a).transpose();
}

void BernsteinTetTerm::AddHessian(const GeneralisedState& state, double scale,
                                  HessianSink* sink) const {
  const int n = static_cast<int>(indices_.size());
  for (size_t e = 0; e < elements_.size(); ++e) {
    const Element& el = elements_[e];
    const Eigen::Matrix3d& R = rotations_[e];
    for (int a = 0; a < n; ++a)
      for (int b = a; b < n; ++b) {
        const Eigen::Matrix3d block = R * el.stiffness.block<3, 3>(3 * a, 3 * b) * R.transpose();
        sink->AddBlock(el.nodes[a], el.nodes[b], block, scale);
      }
  }
}

void BernsteinTetTerm::AddNodeInertia(const GeneralisedState& state,
                                      std::vector<NodeInertia>* inertia) const {
  for (const Element& el : elements_)
    for (size_t a = 0; a < el.nodes.size(); ++a)
      (*inertia)[el.nodes[a]].mass_kg += el.lumped_mass[a];
}

Eigen::Vector3d BernsteinTetTerm::Position(const GeneralisedState& state, int e,
                                           const Eigen::Vector4d& L) const {
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  for (size_t a = 0; a < indices_.size(); ++a)
    p += BernsteinValue(indices_[a], L) * state.position(elements_[e].nodes[a]);
  return p;
}

Eigen::MatrixX3d BernsteinTetTerm::RestGradients(int e, const Eigen::Vector4d& L) const {
  const Element& el = elements_[e];
  if (!el.curved) return BernsteinGradients(mesh_->degree, el.g, L);
  // grad_X B = J^-T grad_xi B, rows: grad_xi B J^-1 (xi = (L1, L2, L3)).
  Eigen::Matrix<double, 4, 3> reference = Eigen::Matrix<double, 4, 3>::Zero();
  reference.row(0).setConstant(-1);
  reference.bottomRows<3>().setIdentity();
  const Eigen::Matrix3d j = BezierTetJacobian(mesh_->degree, el.rest, L);
  return BernsteinGradients(mesh_->degree, reference, L) * j.inverse();
}

void BernsteinTetTerm::InitCurvedElement(int e, double lambda_kpa, double mu_kpa) {
  Element& el = elements_[e];
  const int k = mesh_->degree;
  const int n = static_cast<int>(indices_.size());
  // det J has degree 3(k - 1); cof(J) grad_xi B (the integrand of the mean gradients and
  // of the consistent forces) too, so the patch test holds exactly; the stiffness
  // integrand is rational, integrated to degree 6(k - 1).
  std::vector<Eigen::Vector4d> points;
  std::vector<double> weights;
  TetQuadrature(6 * (k - 1), &points, &weights);
  el.stiffness = Eigen::MatrixXd::Zero(3 * n, 3 * n);
  el.mean_gradients = Eigen::MatrixX3d::Zero(n, 3);
  el.lumped_mass.assign(n, 0.0);
  el.volume = 0;
  const double density = options_.material.DensityKgPerMm3();
  for (size_t q = 0; q < points.size(); ++q) {
    const double det = BezierTetJacobian(k, el.rest, points[q]).determinant();
    ARREG_CHECK_INPUT(det > 0, "", "elements", "curved element ", e,
                      " is inverted at a quadrature point (det J = ", det, ")");
    const double dv = weights[q] * det / 6.0;  // the reference tetrahedron has volume 1/6
    const Eigen::MatrixX3d grads = RestGradients(e, points[q]);
    const Eigen::VectorXd values = BernsteinValues(k, points[q]);
    el.volume += dv;
    el.mean_gradients += dv * grads;
    for (int a = 0; a < n; ++a) {
      el.lumped_mass[a] += density * dv * values[a];
      for (int b = 0; b < n; ++b) {
        const Eigen::Matrix3d G = grads.row(a).transpose() * grads.row(b);
        Eigen::Matrix3d block = lambda_kpa * G + mu_kpa * G.transpose();
        block.diagonal().array() += mu_kpa * G.trace();
        el.stiffness.block<3, 3>(3 * a, 3 * b) += dv * block;
      }
    }
  }
  el.mean_gradients /= el.volume;
}

Eigen::Matrix3d BernsteinTetTerm::DeformationGradientAt(const GeneralisedState& state, int e,
                                                        const Eigen::Vector4d& L) const {
  const Eigen::MatrixX3d grads = RestGradients(e, L);
  Eigen::Matrix3d F = Eigen::Matrix3d::Zero();
  for (size_t a = 0; a < indices_.size(); ++a)
    F += state.position(elements_[e].nodes[a]) * grads.row(a);
  return F;
}

std::vector<int> AddHighOrderNodes(const HighOrderTetMesh& mesh, GeneralisedState* state) {
  std::vector<int> node(mesh.num_nodes());
  for (int i = 0; i < mesh.num_nodes(); ++i)
    node[i] = state->AddPointNode(mesh.nodes.row(i).transpose());
  return node;
}

double NodalForceTerm::Value(const GeneralisedState& state) const {
  double e = 0;
  for (int i = 0; i < forces_.rows(); ++i) e -= forces_.row(i).dot(state.positions().row(i));
  return e;
}

void NodalForceTerm::AddGradient(const GeneralisedState& state, Eigen::VectorXd* gradient) const {
  for (int i = 0; i < forces_.rows(); ++i)
    gradient->segment<3>(state.dof_offset(i)) -= forces_.row(i).transpose();
}

RowMatX3d UniformTractionLoads(
    const HighOrderTetMesh& mesh,
    const std::function<bool(const Eigen::Vector3d&, const Eigen::Vector3d&,
                             const Eigen::Vector3d&)>& select,
    const Eigen::Vector3d& traction_kpa) {
  const int k = mesh.degree;
  const std::vector<std::array<int, 4>> indices = BernsteinIndices(k);
  // Faces by their sorted corner vertices: boundary faces belong to one element.
  std::map<std::array<int, 3>, std::pair<int, int>> faces;  // -> (element, opposite corner)
  std::map<std::array<int, 3>, int> count;
  for (int e = 0; e < mesh.num_elements(); ++e)
    for (int opposite = 0; opposite < 4; ++opposite) {
      std::array<int, 3> key;
      int j = 0;
      for (int i = 0; i < 4; ++i)
        if (i != opposite) key[j++] = mesh.elements(e, i);
      std::sort(key.begin(), key.end());
      faces[key] = {e, opposite};
      ++count[key];
    }
  RowMatX3d loads = RowMatX3d::Zero(mesh.num_nodes(), 3);
  for (const auto& [key, where] : faces) {
    if (count[key] != 1) continue;
    const Eigen::Vector3d a = mesh.nodes.row(key[0]).transpose();
    const Eigen::Vector3d b = mesh.nodes.row(key[1]).transpose();
    const Eigen::Vector3d c = mesh.nodes.row(key[2]).transpose();
    if (!select(a, b, c)) continue;
    const double area = 0.5 * (b - a).cross(c - a).norm();
    const double share = 2.0 * area / ((k + 1) * (k + 2));
    const auto [e, opposite] = where;
    for (size_t alpha = 0; alpha < indices.size(); ++alpha)
      if (indices[alpha][opposite] == 0)
        loads.row(mesh.elements(e, static_cast<int>(alpha))) += share * traction_kpa.transpose();
  }
  return loads;
}

}  // namespace arreg::mechanics
