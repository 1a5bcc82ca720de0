// The model's pieces after a cut, and the welding of debris: fragments of a few elements that
// two nearly coincident cracks cut off follow the nearest piece instead of being simulated.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "core/mesh.h"
#include "mechanics/embedding.h"
#include "mechanics/mechanical_state.h"

namespace arreg::pipeline {

// A piece of the model holding less than this fraction of its rest volume is a sliver.
constexpr double kSliverFraction = 0.05;
// A piece below this fraction of the rest volume is debris: a few elements' fragments that two
// nearly coincident cracks cut off (an event's crack turns away from the previous event's
// look-ahead by a few degrees, and the elements between are cut twice). Debris is welded to
// the nearest piece (DebrisWelds) rather than simulated or refused.
constexpr double kDebrisFraction = 0.005;

// The model's pieces (elements connected through vertices) and their rest volumes.
struct ModelPieces {
  Eigen::VectorXi piece;       // per element, its piece
  std::vector<double> volume;  // per piece, its rest volume
  double total = 0.0;
  bool debris(int p) const { return volume[p] < kDebrisFraction * total; }
  // Pieces that are not debris.
  int Count() const;
  // Pieces from the debris bound to kSliverFraction of the volume.
  int Slivers() const;
};
ModelPieces FindPieces(const TetMesh& rest);

// Debris pieces (below kDebrisFraction of the rest volume) are welded: their vertices are
// fixed in the state and follow one element of the nearest piece affinely (rest barycentric
// coordinates), so they move with it and cannot invert.
class DebrisWelds {
 public:
  // Welds every debris piece of the state (numbered like `rest` and `pieces`) anew: the elements
  // welded to before may have been replaced. Returns how many more vertices are welded than
  // before.
  int Weld(const ModelPieces& pieces, const TetMesh& rest, mechanics::MechanicalState* state);
  // The welded vertices follow their elements (positions and velocities): after every step.
  void Follow(mechanics::MechanicalState* state) const;
  int num_vertices() const { return static_cast<int>(welds_.size()); }

 private:
  struct WeldedVertex {
    int vertex = -1;
    mechanics::EmbeddedPoint at;  // the element it follows, rest barycentric coordinates
  };
  std::vector<WeldedVertex> welds_;
};

}  // namespace arreg::pipeline
