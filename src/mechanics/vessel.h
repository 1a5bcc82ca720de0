// Vessel model: a chain of 6-DOF frames along a centreline skinning the
// material samples of a solid tube (a frame model, frame_model.h, with 1D hat
// weights along the chain), and its separation by a cut.
#pragma once

#include <Eigen/Core>
#include <limits>
#include <memory>
#include <utility>
#include <vector>

#include "mechanics/frame_model.h"
#include "mechanics/frame_shape_functions.h"
#include "mechanics/generalised_state.h"
#include "mechanics/tet_element.h"

namespace arreg::mechanics {

struct VesselOptions {
  double radius_mm = 0;         // tube radius in mm, > 0; default 0 = must be set
  double frame_spacing_mm = 0;  // wanted frame spacing along the arc in mm, > 0; must be set
  // Cross-section quadrature: Gauss-Legendre points along the radius (1 to 3;
  // 2 integrates the second moment pi r^4 / 4 exactly) times equally spaced
  // angles (>= 3, exact for cos^2). Default 2 x 6.
  int radial_points = 2;
  int angular_points = 6;
  FrameModelOptions model;  // passed to the FrameModel; default projected Hessian
  void Check() const;
};

// Frame i of the chain stands for the state's node frame_nodes[i]. Element e
// joins frames elements[e] (a, b); its samples sit on the cross-section at the
// middle of the chord a-b and see only a and b, with the hat weights
// w_b = (X - x_a0) . t / L, w_a = 1 - w_b (t the chord direction, L its
// length). One cross-section per element is reduced integration along the
// axis: the shear strain is taken at the middle, where linear frames give it
// exactly, so slender vessels do not lock in shear.
//
// The cross-sections are rigid (the samples move with the frames' rigid
// motions), so lateral contraction is prevented: the axial and bending
// stiffness use lambda + 2 mu, which equals E for nu = 0. Give the vessel
// nu = 0 (or E (1 + nu)(1 - 2 nu)/(1 - nu)) for the beam stiffness E I.
struct Vessel {
  std::vector<int> frame_nodes;           // state node of each chain frame
  std::vector<Eigen::Vector2i> elements;  // chain frames (a, b) of each element
  std::vector<FrameSample> samples;       // frames: chain frame indices
  std::vector<int> sample_element;        // element of each sample
  Material material;
  VesselOptions options;
  std::unique_ptr<FrameModel> model;  // over frame_nodes and samples; rebuilt by a cut

  // Rebuilds `model` from the frames and samples (after they changed).
  void Rebuild(const GeneralisedState& state);
};

// Frames at equal arc-length steps along the polyline `centreline` (#P x 3,
// mm; ceil(length / spacing) elements, the ends on the polyline's ends), rest
// rotations with z along the tangent (mean of the adjacent chords) and x, y
// carried along by parallel transport (the minimal rotation between
// consecutive tangents), added to `state` as frame nodes. Throws arreg::Error
// for fewer than 2 points, a zero-length chord, or bad options/material.
Vessel MakeVessel(const RowMatX3d& centreline, const Material& material,
                  const VesselOptions& options, GeneralisedState* state);

// A cut surface; a plane is enough for a vessel (a cut crosses it only once
// per branch at the scale of one element). Only crossings within radius_mm of
// `point` count (a scissor cut of finite extent); default infinite.
struct VesselCutPlane {
  Eigen::Vector3d point = Eigen::Vector3d::Zero();    // mm
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  // any length > 0
  double radius_mm = std::numeric_limits<double>::infinity();
};

struct VesselCutResult {
  // (old state node, new state node) of each duplicated frame.
  std::vector<std::pair<int, int>> duplicated;
  std::vector<int> crossed_elements;  // elements whose chord the plane crosses
};

// Separates the vessel where the plane crosses a chord (current positions of
// the frame nodes; a frame on the plane counts as on the normal's negative
// side). For each crossed element (a, b) the frame nearer the plane is
// duplicated (same rest and current position, rotation, velocities and fixed
// flags) and the elements joining it to the other side are re-skinned to the
// copy, so no sample couples the two sides and no material is lost; the cut
// moves to that frame (at most half an element from the plane). When that
// frame is a free end (no element on its own side) the vessel is already open
// there and nothing changes, so repeating a cut is a no-op. Rebuilds
// vessel->model when a frame was duplicated (terms holding the old model, e.g.
// FrameGravity, must be remade; solvers pick up the new nodes).
VesselCutResult CutVessel(const VesselCutPlane& plane, GeneralisedState* state, Vessel* vessel);

}  // namespace arreg::mechanics
