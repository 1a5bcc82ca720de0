// Cutting of quadratic (degree-2 Bernstein-Bezier) tetrahedra (thesis 6.1): the linear
// remesher's operators run on the corner mesh, and every control point an event creates is
// placed on the map of the element it came from.
//
// Each element of degree 2 has its four corners and one control point per edge, shared by the
// elements around that edge. The corners form a linear tetrahedral mesh, the skeleton, which a
// CuttableMesh cuts (1-4 split, 2-3 flip, general flip, snapping, separation: tet_cutter.h). The
// skeleton's rest positions are the reference space the old and new elements share: a point of a
// new element is located in the old element that holds it there (barycentric coordinates L), and
// its rest and current positions and velocity are that old element's Bezier map at L. An edge
// control point of a new edge (a, b) is b_ab = 2 x(L_mid) - (x_a + x_b) / 2, the Bezier point of
// the quadratic through the corners and the old map at the skeleton midpoint; edges that neither
// appear nor have a moved end keep their control point, and an edge whose end was duplicated by
// the separation gets its own copy. Consequences:
//  - a new element inside one old element (every split and bisection) is that element's map
//    restricted: exact in rest and current configurations, so the rest volume is kept and no
//    element is inverted where its parent was not;
//  - a straight (affine) rest mesh stays straight, and a deformation that is one quadratic
//    polynomial over the body is reproduced exactly by every new element, flips included;
//  - a flip or a snap of a curved rest element would replace a piecewise map by one quadratic
//    and change the rest volume: a mesh with curved rest elements is cut without flips and
//    without snapping (min_flip_quality above any quality, snap_epsilon 0, no front moves: faces
//    get vertices and edges are bisected instead).
// S is intersected with the skeleton's straight edges between the current corners (not the
// curved edges); a new vertex lies on the curved element at that edge's crossing parameter.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <unordered_map>
#include <vector>

#include "core/mesh.h"
#include "cutting/cut_surface.h"
#include "cutting/tet_cutter.h"
#include "mechanics/high_order_mesh.h"

namespace arreg::cutting {

// What one event did to the quadratic mesh, for whoever holds per-node data.
struct QuadraticCutChange {
  CutChange corners;  // the skeleton's change (corner numbering = node numbering 0..V-1)
  // Per node before the event: its index after the event, or -1 for an edge control point no
  // element uses any more (a removed edge). Corners keep their index.
  std::vector<int> node_from_old;
  int num_new_edge_nodes = 0;
  int num_removed_edge_nodes = 0;
};

// The control points of a degree-2 mesh over its corner mesh, following the corner mesh's cuts:
// the placement described above, for whoever cuts the corners (QuadraticCuttableMesh below, or the
// pipeline's cut handler, which keeps its own CuttableMesh of the corners).
class QuadraticControlNet {
 public:
  // `mesh` of degree 2 with its current positions and velocities (#N x 3, the mesh's node
  // order). Throws arreg::Error naming "degree" for another degree, "positions"/"velocities" on
  // a row mismatch and "elements" for an element table that does not share edge points.
  QuadraticControlNet(const mechanics::HighOrderTetMesh& mesh, const RowMatX3d& positions,
                      const RowMatX3d& velocities);

  // After the corner mesh took `change`: `tetrahedra` and `reference` are its elements and rest
  // positions now (the corner mesh's rest positions before the event are the reference space of
  // the old elements; the net kept them from the last call).
  void Follow(const std::vector<std::array<int, 4>>& tetrahedra,
              const std::vector<Eigen::Vector3d>& reference, const CutChange& change,
              QuadraticCutChange* out = nullptr);

  // Current positions and velocities of every node (#N x 3, the order of RestMesh()). Throws
  // arreg::Error on a row mismatch or non-finite values.
  void SetDeformation(const RowMatX3d& positions, const RowMatX3d& velocities);

