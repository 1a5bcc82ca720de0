#include "ar/synth/neo_hookean.h"

#include <Eigen/CholmodSupport>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <limits>

#include "core/error.h"

namespace arreg::synth {

void NeoHookeanMaterial::Check() const {
  ARREG_CHECK_INPUT(youngs_modulus_pa > 0 && std::isfinite(youngs_modulus_pa), "",
                    "youngs_modulus_pa", "must be positive, got ", youngs_modulus_pa);
  ARREG_CHECK_INPUT(poisson_ratio > -1 && poisson_ratio < 0.5, "", "poisson_ratio",
                    "must be in (-1, 0.5), got ", poisson_ratio);
}
double NeoHookeanMaterial::mu() const { return youngs_modulus_pa / (2 * (1 + poisson_ratio)); }
double NeoHookeanMaterial::lambda() const {
  return youngs_modulus_pa * poisson_ratio / ((1 + poisson_ratio) * (1 - 2 * poisson_ratio));
}

void QuasiStaticOptions::Check() const {
  ARREG_CHECK_INPUT(max_iterations > 0, "", "max_iterations", "must be positive");
  ARREG_CHECK_INPUT(relative_force_tolerance > 0, "", "relative_force_tolerance",
                    "must be positive");
  ARREG_CHECK_INPUT(step_tolerance_mm >= 0, "", "step_tolerance_mm", "must be >= 0");
  ARREG_CHECK_INPUT(armijo > 0 && armijo < 0.5, "", "armijo", "must be in (0, 0.5)");
  ARREG_CHECK_INPUT(max_line_search_steps > 0, "", "max_line_search_steps", "must be positive");
  ARREG_CHECK_INPUT(min_volume_ratio > 0 && min_volume_ratio < 1, "", "min_volume_ratio",
                    "must be in (0, 1)");
}

NeoHookeanEnergy::NeoHookeanEnergy(const RowMatX3d& rest_positions, const RowMatX4i& tetrahedra,
                                   const NeoHookeanMaterial& material)
    : tets_(tetrahedra), num_vertices_(static_cast<int>(rest_positions.rows())) {
  material.Check();
  mu_ = material.mu();
  lambda_ = material.lambda();
  rest_inverse_.resize(tets_.rows());
  rest_volume_.resize(tets_.rows());
  for (int t = 0; t < tets_.rows(); ++t) {
    Eigen::Matrix3d dm;
    for (int k = 0; k < 4; ++k)
      ARREG_CHECK_INPUT(tets_(t, k) >= 0 && tets_(t, k) < num_vertices_, "", "tetrahedra",
                        "tetrahedron ", t, " has vertex index ", tets_(t, k), " out of range");
    for (int k = 0; k < 3; ++k)
      dm.col(k) =
          (rest_positions.row(tets_(t, k + 1)) - rest_positions.row(tets_(t, 0))).transpose();
    const double det = dm.determinant();
    ARREG_CHECK_INPUT(det > 0, "", "tetrahedra", "tetrahedron ", t,
                      " is inverted or flat at rest (6 V = ", det, " mm^3)");
    rest_inverse_[t] = dm.inverse();
    rest_volume_[t] = det / 6.0;
  }
}

Eigen::Matrix3d NeoHookeanEnergy::DeformationGradient(int t, const RowMatX3d& x) const {
  Eigen::Matrix3d ds;
  for (int k = 0; k < 3; ++k) ds.col(k) = (x.row(tets_(t, k + 1)) - x.row(tets_(t, 0))).transpose();
  return ds * rest_inverse_[t];
}

double NeoHookeanEnergy::Value(const RowMatX3d& x) const {
  double energy = 0;
  for (int t = 0; t < tets_.rows(); ++t) {
    const Eigen::Matrix3d f = DeformationGradient(t, x);
    const double j = f.determinant();
    if (!(j > 0)) return std::numeric_limits<double>::infinity();
    const double log_j = std::log(j);
    energy += rest_volume_[t] *
              (0.5 * mu_ * (f.squaredNorm() - 3) - mu_ * log_j + 0.5 * lambda_ * log_j * log_j);
  }
  return energy;
}

Eigen::VectorXd NeoHookeanEnergy::Gradient(const RowMatX3d& x) const {
  Eigen::VectorXd g = Eigen::VectorXd::Zero(3 * num_vertices_);
  for (int t = 0; t < tets_.rows(); ++t) {
    const Eigen::Matrix3d f = DeformationGradient(t, x);
    const double j = f.determinant();
    const Eigen::Matrix3d f_inv_t = f.inverse().transpose();
    const Eigen::Matrix3d p = mu_ * (f - f_inv_t) + lambda_ * std::log(j) * f_inv_t;
    const Eigen::Matrix3d h =
        rest_volume_[t] * p * rest_inverse_[t].transpose();  // columns: vertices 1..3
    for (int k = 0; k < 3; ++k) {
      g.segment<3>(3 * tets_(t, k + 1)) += h.col(k);
      g.segment<3>(3 * tets_(t, 0)) -= h.col(k);
    }
  }
  return g;
}

Eigen::Matrix<double, 12, 12> NeoHookeanEnergy::ElementHessian(int t, const RowMatX3d& x) const {
  const Eigen::Matrix3d f = DeformationGradient(t, x);
  const double j = f.determinant();
  const Eigen::Matrix3d f_inv = f.inverse();
  const Eigen::Matrix3d f_inv_t = f_inv.transpose();
  const double c1 = mu_ - lambda_ * std::log(j);
  const Eigen::Matrix3d& dm_inv = rest_inverse_[t];
  // Derivative of the forces on vertices 1..3 w.r.t. vertices 1..3 (9 x 9);
  // vertex 0 follows from translation invariance.
  Eigen::Matrix<double, 9, 9> core;
  for (int k = 0; k < 3; ++k) {
    for (int c = 0; c < 3; ++c) {
      const Eigen::Matrix3d df = Eigen::Vector3d::Unit(c) * dm_inv.row(k);
      const Eigen::Matrix3d dp = mu_ * df + c1 * f_inv_t * df.transpose() * f_inv_t +
                                 lambda_ * (f_inv * df).trace() * f_inv_t;
      const Eigen::Matrix3d dh = rest_volume_[t] * dp * dm_inv.transpose();
      for (int kk = 0; kk < 3; ++kk) core.block<3, 1>(3 * kk, 3 * k + c) = dh.col(kk);
    }
  }
  Eigen::Matrix<double, 12, 12> h;
  h.bottomRightCorner<9, 9>() = core;
  for (int a = 0; a < 3; ++a) {
    Eigen::Matrix3d col_sum = Eigen::Matrix3d::Zero();
    for (int b = 0; b < 3; ++b) col_sum += core.block<3, 3>(3 * b, 3 * a);
    h.block<3, 3>(0, 3 + 3 * a) = -col_sum;
  }
  for (int b = 0; b < 3; ++b) {
    Eigen::Matrix3d row_sum = Eigen::Matrix3d::Zero();
    for (int a = 0; a < 3; ++a) row_sum += core.block<3, 3>(3 * b, 3 * a);
    h.block<3, 3>(3 + 3 * b, 0) = -row_sum;
  }
  Eigen::Matrix3d all = Eigen::Matrix3d::Zero();
  for (int a = 0; a < 3; ++a) all += h.block<3, 3>(0, 3 + 3 * a);
  h.block<3, 3>(0, 0) = -all;
  return h;
}

Eigen::SparseMatrix<double> NeoHookeanEnergy::Hessian(const RowMatX3d& x) const {
  std::vector<Eigen::Triplet<double>> triplets;
  triplets.reserve(tets_.rows() * 144);
  for (int t = 0; t < tets_.rows(); ++t) {
    const Eigen::Matrix<double, 12, 12> he = ElementHessian(t, x);
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b)
        for (int i = 0; i < 3; ++i)
          for (int k = 0; k < 3; ++k)
            triplets.emplace_back(3 * tets_(t, a) + i, 3 * tets_(t, b) + k,
                                  he(3 * a + i, 3 * b + k));
  }
  Eigen::SparseMatrix<double> h(3 * num_vertices_, 3 * num_vertices_);
  h.setFromTriplets(triplets.begin(), triplets.end());
  return h;
}

