#include "mechanics/bezier_shell.h"

#include <Eigen/Dense>
#include <array>
#include <cmath>

#include "core/error.h"
#include "mechanics/so3.h"

namespace arreg::mechanics {

using Vector12d = Eigen::Matrix<double, 12, 1>;
using Matrix18d = Eigen::Matrix<double, 18, 18>;
using Vector18d = Eigen::Matrix<double, 18, 1>;

void ShellMaterial::Check() const {
  if (!(youngs_modulus_kpa > 0) || !std::isfinite(youngs_modulus_kpa))
    throw Error("", "ShellMaterial.youngs_modulus_kpa", "must be a positive number");
  if (!(poisson_ratio >= 0 && poisson_ratio < 0.5))
    throw Error("", "ShellMaterial.poisson_ratio", "must lie in [0, 0.5)");
  if (!(thickness_mm > 0) || !std::isfinite(thickness_mm))
    throw Error("", "ShellMaterial.thickness_mm", "must be a positive number");
  if (!(density_kg_per_mm3 >= 0) || !std::isfinite(density_kg_per_mm3))
    throw Error("", "ShellMaterial.density_kg_per_mm3", "must be a non-negative number");
}

void BezierShellOptions::Check() const {
  material.Check();
  if (polar_max_iterations < 1)
    throw Error("", "BezierShellOptions.polar_max_iterations", "must be at least 1");
  if (!(polar_tolerance_rad > 0))
    throw Error("", "BezierShellOptions.polar_tolerance_rad", "must be positive");
}

namespace {

// Edge control points p4..p9 (indices 3..8): the corner they are attached to
// and the other corner of their edge (seed fig. 3, eq. 36-37).
constexpr int kEdgeOwner[6] = {0, 0, 1, 1, 2, 2};
constexpr int kEdgeOther[6] = {1, 2, 2, 0, 0, 1};

// Bernstein monomials c * xi1^i xi2^j xi3^k of p1..p10 (seed eq. 5).
constexpr int kMonomial[10][4] = {{1, 3, 0, 0}, {1, 0, 3, 0}, {1, 0, 0, 3}, {3, 2, 1, 0},
                                  {3, 2, 0, 1}, {3, 0, 2, 1}, {3, 1, 2, 0}, {3, 1, 0, 2},
                                  {3, 0, 1, 2}, {6, 1, 1, 1}};

// d^(da+db+dc) / d xi1^da d xi2^db d xi3^dc of c xi1^i xi2^j xi3^k, the three
// barycentric coordinates taken as independent.
double MonomialDerivative(const int* m, const double b[3], int da, int db, int dc) {
  const int d[3] = {da, db, dc};
  double v = m[0];
  for (int a = 0; a < 3; ++a) {
    const int p = m[a + 1];
    if (d[a] > p) return 0.0;
    for (int q = 0; q < d[a]; ++q) v *= p - q;
    for (int q = 0; q < p - d[a]; ++q) v *= b[a];
  }
  return v;
}

// Basis values and derivatives with respect to (xi1, xi2), xi3 = 1 - xi1 - xi2.
struct Basis {
  Eigen::Matrix<double, 10, 1> n, d1, d2, d11, d22, d12;
};

Basis EvaluateBasis(double xi1, double xi2) {
  const double b[3] = {xi1, xi2, 1.0 - xi1 - xi2};
  Basis r;
  for (int k = 0; k < 10; ++k) {
    const int* m = kMonomial[k];
    auto d = [&](int da, int db, int dc) { return MonomialDerivative(m, b, da, db, dc); };
    r.n(k) = d(0, 0, 0);
    r.d1(k) = d(1, 0, 0) - d(0, 0, 1);
    r.d2(k) = d(0, 1, 0) - d(0, 0, 1);
    r.d11(k) = d(2, 0, 0) - 2 * d(1, 0, 1) + d(0, 0, 2);
    r.d22(k) = d(0, 2, 0) - 2 * d(0, 1, 1) + d(0, 0, 2);
    r.d12(k) = d(1, 1, 0) - d(1, 0, 1) - d(0, 1, 1) + d(0, 0, 2);
  }
  return r;
}

// 6-point Gauss rule on the reference triangle (degree 4; weights sum to 1,
// times the reference area 1/2).
struct GaussPoint {
  double xi1, xi2, weight;
};
const std::array<GaussPoint, 6>& GaussPoints() {
  static const std::array<GaussPoint, 6> points = [] {
    const double a = 0.445948490915965, wa = 0.223381589678011;
    const double b = 0.091576213509771, wb = 0.109951743655322;
    return std::array<GaussPoint, 6>{{{a, a, wa},
                                      {1 - 2 * a, a, wa},
                                      {a, 1 - 2 * a, wa},
                                      {b, b, wb},
                                      {1 - 2 * b, b, wb},
                                      {b, 1 - 2 * b, wb}}};
  }();
  return points;
}

// Element state at the current configuration.
struct Kinematics {
  Eigen::Vector3d a, b;           // x2 - x1, x3 - x1
  Eigen::Matrix<double, 3, 2> A;  // rest-local (2D) -> current (3D)
  Eigen::Matrix3d frame;          // R_e
  Eigen::Matrix2d S;              // stretch R_e^T A (symmetric)
  Eigen::Matrix3d q[3];           // corner rotations relative to the frame
  Eigen::Vector3d psi[3];         // Log(q)
  Vector12d xi;
};

bool ComputeKinematics(const BezierShell::Element& el, const BezierShellOptions& options,
                       const GeneralisedState& state, Kinematics* k) {
  const Eigen::Vector3d x0 = state.position(el.nodes[0]);
  k->a = state.position(el.nodes[1]) - x0;
  k->b = state.position(el.nodes[2]) - x0;
  const Eigen::Vector3d cross = k->a.cross(k->b);
  if (!(cross.norm() > 1e-14 * k->a.norm() * k->b.norm())) return false;
  for (int c = 0; c < 2; ++c)
    k->A.col(c) = k->a * el.rest_edges_inverse(0, c) + k->b * el.rest_edges_inverse(1, c);
  // Preliminary frame along the first edge (seed section 3.4, e2 = e3 x e1),
  // then the 2D polar correction (seed eq. 31) until it no longer turns.
  const Eigen::Vector3d n = cross.normalized();
  Eigen::Vector3d u1 = k->a.normalized();
  Eigen::Vector3d u2 = n.cross(u1);
  for (int it = 0; it < options.polar_max_iterations; ++it) {
    Eigen::Matrix2d f;
    f << u1.dot(k->A.col(0)), u1.dot(k->A.col(1)), u2.dot(k->A.col(0)), u2.dot(k->A.col(1));
    // R proportional to F + sgn(det F) [[F22, -F21], [-F12, F11]]; det F > 0
    // because the frame's normal follows the triangle's orientation.
    const double c = f(0, 0) + f(1, 1), s = f(1, 0) - f(0, 1);
    const double r = std::hypot(c, s);
    const double cn = c / r, sn = s / r;  // normalised columns; c > 0, so |angle| ~ |sn|
    const Eigen::Vector3d v1 = cn * u1 + sn * u2;
    u2 = -sn * u1 + cn * u2;
    u1 = v1;
    if (std::abs(sn) < options.polar_tolerance_rad) break;
  }
  k->frame.col(0) = u1;
  k->frame.col(1) = u2;
  k->frame.col(2) = n;
  Eigen::Matrix2d f;
  f << u1.dot(k->A.col(0)), u1.dot(k->A.col(1)), u2.dot(k->A.col(0)), u2.dot(k->A.col(1));
  k->S = 0.5 * (f + f.transpose());
  k->xi(0) = k->S(0, 0) - 1.0;
  k->xi(1) = k->S(1, 1) - 1.0;
  k->xi(2) = k->S(0, 1);
  for (int i = 0; i < 3; ++i) {
    k->q[i] = k->frame.transpose() * state.rotation(el.nodes[i]) * el.corner_link[i];
    k->psi[i] = LogSO3(k->q[i]);
    k->xi.segment<3>(3 + 3 * i) = k->psi[i];
  }
  return true;
}

// First derivatives of the stretch and of the frame with respect to the corner
// positions: d(S11, S22, S12) = M dx and the frame's spatial angular increment
// omega = W dx (dx = (dx1, dx2, dx3), 9 entries).
void FrameDerivatives(const BezierShell::Element& el, const Kinematics& k,
                      Eigen::Matrix<double, 3, 9>* m, Eigen::Matrix<double, 3, 9>* w) {
  // dA_c = sum_i beta(i, c) dx_i.
  Eigen::Matrix<double, 3, 2> beta;
  for (int c = 0; c < 2; ++c) {
    beta(1, c) = el.rest_edges_inverse(0, c);
    beta(2, c) = el.rest_edges_inverse(1, c);
    beta(0, c) = -beta(1, c) - beta(2, c);
  }
  // S dS + dS S = dA^T A + A^T dA (from S^2 = A^T A), unknowns (dS11, dS22, dS12).
  const Eigen::Matrix2d& s = k.S;
  Eigen::Matrix3d sylvester;
  sylvester << 2 * s(0, 0), 0, 2 * s(0, 1), 0, 2 * s(1, 1), 2 * s(0, 1), s(0, 1), s(0, 1),
      s(0, 0) + s(1, 1);
  const Eigen::Matrix3d inv = sylvester.inverse();
  Eigen::Matrix<double, 3, 9> dc;
  for (Eigen::Index i = 0; i < 3; ++i) {
    dc.block<1, 3>(0, 3 * i) = 2 * beta(i, 0) * k.A.col(0).transpose();
    dc.block<1, 3>(1, 3 * i) = 2 * beta(i, 1) * k.A.col(1).transpose();
    dc.block<1, 3>(2, 3 * i) = (beta(i, 0) * k.A.col(1) + beta(i, 1) * k.A.col(0)).transpose();
  }
  *m = inv * dc;
  // Tilt: omega_t = n x dn with dn the change of the unit normal of a x b;
  // spin about n keeps R_e^T A symmetric: omega_n = (u2.dA1 - u1.dA2) / tr S.
  const Eigen::Vector3d u1 = k.frame.col(0), u2 = k.frame.col(1), n = k.frame.col(2);
  const double len = k.a.cross(k.b).norm();
  const Eigen::Matrix3d sn = Skew(n) / len;
  const Eigen::Matrix3d ta = sn * Skew(k.a), tb = sn * Skew(k.b);
  w->block<3, 3>(0, 0) = tb - ta;
  w->block<3, 3>(0, 3) = -tb;
  w->block<3, 3>(0, 6) = ta;
  const double tr = s(0, 0) + s(1, 1);
  for (Eigen::Index i = 0; i < 3; ++i)
    w->block<3, 3>(0, 3 * i) += n * ((beta(i, 0) * u2 - beta(i, 1) * u1).transpose() / tr);
}

// B = d xi / d(x1, phi1, x2, phi2, x3, phi3) (12 x 18).
Eigen::Matrix<double, 12, 18> XiJacobian(const BezierShell::Element& el, const Kinematics& k) {
  Eigen::Matrix<double, 3, 9> m, w;
  FrameDerivatives(el, k, &m, &w);
  Eigen::Matrix<double, 12, 18> b = Eigen::Matrix<double, 12, 18>::Zero();
  for (Eigen::Index i = 0; i < 3; ++i) b.block<3, 3>(0, 6 * i) = m.block<3, 3>(0, 3 * i);
  for (Eigen::Index c = 0; c < 3; ++c) {
    // Exp(d) Q = Exp(Log Q + J_l^-1(Log Q) d): d = R_e^T (dphi_c - omega).
    const Eigen::Matrix3d p = LeftJacobianInverseSO3(k.psi[c]) * k.frame.transpose();
    b.block<3, 3>(3 + 3 * c, 6 * c + 3) = p;
    for (Eigen::Index i = 0; i < 3; ++i)
      b.block<3, 3>(3 + 3 * c, 6 * i) -= p * w.block<3, 3>(0, 3 * i);
  }
  return b;
}

// ---- Second-order forward differentiation (exact Hessian) -------------------

// A value with its gradient and Hessian with respect to the 18 element DOFs.
struct Jet2 {
  Jet2() = default;
  explicit Jet2(double value) : v(value) {}
  double v = 0;
  Vector18d g = Vector18d::Zero();
  Matrix18d h = Matrix18d::Zero();
};
Jet2 operator+(const Jet2& a, const Jet2& b) {
  Jet2 r;
  r.v = a.v + b.v;
  r.g = a.g + b.g;
  r.h = a.h + b.h;
  return r;
}
Jet2 operator-(const Jet2& a, const Jet2& b) {
  Jet2 r;
  r.v = a.v - b.v;
  r.g = a.g - b.g;
  r.h = a.h - b.h;
  return r;
}
Jet2 operator*(double s, const Jet2& a) {
  Jet2 r;
  r.v = s * a.v;
  r.g = s * a.g;
  r.h = s * a.h;
  return r;
}
Jet2 operator*(const Jet2& a, const Jet2& b) {
  Jet2 r;
  r.v = a.v * b.v;
  r.g = a.v * b.g + b.v * a.g;
  r.h = a.v * b.h + b.v * a.h + a.g * b.g.transpose() + b.g * a.g.transpose();
  return r;
}
// f(a) from f(a.v), f'(a.v), f''(a.v).
Jet2 Chain(const Jet2& a, double f, double f1, double f2) {
  Jet2 r;
  r.v = f;
  r.g = f1 * a.g;
  r.h = f1 * a.h + f2 * a.g * a.g.transpose();
  return r;
}
Jet2 sqrt(const Jet2& a) {
  const double s = std::sqrt(a.v);
  return Chain(a, s, 0.5 / s, -0.25 / (a.v * s));
}
Jet2 Inverse(const Jet2& a) {
  return Chain(a, 1.0 / a.v, -1.0 / (a.v * a.v), 2.0 / (a.v * a.v * a.v));
}

// h(u) = atan(sqrt(u)) / sqrt(u) and its first two derivatives (series near 0).
std::array<double, 3> AtanRatioDerivatives(double u) {
  if (u < 1e-3) {
    const double h =
        1 - u / 3 + u * u / 5 - u * u * u / 7 + u * u * u * u / 9 - u * u * u * u * u / 11;
    const double h1 = -1.0 / 3 + 2 * u / 5 - 3 * u * u / 7 + 4 * u * u * u / 9 -
                      5 * u * u * u * u / 11 + 6 * u * u * u * u * u / 13;
    const double h2 = 2.0 / 5 - 6 * u / 7 + 12 * u * u / 9 - 20 * u * u * u / 11 +
                      30 * u * u * u * u / 13 - 42 * u * u * u * u * u / 15;
    return {h, h1, h2};
  }
  const double r = std::sqrt(u);
  const double h = std::atan(r) / r;
  const double h1 = (1.0 / (1.0 + u) - h) / (2.0 * u);
  const double h2 = (-1.0 / ((1.0 + u) * (1.0 + u)) - 3.0 * h1) / (2.0 * u);
  return {h, h1, h2};
}
Jet2 AtanRatio(const Jet2& u) {
  const auto d = AtanRatioDerivatives(u.v);
  return Chain(u, d[0], d[1], d[2]);
}

// xi as a function of the 18 DOF increments dq around the stored state, the
// frame in closed form (the converged polar rotation): S = sqrt(A^T A),
// U = A S^-1. Rotations use Exp(phi) to second order, exact for derivatives
// up to the second at phi = 0.
template <typename T>
std::array<T, 12> XiOfIncrement(const BezierShell::Element& el, const GeneralisedState& state,
                                const std::array<T, 18>& dq) {
  using std::sqrt;
  using V3 = std::array<T, 3>;
  V3 x[3];
  std::array<std::array<T, 3>, 3> rot[3];
  for (int i = 0; i < 3; ++i) {
    const Eigen::Vector3d p = state.position(el.nodes[i]);
    for (int r = 0; r < 3; ++r) x[i][r] = T(p(r)) + dq[6 * i + r];
    const T* f = &dq[6 * i + 3];
    // M = I + [f] + 1/2 [f]^2; rotation = M R_i.
    T sk[3][3] = {{T(0.0), T(0.0) - f[2], f[1]},
                  {f[2], T(0.0), T(0.0) - f[0]},
                  {T(0.0) - f[1], f[0], T(0.0)}};
    T mm[3][3];
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) {
        T acc = sk[r][c];
        for (int l = 0; l < 3; ++l) acc = acc + 0.5 * (sk[r][l] * sk[l][c]);
        mm[r][c] = r == c ? acc + T(1.0) : acc;
      }
    const Eigen::Matrix3d& ri = state.rotation(el.nodes[i]);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) {
        T acc = T(0.0);
        for (int l = 0; l < 3; ++l) acc = acc + ri(l, c) * mm[r][l];
        rot[i][r][c] = acc;
      }
  }
  V3 a, b;
  for (int r = 0; r < 3; ++r) {
    a[r] = x[1][r] - x[0][r];
    b[r] = x[2][r] - x[0][r];
  }
  V3 acol[2];
  for (int c = 0; c < 2; ++c)
    for (int r = 0; r < 3; ++r)
      acol[c][r] = el.rest_edges_inverse(0, c) * a[r] + el.rest_edges_inverse(1, c) * b[r];
  auto dot = [](const V3& p, const V3& q) { return p[0] * q[0] + p[1] * q[1] + p[2] * q[2]; };
  const T c00 = dot(acol[0], acol[0]), c11 = dot(acol[1], acol[1]), c01 = dot(acol[0], acol[1]);
  const T sdet = sqrt(c00 * c11 - c01 * c01);
  const T t = sqrt(c00 + c11 + 2.0 * sdet);
  const T it = Inverse(t);
  const T s00 = (c00 + sdet) * it, s11 = (c11 + sdet) * it, s01 = c01 * it;
  const T idet = Inverse(s00 * s11 - s01 * s01);
  // U = A S^-1, S^-1 = [[s11, -s01], [-s01, s00]] / det.
  V3 u[3];
  for (int r = 0; r < 3; ++r) {
    u[0][r] = (acol[0][r] * s11 - acol[1][r] * s01) * idet;
    u[1][r] = (acol[1][r] * s00 - acol[0][r] * s01) * idet;
  }
  u[2] = {u[0][1] * u[1][2] - u[0][2] * u[1][1], u[0][2] * u[1][0] - u[0][0] * u[1][2],
          u[0][0] * u[1][1] - u[0][1] * u[1][0]};
  std::array<T, 12> xi;
  xi[0] = s00 - T(1.0);
  xi[1] = s11 - T(1.0);
  xi[2] = s01;
  for (int i = 0; i < 3; ++i) {
    // Q = R_e^T rot C: Q(r, c) = sum_l u[r][l] (rot C)(l, c).
    T rc[3][3];
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) {
        T acc = T(0.0);
        for (int l = 0; l < 3; ++l) acc = acc + el.corner_link[i](l, c) * rot[i][r][l];
        rc[r][c] = acc;
      }
    T q[3][3];
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c)
        q[r][c] = u[r][0] * rc[0][c] + u[r][1] * rc[1][c] + u[r][2] * rc[2][c];
    // Log via the unit quaternion (w, v): psi = 2 atan(|v| / w) v / |v|.
    const T w = 0.5 * sqrt(T(1.0) + q[0][0] + q[1][1] + q[2][2]);
    const T i4w = Inverse(4.0 * w);
    const V3 v = {(q[2][1] - q[1][2]) * i4w, (q[0][2] - q[2][0]) * i4w, (q[1][0] - q[0][1]) * i4w};
    const T iw = Inverse(w);
    const T ratio = 2.0 * (AtanRatio(dot(v, v) * iw * iw) * iw);
    for (int r = 0; r < 3; ++r) xi[3 + 3 * i + r] = ratio * v[r];
  }
  return xi;
}