  // Corners first (the corner mesh's vertices), then one control point per edge.
  mechanics::HighOrderTetMesh RestMesh() const;
  RowMatX3d Positions() const;
  RowMatX3d Velocities() const;
  int num_corners() const { return static_cast<int>(corners_.size()); }
  int num_nodes() const { return num_corners() + static_cast<int>(edges_.size()); }
  // Some rest element is not affine (its edge control points off the straight midpoints).
  bool curved() const { return curved_; }

 private:
  struct NodeData {
    Eigen::Vector3d rest, current, velocity;
  };
  struct EdgeNode {
    int a = -1, b = -1;  // corner vertices
    NodeData data;
  };
  int EdgeNodeIndex(int a, int b) const;
  RowMatX3d Gather(Eigen::Vector3d NodeData::*field) const;  // #N x 3, RestMesh() order

  std::vector<std::array<int, 4>> tets_;    // the corner mesh's elements
  std::vector<Eigen::Vector3d> reference_;  // the corner mesh's rest positions
  std::vector<NodeData> corners_;
  std::vector<EdgeNode> edges_;
  std::unordered_map<std::uint64_t, int> edge_of_;  // edge key (sorted corners) -> edges_ index
  bool curved_ = false;
};

// A degree-2 mesh that can be cut repeatedly: a CuttableMesh of the corners (the skeleton) and
// the control net that follows it.
class QuadraticCuttableMesh {
 public:
  // `mesh` of degree 2 (rest control points; current = rest, zero velocities unless given, #N x 3
  // in the mesh's node order). Throws arreg::Error as QuadraticControlNet and CuttableMesh.
  explicit QuadraticCuttableMesh(const mechanics::HighOrderTetMesh& mesh);
  QuadraticCuttableMesh(const mechanics::HighOrderTetMesh& mesh, const RowMatX3d& positions,
                        const RowMatX3d& velocities);

  // One cutting event along S (in the frame of the current positions). A mesh with curved rest
  // elements is cut with options' flips and snapping off (see above). Returns the skeleton's
  // summary; the mesh is unchanged unless the status is kCut.
  CutSummary Cut(const CutSurface& surface, const CutOptions& options,
                 QuadraticCutChange* change = nullptr);

  // Current positions and velocities of every node (#N x 3, the order of RestMesh()). Throws
  // arreg::Error on a row mismatch or non-finite values.
  void SetDeformation(const RowMatX3d& positions, const RowMatX3d& velocities);

  mechanics::HighOrderTetMesh RestMesh() const { return net_.RestMesh(); }
  RowMatX3d Positions() const { return net_.Positions(); }
  RowMatX3d Velocities() const { return net_.Velocities(); }
  int num_nodes() const { return net_.num_nodes(); }
  int num_tetrahedra() const { return skeleton_.num_tetrahedra(); }
  // The corner mesh the linear remesher cuts (rest = the reference space; current = the corners'
  // current positions).
  const CuttableMesh& skeleton() const { return skeleton_; }
  bool curved() const { return net_.curved(); }

 private:
  QuadraticControlNet net_;  // before skeleton_: constructed (and checks its input) first
  CuttableMesh skeleton_;
};

// Checks of a quadratic mesh the remesher must keep: the corner mesh's (CheckMeshInvariants),
// one control point per edge shared by every element around it and used by no other edge, and
// the rest Jacobian determinant positive at every point of a degree-3 quadrature (where a
// degree-2 element's volume integral is exact) and at the corners.
struct QuadraticMeshInvariants {
  int num_edge_mismatches = 0;    // elements around one edge with different control points
  int num_shared_edge_nodes = 0;  // control points used by two edges, or by a corner and an edge
  int num_nonpositive_jacobians = 0;  // elements with det J <= 0 at a sampled point (rest)
  double volume = 0;                  // sum of the elements' rest volumes (exact quadrature)
  double min_jacobian_ratio = 0;      // smallest det J / (6 x the skeleton element's volume)
  bool ok() const {
    return num_edge_mismatches == 0 && num_shared_edge_nodes == 0 && num_nonpositive_jacobians == 0;
  }
};
QuadraticMeshInvariants CheckQuadraticMesh(const mechanics::HighOrderTetMesh& mesh);

}  // namespace arreg::cutting
