#include "mechanics/frame_shape_functions.h"

#include <Eigen/Dense>
#include <array>
#include <cmath>

#include "core/error.h"

namespace arreg::mechanics {

namespace {

using internal::Concat;

// Gauss-Legendre points and weights on [-1, 1].
void GaussLegendre(int n, std::vector<double>* points, std::vector<double>* weights) {
  if (n == 1) {
    *points = {0.0};
    *weights = {2.0};
  } else if (n == 2) {
    const double a = 1.0 / std::sqrt(3.0);
    *points = {-a, a};
    *weights = {1.0, 1.0};
  } else {
    const double a = std::sqrt(0.6);
    *points = {-a, 0.0, a};
    *weights = {5.0 / 9.0, 8.0 / 9.0, 5.0 / 9.0};
  }
}

// Reference-cube corner signs in the HexMesh corner order.
constexpr std::array<std::array<int, 3>, 8> kHexCorners = {{{-1, -1, -1},
                                                            {1, -1, -1},
                                                            {1, 1, -1},
                                                            {-1, 1, -1},
                                                            {-1, -1, 1},
                                                            {1, -1, 1},
                                                            {1, 1, 1},
                                                            {-1, 1, 1}}};

}  // namespace

HexMesh MakeBoxHexMesh(const Eigen::Vector3d& size_mm, const Eigen::Vector3i& cells) {
  for (int c = 0; c < 3; ++c) {
    if (!(size_mm[c] > 0) || !std::isfinite(size_mm[c]))
      throw Error("", "size_mm", "box size must be positive and finite");
    if (cells[c] < 1) throw Error("", "cells", "at least one cell per axis");
  }
  const int nx = cells.x() + 1, ny = cells.y() + 1, nz = cells.z() + 1;
  HexMesh mesh;
  mesh.vertices.resize(nx * ny * nz, 3);
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i)
        mesh.vertices.row(i + nx * (j + ny * k)) << i * size_mm.x() / cells.x(),
            j * size_mm.y() / cells.y(), k * size_mm.z() / cells.z();
  mesh.hexahedra.resize(cells.prod(), 8);
  int h = 0;
  for (int k = 0; k < cells.z(); ++k)
    for (int j = 0; j < cells.y(); ++j)
      for (int i = 0; i < cells.x(); ++i, ++h)
        for (int c = 0; c < 8; ++c) {
          const int di = kHexCorners[c][0] > 0, dj = kHexCorners[c][1] > 0,
                    dk = kHexCorners[c][2] > 0;
          mesh.hexahedra(h, c) = (i + di) + nx * ((j + dj) + ny * (k + dk));
        }
  return mesh;
}

FrameSampling SampleTetMesh(const TetMesh& mesh, int points_per_tet) {
  if (points_per_tet != 1 && points_per_tet != 4)
    throw Error("", "points_per_tet", "1 or 4 samples per tetrahedron");
  // Barycentric coordinates of the sample points.
  std::vector<Eigen::Vector4d> bary;
  if (points_per_tet == 1) {
    bary.push_back(Eigen::Vector4d::Constant(0.25));
  } else {
    const double a = 0.5854101966249685, b = 0.1381966011250105;
    for (int k = 0; k < 4; ++k) {
      Eigen::Vector4d l = Eigen::Vector4d::Constant(b);
      l[k] = a;
      bary.push_back(l);
    }
  }
  FrameSampling out;
  out.frame_positions = mesh.vertices;
  out.samples.reserve(static_cast<size_t>(mesh.num_tetrahedra()) * points_per_tet);
  for (int t = 0; t < mesh.num_tetrahedra(); ++t) {
    Eigen::Matrix3d edges;
    std::array<Eigen::Vector3d, 4> x;
    for (int k = 0; k < 4; ++k) x[k] = mesh.vertices.row(mesh.tetrahedra(t, k)).transpose();
    for (int k = 0; k < 3; ++k) edges.col(k) = x[k + 1] - x[0];
    const double volume = edges.determinant() / 6.0;
    if (!(volume > 0))
      throw Error("", Concat("tetrahedron ", t), "degenerate or inverted (volume <= 0)");
    // Rows of edges^-1 are the gradients of the barycentric coordinates 1..3.
    const Eigen::Matrix3d inverse = edges.inverse();
    std::array<Eigen::Vector3d, 4> gradient;
    for (int k = 0; k < 3; ++k) gradient[k + 1] = inverse.row(k).transpose();
    gradient[0] = -(gradient[1] + gradient[2] + gradient[3]);
    for (const Eigen::Vector4d& l : bary) {
      FrameSample s;
      s.volume_mm3 = volume / points_per_tet;
      for (int k = 0; k < 4; ++k) {
        s.rest_position += l[k] * x[k];
        s.frames.push_back(mesh.tetrahedra(t, k));
        s.weights.push_back(l[k]);
        s.weight_gradients.push_back(gradient[k]);
      }
      out.samples.push_back(std::move(s));
    }
  }
  return out;
}