double ExactEnergyDerivatives(const BezierShell::Element& el, const GeneralisedState& state,
                              Vector18d* gradient, Matrix18d* hessian) {
  std::array<Jet2, 18> dq;
  for (int k = 0; k < 18; ++k) dq[k].g(k) = 1.0;
  const std::array<Jet2, 12> xi = XiOfIncrement(el, state, dq);
  Jet2 e;
  for (int a = 0; a < 12; ++a) {
    Jet2 kx;
    for (int b = 0; b < 12; ++b) kx = kx + el.k(a, b) * xi[b];
    e = e + 0.5 * (xi[a] * kx);
  }
  if (gradient) *gradient = e.g;
  if (hessian) *hessian = 0.5 * (e.h + e.h.transpose());
  return e.v;
}

}  // namespace

Eigen::Matrix<double, 10, 1> BezierTriangleWeights(double xi1, double xi2) {
  // The monomials of kMonomial directly (called per feature spring and fine point at every
  // state; EvaluateBasis also forms five derivatives).
  const double a = xi1, b = xi2, c = 1.0 - xi1 - xi2;
  Eigen::Matrix<double, 10, 1> n;
  n << a * a * a, b * b * b, c * c * c, 3 * a * a * b, 3 * a * a * c, 3 * b * b * c, 3 * a * b * b,
      3 * a * c * c, 3 * b * c * c, 6 * a * b * c;
  return n;
}

