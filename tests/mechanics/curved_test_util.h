// Test meshes of curved Bernstein tetrahedra: a tetrahedral ball (icosphere shells) and
// the ball raised onto its sphere.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <vector>

#include "core/mesh.h"
#include "core/mesh_ops.h"
#include "generalised_fd.h"
#include "mechanics/curved_boundary.h"

namespace arreg::mechanics::testing {

constexpr double kRadius = 10.0;  // mm

inline Eigen::Vector3d OntoSphere(const Eigen::Vector3d& x) { return kRadius * x.normalized(); }

// A ball of radius kRadius: an icosahedron subdivided `level` times on the sphere, 2^level
// shells of prisms (each split into 3 tets by the global vertex order, so neighbours
// match) around a core of tets to the centre. Every boundary tet has one boundary face,
// edge length about 1.1 kRadius / 2^level; vertices of the outer shell on the sphere.
// inner_radius > 0: a hollow sphere instead, 2^level shells from inner_radius to kRadius.
inline TetMesh LinearBall(int level, double inner_radius = 0) {
  std::vector<Eigen::Vector3d> v;
  const double t = (1 + std::sqrt(5.0)) / 2;
  for (double a : {-1.0, 1.0})
    for (double b : {-t, t}) {
      v.emplace_back(0, a, b);
      v.emplace_back(a, b, 0);
      v.emplace_back(b, 0, a);
    }
  for (auto& p : v) p.normalize();
  // The 20 faces: triples of mutually adjacent vertices (edge length 2 before normalizing).
  std::vector<std::array<int, 3>> faces;
  double min_edge = 1e9;
  for (size_t i = 0; i < v.size(); ++i)
    for (size_t j = i + 1; j < v.size(); ++j) min_edge = std::min(min_edge, (v[i] - v[j]).norm());
  auto adjacent = [&](int i, int j) { return (v[i] - v[j]).norm() < 1.01 * min_edge; };
  for (int i = 0; i < 12; ++i)
    for (int j = i + 1; j < 12; ++j)
      for (int k = j + 1; k < 12; ++k)
        if (adjacent(i, j) && adjacent(j, k) && adjacent(i, k)) faces.push_back({i, j, k});
  for (int l = 0; l < level; ++l) {
    std::map<std::pair<int, int>, int> mid;
    auto midpoint = [&](int a, int b) {
      const auto key = std::minmax(a, b);
      auto [it, inserted] = mid.emplace(key, static_cast<int>(v.size()));
      if (inserted) v.push_back((v[a] + v[b]).normalized());
      return it->second;
    };
    std::vector<std::array<int, 3>> finer;
    for (const auto& f : faces) {
      const int ab = midpoint(f[0], f[1]), bc = midpoint(f[1], f[2]), ca = midpoint(f[2], f[0]);
      finer.push_back({f[0], ab, ca});
      finer.push_back({f[1], bc, ab});
      finer.push_back({f[2], ca, bc});
      finer.push_back({ab, bc, ca});
    }
    faces = std::move(finer);
  }
  const int per_shell = static_cast<int>(v.size()), shells = 1 << level;
  const bool hollow = inner_radius > 0;
  const int layers = hollow ? shells + 1 : shells;
  TetMesh ball;
  ball.vertices.resize(per_shell * layers + (hollow ? 0 : 1), 3);
  for (int s = 0; s < layers; ++s) {
    const double r =
        hollow ? inner_radius + (kRadius - inner_radius) * s / shells : kRadius * (s + 1) / shells;
    for (int i = 0; i < per_shell; ++i)
      ball.vertices.row(s * per_shell + i) = (r * v[i]).transpose();
  }
  const int centre = per_shell * layers;
  if (!hollow) ball.vertices.row(centre).setZero();
  std::vector<Eigen::Vector4i> tets;
  for (auto f : faces) {
    std::sort(f.begin(), f.end());
    if (!hollow) tets.emplace_back(centre, f[0], f[1], f[2]);
    for (int s = 1; s < layers; ++s) {
      const int lo = (s - 1) * per_shell, hi = s * per_shell;
      const int a = lo + f[0], b = lo + f[1], c = lo + f[2];
      const int a1 = hi + f[0], b1 = hi + f[1], c1 = hi + f[2];
      // Quad diagonals from the smaller bottom vertex to the larger one's top vertex.
      tets.emplace_back(a, b, c, c1);
      tets.emplace_back(a, b, b1, c1);
      tets.emplace_back(a, a1, b1, c1);
    }
  }
  ball.tetrahedra.resize(static_cast<int>(tets.size()), 4);
  for (size_t i = 0; i < tets.size(); ++i) ball.tetrahedra.row(static_cast<int>(i)) = tets[i];
  FixOrientation(&ball);
  return ball;
}

inline HighOrderTetMesh RaisedBall(int level, int degree, SurfaceRaiseSummary* summary = nullptr,
                                   bool relax = true) {
  SurfaceRaiseOptions options;
  options.project = OntoSphere;
  options.relax_interior = relax;
  return RaiseTetMeshOntoSurface(LinearBall(level), degree, options, summary);
}

// Central differences (step h) of a term's energy (Update, then Value) along every DOF.
inline Eigen::VectorXd EnergyGradientByDifferences(GeneralisedEnergyTerm* term,
                                                   const GeneralisedState& state, double h) {
  Eigen::VectorXd fd(state.num_dofs());
  for (int i = 0; i < fd.size(); ++i) {
    const GeneralisedState plus = Perturbed(state, i, h), minus = Perturbed(state, i, -h);
    term->Update(plus);
    const double e_plus = term->Value(plus);
    term->Update(minus);
    fd[i] = (e_plus - term->Value(minus)) / (2 * h);
  }
  term->Update(state);
  return fd;
}

}  // namespace arreg::mechanics::testing