FrameSampling SampleHexMesh(const HexMesh& mesh, int gauss_per_axis) {
  if (gauss_per_axis < 1 || gauss_per_axis > 3)
    throw Error("", "gauss_per_axis", "1 to 3 Gauss points per axis");
  if (mesh.hexahedra.cols() != 8 && mesh.hexahedra.rows() > 0)
    throw Error("", "hexahedra", "8 vertex indices per hexahedron");
  std::vector<double> points, gauss_weights;
  GaussLegendre(gauss_per_axis, &points, &gauss_weights);
  FrameSampling out;
  out.frame_positions = mesh.vertices;
  for (int h = 0; h < mesh.hexahedra.rows(); ++h) {
    Eigen::Matrix<double, 8, 3> corners;
    for (int c = 0; c < 8; ++c) corners.row(c) = mesh.vertices.row(mesh.hexahedra(h, c));
    for (int a = 0; a < gauss_per_axis; ++a)
      for (int b = 0; b < gauss_per_axis; ++b)
        for (int c = 0; c < gauss_per_axis; ++c) {
          const Eigen::Vector3d xi(points[a], points[b], points[c]);
          Eigen::Matrix<double, 8, 1> n;
          Eigen::Matrix<double, 8, 3> dn_dxi;
          for (int k = 0; k < 8; ++k) {
            Eigen::Vector3d f;
            for (int d = 0; d < 3; ++d) f[d] = 0.5 * (1 + kHexCorners[k][d] * xi[d]);
            n[k] = f[0] * f[1] * f[2];
            for (int d = 0; d < 3; ++d)
              dn_dxi(k, d) = 0.5 * kHexCorners[k][d] * f[(d + 1) % 3] * f[(d + 2) % 3];
          }
          // jacobian(r, d) = dX_r / dxi_d.
          const Eigen::Matrix3d jacobian = corners.transpose() * dn_dxi;
          const double det = jacobian.determinant();
          if (!(det > 0)) throw Error("", Concat("hexahedron ", h), "det J <= 0 at a Gauss point");
          const Eigen::Matrix<double, 8, 3> dn_dx = dn_dxi * jacobian.inverse();
          FrameSample s;
          s.rest_position = corners.transpose() * n;
          s.volume_mm3 = det * gauss_weights[a] * gauss_weights[b] * gauss_weights[c];
          for (int k = 0; k < 8; ++k) {
            s.frames.push_back(mesh.hexahedra(h, k));
            s.weights.push_back(n[k]);
            s.weight_gradients.push_back(dn_dx.row(k).transpose());
          }
          out.samples.push_back(std::move(s));
        }
  }
  return out;
}

void MlsOptions::Check() const {
  if (!(support_radius_mm > 0) || !std::isfinite(support_radius_mm))
    throw Error("", "support_radius_mm", "MLS support radius must be positive and finite");
  if (!(min_reciprocal_condition > 0) || !(min_reciprocal_condition < 1))
    throw Error("", "min_reciprocal_condition", "must lie in (0, 1)");
  if (basis_order != 0 && basis_order != 1)
    throw Error("", "basis_order", "0 (Shepard) or 1 (linear basis)");
}