std::vector<Eigen::Matrix3d> ShellVertexRotations(const RowMatX3d& positions,
                                                  const std::vector<Eigen::Vector3i>& triangles) {
  const int nv = static_cast<int>(positions.rows());
  std::vector<Eigen::Vector3d> normal(nv, Eigen::Vector3d::Zero());
  std::vector<Eigen::Vector3d> edge(nv, Eigen::Vector3d::Zero());
  for (size_t t = 0; t < triangles.size(); ++t) {
    const Eigen::Vector3i& tri = triangles[t];
    for (int c = 0; c < 3; ++c)
      if (tri[c] < 0 || tri[c] >= nv)
        throw Error("", "shell triangle " + std::to_string(t),
                    "vertex index " + std::to_string(tri[c]) + " out of range");
    const Eigen::Vector3d p0 = positions.row(tri[0]), p1 = positions.row(tri[1]),
                          p2 = positions.row(tri[2]);
    const Eigen::Vector3d area_normal = 0.5 * (p1 - p0).cross(p2 - p0);
    for (int c = 0; c < 3; ++c) {
      normal[tri[c]] += area_normal;
      if (edge[tri[c]].isZero())
        edge[tri[c]] = Eigen::Vector3d(positions.row(tri[(c + 1) % 3])) -
                       Eigen::Vector3d(positions.row(tri[c]));
    }
  }
  std::vector<Eigen::Matrix3d> rotations(nv, Eigen::Matrix3d::Identity());
  for (int v = 0; v < nv; ++v) {
    if (normal[v].isZero()) continue;  // not on the shell: identity
    const Eigen::Vector3d z = normal[v].normalized();
    Eigen::Vector3d x = edge[v] - edge[v].dot(z) * z;
    if (!(x.norm() > 1e-12 * edge[v].norm()))
      throw Error("", "shell vertex " + std::to_string(v), "no edge off the normal direction");
    x.normalize();
    rotations[v].col(0) = x;
    rotations[v].col(1) = z.cross(x);
    rotations[v].col(2) = z;
  }
  return rotations;
}

