#include "ar/pipeline/cut_handler.h"

#include <limits>
#include <string>

#include "ar/lift/lifting.h"
#include "ar/pipeline/thin_model.h"
#include "core/error.h"
#include "core/log.h"
#include "core/mesh_ops.h"
#include "cutting/cut_extrusion.h"
#include "cutting/cut_surface.h"
#include "cutting/mechanics_update.h"

namespace arreg::pipeline {

CutHandler::CutHandler(const CuttingStageOptions& options, const mechanics::MechanicalState& state)
    : options_(options) {
  options_.Check();
  mesh_ = std::make_unique<cutting::CuttableMesh>(state.RestMesh(), state.positions(),
                                                  state.velocities());
}

CutHandler::~CutHandler() = default;

bool CutHandler::Applied(const Eigen::Vector3d& p) const {
  for (const Eigen::Vector3d& q : applied_points_)
    if ((p - q).squaredNorm() <= 1e-18) return true;
  return false;
}

SurfaceMesh CutHandler::NewPart(const std::vector<Eigen::Vector3d>& polyline_mm,
                                const Eigen::Vector3d& eye_mm,
                                const cutting::CutExtrusionOptions& ext) const {
  SurfaceMesh out;
  out.vertices.resize(0, 3);
  out.faces.resize(0, 3);
  const int n = static_cast<int>(polyline_mm.size());
  std::vector<char> old(n);
  for (int i = 0; i < n; ++i) old[i] = Applied(polyline_mm[i]);
  for (int i = 0; i + 1 < n;) {
    if (old[i] && old[i + 1]) {
      ++i;
      continue;
    }
    // A run of consecutive segments with a new point: extrude it as one strip.
    int j = i + 1;
    while (j + 1 < n && !(old[j] && old[j + 1])) ++j;
    const std::vector<Eigen::Vector3d> run(polyline_mm.begin() + i, polyline_mm.begin() + j + 1);
    bool distinct = false;
    for (const Eigen::Vector3d& p : run) distinct = distinct || (p - run.front()).norm() > 0;
    if (distinct) {
      const SurfaceMesh strip = cutting::ExtrudeCutPolyline(run, eye_mm, ext);
      const int nv = static_cast<int>(out.vertices.rows()), nf = static_cast<int>(out.faces.rows());
      out.vertices.conservativeResize(nv + strip.vertices.rows(), 3);
      out.vertices.bottomRows(strip.vertices.rows()) = strip.vertices;
      out.faces.conservativeResize(nf + strip.faces.rows(), 3);
      out.faces.bottomRows(strip.faces.rows()) = strip.faces.array() + nv;
    }
    i = j;
  }
  return out;
}

namespace {

// Depths of S behind the polyline tried by CuttingStageOptions::keep_connected, as fractions
// of the extent that covers the model.
constexpr double kDepthFractions[] = {1.0, 0.75, 0.5, 0.25};

// An end of the crack this close to the model's outline, in mean rest edge lengths, is
// carried across it: the elements between could not hold a ligament that thin, and a crack
// that stops a fraction of an element short of the border keeps its lips sewn there (a slit
// from the side, its look-ahead ending 0.4 mm inside the band's edge).
constexpr double kBorderSnapEdges = 0.5;

// `line` with each end moved on along its last segment to just beyond the outline of the
// model seen from `eye_mm`, when the outline is within `reach_mm` of it (kBorderSnapEdges edge
// lengths for the crack's ends, r_F for the foresight of keep_connected).
// The outline is where the rays from the eye stop hitting the surface `boundary`.
std::vector<Eigen::Vector3d> CarryEndsAcrossTheOutline(std::vector<Eigen::Vector3d> line,
                                                       const Eigen::Vector3d& eye_mm,
                                                       const SurfaceMesh& boundary, double edge_mm,
                                                       double reach_mm) {
  if (line.size() < 2 || edge_mm <= 0) return line;
  lift::TriangleBvh bvh;
  bvh.Build(boundary.vertices, boundary.faces);
  auto over_model = [&](const Eigen::Vector3d& q) {
    Ray ray;
    ray.origin_in_world = eye_mm;
    ray.direction_in_world = (q - eye_mm).normalized();
    lift::RayHit hit;
    return bvh.Intersect(ray, &hit);
  };
  const double step = edge_mm / 8;
  for (int end = 0; end < 2; ++end) {
    Eigen::Vector3d& tip = end == 0 ? line.front() : line.back();
    const Eigen::Vector3d& prev = end == 0 ? line[1] : line[line.size() - 2];
    if ((tip - prev).norm() == 0 || !over_model(tip)) continue;
    const Eigen::Vector3d dir = (tip - prev).normalized();
    for (double d = step; d <= reach_mm + 1e-9; d += step) {
      if (over_model(tip + d * dir)) continue;
      tip += (d + edge_mm / 2) * dir;
      break;
    }
  }
  return line;
}

}  // namespace

// One event's cut as PlanCut finds it; mesh_ holds it when cut.status is kCut.
struct CutHandler::Plan {
  SurfaceMesh s;  // the S cut (or the last one tried)
  cutting::CutChange change;
  cutting::CutSummary cut;
  ModelPieces pieces_after;  // of the cut that applies
  double depth = 0.0;        // of S, as a fraction of the depth that covers the model
  bool in_rest = false;
  bool splits = false;  // the last S tried was refused by keep_connected
  // The polyline S was extruded from, in the rest configuration (CutEvent::polyline_rest_mm).
  std::vector<Eigen::Vector3d> polyline_rest_mm;
};

cutting::CutSummary CutHandler::CutWithRetry(const SurfaceMesh& s, cutting::CutChange* change) {
  const cutting::CutSurface cs{s.vertices, s.faces};
  cutting::CutOptions co;
  co.method = options_.method;
  co.snap_epsilon = options_.snap_epsilon;
  co.on_surface_tolerance = options_.on_surface_tolerance;
  cutting::CutSummary cut = mesh_->Cut(cs, co, change);
  const double exact_tolerance = cutting::CutOptions().on_surface_tolerance;
  // Vertices merged into S can make S touch the boundary in a point (manifold guard); a
  // smaller tolerance may resolve it (a rejected event leaves the mesh unchanged). Going
  // straight to the exact test crossed 265 elements along an earlier crack, whose vertices lie
  // within rounding of a new S that runs along it, instead of merging them.
  constexpr double kSmallestTolerance = 0.01;
  while (cut.status == cutting::CutStatus::kRejected &&
         co.on_surface_tolerance > kSmallestTolerance) {
    co.on_surface_tolerance = std::max(kSmallestTolerance, co.on_surface_tolerance / 2);
    cut = mesh_->Cut(cs, co, change);
  }
  if (cut.status == cutting::CutStatus::kRejected && co.on_surface_tolerance > exact_tolerance) {
    co.on_surface_tolerance = exact_tolerance;
    cut = mesh_->Cut(cs, co, change);
  }
  return cut;
}

CutHandler::Plan CutHandler::PlanCut(const std::vector<Eigen::Vector3d>& polyline_mm,
                                     const std::vector<Eigen::Vector3d>& rest_polyline_mm,
                                     const Eigen::Vector3d& eye_mm,
                                     const mechanics::MechanicalState& state,
                                     const ModelPieces& pieces_before) {
  // In the rest configuration (the frame-0 polyline along the frame-0 rays) S of the applied
  // segments is the same surface as before and lies on the crack, so the whole polyline is
  // cut and the new part continues the crack where the last event left it. In the current
  // configuration (this frame's polyline and rays; the model may have inverted elements,
  // which CuttableMesh subdivides in the rest configuration) only the segments with a point
  // not applied before are cut: the detector keeps its cut points, so a segment between two
  // applied points lies on the crack already, and cutting it again with this frame's S
  // (the model has moved since) would cross the elements along the crack a second time.
  // An event the rest configuration cannot apply, or that would cut off a sliver there (the
  // polyline turned away from an earlier look-ahead, and the two cracks cut off the elements
  // between them), is tried in the current configuration.
  // A cut that is not applied leaves mesh_ unchanged; one that splits the body is undone.
  Plan plan;
  SurfaceMesh& s = plan.s;
  cutting::CutChange& change = plan.change;
  cutting::CutSummary& cut = plan.cut;
  double& depth = plan.depth;
  bool& in_rest = plan.in_rest;
  std::vector<bool> configurations = {false};
  if (options_.cut_configuration == CutConfiguration::kRest) configurations = {true, false};
  // The first event of a cut foresees its polyline reaching the outline where an end is
  // within options_.foresight_mm of it (see CuttingStageOptions::foresight_mm).
  const bool foresight = options_.keep_connected && options_.foresight_mm > 0;
  const double edge_mm = mesh_->mean_rest_edge_length();
  for (bool rest : configurations) {
    in_rest = rest;
    const SurfaceMesh rest_boundary = rest ? ExtractBoundary(state.RestMesh()) : SurfaceMesh();
    const std::vector<Eigen::Vector3d> line =
        rest ? CarryEndsAcrossTheOutline(rest_polyline_mm, eye_mm, rest_boundary, edge_mm,
                                         kBorderSnapEdges * edge_mm)
             : polyline_mm;
    const RowMatX3d& positions = rest ? state.rest_positions() : state.positions();
    mesh_->SetDeformation(positions,
                          rest ? RowMatX3d::Zero(state.num_vertices(), 3) : state.velocities());
    const cutting::CuttableMesh start = *mesh_;  // this configuration, before any attempt
    cutting::CutExtrusionOptions ext =
        cutting::CutExtrusionCovering(line, eye_mm, positions, options_.extrusion_margin_mm);
    const double full_depth = ext.extent_away_from_camera_mm;
    std::vector<Eigen::Vector3d> foreseen;
    if (foresight && rest && applied_points_.empty())
      foreseen = CarryEndsAcrossTheOutline(rest_polyline_mm, eye_mm, rest_boundary, edge_mm,
                                           options_.foresight_mm);
    if (foreseen == line) foreseen.clear();  // no end near the outline: nothing to foresee
    cutting::CutExtrusionOptions foreseen_ext;
    if (!foreseen.empty())
      foreseen_ext =
          cutting::CutExtrusionCovering(foreseen, eye_mm, positions, options_.extrusion_margin_mm);
    const double foreseen_full_depth = foreseen_ext.extent_away_from_camera_mm;
    for (double fraction : kDepthFractions) {
      if (foresight && fraction > depth_of_cut_) continue;
      depth = fraction;
      ext.extent_away_from_camera_mm = depth * full_depth;
      if (!foreseen.empty() && fraction != kDepthFractions[3]) {
        foreseen_ext.extent_away_from_camera_mm = depth * foreseen_full_depth;
        const cutting::CutSummary trial =
            CutWithRetry(cutting::ExtrudeCutPolyline(foreseen, eye_mm, foreseen_ext), &change);
        const bool splits = trial.status == cutting::CutStatus::kCut &&
                            FindPieces(mesh_->RestMesh()).Count() > pieces_before.Count();
        *mesh_ = start;
        if (splits) continue;
      }
      s = rest ? cutting::ExtrudeCutPolyline(line, eye_mm, ext) : NewPart(line, eye_mm, ext);
      plan.polyline_rest_mm = rest ? line : rest_polyline_mm;
      ARREG_CHECK_INPUT(s.faces.rows() > 0, "", "CutHandler::Apply",
                        "every segment of the polyline was applied before");
      cut = CutWithRetry(s, &change);
      plan.splits = false;
      if (cut.status != cutting::CutStatus::kCut) break;
      plan.pieces_after = FindPieces(mesh_->RestMesh());
      if (rest && plan.pieces_after.Slivers() > pieces_before.Slivers()) {
        // The polyline turned away from an earlier look-ahead, and the two cracks cut off
        // the elements between them; this frame's strip (current configuration) may not.
        *mesh_ = start;
        cut.status = cutting::CutStatus::kRejected;
        cut.message = "S cuts off a sliver of the model";
        break;
      }
      if (!options_.keep_connected || plan.pieces_after.Count() <= pieces_before.Count()) break;
      *mesh_ = start;
      cut.status = cutting::CutStatus::kRejected;
      cut.message = "S splits the body at every depth tried (cutting.keep_connected)";
      plan.splits = true;
    }
    if (cut.status == cutting::CutStatus::kCut) break;
    // S splits the model at every depth: the current configuration, which cuts only this
    // frame's strip, would leave the crack sewn where the strips meet and keep the pieces
    // joined there, not because the cut stops short (a false polyline along a stretched band's
    // junction with its stem, refused in the rest configuration, would be cut there). Only a
    // cut the remesher refuses, or a sliver, goes on to it.
    if (rest && plan.splits) break;
  }
  return plan;
}

struct CutHandler::Planned {
  std::vector<Eigen::Vector3d> polyline_mm, rest_polyline_mm;
  Eigen::Vector3d eye_mm;
  RowMatX3d positions, rest_positions, velocities;  // of the state planned on
  cutting::CuttableMesh after;                      // mesh_ with the plan's cut
  Plan plan;