void EvaluateMls(const RowMatX3d& frame_positions, const Eigen::Vector3d& point,
                 const MlsOptions& options, FrameSample* sample) {
  options.Check();
  using Vector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, 4, 1>;
  using Matrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, 4, 4>;
  const double h = options.support_radius_mm;
  const int m = options.basis_order == 1 ? 4 : 1;
  // Basis p(y) = [1, (y - point) / h]: centred and scaled so that the moment
  // matrix is well conditioned; MLS weights do not depend on this affine choice.
  struct Near {
    int frame;
    Vector p;
    double phi;
    Eigen::Vector3d grad_phi;
  };
  std::vector<Near> near;
  Matrix moment = Matrix::Zero(m, m);
  for (int i = 0; i < frame_positions.rows(); ++i) {
    const Eigen::Vector3d d = point - frame_positions.row(i).transpose();
    const double q = d.norm() / h;
    if (q >= 1) continue;
    Near n;
    n.frame = i;
    n.p.resize(m);
    n.p[0] = 1;
    if (m == 4) n.p.tail<3>() = -d / h;
    n.phi = std::pow(1 - q, 4) * (4 * q + 1);
    // d phi / d point = -20 (1 - q)^3 (point - x_i) / h^2 (smooth at q = 0).
    n.grad_phi = -20 * std::pow(1 - q, 3) * d / (h * h);
    moment += n.phi * n.p * n.p.transpose();
    near.push_back(n);
  }
  if (static_cast<int>(near.size()) < m)
    throw Error("", "support_radius_mm",
                Concat("fewer than ", m, " frames within ", h, " mm of a sample at (",
                       point.transpose(), ")"));
  const Eigen::JacobiSVD<Matrix> svd(moment);
  const Vector sv = svd.singularValues();
  if (!(sv[m - 1] > options.min_reciprocal_condition * sv[0]))
    throw Error("", "support_radius_mm",
                Concat("frames near the sample at (", point.transpose(),
                       ") are nearly coplanar (MLS moment matrix singular)"));
  const Eigen::LDLT<Matrix> ldlt(moment);
  // w_i = phi_i a^T p_i with a = A^-1 p(point), p(point) = e0, and
  // d w_i = phi_i (A^-1 dp - A^-1 dA a)^T p_i + d phi_i a^T p_i.
  const Vector a = ldlt.solve(Vector::Unit(m, 0));
  std::array<Vector, 3> b_minus_c;
  for (int d = 0; d < 3; ++d) {
    Matrix dmoment = Matrix::Zero(m, m);
    for (const Near& n : near) dmoment += n.grad_phi[d] * n.p * n.p.transpose();
    // d p(point) / d point_d = e_{d+1} / h (the basis centre is held fixed).
    Vector dp = Vector::Zero(m);
    if (m == 4) dp[d + 1] = 1 / h;
    b_minus_c[d] = ldlt.solve(dp) - ldlt.solve(dmoment * a);
  }
  sample->frames.clear();
  sample->weights.clear();
  sample->weight_gradients.clear();
  for (const Near& n : near) {
    const double ap = a.dot(n.p);
    Eigen::Vector3d gradient;
    for (int d = 0; d < 3; ++d) gradient[d] = n.phi * b_minus_c[d].dot(n.p) + n.grad_phi[d] * ap;
    sample->frames.push_back(n.frame);
    sample->weights.push_back(n.phi * ap);
    sample->weight_gradients.push_back(gradient);
  }
}

FrameSampling SampleMls(const RowMatX3d& frame_positions, const RowMatX3d& sample_positions,
                        const Eigen::VectorXd& sample_volumes_mm3, const MlsOptions& options) {
  options.Check();
  if (sample_volumes_mm3.size() != sample_positions.rows())
    throw Error("", "sample_volumes_mm3", "one volume per sample position");
  FrameSampling out;
  out.frame_positions = frame_positions;
  out.samples.resize(sample_positions.rows());
  for (int s = 0; s < sample_positions.rows(); ++s) {
    if (!(sample_volumes_mm3[s] > 0))
      throw Error("", Concat("sample_volumes_mm3[", s, "]"), "volume must be positive");
    FrameSample& sample = out.samples[s];
    sample.rest_position = sample_positions.row(s).transpose();
    sample.volume_mm3 = sample_volumes_mm3[s];
    EvaluateMls(frame_positions, sample.rest_position, options, &sample);
  }
  return out;
}

void BoxCellCentres(const Eigen::Vector3d& size_mm, const Eigen::Vector3i& n, RowMatX3d* positions,
                    Eigen::VectorXd* volumes_mm3) {
  const HexMesh grid = MakeBoxHexMesh(size_mm, n);  // validates the arguments
  const Eigen::Vector3d cell = size_mm.cwiseQuotient(n.cast<double>());
  positions->resize(n.prod(), 3);
  *volumes_mm3 = Eigen::VectorXd::Constant(n.prod(), cell.prod());
  for (int h = 0; h < grid.hexahedra.rows(); ++h)
    positions->row(h) = grid.vertices.row(grid.hexahedra(h, 0)) + 0.5 * cell.transpose();
}

}  // namespace arreg::mechanics