BezierShell::BezierShell(const GeneralisedState& state,
                         const std::vector<Eigen::Vector3i>& triangles,
                         const BezierShellOptions& options)
    : options_(options) {
  options_.Check();
  ReplaceElements(state, triangles, {});
}

void BezierShell::ReplaceElements(const GeneralisedState& state,
                                  const std::vector<Eigen::Vector3i>& triangles,
                                  const std::vector<char>& reuse) {
  const ShellMaterial& mat = options_.material;
  Eigen::Matrix3d d;
  d << 1, mat.poisson_ratio, 0, mat.poisson_ratio, 1, 0, 0, 0, 0.5 * (1 - mat.poisson_ratio);
  d *= mat.youngs_modulus_kpa / (1 - mat.poisson_ratio * mat.poisson_ratio);
  const double t = mat.thickness_mm;
  std::vector<Element> built;
  built.reserve(triangles.size());
  for (size_t e = 0; e < triangles.size(); ++e) {
    const std::string where = "shell triangle " + std::to_string(e);
    Element el;
    if (e < reuse.size() && reuse[e] && e < elements_.size()) {
      // Rest data depend only on the corners' rest positions and rotations.
      el = elements_[e];
      for (int i = 0; i < 3; ++i) {
        const int a = el.nodes[i], b = triangles[e][i];
        if (b < 0 || b >= state.num_nodes() || !state.is_frame(b) ||
            state.rest_positions().row(a) != state.rest_positions().row(b) ||
            state.rest_rotation(a) != state.rest_rotation(b))
          throw Error("", where, "reused with corners of other rest positions or rotations");
      }
      el.nodes = triangles[e];
      built.push_back(el);
      continue;
    }
    el.nodes = triangles[e];
    Eigen::Vector3d x[3], m[3];
    for (int i = 0; i < 3; ++i) {
      const int node = el.nodes[i];
      if (node < 0 || node >= state.num_nodes() || !state.is_frame(node))
        throw Error("", where, "node " + std::to_string(node) + " is not a frame node");
      x[i] = state.rest_positions().row(node).transpose();
      m[i] = state.rest_rotation(node).col(2);
    }
    const Eigen::Vector3d cross = (x[1] - x[0]).cross(x[2] - x[0]);
    if (!(cross.norm() > 1e-12 * (x[1] - x[0]).squaredNorm()))
      throw Error("", where, "degenerate (zero area)");
    const Eigen::Vector3d n = cross.normalized();
    for (int i = 0; i < 3; ++i)
      if (!(m[i].dot(n) > 0.1))
        throw Error("", where,
                    "the rest normal (z axis) of node " + std::to_string(el.nodes[i]) +
                        " points away from the triangle's normal");
    // Rest control net (seed section 2.2): edge point = intersection of the
    // tangent plane at its corner, the plane through the edge and the mean of
    // the two corner normals, and the plane normal to the edge at 1/3.
    Eigen::Matrix<double, 10, 3> net;
    for (int i = 0; i < 3; ++i) net.row(i) = x[i].transpose();
    for (int j = 0; j < 6; ++j) {
      const int i = kEdgeOwner[j], o = kEdgeOther[j];
      const Eigen::Vector3d edge = x[o] - x[i];
      Eigen::Matrix3d planes;
      planes.row(0) = m[i].transpose();
      planes.row(1) = edge.cross(0.5 * (m[i] + m[o])).transpose();
      planes.row(2) = edge.transpose();
      if (!(std::abs(planes.determinant()) > 1e-9 * edge.squaredNorm() * edge.norm()))
        throw Error("", where, "the corner normals do not define the edge control points");
      const Eigen::Vector3d rhs(0, 0, edge.squaredNorm() / 3.0);
      net.row(3 + j) = (x[i] + planes.partialPivLu().solve(rhs)).transpose();
    }
    net.row(9) =
        0.25 * net.middleRows<6>(3).colwise().sum() - net.topRows<3>().colwise().sum() / 6.0;
    // Rest element frame: e1 along the first edge, e3 the normal, e2 = e3 x e1.
    el.rest_frame.col(0) = (x[1] - x[0]).normalized();
    el.rest_frame.col(2) = n;
    el.rest_frame.col(1) = n.cross(el.rest_frame.col(0));
    const Eigen::Vector3d centroid = (x[0] + x[1] + x[2]) / 3.0;
    for (int k = 0; k < 10; ++k)
      el.rest_local.row(k) =
          (el.rest_frame.transpose() * (net.row(k).transpose() - centroid)).transpose();
    Eigen::Matrix2d edges;
    edges.col(0) = (el.rest_local.row(1) - el.rest_local.row(0)).head<2>().transpose();
    edges.col(1) = (el.rest_local.row(2) - el.rest_local.row(0)).head<2>().transpose();
    el.rest_edges_inverse = edges.inverse();
    for (int i = 0; i < 3; ++i)
      el.corner_link[i] = state.rest_rotation(el.nodes[i]).transpose() * el.rest_frame;
    for (int j = 0; j < 6; ++j)
      el.attachment[j] = (el.rest_local.row(3 + j) - el.rest_local.row(kEdgeOwner[j])).transpose();

    // Linear map L: xi -> control point displacements in the element frame (30).
    Eigen::Matrix<double, 30, 12> lmap = Eigen::Matrix<double, 30, 12>::Zero();
    for (Eigen::Index i = 0; i < 3; ++i) {  // corners: (S - I) X_i
      const double cx = el.rest_local(i, 0), cy = el.rest_local(i, 1);
      lmap(3 * i, 0) = cx;
      lmap(3 * i, 2) = cy;
      lmap(3 * i + 1, 1) = cy;
      lmap(3 * i + 1, 2) = cx;
    }
    for (Eigen::Index j = 0; j < 6; ++j) {  // edges: corner + (S3 - I) a + psi x a
      const Eigen::Index i = kEdgeOwner[j], r = 3 * (3 + j);
      const Eigen::Vector3d& at = el.attachment[j];
      lmap.middleRows<3>(r) = lmap.middleRows<3>(3 * i);
      lmap(r, 0) += at.x();
      lmap(r, 2) += at.y();
      lmap(r + 1, 1) += at.y();
      lmap(r + 1, 2) += at.x();
      lmap.block<3, 3>(r, 3 + 3 * i) -= Skew(at);
      // As the seed's split (section 3.2): in-plane motion from the drilling
      // rotation only, out-of-plane from the two others. The rotations about
      // in-plane axes would move a curved element's raised edge points in
      // plane and stiffen bending with membrane strain (membrane locking).
      lmap(r, 4 + 3 * i) = 0;
      lmap(r + 1, 3 + 3 * i) = 0;
    }
    lmap.middleRows<3>(27).setZero();  // centre: seed eq. 7
    for (Eigen::Index j = 0; j < 6; ++j)
      lmap.middleRows<3>(27) += 0.25 * lmap.middleRows<3>(3 * (3 + j));
    for (Eigen::Index i = 0; i < 3; ++i) lmap.middleRows<3>(27) -= lmap.middleRows<3>(3 * i) / 6.0;

    // Membrane: Bezier stiffness on the 30 control point displacements (seed
    // eq. 24-29), derivatives in the rest surface's own (isoparametric)
    // in-plane coordinates. Bending: the Bezier curvature's deviation from its
    // element mean, plus a constant curvature from the boundary integral
    // kappa = -(1/A) int_dA sym(grad w (x) n) ds with the normal slope
    // interpolated linearly between the corner rotations along each edge (the
    // tangential part vanishes: corners stay in the element plane). The
    // boundary term is shared by neighbours, so the mesh passes the
    // constant-curvature patch test; the Bezier surface alone is only C0
    // across edges and leaves an interior residual (~11 % of the boundary
    // forces on a patch) that converges plates 3-4 % too soft.
    Eigen::Matrix<double, 30, 30> k30 = Eigen::Matrix<double, 30, 30>::Zero();
    std::array<Eigen::Matrix<double, 3, 12>, 6> bend;
    std::array<double, 6> bend_area;
    Eigen::Matrix<double, 3, 12> bend_mean = Eigen::Matrix<double, 3, 12>::Zero();
    el.area = 0;
    for (int i = 0; i < 3; ++i) el.lumped_inertia[i].setZero();
    for (size_t g = 0; g < GaussPoints().size(); ++g) {
      const GaussPoint& gp = GaussPoints()[g];
      const Basis basis = EvaluateBasis(gp.xi1, gp.xi2);
      Eigen::Matrix2d jac;  // jac(r, c) = dX_r / dxi_c
      jac.col(0) = el.rest_local.leftCols<2>().transpose() * basis.d1;
      jac.col(1) = el.rest_local.leftCols<2>().transpose() * basis.d2;
      const double det = jac.determinant();
      if (!(det > 0)) throw Error("", where, "rest Bezier surface folds over (Jacobian <= 0)");
      const Eigen::Matrix2d jit = jac.inverse().transpose();
      Eigen::Matrix<double, 2, 10> nxi;
      nxi.row(0) = basis.d1.transpose();
      nxi.row(1) = basis.d2.transpose();
      const Eigen::Matrix<double, 2, 10> nx = jit * nxi;
      Eigen::Matrix2d xxi[2];  // second derivatives of X and Y with respect to xi
      for (int c = 0; c < 2; ++c) {
        const Eigen::Matrix<double, 10, 1> pc = el.rest_local.col(c);
        xxi[c] << basis.d11.dot(pc), basis.d12.dot(pc), basis.d12.dot(pc), basis.d22.dot(pc);
      }
      Eigen::Matrix<double, 3, 30> bm = Eigen::Matrix<double, 3, 30>::Zero();
      Eigen::Matrix<double, 3, 30> bb = Eigen::Matrix<double, 3, 30>::Zero();
      for (Eigen::Index k = 0; k < 10; ++k) {
        bm(0, 3 * k) = nx(0, k);
        bm(1, 3 * k + 1) = nx(1, k);
        bm(2, 3 * k) = nx(1, k);
        bm(2, 3 * k + 1) = nx(0, k);
        Eigen::Matrix2d hxi;
        hxi << basis.d11(k), basis.d12(k), basis.d12(k), basis.d22(k);
        const Eigen::Matrix2d hx =
            jit * (hxi - nx(0, k) * xxi[0] - nx(1, k) * xxi[1]) * jit.transpose();
        bb(0, 3 * k + 2) = -hx(0, 0);
        bb(1, 3 * k + 2) = -hx(1, 1);
        bb(2, 3 * k + 2) = -2 * hx(0, 1);
      }
      const double da = 0.5 * gp.weight * det;
      k30 += da * t * bm.transpose() * d * bm;
      bend[g] = bb * lmap;
      bend_area[g] = da;
      bend_mean += da * bend[g];
      el.area += da;
      // Lumped mass and rotational inertia (see the header).
      const double mg = mat.density_kg_per_mm3 * t * da;
      const Eigen::Vector3d pos = el.rest_local.transpose() * basis.n;
      const double lambda[3] = {gp.xi1, gp.xi2, 1.0 - gp.xi1 - gp.xi2};
      for (int i = 0; i < 3; ++i) {
        const Eigen::Vector3d r = pos - el.rest_local.row(i).transpose();
        el.lumped_mass[i] += lambda[i] * mg;
        Eigen::Matrix3d moment = r.squaredNorm() * Eigen::Matrix3d::Identity() - r * r.transpose();
        moment(0, 0) += t * t / 12.0;
        moment(1, 1) += t * t / 12.0;
        el.lumped_inertia[i] += lambda[i] * mg * moment;
      }
    }
    bend_mean /= el.area;
    const double bending = t * t * t / 12.0;
    Eigen::Matrix<double, 12, 12> kb = Eigen::Matrix<double, 12, 12>::Zero();
    for (size_t g = 0; g < bend.size(); ++g) {
      const Eigen::Matrix<double, 3, 12> dev = bend[g] - bend_mean;
      kb += bend_area[g] * bending * dev.transpose() * d * dev;
    }
    Eigen::Matrix<double, 3, 12> edge_curvature = Eigen::Matrix<double, 3, 12>::Zero();
    const double tri_area = 0.5 * std::abs(edges.determinant());
    for (int i = 0; i < 3; ++i) {
      const int k2 = (i + 1) % 3;
      const Eigen::Vector2d span = (el.rest_local.row(k2) - el.rest_local.row(i)).head<2>();
      const double len = span.norm();
      const Eigen::Vector2d nrm(span.y() / len, -span.x() / len);  // outward (counter-clockwise)
      const Eigen::Vector3d out(nrm.x() * nrm.x(), nrm.y() * nrm.y(), 2 * nrm.x() * nrm.y());
      // Normal slope of corner c: (w_x, w_y) = (-psi_y, psi_x), dotted with n.
      for (int c : {i, k2}) {
        edge_curvature.block<3, 1>(0, 3 + 3 * c) += -0.5 * len / tri_area * nrm.y() * out;
        edge_curvature.block<3, 1>(0, 4 + 3 * c) += 0.5 * len / tri_area * nrm.x() * out;
      }
    }
    kb += tri_area * bending * edge_curvature.transpose() * d * edge_curvature;
    el.k = lmap.transpose() * k30 * lmap + kb;
    el.k = 0.5 * (el.k + el.k.transpose()).eval();
    built.push_back(el);
  }
  elements_.swap(built);
  cached_gradient_.clear();
  cached_hessian_.clear();
  cached_state_ = StateSnapshot();
}