  bool Matches(const std::vector<Eigen::Vector3d>& polyline,
               const std::vector<Eigen::Vector3d>& rest, const Eigen::Vector3d& eye,
               const mechanics::MechanicalState& state) const {
    return polyline == polyline_mm && rest == rest_polyline_mm && eye == eye_mm &&
           state.positions() == positions && state.rest_positions() == rest_positions &&
           state.velocities() == velocities;
  }
};

bool CutHandler::SplitsTheModel(const std::vector<Eigen::Vector3d>& polyline_mm,
                                const std::vector<Eigen::Vector3d>& rest_polyline_mm,
                                const Eigen::Vector3d& eye_mm,
                                const mechanics::MechanicalState& state) {
  if (!options_.keep_connected || rest_polyline_mm.size() != polyline_mm.size() ||
      mesh_->num_vertices() != state.num_vertices() ||
      mesh_->num_tetrahedra() != state.num_tetrahedra())
    return false;
  planned_.reset();
  const cutting::CuttableMesh before = *mesh_;
  bool splits = false;
  try {
    Plan plan =
        PlanCut(polyline_mm, rest_polyline_mm, eye_mm, state, FindPieces(before.RestMesh()));
    splits = plan.splits;
    if (plan.cut.status == cutting::CutStatus::kCut)
      planned_ = std::make_unique<Planned>(Planned{polyline_mm, rest_polyline_mm, eye_mm,
                                                   state.positions(), state.rest_positions(),
                                                   state.velocities(), *mesh_, std::move(plan)});
  } catch (const Error&) {
    // Apply reports the failure when the segment comes.
  }
  *mesh_ = before;
  return splits;
}

CutEvent CutHandler::Apply(int frame, const std::vector<Eigen::Vector3d>& polyline_mm,
                           const std::vector<Eigen::Vector3d>& rest_polyline_mm,
                           const Eigen::Vector3d& eye_mm, const CutTargets& t,
                           SurfaceMesh* cut_surface) {
  ARREG_CHECK_INPUT(t.state && t.springs && t.features && t.internal, "", "CutHandler::Apply",
                    "every target must be set");
  mechanics::MechanicalState& state = *t.state;
  CutEvent ev;
  ev.frame = frame;
  ev.polyline_points = static_cast<int>(polyline_mm.size());
  try {
    ARREG_CHECK_INPUT(rest_polyline_mm.size() == polyline_mm.size(), "", "CutHandler::Apply",
                      "the polyline has ", polyline_mm.size(), " points at frame ", frame, " and ",
                      rest_polyline_mm.size(), " at frame 0");
    // The persistent topology is numbered like the state (events are its only changes).
    ARREG_CHECK_INPUT(mesh_->num_vertices() == state.num_vertices() &&
                          mesh_->num_tetrahedra() == state.num_tetrahedra(),
                      "", "CutHandler::Apply", "the state has ", state.num_vertices(),
                      " vertices and ", state.num_tetrahedra(), " elements, the cut topology ",
                      mesh_->num_vertices(), " and ", mesh_->num_tetrahedra());
    const cutting::CuttableMesh before = *mesh_;
    Plan plan;
    if (planned_ && planned_->Matches(polyline_mm, rest_polyline_mm, eye_mm, state)) {
      *mesh_ = std::move(planned_->after);  // SplitsTheModel's cut of these arguments
      plan = std::move(planned_->plan);
    } else {
      plan = PlanCut(polyline_mm, rest_polyline_mm, eye_mm, state, FindPieces(before.RestMesh()));
    }
    planned_.reset();
    const SurfaceMesh& s = plan.s;
    const cutting::CutSummary& cut = plan.cut;
    const double depth = plan.depth;
    const bool in_rest = plan.in_rest;
    ev.message = cut.message;
    if (cut.status == cutting::CutStatus::kCut) {
      ev.status = CutEventStatus::kCut;
      ev.depth_fraction = depth;
      if (in_rest && applied_points_.empty()) depth_of_cut_ = depth;
      ev.configuration = in_rest ? CutConfiguration::kRest : CutConfiguration::kCurrent;
      ev.polyline_rest_mm = plan.polyline_rest_mm;
      const int v_before = state.num_vertices(), t_before = state.num_tetrahedra();
      std::vector<int> new_elements;
      try {
        // Throws only for elements of non-positive rest volume, which the cutter never makes.
        new_elements = cutting::ApplyCutChange(plan.change, &state);
      } catch (const Error&) {
        *mesh_ = before;
        throw;
      }
      if (t.curved)
        t.curved->FollowCut(plan.change, mesh_->tetrahedra(), mesh_->rest_positions(), &state);
      const TetMesh rest = state.RestMesh();  // after the cut
      FollowCut(plan.change, new_elements, rest, s, in_rest, mesh_->mean_rest_edge_length(),
                options_, t, &ev);
      applied_points_.insert(applied_points_.end(), polyline_mm.begin(), polyline_mm.end());
      // The state is numbered like mesh_, so the pieces found there are the state's.
      ev.welded_vertices = welds_.Weld(plan.pieces_after, rest, &state);
      ev.new_vertices = state.num_vertices() - v_before;
      ev.new_tetrahedra = state.num_tetrahedra() - t_before;
    } else {
      ev.status = cut.status == cutting::CutStatus::kNoCrossing ? CutEventStatus::kNoCrossing
                                                                : CutEventStatus::kRejected;
    }
    if (cut_surface) {
      cutting::CutExtrusionOptions shown = cutting::CutExtrusionCovering(
          polyline_mm, eye_mm, state.positions(), options_.extrusion_margin_mm);
      shown.extent_away_from_camera_mm *= depth;
      *cut_surface = cutting::ExtrudeCutPolyline(polyline_mm, eye_mm, shown);
    }
  } catch (const Error& e) {
    ev.status = CutEventStatus::kFailed;
    ev.message = e.what();
    ev.polyline_rest_mm.clear();
    ARREG_LOG_WARNING("run: frame ", frame, ": cut not applied: ", e.what());
  }
  return ev;
}

}  // namespace arreg::pipeline