Eigen::VectorXd NeoHookeanEnergy::VolumeRatios(const RowMatX3d& x) const {
  Eigen::VectorXd ratios(tets_.rows());
  for (int t = 0; t < tets_.rows(); ++t) ratios[t] = DeformationGradient(t, x).determinant();
  return ratios;
}

struct QuasiStaticSolver::Impl {
  const NeoHookeanEnergy* energy;
  std::vector<bool> fixed;
  QuasiStaticOptions options;
  std::vector<int> free_index;  // per DOF: index among free DOFs, -1 when fixed
  int num_free = 0;
  Eigen::SparseMatrix<double> hessian;  // free x free, lower triangle stored
  std::vector<int> value_slot;          // per tet, 144 slots into hessian's values (-1: none)
  Eigen::CholmodSupernodalLLT<Eigen::SparseMatrix<double>, Eigen::Lower> llt;

  void BuildPattern() {
    const RowMatX4i& tets = energy->tetrahedra();
    std::vector<Eigen::Triplet<double>> triplets;
    triplets.reserve(tets.rows() * 78);
    for (int t = 0; t < tets.rows(); ++t)
      for (int a = 0; a < 12; ++a)
        for (int b = 0; b < 12; ++b) {
          const int r = free_index[3 * tets(t, a / 3) + a % 3];
          const int c = free_index[3 * tets(t, b / 3) + b % 3];
          if (r >= 0 && c >= 0 && r >= c) triplets.emplace_back(r, c, 0.0);
        }
    hessian.resize(num_free, num_free);
    hessian.setFromTriplets(triplets.begin(), triplets.end());
    hessian.makeCompressed();
    value_slot.assign(tets.rows() * 144, -1);
    const int* outer = hessian.outerIndexPtr();
    const int* inner = hessian.innerIndexPtr();
    for (int t = 0; t < tets.rows(); ++t)
      for (int a = 0; a < 12; ++a)
        for (int b = 0; b < 12; ++b) {
          const int r = free_index[3 * tets(t, a / 3) + a % 3];
          const int c = free_index[3 * tets(t, b / 3) + b % 3];
          if (r < 0 || c < 0 || r < c) continue;
          const int* begin = inner + outer[c];
          const int* end = inner + outer[c + 1];
          const int* it = std::lower_bound(begin, end, r);
          ARREG_ASSERT(it != end && *it == r, "sparsity pattern misses an entry");
          value_slot[t * 144 + a * 12 + b] = static_cast<int>(it - inner);
        }
    llt.analyzePattern(hessian);
  }