void BezierShell::AppendStencils(std::vector<std::vector<int>>* stencils) const {
  for (const Element& el : elements_) stencils->push_back({el.nodes[0], el.nodes[1], el.nodes[2]});
}

Eigen::Matrix<double, 12, 1> BezierShell::DeformationalCoordinates(const GeneralisedState& state,
                                                                   int element) const {
  Kinematics k;
  if (!ComputeKinematics(elements_[element], options_, state, &k))
    return Vector12d::Constant(std::numeric_limits<double>::quiet_NaN());
  return k.xi;
}

double BezierShell::ElementEnergy(const GeneralisedState& state, int element,
                                  Eigen::Matrix<double, 18, 1>* gradient,
                                  Eigen::Matrix<double, 18, 18>* hessian) const {
  const Element& el = elements_[element];
  Kinematics k;
  if (!ComputeKinematics(el, options_, state, &k)) {
    if (gradient) gradient->setZero();
    if (hessian) hessian->setZero();
    return std::numeric_limits<double>::infinity();  // collapsed triangle
  }
  const Vector12d kx = el.k * k.xi;
  const double energy = 0.5 * k.xi.dot(kx);
  if (!gradient && !hessian) return energy;
  const Eigen::Matrix<double, 12, 18> b = XiJacobian(el, k);
  if (gradient) *gradient = b.transpose() * kx;
  if (hessian) {
    if (options_.hessian == ShellHessian::kGaussNewton) {
      // Coefficient-wise (lazy) products: faster than the blocked kernel at these sizes.
      const Eigen::Matrix<double, 12, 18> kb = el.k.lazyProduct(b);
      *hessian = b.transpose().lazyProduct(kb);
    } else {
      ExactEnergyDerivatives(el, state, nullptr, hessian);
      if (options_.hessian == ShellHessian::kExactProjected) {
        Eigen::SelfAdjointEigenSolver<Matrix18d> eig(*hessian);
        *hessian = eig.eigenvectors() * eig.eigenvalues().cwiseMax(0.0).asDiagonal() *
                   eig.eigenvectors().transpose();
      }
    }
  }
  return energy;
}

