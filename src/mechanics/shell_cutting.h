// Topology changes of a Bezier shell (a triangle mesh over frame nodes of a
// GeneralisedState, docs/shell-cutting.md): cuts by a polyline on the rest
// surface, and tearing where the largest principal membrane stress exceeds the
// material's strength (thesis section 6.2).
//
// A cut edits the triangle list and adds frame nodes to the state; the caller
// then updates the BezierShell with ReplaceElements(state, triangles,
// cut.ReusableElements(triangles.size())) (the rest control net of an element
// depends only on its corners' rest positions and rest rotations, so elements
// that were not split keep their rest data; a new BezierShell gives the same)
// and re-anchors what pointed into the old shell with the returned mapping
// (RemapSurfacePoint, RemapShellMapping; springs on nodes with node_copies).
#pragma once

#include <Eigen/Core>
#include <array>
#include <vector>

#include "mechanics/bezier_shell.h"
#include "mechanics/generalised_state.h"
#include "mechanics/shell_mapping.h"

namespace arreg::mechanics {

struct ShellCutOptions {
  // A vertex lies on the cut when its distance to the cut line (seen along the
  // projection direction) is below snap_fraction times its shortest incident
  // edge, or when the line crosses an incident edge within snap_fraction of the
  // edge's length from it: the cut then runs through the vertex instead of
  // splitting the edge close to it (no slivers). Dimensionless, [0, 0.5),
  // default 0.2.
  double snap_fraction = 0.2;
  // The line cuts the surface only where it lies within this distance of it
  // along the projection direction (mm, > 0, default 5): a cut seen through a
  // folded sheet separates only the layer it was drawn on.
  double max_depth_mm = 5.0;
  void Check() const;  // throws arreg::Error naming the field
};

// What a cut or a tear changed. Node and element indices before the change
// stay valid: element e keeps index e for its first piece, nodes are only added.
struct ShellCutResult {
  std::vector<Eigen::Vector3i> old_triangles;      // the triangle list before the change
  std::vector<std::vector<int>> node_copies;       // old node -> its copies (first: itself)
  std::vector<std::vector<int>> element_children;  // old element -> new elements (first: itself)
  std::vector<int> inserted_nodes;                 // nodes added on crossed edges
  std::vector<std::array<int, 2>> crack_edges;     // separated edges (node ids before duplication)
  int duplicated_nodes = 0;                        // nodes added along the crack
  bool changed() const { return !crack_edges.empty() || !inserted_nodes.empty(); }
  // Per element of the new list: 1 where it is an old element that was not
  // split (its corners at most replaced by copies), whose rest data
  // BezierShell::ReplaceElements can keep.
  std::vector<char> ReusableElements(int num_new_elements) const;
};

// Cuts the shell along `polyline` (>= 2 points, rest coordinates, on or near
// the rest surface) projected along `direction` (e.g. the view direction or the
// sheet's normal; need not be unit): crossed triangles are split so that the
// crack runs along new edges (vertices near the line are snapped onto it), the
// nodes along the crack are duplicated (same rest and current position,
// rotation, velocities and fixed flags) so that the two sides separate; a
// node where the crack ends inside the sheet is not duplicated (crack tip).
// New nodes on crossed edges interpolate their edge's rest and current
// positions linearly (the rest corner triangles are partitioned exactly, so
// the rest area is kept) and its rotations (rest: normalised interpolated
// axes; current: the edge's relative rotation interpolated on SO(3)).
// Throws arreg::Error for bad options, a polyline with fewer than 2 points, a
// zero direction, or a triangle index that is not a frame node.
ShellCutResult CutShell(GeneralisedState* state, std::vector<Eigen::Vector3i>* triangles,
                        const std::vector<Eigen::Vector3d>& polyline,
                        const Eigen::Vector3d& direction, const ShellCutOptions& options);

// Separates the shell along existing edges (pairs of node ids), duplicating
// nodes as CutShell does. Used by tearing without snapping.
ShellCutResult SeparateEdges(GeneralisedState* state, std::vector<Eigen::Vector3i>* triangles,
                             const std::vector<std::array<int, 2>>& edges);

// A point of an element before the change, re-anchored: the piece of the
// element that contains its rest position (the side it belongs to). `triangles`
// is the list after the change.
ShellSurfacePoint RemapSurfacePoint(const ShellCutResult& cut,
                                    const std::vector<Eigen::Vector3i>& triangles,
                                    const GeneralisedState& state, const ShellSurfacePoint& point);
// Every point of `mapping` re-anchored onto `new_shell` (built after the change).
ShellMapping RemapShellMapping(const ShellMapping& mapping, const ShellCutResult& cut,
                               const BezierShell& new_shell, const GeneralisedState& state);

// Membrane stress of an element from the stretch of its corner triangle (the
// element's S = sqrt(A^T A), A the map from rest to current): plane stress
// sigma = E/(1-nu^2) [(e11 + nu e22), (e22 + nu e11), (1 - nu) e12], e = S - I;
// principal stress sigma_P+ (thesis eq. 6.2) at the angle
// theta_P = 1/2 atan2(2 s12, s11 - s22) (eq. 6.1).
struct ShellStress {
  double principal_kpa = 0;  // sigma_P+ (kPa)
  double minor_kpa = 0;      // sigma_P- (kPa)
  // Unit direction of sigma_P+ in rest coordinates (in the element's rest plane).
  Eigen::Vector3d direction_rest = Eigen::Vector3d::UnitX();
  int element = -1;  // for a node: the element whose stress it takes
};
ShellStress ElementMembraneStress(const GeneralisedState& state, const Eigen::Vector3i& triangle,
                                  const ShellMaterial& material);
// How element stresses become a node's stress.
enum class NodeStressSmoothing {
  // The thesis's choice: the stress of the incident element with the largest
  // sigma_P+. The nodes of the most stressed element tie, and at a node on a
  // symmetry line the direction is one side's.
  kMaxElement,
  // The area-weighted mean of the incident elements' stress tensors (in
  // rest coordinates, principal values in the node's rest tangent plane):
  // symmetric where the mesh and load are, and a node with a less stressed
  // neighbour ranks below one surrounded by stress.
  kAreaAverage,
};
// Per node (num_nodes() entries; element -1 and zero stress for nodes of no
// triangle). direction_rest lies in the node's rest tangent plane (the z axis
// of its rest rotation) for kAreaAverage; element is the most stressed
// incident element in both modes.
std::vector<ShellStress> NodeMembraneStresses(const GeneralisedState& state,
                                              const std::vector<Eigen::Vector3i>& triangles,
                                              const ShellMaterial& material,
                                              NodeStressSmoothing smoothing);

struct ShellTearOptions {
  double strength_kpa = 1.0;  // ultimate tensile strength sigma_f (kPa, > 0, default 1)
  NodeStressSmoothing smoothing = NodeStressSmoothing::kAreaAverage;  // default kAreaAverage
  // Nodes with a fixed translation (grips, supports) do not fail: their
  // stress is the support's concentration, not the material's (default true).
  bool skip_held_nodes = true;
  // false: separate the existing edges from the failing node that follow the
  // crack line best (the thesis's choice: smallest angle between the crack
  // direction and the edge); true: cut through the elements along the crack
  // line from the node (CutShell, vertices near the line snapped onto it).
  bool snap = false;
  // With snap: the crack segment reaches this many mean incident edge lengths
  // from the node on each side (dimensionless, > 0, default 1).
  double crack_length_factor = 1.0;
  // Without snap: an edge is taken only within this angle of the crack line
  // (degrees, (0, 90], default 60).
  double max_edge_angle_deg = 60.0;
  ShellCutOptions cut;
  void Check() const;  // throws arreg::Error naming the field
};

struct ShellTearResult {
  bool torn = false;
  int node = -1;             // the failing node (largest sigma_P+ above the strength)
  double principal_kpa = 0;  // its sigma_P+
  Eigen::Vector3d crack_direction_rest = Eigen::Vector3d::Zero();  // unit, perpendicular to
                                                                   // the principal direction
  ShellCutResult cut;
};

// One fracture step: among the nodes whose sigma_P+ (smoothed per
// options.smoothing) exceeds options.strength_kpa, most stressed first, the
// first that opens fractures along the line through it perpendicular to its
// principal direction (in the rest configuration: the stretch's principal
// directions are those of the rest element, so the crack line is mapped to
// the rest surface exactly, the thesis's fig. 6.14). A node opens when the
// crack duplicates a node (an interior node needs an edge on each side without
// snapping). Call again after re-solving; torn = false when no node fails.
ShellTearResult TearShell(GeneralisedState* state, std::vector<Eigen::Vector3i>* triangles,
                          const ShellMaterial& material, const ShellTearOptions& options);

}  // namespace arreg::mechanics