  // Assembles the free-free Hessian, the free gradient and the coupling
  // H_free,fixed * delta_fixed.
  void Assemble(const RowMatX3d& x, const Eigen::VectorXd& delta_fixed, Eigen::VectorXd* grad_free,
                Eigen::VectorXd* coupling) {
    const RowMatX4i& tets = energy->tetrahedra();
    std::fill(hessian.valuePtr(), hessian.valuePtr() + hessian.nonZeros(), 0.0);
    const Eigen::VectorXd g = energy->Gradient(x);
    grad_free->setZero(num_free);
    coupling->setZero(num_free);
    for (int d = 0; d < static_cast<int>(free_index.size()); ++d)
      if (free_index[d] >= 0) (*grad_free)[free_index[d]] = g[d];
    double* values = hessian.valuePtr();
    for (int t = 0; t < tets.rows(); ++t) {
      const Eigen::Matrix<double, 12, 12> he = energy->ElementHessian(t, x);
      for (int a = 0; a < 12; ++a) {
        const int r = free_index[3 * tets(t, a / 3) + a % 3];
        if (r < 0) continue;
        for (int b = 0; b < 12; ++b) {
          const int slot = value_slot[t * 144 + a * 12 + b];
          if (slot >= 0) {
            values[slot] += he(a, b);
          } else {
            const int dof = 3 * tets(t, b / 3) + b % 3;
            if (free_index[dof] < 0) (*coupling)[r] += he(a, b) * delta_fixed[dof];
          }
        }
      }
    }
  }
};

QuasiStaticSolver::QuasiStaticSolver(const NeoHookeanEnergy* energy,
                                     const std::vector<bool>& fixed_vertex,
                                     const QuasiStaticOptions& options)
    : impl_(new Impl) {
  options.Check();
  ARREG_CHECK_INPUT(static_cast<int>(fixed_vertex.size()) == energy->num_vertices(), "",
                    "fixed_vertex", "needs one flag per vertex (", energy->num_vertices(), ")");
  impl_->energy = energy;
  impl_->fixed = fixed_vertex;
  impl_->options = options;
  impl_->free_index.assign(3 * energy->num_vertices(), -1);
  for (int v = 0; v < energy->num_vertices(); ++v)
    if (!fixed_vertex[v])
      for (int c = 0; c < 3; ++c) impl_->free_index[3 * v + c] = impl_->num_free++;
  // Indefinite Hessians are expected far from equilibrium and handled by a
  // diagonal shift; keep CHOLMOD from printing a warning for each.
  impl_->llt.cholmod().print = 0;
  impl_->BuildPattern();
}

QuasiStaticSolver::~QuasiStaticSolver() = default;