bool BezierShell::CacheHolds(const GeneralisedState& state) const {
  return static_cast<int>(cached_gradient_.size()) == num_elements() &&
         cached_state_.Matches(state);
}

double BezierShell::Value(const GeneralisedState& state) const {
  if (CacheHolds(state)) return cached_energy_;
  double sum = 0;
  for (int e = 0; e < num_elements(); ++e) sum += ElementEnergy(state, e);
  return sum;
}

void BezierShell::Update(const GeneralisedState&) { cached_state_ = StateSnapshot(); }

void BezierShell::CacheDerivatives(const GeneralisedState& state) const {
  if (CacheHolds(state)) return;
  cached_gradient_.resize(elements_.size());
  cached_hessian_.resize(elements_.size());
  cached_energy_ = 0;
  for (int e = 0; e < num_elements(); ++e)
    cached_energy_ += ElementEnergy(state, e, &cached_gradient_[e], &cached_hessian_[e]);
  cached_state_.Take(state);
}

void StateSnapshot::Take(const GeneralisedState& state) {
  positions = state.positions();
  rotations.resize(state.num_nodes());
  for (int n = 0; n < state.num_nodes(); ++n) rotations[n] = state.rotation(n);
}

bool StateSnapshot::Matches(const GeneralisedState& state) const {
  if (positions.rows() != state.num_nodes() || positions != state.positions()) return false;
  for (int n = 0; n < state.num_nodes(); ++n)
    if (rotations[n] != state.rotation(n)) return false;
  return true;
}

