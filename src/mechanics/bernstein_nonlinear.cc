#include "mechanics/bernstein_nonlinear.h"

#include <cmath>

#include "core/error.h"
#include "mechanics/bernstein_tet.h"

namespace arreg::mechanics {

namespace {

// Gauss-Legendre points and weights on [0, 1] (n points, exact to degree 2n - 1), by
// Newton on the Legendre polynomial P_n from the usual cosine guesses.
void GaussLegendre01(int n, std::vector<double>* x, std::vector<double>* w) {
  x->clear();
  w->clear();
  for (int i = 0; i < n; ++i) {
    double t = std::cos(M_PI * (i + 0.75) / (n + 0.5));
    double dp = 1;
    for (int it = 0; it < 100; ++it) {
      double p0 = 1, p1 = t;
      for (int k = 2; k <= n; ++k) {
        const double p2 = ((2 * k - 1) * t * p1 - (k - 1) * p0) / k;
        p0 = p1;
        p1 = p2;
      }
      dp = n * (t * p1 - p0) / (t * t - 1);
      const double step = p1 / dp;
      t -= step;
      if (std::abs(step) < 1e-16) break;
    }
    x->push_back(0.5 * (1 - t));
    w->push_back(1.0 / ((1 - t * t) * dp * dp));  // 2 / ((1 - t^2) P_n'^2) / 2
  }
}

Eigen::Matrix3d Sym(const Eigen::Matrix3d& h) { return 0.5 * (h + h.transpose()); }

}  // namespace

void TetQuadrature(int degree, std::vector<Eigen::Vector4d>* points, std::vector<double>* weights) {
  ARREG_CHECK_INPUT(degree >= 0 && degree <= 20, "", "degree", "must be 0 .. 20, got ", degree);
  // L1 = u, L2 = (1 - u) v, L3 = (1 - u)(1 - v) w with Jacobian (1 - u)^2 (1 - v): the
  // integrand has degree degree + 2 in u, so n points with 2n - 1 >= degree + 2.
  const int n = (degree + 4) / 2;
  std::vector<double> x, w;
  GaussLegendre01(n, &x, &w);
  points->clear();
  weights->clear();
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j)
      for (int k = 0; k < n; ++k) {
        const double u = x[i], v = x[j], s = x[k];
        const double l1 = u, l2 = (1 - u) * v, l3 = (1 - u) * (1 - v) * s;
        points->emplace_back(1 - l1 - l2 - l3, l1, l2, l3);
        weights->push_back(6.0 * w[i] * w[j] * w[k] * (1 - u) * (1 - u) * (1 - v));
      }
}

void StiffeningMaterial::Check() const {
  material.Check();
  ARREG_CHECK_INPUT(nonlinearity >= 0 && std::isfinite(nonlinearity), "", "nonlinearity",
                    "must be finite and >= 0, got ", nonlinearity);
}

double StiffeningMaterial::Energy(const Eigen::Matrix3d& eps) const {
  const double mu = material.LameMuKpa(), lambda = material.LameLambdaKpa();
  const double s = (eps.array() * eps.array()).sum(), tr = eps.trace();
  const double psi = mu * s + 0.5 * lambda * tr * tr;
  return psi * (1 + 0.5 * nonlinearity * s);
}

Eigen::Matrix3d StiffeningMaterial::Stress(const Eigen::Matrix3d& eps) const {
  const double mu = material.LameMuKpa(), lambda = material.LameLambdaKpa();
  const double s = (eps.array() * eps.array()).sum(), tr = eps.trace();
  const double psi = mu * s + 0.5 * lambda * tr * tr;
  const Eigen::Matrix3d linear = 2 * mu * eps + lambda * tr * Eigen::Matrix3d::Identity();
  return (1 + 0.5 * nonlinearity * s) * linear + nonlinearity * psi * eps;
}

Eigen::Matrix3d StiffeningMaterial::StressIncrement(const Eigen::Matrix3d& eps,
                                                    const Eigen::Matrix3d& deps) const {
  const double mu = material.LameMuKpa(), lambda = material.LameLambdaKpa();
  const double s = (eps.array() * eps.array()).sum(), tr = eps.trace();
  const double psi = mu * s + 0.5 * lambda * tr * tr;
  const Eigen::Matrix3d linear = 2 * mu * eps + lambda * tr * Eigen::Matrix3d::Identity();
  const Eigen::Matrix3d dlinear =
      2 * mu * deps + lambda * deps.trace() * Eigen::Matrix3d::Identity();
  const double ds = 2 * (eps.array() * deps.array()).sum();   // d(eps:eps)
  const double dpsi = (linear.array() * deps.array()).sum();  // dpsi = sigma_lin:deps
  const double a = nonlinearity;
  return (1 + 0.5 * a * s) * dlinear + 0.5 * a * ds * linear + a * dpsi * eps + a * psi * deps;
}

