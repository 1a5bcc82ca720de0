#include "mechanics/curved_tet.h"

#include <Eigen/LU>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include "core/error.h"
#include "mechanics/bernstein_tet.h"
#include "mechanics/embedding.h"

namespace arreg::mechanics {

namespace {

// L_i^j for j = 0..degree, per coordinate i (4 x (degree + 1)).
Eigen::Matrix<double, 4, Eigen::Dynamic> Powers(int degree, const Eigen::Vector4d& L) {
  Eigen::Matrix<double, 4, Eigen::Dynamic> p(4, degree + 1);
  p.col(0).setOnes();
  for (int j = 1; j <= degree; ++j) p.col(j) = p.col(j - 1).cwiseProduct(L);
  return p;
}

double Factorial(int n) {
  double f = 1.0;
  for (int i = 2; i <= n; ++i) f *= i;
  return f;
}

// Per degree 0 .. kMaxDegree: the multi-indices, their multinomial coefficients and,
// for degree >= 1, the index of alpha - e_i among the indices of degree - 1 (-1 when
// alpha_i = 0). Built once: evaluation runs per point per element.
constexpr int kMaxDegree = 12;
struct BernsteinTable {
  std::vector<std::array<int, 4>> indices;
  std::vector<double> multinomial;
  std::vector<std::array<int, 4>> lowered;
};
const BernsteinTable& TableOf(int degree) {
  static const std::vector<BernsteinTable> tables = [] {
    std::vector<BernsteinTable> out(kMaxDegree + 1);
    for (int d = 0; d <= kMaxDegree; ++d) {
      out[d].indices = BernsteinIndices(d);
      for (const std::array<int, 4>& alpha : out[d].indices) {
        double m = Factorial(d);
        for (int a : alpha) m /= Factorial(a);
        out[d].multinomial.push_back(m);
        std::array<int, 4> lowered = {-1, -1, -1, -1};
        for (int i = 0; i < 4 && d > 0; ++i) {
          if (alpha[i] == 0) continue;
          std::array<int, 4> beta = alpha;
          --beta[i];
          const auto& lower = out[d - 1].indices;
          lowered[i] =
              static_cast<int>(std::find(lower.begin(), lower.end(), beta) - lower.begin());
        }
        out[d].lowered.push_back(lowered);
      }
    }
    return out;
  }();
  return tables[degree];
}

double Diagonal(const Eigen::MatrixX3d& control) {
  return (control.colwise().maxCoeff() - control.colwise().minCoeff()).norm();
}

// Inverse of the collocation matrix V_(alpha, beta) = B_beta(alpha / k) over the
// lattice points alpha of BernsteinIndices(k): Bernstein coefficients from values.
const Eigen::MatrixXd& InverseCollocation(int degree) {
  static const std::array<Eigen::MatrixXd, 4> inverses = [] {
    std::array<Eigen::MatrixXd, 4> out;
    for (int k = 1; k <= 3; ++k) {
      const std::vector<std::array<int, 4>> indices = BernsteinIndices(k);
      const int n = static_cast<int>(indices.size());
      Eigen::MatrixXd v(n, n);
      for (int a = 0; a < n; ++a) {
        const Eigen::Vector4d L(indices[a][0], indices[a][1], indices[a][2], indices[a][3]);
        v.row(a) = BernsteinValues(k, L / k).transpose();
      }
      out[k] = v.inverse();
    }
    return out;
  }();
  return inverses[degree];
}

// Lattice points alpha / d (rows) and the inverse collocation matrix of degree d in
// {1, 3, 6}, the degrees of the Jacobian determinant of elements of degree 1, 2, 3.
struct DeterminantBasis {
  std::vector<Eigen::Vector4d> points;
  Eigen::MatrixXd inverse;
};
const DeterminantBasis& DeterminantBasisOf(int element_degree) {
  static const std::array<DeterminantBasis, 4> bases = [] {
    std::array<DeterminantBasis, 4> out;
    for (int k = 1; k <= 3; ++k) {
      const int d = std::max(3 * (k - 1), 1);
      const std::vector<std::array<int, 4>> indices = BernsteinIndices(d);
      const int n = static_cast<int>(indices.size());
      Eigen::MatrixXd v(n, n);
      for (int a = 0; a < n; ++a) {
        const Eigen::Vector4d L =
            Eigen::Vector4d(indices[a][0], indices[a][1], indices[a][2], indices[a][3]) / d;
        out[k].points.push_back(L);
        v.row(a) = BernsteinValues(d, L).transpose();
      }
      out[k].inverse = v.fullPivLu().inverse();
    }
    return out;
  }();
  return bases[element_degree];
}

}  // namespace

Eigen::VectorXd BernsteinValues(int degree, const Eigen::Vector4d& L) {
  ARREG_CHECK_INPUT(degree >= 0 && degree <= kMaxDegree, "", "degree", "must be 0 .. ", kMaxDegree,
                    ", got ", degree);
  const BernsteinTable& table = TableOf(degree);
  const Eigen::Matrix<double, 4, Eigen::Dynamic> p = Powers(degree, L);
  Eigen::VectorXd out(static_cast<int>(table.indices.size()));
  for (size_t a = 0; a < table.indices.size(); ++a) {
    const std::array<int, 4>& alpha = table.indices[a];
    out[static_cast<int>(a)] =
        table.multinomial[a] * p(0, alpha[0]) * p(1, alpha[1]) * p(2, alpha[2]) * p(3, alpha[3]);
  }
  return out;
}

Eigen::MatrixX3d ElementControlPoints(const HighOrderTetMesh& mesh, const RowMatX3d& nodes, int e) {
  ARREG_CHECK_INPUT(nodes.rows() == mesh.num_nodes(), "", "nodes", "expected ", mesh.num_nodes(),
                    " rows, got ", nodes.rows());
  Eigen::MatrixX3d control(mesh.elements.cols(), 3);
  for (int a = 0; a < mesh.elements.cols(); ++a) control.row(a) = nodes.row(mesh.elements(e, a));
  return control;
}

Eigen::Vector3d BezierTetPoint(int degree, const Eigen::MatrixX3d& control,
                               const Eigen::Vector4d& L) {
  return control.transpose() * BernsteinValues(degree, L);
}

Eigen::Matrix3d BezierTetJacobian(int degree, const Eigen::MatrixX3d& control,
                                  const Eigen::Vector4d& L) {
  ARREG_CHECK_INPUT(degree >= 1 && degree <= kMaxDegree, "", "degree", "must be 1 .. ", kMaxDegree,
                    ", got ", degree);
  const BernsteinTable& table = TableOf(degree);
  const Eigen::VectorXd lower = BernsteinValues(degree - 1, L);
  // dx/dL_i = k sum_{alpha_i > 0} B^{k-1}_{alpha - e_i} P_alpha
  Eigen::Matrix<double, 3, 4> dx_dl = Eigen::Matrix<double, 3, 4>::Zero();
  for (size_t a = 0; a < table.indices.size(); ++a)
    for (int i = 0; i < 4; ++i)
      if (table.lowered[a][i] >= 0)
        dx_dl.col(i) += degree * lower[table.lowered[a][i]] * control.row(a).transpose();
  Eigen::Matrix3d j;
  for (int c = 0; c < 3; ++c) j.col(c) = dx_dl.col(c + 1) - dx_dl.col(0);
  return j;
}

JacobianBounds BezierTetJacobianBounds(int degree, const Eigen::MatrixX3d& control) {
  ARREG_CHECK_INPUT(degree >= 1 && degree <= 3, "", "degree", "must be 1, 2 or 3, got ", degree);
  const DeterminantBasis& basis = DeterminantBasisOf(degree);
  Eigen::VectorXd values(static_cast<int>(basis.points.size()));
  for (size_t a = 0; a < basis.points.size(); ++a)
    values[static_cast<int>(a)] = BezierTetJacobian(degree, control, basis.points[a]).determinant();
  JacobianBounds out;
  out.min_sampled = values.minCoeff();
  out.min_coefficient = (basis.inverse * values).minCoeff();
  return out;
}

RowMatX3d InterpolateMap(const HighOrderTetMesh& mesh, const RowMatX3d& nodes,
                         const std::function<Eigen::Vector3d(const Eigen::Vector3d&)>& f) {
  ARREG_CHECK_INPUT(mesh.degree >= 1 && mesh.degree <= 3, "", "degree", "must be 1, 2 or 3, got ",
                    mesh.degree);
  const std::vector<std::array<int, 4>> indices = BernsteinIndices(mesh.degree);
  const int n = static_cast<int>(indices.size());
  const Eigen::MatrixXd& inverse = InverseCollocation(mesh.degree);
  RowMatX3d out = nodes;
  Eigen::MatrixX3d values(n, 3);
  for (int e = 0; e < mesh.num_elements(); ++e) {
    const Eigen::MatrixX3d control = ElementControlPoints(mesh, nodes, e);
    for (int a = 0; a < n; ++a) {
      const Eigen::Vector4d L(indices[a][0], indices[a][1], indices[a][2], indices[a][3]);
      values.row(a) = f(BezierTetPoint(mesh.degree, control, L / mesh.degree)).transpose();
    }
    const Eigen::MatrixX3d coefficients = inverse * values;
    for (int a = 0; a < n; ++a) out.row(mesh.elements(e, a)) = coefficients.row(a);
  }
  return out;
}

void InverseMapOptions::Check() const {
  ARREG_CHECK_INPUT(relative_tolerance > 0 && relative_tolerance < 1e-3, "", "relative_tolerance",
                    "must lie in (0, 1e-3), got ", relative_tolerance);
  ARREG_CHECK_INPUT(max_iterations >= 1, "", "max_iterations", "must be >= 1, got ",
                    max_iterations);
  ARREG_CHECK_INPUT(inside_tolerance >= 0, "", "inside_tolerance", "must be >= 0, got ",
                    inside_tolerance);
  ARREG_CHECK_INPUT(max_extrapolation > 0, "", "max_extrapolation", "must be > 0, got ",
                    max_extrapolation);
}

InverseMapResult InvertBezierTet(int degree, const Eigen::MatrixX3d& control,
                                 const Eigen::Vector3d& p, const InverseMapOptions& options) {
  options.Check();
  const double tolerance = options.relative_tolerance * Diagonal(control);
  InverseMapResult out;
  Eigen::Vector4d L =
      BarycentricCoordinates(p, control.row(0), control.row(1), control.row(2), control.row(3));
  auto residual = [&](const Eigen::Vector4d& l) -> Eigen::Vector3d {
    return BezierTetPoint(degree, control, l) - p;
  };
  Eigen::Vector3d r = residual(L);
  double norm = r.norm();
  for (; out.iterations < options.max_iterations && norm > tolerance; ++out.iterations) {
    if (L.minCoeff() < -options.max_extrapolation) break;
    const Eigen::Matrix3d j = BezierTetJacobian(degree, control, L);
    const Eigen::FullPivLU<Eigen::Matrix3d> lu(j);
    if (!lu.isInvertible()) break;
    const Eigen::Vector3d dxi = -lu.solve(r);
    const Eigen::Vector4d dl(-dxi.sum(), dxi[0], dxi[1], dxi[2]);
    // Halve the step until the residual falls: far from the solution (a strongly
    // curved element, a start outside) the full Newton step can overshoot.
    double t = 1.0;
    bool reduced = false;
    for (int h = 0; h < 20 && !reduced; ++h, t *= 0.5) {
      const Eigen::Vector4d trial = L + t * dl;
      const Eigen::Vector3d trial_r = residual(trial);
      if (trial_r.norm() < norm) {
        L = trial;
        r = trial_r;
        norm = r.norm();
        reduced = true;
      }
    }
    if (!reduced) break;
  }
  out.barycentric = L;
  out.residual_mm = norm;
  out.converged = norm <= tolerance;
  out.inside = out.converged && L.minCoeff() >= -options.inside_tolerance;
  return out;
}

void HighOrderEmbeddingOptions::Check() const {
  inverse.Check();
  ARREG_CHECK_INPUT(max_outside >= 0 && max_outside <= inverse.max_extrapolation, "", "max_outside",
                    "must lie in [0, inverse.max_extrapolation], got ", max_outside);
}

HighOrderEmbedding HighOrderEmbedding::Embed(const HighOrderTetMesh& mesh, const RowMatX3d& nodes,
                                             const RowMatX3d& points,
                                             const HighOrderEmbeddingOptions& options) {
  options.Check();
  ARREG_CHECK_INPUT(nodes.rows() == mesh.num_nodes(), "", "nodes", "expected ", mesh.num_nodes(),
                    " rows, got ", nodes.rows());
  const int num_elements = mesh.num_elements();
  std::vector<Eigen::MatrixX3d> control(num_elements);
  std::vector<Eigen::Vector3d> low(num_elements), high(num_elements);
  for (int e = 0; e < num_elements; ++e) {
    control[e] = ElementControlPoints(mesh, nodes, e);
    low[e] = control[e].colwise().minCoeff();
    high[e] = control[e].colwise().maxCoeff();
    const double pad = options.max_outside * (high[e] - low[e]).norm();
    low[e].array() -= pad;
    high[e].array() += pad;
  }
  std::vector<int> elements(points.rows(), -1);
  std::vector<Eigen::Vector4d> barycentric(points.rows());
  int num_outside = 0;
  for (int i = 0; i < points.rows(); ++i) {
    const Eigen::Vector3d p = points.row(i);
    double best = -std::numeric_limits<double>::infinity();
    for (int e = 0; e < num_elements; ++e) {
      if ((p.array() < low[e].array()).any() || (p.array() > high[e].array()).any()) continue;
      const InverseMapResult r = InvertBezierTet(mesh.degree, control[e], p, options.inverse);
      if (!r.converged || r.barycentric.minCoeff() <= best) continue;
      best = r.barycentric.minCoeff();
      elements[i] = e;
      barycentric[i] = r.barycentric;
    }
    ARREG_CHECK_INPUT(
        elements[i] >= 0 && best >= -options.max_outside, "", "points", "point ", i, " at (", p.x(),
        ", ", p.y(), ", ", p.z(),
        ") lies outside every element by more than max_outside = ", options.max_outside);
    if (best < -options.inverse.inside_tolerance) ++num_outside;
  }
  HighOrderEmbedding out = FromCoordinates(mesh, std::move(elements), std::move(barycentric));
  out.num_outside_ = num_outside;
  return out;
}

HighOrderEmbedding HighOrderEmbedding::FromCoordinates(const HighOrderTetMesh& mesh,
                                                       std::vector<int> elements,
                                                       std::vector<Eigen::Vector4d> barycentric) {
  ARREG_CHECK_INPUT(elements.size() == barycentric.size(), "", "barycentric", "expected ",
                    elements.size(), " entries, got ", barycentric.size());
  HighOrderEmbedding out;
  out.count_ = static_cast<int>(mesh.elements.cols());
  out.nodes_.reserve(elements.size() * out.count_);
  out.weights_.reserve(elements.size() * out.count_);
  for (size_t i = 0; i < elements.size(); ++i) {
    ARREG_CHECK_INPUT(elements[i] >= 0 && elements[i] < mesh.num_elements(), "", "elements",
                      "point ", i, " has element ", elements[i], " out of range");
    const Eigen::VectorXd w = BernsteinValues(mesh.degree, barycentric[i]);
    for (int a = 0; a < out.count_; ++a) {
      out.nodes_.push_back(mesh.elements(elements[i], a));
      out.weights_.push_back(w[a]);
    }
  }
  out.elements_ = std::move(elements);
  out.barycentric_ = std::move(barycentric);
  return out;
}

RowMatX3d HighOrderEmbedding::Positions(const RowMatX3d& nodes) const {
  RowMatX3d out = RowMatX3d::Zero(size(), 3);
  for (int i = 0; i < size(); ++i)
    for (int a = 0; a < count_; ++a) {
      const size_t k = static_cast<size_t>(i) * count_ + a;
      out.row(i) += weights_[k] * nodes.row(nodes_[k]);
    }
  return out;
}

}  // namespace arreg::mechanics
