#include "ar/pipeline/debris_welds.h"

#include <limits>

#include "core/mesh_ops.h"

namespace arreg::pipeline {

int ModelPieces::Count() const {
  int n = 0;
  for (int p = 0; p < static_cast<int>(volume.size()); ++p) n += !debris(p);
  return n;
}

int ModelPieces::Slivers() const {
  int n = 0;
  for (int p = 0; p < static_cast<int>(volume.size()); ++p)
    n += !debris(p) && volume[p] < kSliverFraction * total;
  return n;
}

ModelPieces FindPieces(const TetMesh& rest) {
  ModelPieces pieces;
  int count = 0;
  pieces.piece = ConnectedComponents(rest, Adjacency::kVertex, &count);
  const Eigen::VectorXd volumes = TetVolumes(rest);
  pieces.volume.assign(count, 0.0);
  for (int t = 0; t < rest.num_tetrahedra(); ++t) pieces.volume[pieces.piece(t)] += volumes(t);
  pieces.total = volumes.sum();
  return pieces;
}

int DebrisWelds::Weld(const ModelPieces& pieces, const TetMesh& rest,
                      mechanics::MechanicalState* state) {
  // The elements before this event may have been replaced: every weld is made again.
  const size_t welded_before = welds_.size();
  welds_.clear();
  const int num_pieces = static_cast<int>(pieces.volume.size());
  std::vector<std::vector<int>> elements(num_pieces);
  for (int t = 0; t < rest.num_tetrahedra(); ++t) elements[pieces.piece(t)].push_back(t);
  const auto centroid = [&](int t) {
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (int a = 0; a < 4; ++a) c += rest.vertices.row(rest.tetrahedra(t, a)).transpose();
    return Eigen::Vector3d(c / 4.0);
  };
  std::vector<char> is_welded(state->num_vertices(), 0);
  for (int p = 0; p < num_pieces; ++p) {
    if (!pieces.debris(p)) continue;
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    for (int t : elements[p]) centre += centroid(t);
    centre /= static_cast<double>(elements[p].size());
    // The fragment follows one element (so it moves affinely and cannot invert): the element of
    // another piece, not debris, whose rest centroid is nearest to the fragment's.
    int parent = -1;
    double best = std::numeric_limits<double>::infinity();
    for (int t = 0; t < rest.num_tetrahedra(); ++t) {
      if (pieces.debris(pieces.piece(t))) continue;
      const double d2 = (centroid(t) - centre).squaredNorm();
      if (d2 < best) {
        best = d2;
        parent = t;
      }
    }
    if (parent < 0) continue;  // the whole model is debris: leave it to the solver
    const auto corner = [&](int a) -> Eigen::Vector3d {
      return rest.vertices.row(rest.tetrahedra(parent, a)).transpose();
    };
    for (int t : elements[p])
      for (int a = 0; a < 4; ++a) {
        const int v = rest.tetrahedra(t, a);
        if (is_welded[v]) continue;
        is_welded[v] = 1;
        welds_.push_back(
            {v,
             {parent, mechanics::BarycentricCoordinates(rest.vertices.row(v).transpose(), corner(0),
                                                        corner(1), corner(2), corner(3))}});
      }
  }
  std::vector<int> vertices;
  for (const WeldedVertex& w : welds_) vertices.push_back(w.vertex);
  state->SetFixed(vertices);
  Follow(state);
  return static_cast<int>(welds_.size()) - static_cast<int>(welded_before);
}

void DebrisWelds::Follow(mechanics::MechanicalState* state) const {
  RowMatX3d& x = state->mutable_positions();
  RowMatX3d& v = state->mutable_velocities();
  for (const WeldedVertex& w : welds_) {
    Eigen::RowVector3d position = Eigen::RowVector3d::Zero(), velocity = position;
    for (int a = 0; a < 4; ++a) {
      const int corner = state->tetrahedra()(w.at.tet, a);
      position += w.at.barycentric(a) * x.row(corner);
      velocity += w.at.barycentric(a) * v.row(corner);
    }
    x.row(w.vertex) = position;
    v.row(w.vertex) = velocity;
  }
}

}  // namespace arreg::pipeline