BernsteinStiffeningTerm::BernsteinStiffeningTerm(const HighOrderTetMesh* mesh,
                                                 std::vector<int> node,
                                                 const StiffeningMaterial& material)
    : mesh_(mesh), node_(std::move(node)), material_(material) {
  material_.Check();
  ARREG_CHECK_INPUT(static_cast<int>(node_.size()) == mesh_->num_nodes(), "", "node", "expected ",
                    mesh_->num_nodes(), " entries, got ", node_.size());
  const int k = mesh_->degree;
  std::vector<Eigen::Vector4d> points;
  std::vector<double> weights;
  TetQuadrature(4 * (k - 1), &points, &weights);
  const int n = static_cast<int>(mesh_->elements.cols());
  for (int e = 0; e < mesh_->num_elements(); ++e) {
    Element el;
    el.rest.resize(n, 3);
    for (int a = 0; a < n; ++a) {
      el.nodes.push_back(node_[mesh_->elements(e, a)]);
      el.rest.row(a) = mesh_->nodes.row(mesh_->elements(e, a));
    }
    Eigen::Matrix3d d;
    for (int c = 0; c < 3; ++c) d.col(c) = (el.rest.row(c + 1) - el.rest.row(0)).transpose();
    const double volume = d.determinant() / 6.0;
    ARREG_CHECK_INPUT(volume > 0, "", "elements", "element ", e, " has volume ", volume,
                      " mm^3 (must be positive)");
    Eigen::Matrix<double, 4, 3> g;
    g.bottomRows<3>() = d.inverse();
    g.row(0) = -g.bottomRows<3>().colwise().sum();
    for (size_t q = 0; q < points.size(); ++q) {
      el.grad.push_back(BernsteinGradients(k, g, points[q]));
      el.weight.push_back(weights[q] * volume);
    }
    elements_.push_back(std::move(el));
  }
}

void BernsteinStiffeningTerm::AppendStencils(std::vector<std::vector<int>>* stencils) const {
  for (const Element& el : elements_) stencils->push_back(el.nodes);
}

Eigen::Matrix3d BernsteinStiffeningTerm::Strain(const GeneralisedState& state, const Element& el,
                                                int q) const {
  Eigen::Matrix3d h = Eigen::Matrix3d::Zero();  // grad u = sum_alpha u_alpha grad B_alpha^T
  for (size_t a = 0; a < el.nodes.size(); ++a)
    h += (state.position(el.nodes[a]) - el.rest.row(a).transpose()) * el.grad[q].row(a);
  return Sym(h);
}

void BernsteinStiffeningTerm::Update(const GeneralisedState& state) {
  energy_ = 0;
  for (const Element& el : elements_)
    for (size_t q = 0; q < el.weight.size(); ++q)
      energy_ += el.weight[q] * material_.Energy(Strain(state, el, static_cast<int>(q)));
}

double BernsteinStiffeningTerm::Value(const GeneralisedState&) const { return energy_; }

void BernsteinStiffeningTerm::AddGradient(const GeneralisedState& state,
                                          Eigen::VectorXd* gradient) const {
  for (const Element& el : elements_)
    for (size_t q = 0; q < el.weight.size(); ++q) {
      const Eigen::Matrix3d sigma = material_.Stress(Strain(state, el, static_cast<int>(q)));
      for (size_t a = 0; a < el.nodes.size(); ++a)
        gradient->segment<3>(state.dof_offset(el.nodes[a])) +=
            el.weight[q] * sigma * el.grad[q].row(a).transpose();
    }
}

void BernsteinStiffeningTerm::AddHessian(const GeneralisedState& state, double scale,
                                         HessianSink* sink) const {
  for (const Element& el : elements_) {
    const int n = static_cast<int>(el.nodes.size());
    Eigen::MatrixXd k = Eigen::MatrixXd::Zero(3 * n, 3 * n);
    for (size_t q = 0; q < el.weight.size(); ++q) {
      const Eigen::Matrix3d eps = Strain(state, el, static_cast<int>(q));
      for (int b = 0; b < n; ++b)
        for (int j = 0; j < 3; ++j) {
          // d(force on a) / d(x_b,j) = D[sym(e_j grad B_b^T)] grad B_a
          Eigen::Matrix3d dh = Eigen::Matrix3d::Zero();
          dh.row(j) = el.grad[q].row(b);
          const Eigen::Matrix3d dsigma = material_.StressIncrement(eps, Sym(dh));
          for (int a = 0; a < n; ++a)
            k.block<3, 1>(3 * a, 3 * b + j) +=
                el.weight[q] * dsigma * el.grad[q].row(a).transpose();
        }
    }
    for (int a = 0; a < n; ++a)
      for (int b = a; b < n; ++b)
        sink->AddBlock(el.nodes[a], el.nodes[b], k.block<3, 3>(3 * a, 3 * b), scale);
  }
}

}  // namespace arreg::mechanics
