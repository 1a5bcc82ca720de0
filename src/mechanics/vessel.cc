#include "mechanics/vessel.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <string>

#include "core/error.h"

namespace arreg::mechanics {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Minimal rotation taking unit vector a to unit vector b (parallel transport).
Eigen::Matrix3d RotationBetween(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return Eigen::Quaterniond::FromTwoVectors(a, b).toRotationMatrix();
}

// Any unit vector perpendicular to t.
Eigen::Vector3d Perpendicular(const Eigen::Vector3d& t) {
  const Eigen::Vector3d helper =
      std::abs(t.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  return t.cross(helper).normalized();
}

}  // namespace

void VesselOptions::Check() const {
  if (!(radius_mm > 0) || !std::isfinite(radius_mm))
    throw Error("", "radius_mm", "vessel radius must be positive and finite");
  if (!(frame_spacing_mm > 0) || !std::isfinite(frame_spacing_mm))
    throw Error("", "frame_spacing_mm", "frame spacing must be positive and finite");
  if (radial_points < 1 || radial_points > 3)
    throw Error("", "radial_points", "1 to 3 radial points");
  if (angular_points < 3) throw Error("", "angular_points", "at least 3 angular points");
}

void Vessel::Rebuild(const GeneralisedState& state) {
  model = std::make_unique<FrameModel>(state, frame_nodes, samples, material, options.model);
}

Vessel MakeVessel(const RowMatX3d& centreline, const Material& material,
                  const VesselOptions& options, GeneralisedState* state) {
  options.Check();
  material.Check();
  const int num_points = static_cast<int>(centreline.rows());
  if (num_points < 2) throw Error("", "centreline", "at least 2 points");
  std::vector<double> arc(num_points, 0.0);
  for (int p = 1; p < num_points; ++p) {
    const double chord = (centreline.row(p) - centreline.row(p - 1)).norm();
    if (!(chord > 0) || !std::isfinite(chord))
      throw Error("", "centreline",
                  "zero-length or non-finite chord at point " + std::to_string(p));
    arc[p] = arc[p - 1] + chord;
  }
  const double length = arc.back();
  const int num_elements =
      std::max(1, static_cast<int>(std::ceil(length / options.frame_spacing_mm - 1e-9)));
  const int num_frames = num_elements + 1;

  // Frame positions at equal arc-length steps on the polyline.
  std::vector<Eigen::Vector3d> x(num_frames);
  int p = 0;
  for (int i = 0; i < num_frames; ++i) {
    const double s = length * i / num_elements;
    while (p < num_points - 2 && arc[p + 1] < s) ++p;
    const double u = std::clamp((s - arc[p]) / (arc[p + 1] - arc[p]), 0.0, 1.0);
    x[i] = ((1 - u) * centreline.row(p) + u * centreline.row(p + 1)).transpose();
  }
  std::vector<Eigen::Vector3d> chord(num_elements);
  for (int e = 0; e < num_elements; ++e) {
    chord[e] = x[e + 1] - x[e];
    if (!(chord[e].norm() > 1e-9 * length))
      throw Error("", "centreline", "two frames coincide (the polyline folds back)");
    chord[e].normalize();
  }
  // Tangents (mean of the adjacent chords) and parallel-transported axes.
  std::vector<Eigen::Matrix3d> rotation(num_frames);
  Eigen::Vector3d previous_t = chord[0], u_axis = Perpendicular(chord[0]);
  for (int i = 0; i < num_frames; ++i) {
    Eigen::Vector3d t = i == 0              ? chord[0]
                        : i == num_elements ? chord[num_elements - 1]
                                            : (chord[i - 1] + chord[i]);
    if (!(t.norm() > 1e-9)) throw Error("", "centreline", "the polyline turns back on itself");
    t.normalize();
    u_axis = RotationBetween(previous_t, t) * u_axis;
    u_axis = (u_axis - u_axis.dot(t) * t).normalized();
    rotation[i].col(0) = u_axis;
    rotation[i].col(1) = t.cross(u_axis);
    rotation[i].col(2) = t;
    previous_t = t;
  }

  Vessel vessel;
  vessel.material = material;
  vessel.options = options;
  for (int i = 0; i < num_frames; ++i)
    vessel.frame_nodes.push_back(state->AddFrameNode(x[i], rotation[i]));

  // Cross-section quadrature: Gauss-Legendre in r on [0, R] (weight r dr),
  // equal angles.
  static const double kNodes[3][3] = {{0, 0, 0},
                                      {-0.5773502691896258, 0.5773502691896258, 0},
                                      {-0.7745966692414834, 0, 0.7745966692414834}};
  static const double kWeights[3][3] = {{2, 0, 0}, {1, 1, 0}, {5.0 / 9, 8.0 / 9, 5.0 / 9}};
  const int nr = options.radial_points, na = options.angular_points;
  const double radius = options.radius_mm;
  for (int e = 0; e < num_elements; ++e) {
    vessel.elements.emplace_back(e, e + 1);
    const double element_length = (x[e + 1] - x[e]).norm();
    const Eigen::Vector3d t = chord[e];
    const Eigen::Vector3d u = (rotation[e].col(0) - rotation[e].col(0).dot(t) * t).normalized();
    const Eigen::Vector3d v = t.cross(u);
    const Eigen::Vector3d centre = 0.5 * (x[e] + x[e + 1]);
    for (int k = 0; k < nr; ++k) {
      const double r = 0.5 * radius * (1 + kNodes[nr - 1][k]);
      const double radial_weight = 0.5 * radius * kWeights[nr - 1][k] * r;  // int r dr
      for (int a = 0; a < na; ++a) {
        const double angle = 2 * kPi * (a + 0.5 * k) / na;  // rings staggered
        FrameSample sample;
        sample.rest_position = centre + r * (std::cos(angle) * u + std::sin(angle) * v);
        sample.volume_mm3 = element_length * radial_weight * 2 * kPi / na;
        const double wb = (sample.rest_position - x[e]).dot(t) / element_length;
        sample.frames = {e, e + 1};
        sample.weights = {1 - wb, wb};
        sample.weight_gradients = {-t / element_length, t / element_length};
        vessel.samples.push_back(sample);
        vessel.sample_element.push_back(e);
      }
    }
  }
  vessel.Rebuild(*state);
  return vessel;
}

VesselCutResult CutVessel(const VesselCutPlane& plane, GeneralisedState* state, Vessel* vessel) {
  if (!(plane.normal.norm() > 0)) throw Error("", "normal", "cut plane normal must be non-zero");
  const Eigen::Vector3d n = plane.normal.normalized();
  auto distance = [&](int frame) {
    return (state->position(vessel->frame_nodes[frame]) - plane.point).dot(n);
  };
  auto side = [&](int frame) { return distance(frame) > 0; };
  VesselCutResult result;
  const int num_elements = static_cast<int>(vessel->elements.size());
  for (int e = 0; e < num_elements; ++e) {
    const int a = vessel->elements[e][0], b = vessel->elements[e][1];
    const double da = distance(a), db = distance(b);
    if (side(a) == side(b)) continue;
    const Eigen::Vector3d crossing =
        state->position(vessel->frame_nodes[a]) +
        da / (da - db) *
            (state->position(vessel->frame_nodes[b]) - state->position(vessel->frame_nodes[a]));
    if ((crossing - plane.point).norm() > plane.radius_mm) continue;
    result.crossed_elements.push_back(e);
    // The frame nearer the plane is duplicated when it keeps an element on
    // its own side; otherwise it is a free end, the vessel is already open
    // within half an element of the plane (e.g. a repeated cut) and nothing
    // changes.
    const int j = std::abs(db) < std::abs(da) ? b : a;
    std::vector<int> same_side, other_side;
    for (int f = 0; f < static_cast<int>(vessel->elements.size()); ++f) {
      const Eigen::Vector2i& el = vessel->elements[f];
      if (el[0] != j && el[1] != j) continue;
      const int other = el[0] == j ? el[1] : el[0];
      (side(other) == side(j) ? same_side : other_side).push_back(f);
    }
    if (same_side.empty()) continue;
    const int node = vessel->frame_nodes[j];
    const int copy_node = state->DuplicateNode(node);
    const int copy = static_cast<int>(vessel->frame_nodes.size());
    vessel->frame_nodes.push_back(copy_node);
    for (int f : other_side)
      for (int c = 0; c < 2; ++c)
        if (vessel->elements[f][c] == j) vessel->elements[f][c] = copy;
    for (size_t s = 0; s < vessel->samples.size(); ++s) {
      if (std::find(other_side.begin(), other_side.end(), vessel->sample_element[s]) ==
          other_side.end())
        continue;
      for (int& frame : vessel->samples[s].frames)
        if (frame == j) frame = copy;
    }
    result.duplicated.emplace_back(node, copy_node);
  }
  if (!result.duplicated.empty()) vessel->Rebuild(*state);
  return result;
}

}  // namespace arreg::mechanics