void BezierShell::AddGradient(const GeneralisedState& state, Eigen::VectorXd* gradient) const {
  CacheDerivatives(state);
  for (int e = 0; e < num_elements(); ++e)
    for (Eigen::Index i = 0; i < 3; ++i)
      gradient->segment<6>(state.dof_offset(elements_[e].nodes[i])) +=
          cached_gradient_[e].segment<6>(6 * i);
}

void BezierShell::AddHessian(const GeneralisedState& state, double scale, HessianSink* sink) const {
  CacheDerivatives(state);
  for (int e = 0; e < num_elements(); ++e) {
    const Eigen::Vector3i& nodes = elements_[e].nodes;
    for (Eigen::Index a = 0; a < 3; ++a)
      for (Eigen::Index b = a; b < 3; ++b)
        sink->AddBlock(nodes[a], nodes[b], cached_hessian_[e].block<6, 6>(6 * a, 6 * b), scale);
  }
}

void BezierShell::AddNodeInertia(const GeneralisedState& state,
                                 std::vector<NodeInertia>* inertia) const {
  for (const Element& el : elements_)
    for (int i = 0; i < 3; ++i) {
      NodeInertia& ni = (*inertia)[el.nodes[i]];
      ni.mass_kg += el.lumped_mass[i];
      ni.body_inertia += el.corner_link[i] * el.lumped_inertia[i] * el.corner_link[i].transpose();
    }
}

