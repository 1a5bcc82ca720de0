#include "mechanics/curved_boundary.h"

#include <Eigen/LU>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <memory>

#include "core/error.h"
#include "core/geometry.h"
#include "mechanics/bernstein_tet.h"
#include "mechanics/linear_solver.h"
#include "mechanics/tet_element.h"

namespace arreg::mechanics {

namespace {

// Local vertices of the face opposite local vertex i, counter-clockwise seen from
// outside for a positively oriented tetrahedron.
constexpr int kOutwardFace[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};

std::array<int, 3> SortedFace(const HighOrderTetMesh& mesh, int e, int opposite) {
  std::array<int, 3> f;
  for (int c = 0; c < 3; ++c) f[c] = mesh.elements(e, kOutwardFace[opposite][c]);
  std::sort(f.begin(), f.end());
  return f;
}

Eigen::Vector4d LatticeL(const std::array<int, 4>& alpha, int degree) {
  return Eigen::Vector4d(alpha[0], alpha[1], alpha[2], alpha[3]) / degree;
}

}  // namespace

std::vector<HighOrderBoundaryFace> HighOrderBoundaryFaces(const HighOrderTetMesh& mesh) {
  std::map<std::array<int, 3>, int> count;
  for (int e = 0; e < mesh.num_elements(); ++e)
    for (int i = 0; i < 4; ++i) ++count[SortedFace(mesh, e, i)];
  std::vector<HighOrderBoundaryFace> out;
  for (int e = 0; e < mesh.num_elements(); ++e)
    for (int i = 0; i < 4; ++i)
      if (count[SortedFace(mesh, e, i)] == 1) out.push_back({e, i});
  return out;
}

SurfaceMesh CurvedBoundary::Evaluate(const RowMatX3d& nodes) const {
  SurfaceMesh out = surface;
  out.vertices = vertices.Positions(nodes);
  return out;
}

CurvedBoundary TessellateBoundary(const HighOrderTetMesh& mesh, const RowMatX3d& nodes,
                                  int subdivisions) {
  ARREG_CHECK_INPUT(subdivisions >= 1, "", "subdivisions", "must be >= 1, got ", subdivisions);
  const int n = subdivisions;
  CurvedBoundary out;
  out.faces = HighOrderBoundaryFaces(mesh);
  // Surface vertex of a lattice point: a mesh vertex {0, v}, a point on the edge (u, v),
  // u < v, with s steps of weight on u {1, u, v, s}, or inside face f {2, f, i, j}.
  std::map<std::array<int, 4>, int> vertex_of;
  std::vector<int> elements;
  std::vector<Eigen::Vector4d> barycentric;
  std::vector<Eigen::Vector3i> triangles;
  for (size_t f = 0; f < out.faces.size(); ++f) {
    const int e = out.faces[f].element;
    int local[3];
    for (int c = 0; c < 3; ++c) local[c] = kOutwardFace[out.faces[f].opposite][c];
    // A negatively oriented element turns its faces inward: flip them.
    const Eigen::MatrixX3d control = ElementControlPoints(mesh, nodes, e);
    if (BezierTetJacobian(mesh.degree, control, Eigen::Vector4d::Constant(0.25)).determinant() < 0)
      std::swap(local[1], local[2]);
    std::vector<int> index((n + 1) * (n + 1), -1);
    for (int j = 0; j <= n; ++j) {
      for (int i = 0; i + j <= n; ++i) {
        const int w[3] = {n - i - j, i, j};  // weights (in steps) of local[0], local[1], local[2]
        int nonzero[3], m = 0;
        for (int c = 0; c < 3; ++c)
          if (w[c] > 0) nonzero[m++] = c;
        std::array<int, 4> key;
        if (m == 1) {
          key = {0, mesh.elements(e, local[nonzero[0]]), 0, 0};
        } else if (m == 2) {
          int a = nonzero[0], b = nonzero[1];
          if (mesh.elements(e, local[a]) > mesh.elements(e, local[b])) std::swap(a, b);
          key = {1, mesh.elements(e, local[a]), mesh.elements(e, local[b]), w[a]};
        } else {
          key = {2, static_cast<int>(f), i, j};
        }
        auto [it, inserted] = vertex_of.emplace(key, static_cast<int>(elements.size()));
        if (inserted) {
          Eigen::Vector4d L = Eigen::Vector4d::Zero();
          for (int c = 0; c < 3; ++c) L[local[c]] = static_cast<double>(w[c]) / n;
          elements.push_back(e);
          barycentric.push_back(L);
        }
        index[i + (n + 1) * j] = it->second;
      }
    }
    auto at = [&](int i, int j) { return index[i + (n + 1) * j]; };
    for (int j = 0; j < n; ++j) {
      for (int i = 0; i + j < n; ++i) {
        triangles.emplace_back(at(i, j), at(i + 1, j), at(i, j + 1));
        out.face_of_triangle.push_back(static_cast<int>(f));
        if (i + j + 1 < n) {
          triangles.emplace_back(at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
          out.face_of_triangle.push_back(static_cast<int>(f));
        }
      }
    }
  }
  out.vertices =
      HighOrderEmbedding::FromCoordinates(mesh, std::move(elements), std::move(barycentric));
  out.surface.vertices = out.vertices.Positions(nodes);
  out.surface.faces.resize(static_cast<int>(triangles.size()), 3);
  for (size_t t = 0; t < triangles.size(); ++t)
    out.surface.faces.row(static_cast<int>(t)) = triangles[t].transpose();
  return out;
}

std::function<Eigen::Vector3d(const Eigen::Vector3d&)> ClosestPointProjector(SurfaceMesh surface) {
  ARREG_CHECK_INPUT(surface.num_faces() > 0, "", "surface", "has no faces");
  return [s = std::move(surface)](const Eigen::Vector3d& p) {
    Eigen::Vector3d best = p;
    double best_d2 = std::numeric_limits<double>::infinity();
    for (int f = 0; f < s.num_faces(); ++f) {
      const Eigen::Vector3d q =
          ClosestPointOnTriangle(p, s.vertices.row(s.faces(f, 0)), s.vertices.row(s.faces(f, 1)),
                                 s.vertices.row(s.faces(f, 2)));
      const double d2 = (q - p).squaredNorm();
      if (d2 < best_d2) {
        best_d2 = d2;
        best = q;
      }
    }
    return best;
  };
}

void SurfaceRaiseOptions::Check() const {
  ARREG_CHECK_INPUT(static_cast<bool>(project), "", "project", "must be set");
  ARREG_CHECK_INPUT(poisson_ratio > -1 && poisson_ratio < 0.5, "", "poisson_ratio",
                    "must lie in (-1, 0.5), got ", poisson_ratio);
}

HighOrderTetMesh RaiseTetMeshOntoSurface(const TetMesh& mesh, int degree,
                                         const SurfaceRaiseOptions& options,
                                         SurfaceRaiseSummary* summary) {
  options.Check();
  HighOrderTetMesh out = RaiseTetMesh(mesh, degree);
  const RowMatX3d straight = out.nodes;
  const std::vector<std::array<int, 4>> indices = BernsteinIndices(degree);
  const int count = static_cast<int>(indices.size());
  SurfaceRaiseSummary s;
  const std::vector<HighOrderBoundaryFace> faces = HighOrderBoundaryFaces(out);
  s.num_boundary_faces = static_cast<int>(faces.size());
  std::vector<char> on_boundary(out.num_nodes(), 0);
  for (const HighOrderBoundaryFace& face : faces) {
    // The face's control points (alpha_opposite = 0) interpolate the projected lattice
    // points; tet Bernstein polynomials off the face vanish on it, so the face block of
    // the collocation matrix is the triangle's.
    std::vector<int> on_face;
    for (int a = 0; a < count; ++a)
      if (indices[a][face.opposite] == 0) on_face.push_back(a);
    const int m = static_cast<int>(on_face.size());
    Eigen::MatrixXd v(m, m);
    Eigen::MatrixX3d values(m, 3);
    const Eigen::MatrixX3d control = ElementControlPoints(out, straight, face.element);
    for (int r = 0; r < m; ++r) {
      const Eigen::Vector4d L = LatticeL(indices[on_face[r]], degree);
      const Eigen::VectorXd b = BernsteinValues(degree, L);
      for (int c = 0; c < m; ++c) v(r, c) = b[on_face[c]];
      values.row(r) = options.project(BezierTetPoint(degree, control, L)).transpose();
    }
    const Eigen::MatrixX3d points = v.partialPivLu().solve(values);
    for (int r = 0; r < m; ++r) {
      const int node = out.elements(face.element, on_face[r]);
      out.nodes.row(node) = points.row(r);
      on_boundary[node] = 1;
    }
  }
  for (int i = 0; i < out.num_nodes(); ++i) {
    if (!on_boundary[i]) continue;
    ++s.num_boundary_nodes;
    s.max_boundary_move_mm =
        std::max(s.max_boundary_move_mm, (out.nodes.row(i) - straight.row(i)).norm());
  }

  if (options.relax_interior && degree >= 2) {
    // Linear elasticity on the straight elements: K_ff u_f = -K_fb u_b.
    std::vector<int> free_index(out.num_nodes(), -1);
    int num_free = 0;
    for (int i = 0; i < out.num_nodes(); ++i)
      if (!on_boundary[i]) free_index[i] = num_free++;
    if (num_free > 0) {
      Material material;
      material.youngs_modulus_pa = 1000.0;
      material.poisson_ratio = options.poisson_ratio;
      std::vector<Eigen::Triplet<double>> triplets;
      Eigen::VectorXd rhs = Eigen::VectorXd::Zero(3 * num_free);
      for (int e = 0; e < out.num_elements(); ++e) {
        const Eigen::MatrixX3d x = ElementControlPoints(out, straight, e);
        Eigen::Matrix3d d;
        for (int c = 0; c < 3; ++c) d.col(c) = (x.row(c + 1) - x.row(0)).transpose();
        Eigen::Matrix<double, 4, 3> g;
        g.bottomRows<3>() = d.inverse();
        g.row(0) = -g.bottomRows<3>().colwise().sum();
        const Eigen::MatrixXd k =
            BernsteinStiffnessMatrix(degree, g, std::abs(d.determinant()) / 6.0,
                                     material.LameLambdaKpa(), material.LameMuKpa());
        for (int a = 0; a < count; ++a) {
          const int fa = free_index[out.elements(e, a)];
          if (fa < 0) continue;
          for (int b = 0; b < count; ++b) {
            const int node_b = out.elements(e, b);
            const int fb = free_index[node_b];
            if (fb >= 0) {
              for (int r = 0; r < 3; ++r)
                for (int c = 0; c < 3; ++c)
                  triplets.emplace_back(3 * fa + r, 3 * fb + c, k(3 * a + r, 3 * b + c));
            } else {
              const Eigen::Vector3d u = (out.nodes.row(node_b) - straight.row(node_b)).transpose();
              rhs.segment<3>(3 * fa) -= k.block<3, 3>(3 * a, 3 * b) * u;
            }
          }
        }
      }
      SparseMatrixd kff(3 * num_free, 3 * num_free);
      kff.setFromTriplets(triplets.begin(), triplets.end());
      triplets = {};
      std::unique_ptr<LinearSolver> solver = LinearSolver::Create({});
      Eigen::VectorXd u = Eigen::VectorXd::Zero(3 * num_free);
      const LinearSolverSummary solved = solver->Solve(kff, rhs, &u);
      // K_ff is positive definite (a boundary node fixes every rigid motion); a failure
      // here is a bug, not an input error.
      ARREG_ASSERT(solved.status == LinearSolverStatus::kConverged,
                   "relaxation solve failed: ", solved.message);
      for (int i = 0; i < out.num_nodes(); ++i) {
        if (free_index[i] < 0) continue;
        const Eigen::Vector3d d = u.segment<3>(3 * free_index[i]);
        out.nodes.row(i) = straight.row(i) + d.transpose();
        s.max_interior_move_mm = std::max(s.max_interior_move_mm, d.norm());
      }
    }
  }

  s.min_sampled_ratio = std::numeric_limits<double>::infinity();
  s.min_coefficient_ratio = std::numeric_limits<double>::infinity();
  for (int e = 0; e < out.num_elements(); ++e) {
    const Eigen::MatrixX3d x0 = ElementControlPoints(out, straight, e);
    const double rest =
        (x0.row(1) - x0.row(0)).cross(x0.row(2) - x0.row(0)).dot(x0.row(3) - x0.row(0));
    const JacobianBounds bounds =
        BezierTetJacobianBounds(degree, ElementControlPoints(out, out.nodes, e));
    const double sampled = bounds.min_sampled / rest, coefficient = bounds.min_coefficient / rest;
    s.min_sampled_ratio = std::min(s.min_sampled_ratio, sampled);
    s.min_coefficient_ratio = std::min(s.min_coefficient_ratio, coefficient);
    if (sampled < 0)
      ++s.num_inverted;
    else if (coefficient <= 0)
      ++s.num_undecided;
  }
  if (summary) *summary = s;
  return out;
}

}  // namespace arreg::mechanics
