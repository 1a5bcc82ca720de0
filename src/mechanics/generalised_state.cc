#include "mechanics/generalised_state.h"

#include <Eigen/LU>
#include <cmath>

#include "core/error.h"
#include "mechanics/so3.h"

namespace arreg::mechanics {

namespace {

void AppendRow(RowMatX3d* m, const Eigen::Vector3d& row) {
  m->conservativeResize(m->rows() + 1, 3);
  m->row(m->rows() - 1) = row.transpose();
}

}  // namespace

int GeneralisedState::AddPointNode(const Eigen::Vector3d& rest_position) {
  AppendRow(&rest_positions_, rest_position);
  AppendRow(&positions_, rest_position);
  AppendRow(&velocities_, Eigen::Vector3d::Zero());
  AppendRow(&angular_velocities_, Eigen::Vector3d::Zero());
  rest_rotations_.push_back(Eigen::Matrix3d::Identity());
  rotations_.push_back(Eigen::Matrix3d::Identity());
  is_frame_.push_back(0);
  fixed_translation_.push_back(0);
  fixed_rotation_.push_back(0);
  dof_offset_.push_back(num_dofs_);
  num_dofs_ += 3;
  ++topology_version_;
  return num_nodes() - 1;
}

int GeneralisedState::AddFrameNode(const Eigen::Vector3d& rest_position,
                                   const Eigen::Matrix3d& rest_rotation) {
  const double orthonormality =
      (rest_rotation.transpose() * rest_rotation - Eigen::Matrix3d::Identity()).norm();
  if (!(orthonormality < 1e-9) || !(std::abs(rest_rotation.determinant() - 1.0) < 1e-9))
    throw Error("", "frame node " + std::to_string(num_nodes()),
                "rest orientation is not a rotation matrix");
  const int node = AddPointNode(rest_position);
  rest_rotations_[node] = rest_rotation;
  rotations_[node] = rest_rotation;
  is_frame_[node] = 1;
  num_dofs_ += 3;
  ++num_frames_;
  return node;
}

int GeneralisedState::DuplicateNode(int node) {
  // Copies: adding a node grows the arrays that references would point into.
  const Eigen::Vector3d rest_position = rest_positions_.row(node).transpose();
  const Eigen::Matrix3d rest_rotation = rest_rotations_[node];
  const int copy =
      is_frame(node) ? AddFrameNode(rest_position, rest_rotation) : AddPointNode(rest_position);
  positions_.row(copy) = positions_.row(node);
  velocities_.row(copy) = velocities_.row(node);
  angular_velocities_.row(copy) = angular_velocities_.row(node);
  rotations_[copy] = rotations_[node];
  SetFixedTranslation(copy, fixed_translation(node));
  SetFixedRotation(copy, fixed_rotation(node));
  return copy;
}

void GeneralisedState::ApplyIncrement(const Eigen::VectorXd& increment) {
  if (increment.size() != num_dofs_)
    throw Error("", "generalised increment",
                std::to_string(increment.size()) + " entries, the state has " +
                    std::to_string(num_dofs_) + " DOFs");
  for (int n = 0; n < num_nodes(); ++n) {
    const int o = dof_offset_[n];
    positions_.row(n) += increment.segment<3>(o).transpose();
    if (is_frame_[n]) rotations_[n] = ExpSO3(increment.segment<3>(o + 3)) * rotations_[n];
  }
}

void GeneralisedState::SetFixedTranslation(int node, bool fixed) {
  fixed_translation_.at(node) = fixed ? 1 : 0;
  ++constraint_version_;
}

void GeneralisedState::SetFixedRotation(int node, bool fixed) {
  fixed_rotation_.at(node) = fixed ? 1 : 0;
  ++constraint_version_;
}

std::vector<char> GeneralisedState::FixedDofMask() const {
  std::vector<char> mask(num_dofs_, 0);
  for (int n = 0; n < num_nodes(); ++n) {
    const int o = dof_offset_[n];
    for (int k = 0; k < 3; ++k) mask[o + k] = fixed_translation_[n];
    if (is_frame_[n])
      for (int k = 3; k < 6; ++k) mask[o + k] = fixed_rotation_[n];
  }
  return mask;
}

}  // namespace arreg::mechanics
