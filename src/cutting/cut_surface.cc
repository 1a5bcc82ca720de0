#include "cutting/cut_surface.h"

#include <Eigen/Geometry>
#include <cmath>

#include "core/error.h"
#include "cutting/predicates.h"

namespace arreg::cutting {

void CutSurface::Check() const {
  for (int i = 0; i < vertices.rows(); ++i)
    ARREG_CHECK_INPUT(vertices.row(i).allFinite(), "", "CutSurface.vertices", "vertex ", i,
                      " is not finite");
  for (int f = 0; f < triangles.rows(); ++f)
    for (int k = 0; k < 3; ++k)
      ARREG_CHECK_INPUT(triangles(f, k) >= 0 && triangles(f, k) < vertices.rows(), "",
                        "CutSurface.triangles", "triangle ", f, " refers to vertex ",
                        triangles(f, k), " of ", vertices.rows());
}

CutSurface MakeGridSurface(const std::function<Eigen::Vector3d(double, double)>& p, int nu,
                           int nv) {
  ARREG_CHECK_INPUT(nu >= 1 && nv >= 1, "", "MakeGridSurface", "nu and nv must be >= 1");
  CutSurface s;
  s.vertices.resize((nu + 1) * (nv + 1), 3);
  for (int j = 0; j <= nv; ++j)
    for (int i = 0; i <= nu; ++i)
      s.vertices.row(j * (nu + 1) + i) =
          p(static_cast<double>(i) / nu, static_cast<double>(j) / nv).transpose();
  s.triangles.resize(2 * nu * nv, 3);
  int f = 0;
  for (int j = 0; j < nv; ++j)
    for (int i = 0; i < nu; ++i) {
      const int a = j * (nu + 1) + i, b = a + 1, c = a + nu + 1, d = c + 1;
      s.triangles.row(f++) << a, b, d;
      s.triangles.row(f++) << a, d, c;
    }
  return s;
}

CutSurface MakePlaneSurface(const Eigen::Vector3d& point, const Eigen::Vector3d& normal,
                            double half_u, double half_v, const Eigen::Vector3d& u_hint, int n) {
  ARREG_CHECK_INPUT(normal.norm() > 0 && normal.allFinite(), "", "MakePlaneSurface.normal",
                    "must be finite and non-zero");
  const Eigen::Vector3d nn = normal.normalized();
  Eigen::Vector3d u = u_hint - u_hint.dot(nn) * nn;
  if (u.norm() < 1e-9) u = nn.unitOrthogonal();
  u.normalize();
  const Eigen::Vector3d v = nn.cross(u);
  return MakeGridSurface(
      [&](double s, double t) -> Eigen::Vector3d {
        return point + (2 * s - 1) * half_u * u + (2 * t - 1) * half_v * v;
      },
      n, n);
}

CutSurface ExtrudePolyline(const RowMatX3d& polyline, const RowMatX3d& directions,
                           double depth_before, double depth_after) {
  ARREG_CHECK_INPUT(polyline.rows() >= 2 && directions.rows() == polyline.rows(), "",
                    "ExtrudePolyline", "need >= 2 points and one direction per point");
  const int n = static_cast<int>(polyline.rows());
  CutSurface s;
  s.vertices.resize(2 * n, 3);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d d = directions.row(i).transpose().normalized();
    s.vertices.row(2 * i) = polyline.row(i) - depth_before * d.transpose();
    s.vertices.row(2 * i + 1) = polyline.row(i) + depth_after * d.transpose();
  }
  s.triangles.resize(2 * (n - 1), 3);
  for (int i = 0; i + 1 < n; ++i) {
    s.triangles.row(2 * i) << 2 * i, 2 * i + 2, 2 * i + 3;
    s.triangles.row(2 * i + 1) << 2 * i, 2 * i + 3, 2 * i + 1;
  }
  return s;
}

bool SegmentCrossesSurface(const CutSurface& surface, const Eigen::Vector3d& a,
                           const Eigen::Vector3d& b) {
  for (int f = 0; f < surface.num_triangles(); ++f) {
    const Eigen::Vector3d p = surface.vertices.row(surface.triangles(f, 0)).transpose();
    const Eigen::Vector3d q = surface.vertices.row(surface.triangles(f, 1)).transpose();
    const Eigen::Vector3d r = surface.vertices.row(surface.triangles(f, 2)).transpose();
    if (Orient3d(p, q, r, a) * Orient3d(p, q, r, b) >= 0) continue;
    const int s0 = Orient3d(a, b, p, q), s1 = Orient3d(a, b, q, r), s2 = Orient3d(a, b, r, p);
    if ((s0 >= 0 && s1 >= 0 && s2 >= 0) || (s0 <= 0 && s1 <= 0 && s2 <= 0)) return true;
  }
  return false;
}

}  // namespace arreg::cutting