QuasiStaticSummary QuasiStaticSolver::Solve(const RowMatX3d& targets, RowMatX3d* positions) {
  Impl& s = *impl_;
  const NeoHookeanEnergy& e = *s.energy;
  ARREG_CHECK_INPUT(targets.rows() == e.num_vertices() && positions->rows() == e.num_vertices(), "",
                    "positions", "need ", e.num_vertices(), " rows");
  QuasiStaticSummary summary;
  RowMatX3d& x = *positions;
  const int nv = e.num_vertices();
  // Reference force: a typical stiffness (mean Hessian diagonal) times 1 mm per free DOF.
  double tolerance = -1;
  Eigen::VectorXd grad_free, coupling, delta_fixed = Eigen::VectorXd::Zero(3 * nv);
  for (int it = 0; it < s.options.max_iterations; ++it) {
    double max_delta_fixed = 0;
    for (int v = 0; v < nv; ++v) {
      if (!s.fixed[v]) continue;
      for (int c = 0; c < 3; ++c) {
        delta_fixed[3 * v + c] = targets(v, c) - x(v, c);
        max_delta_fixed = std::max(max_delta_fixed, std::abs(delta_fixed[3 * v + c]));
      }
    }
    const bool moving_fixed = max_delta_fixed > 0;
    s.Assemble(x, delta_fixed, &grad_free, &coupling);
    if (tolerance < 0) {
      const double diag_mean = s.hessian.diagonal().cwiseAbs().mean();
      tolerance = s.options.relative_force_tolerance * std::max(diag_mean, 1e-300) *
                  std::sqrt(static_cast<double>(std::max(1, s.num_free)));
    }
    summary.iterations = it + 1;
    summary.final_gradient_norm = grad_free.norm();
    if (!moving_fixed && summary.final_gradient_norm <= tolerance) {
      summary.converged = true;
      break;
    }
    const Eigen::VectorXd rhs = -(grad_free + coupling);
    Eigen::VectorXd step;
    double shift = 0;
    const double diag_mean = s.hessian.diagonal().mean();
    for (int attempt = 0; attempt < 8; ++attempt) {
      if (shift > 0) {
        Eigen::SparseMatrix<double> shifted = s.hessian;
        for (int i = 0; i < s.num_free; ++i) shifted.coeffRef(i, i) += shift;
        s.llt.factorize(shifted);
      } else {
        s.llt.factorize(s.hessian);
      }
      if (s.llt.info() == Eigen::Success) {
        step = s.llt.solve(rhs);
        if (moving_fixed || step.dot(grad_free) < 0) break;
      }
      shift = shift == 0 ? 1e-4 * diag_mean : shift * 10;
      ++summary.regularised_factorisations;
      step.resize(0);
    }
    if (step.size() != s.num_free) {
      summary.message = "Hessian could not be factorised even with a diagonal shift";
      break;
    }
    // Line search: while grips move, only keep elements from collapsing; then
    // Armijo on the energy.
    const double energy0 = moving_fixed ? 0 : e.Value(x);
    const double slope = step.dot(grad_free);
    double alpha = 1;
    RowMatX3d trial = x;
    bool accepted = false;
    for (int ls = 0; ls < s.options.max_line_search_steps; ++ls, alpha *= 0.5) {
      for (int v = 0; v < nv; ++v)
        for (int c = 0; c < 3; ++c) {
          const int d = 3 * v + c;
          trial(v, c) = x(v, c) + alpha * (s.fixed[v] ? delta_fixed[d] : step[s.free_index[d]]);
        }
      if (moving_fixed) {
        if (e.VolumeRatios(trial).minCoeff() >= s.options.min_volume_ratio) {
          accepted = true;
          break;
        }
      } else if (e.Value(trial) <= energy0 + s.options.armijo * alpha * slope) {
        accepted = true;
        break;
      }
    }
    if (!accepted) {
      summary.message = moving_fixed ? "grip motion collapses elements (line search failed)"
                                     : "line search found no decrease";
      break;
    }
    const double max_step = (trial - x).cwiseAbs().maxCoeff();
    x = trial;
    if (!moving_fixed && max_step <= s.options.step_tolerance_mm) {
      summary.converged = true;
      summary.final_gradient_norm = -1;  // not re-evaluated
      break;
    }
  }
  if (summary.final_gradient_norm < 0) {
    Eigen::VectorXd g = e.Gradient(x);
    double norm2 = 0;
    for (int d = 0; d < 3 * nv; ++d)
      if (s.free_index[d] >= 0) norm2 += g[d] * g[d];
    summary.final_gradient_norm = std::sqrt(norm2);
  }
  summary.energy = e.Value(x);
  if (!summary.converged && summary.message.empty())
    summary.message = "no convergence within max_iterations";
  return summary;
}

}  // namespace arreg::synth