void BezierShell::ControlPoints(const GeneralisedState& state, int element,
                                Eigen::Matrix<double, 10, 3>* points,
                                Eigen::Matrix<double, 30, 18>* jacobian) const {
  const Element& el = elements_[element];
  Kinematics k;
  if (!ComputeKinematics(el, options_, state, &k))
    throw Error("", "shell triangle " + std::to_string(element), "collapsed (zero area)");
  Eigen::Matrix<double, 3, 9> m, w;
  if (jacobian) {
    FrameDerivatives(el, k, &m, &w);
    jacobian->setZero();
  }
  for (Eigen::Index i = 0; i < 3; ++i) {
    points->row(i) = state.position(el.nodes[i]).transpose();
    if (jacobian) jacobian->block<3, 3>(3 * i, 6 * i).setIdentity();
  }
  for (Eigen::Index j = 0; j < 6; ++j) {
    const Eigen::Index i = kEdgeOwner[j], r = 3 * (3 + j);
    const Eigen::Vector3d& at = el.attachment[j];
    const Eigen::Vector3d stretched(k.S(0, 0) * at.x() + k.S(0, 1) * at.y(),
                                    k.S(0, 1) * at.x() + k.S(1, 1) * at.y(), at.z());
    const Eigen::Matrix3d link = state.rotation(el.nodes[i]) * el.corner_link[i];
    const Eigen::Vector3d segment = link * stretched;
    points->row(3 + j) = (state.position(el.nodes[i]) + segment).transpose();
    if (jacobian) {
      jacobian->block<3, 3>(r, 6 * i).setIdentity();
      jacobian->block<3, 3>(r, 6 * i + 3) = -Skew(segment);
      // d(S3 a) / d(S11, S22, S12).
      Eigen::Matrix3d g = Eigen::Matrix3d::Zero();
      g(0, 0) = at.x();
      g(1, 1) = at.y();
      g(0, 2) = at.y();
      g(1, 2) = at.x();
      const Eigen::Matrix<double, 3, 9> ds = link * g * m;
      for (Eigen::Index c = 0; c < 3; ++c)
        jacobian->block<3, 3>(r, 6 * c) += ds.block<3, 3>(0, 3 * c);
    }
  }
  points->row(9) =
      0.25 * points->middleRows<6>(3).colwise().sum() - points->topRows<3>().colwise().sum() / 6.0;
  if (jacobian) {
    jacobian->middleRows<3>(27).setZero();
    for (int j = 0; j < 6; ++j)
      jacobian->middleRows<3>(27) += 0.25 * jacobian->middleRows<3>(9 + 3 * j);
    for (Eigen::Index i = 0; i < 3; ++i)
      jacobian->middleRows<3>(27) -= jacobian->middleRows<3>(3 * i) / 6.0;
  }
}

namespace {

Eigen::Vector3d CheckedDirection(const Eigen::Vector3d& direction, double stiffness, int node) {
  if (!(direction.norm() > 0) || !direction.allFinite())
    throw Error("", "shell support at node " + std::to_string(node), "zero direction");
  if (!(stiffness > 0) || !std::isfinite(stiffness))
    throw Error("", "shell support at node " + std::to_string(node), "stiffness must be positive");
  return direction.normalized();
}

}  // namespace

void ShellSupportTerm::HoldTranslation(int node, const Eigen::Vector3d& direction,
                                       double stiffness_n_per_m) {
  holds_.push_back(
      {node, false, CheckedDirection(direction, stiffness_n_per_m, node), stiffness_n_per_m});
}

void ShellSupportTerm::HoldRotation(int node, const Eigen::Vector3d& direction,
                                    double stiffness_nmm_per_rad2) {
  holds_.push_back({node, true, CheckedDirection(direction, stiffness_nmm_per_rad2, node),
                    stiffness_nmm_per_rad2});
}

void ShellSupportTerm::AddForce(int node, const Eigen::Vector3d& force_mn) {
  forces_.emplace_back(node, force_mn);
}

void ShellSupportTerm::AppendStencils(std::vector<std::vector<int>>* stencils) const {
  for (const Hold& h : holds_) stencils->push_back({h.node});
}

double ShellSupportTerm::Value(const GeneralisedState& state) const {
  double e = 0;
  for (const Hold& h : holds_) {
    const double c = h.rotation ? h.direction.dot(LogSO3(state.rotation(h.node) *
                                                         state.rest_rotation(h.node).transpose()))
                                : h.direction.dot(state.position(h.node) -
                                                  state.rest_positions().row(h.node).transpose());
    e += 0.5 * h.stiffness * c * c;
  }
  for (const auto& f : forces_) e -= f.second.dot(state.position(f.first));
  return e;
}

void ShellSupportTerm::AddGradient(const GeneralisedState& state, Eigen::VectorXd* gradient) const {
  for (const Hold& h : holds_) {
    const int o = state.dof_offset(h.node);
    if (h.rotation) {
      const Eigen::Vector3d psi =
          LogSO3(state.rotation(h.node) * state.rest_rotation(h.node).transpose());
      gradient->segment<3>(o + 3) += h.stiffness * h.direction.dot(psi) *
                                     LeftJacobianInverseSO3(psi).transpose() * h.direction;
    } else {
      gradient->segment<3>(o) +=
          h.stiffness *
          h.direction.dot(state.position(h.node) - state.rest_positions().row(h.node).transpose()) *
          h.direction;
    }
  }
  for (const auto& f : forces_) gradient->segment<3>(state.dof_offset(f.first)) -= f.second;
}

void ShellSupportTerm::AddHessian(const GeneralisedState& state, double scale,
                                  HessianSink* sink) const {
  for (const Hold& h : holds_) {
    const int dofs = state.node_dofs(h.node);
    Eigen::MatrixXd block = Eigen::MatrixXd::Zero(dofs, dofs);
    if (h.rotation) {
      const Eigen::Vector3d psi =
          LogSO3(state.rotation(h.node) * state.rest_rotation(h.node).transpose());
      const Eigen::Vector3d j = LeftJacobianInverseSO3(psi).transpose() * h.direction;
      block.block<3, 3>(3, 3) = h.stiffness * j * j.transpose();
    } else {
      block.block<3, 3>(0, 0) = h.stiffness * h.direction * h.direction.transpose();
    }
    sink->AddBlock(h.node, h.node, block, scale);
  }
}

}  // namespace arreg::mechanics
