#include "ar/pipeline/cut_handler.h"

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

// Pieces of the model: elements connected through shared vertices.
int Pieces(const cutting::CuttableMesh& mesh) {
  int count = 0;
  ConnectedComponents(mesh.RestMesh(), Adjacency::kVertex, &count);
  return count;
}

}  // namespace

cutting::CutSummary CutHandler::CutWithRetry(const SurfaceMesh& s, cutting::CutChange* change) {
  const cutting::CutSurface cs{s.vertices, s.faces};
  cutting::CutOptions co;
  co.method = options_.method == "bielser" ? cutting::RemeshMethod::kBielser
                                           : cutting::RemeshMethod::kFlips;
  co.snap_epsilon = options_.snap_epsilon;
  co.on_surface_tolerance = options_.on_surface_tolerance;
  cutting::CutSummary cut = mesh_->Cut(cs, co, change);
  const double exact_tolerance = cutting::CutOptions().on_surface_tolerance;
  if (cut.status == cutting::CutStatus::kRejected && co.on_surface_tolerance > exact_tolerance) {
    // Vertices merged into S can make S touch the boundary in a point (manifold guard);
    // the exact test may resolve it (a rejected event leaves the mesh unchanged).
    co.on_surface_tolerance = exact_tolerance;
    cut = mesh_->Cut(cs, co, change);
  }
  return cut;
}

CutEvent CutHandler::Apply(int frame, const std::vector<Eigen::Vector3d>& polyline_mm,
                           const Eigen::Vector3d& eye_mm, const CutTargets& t,
                           SurfaceMesh* cut_surface) {
  ARREG_CHECK_INPUT(t.state && t.springs && t.features && t.features_rest_mm &&
                        t.feature_embedding && t.internal && t.internal_rest_mm &&
                        t.internal_embedding,
                    "", "CutHandler::Apply", "every target must be set");
  mechanics::MechanicalState& state = *t.state;
  std::vector<FeatureView>& features = *t.features;
  const int nf = static_cast<int>(features.size());
  CutEvent ev;
  ev.frame = frame;
  ev.polyline_points = static_cast<int>(polyline_mm.size());
  try {
    cutting::CutExtrusionOptions ext = cutting::CutExtrusionCovering(
        polyline_mm, eye_mm, state.positions(), options_.extrusion_margin_mm);
    // The persistent topology is numbered like the state (events are its only changes);
    // it takes this frame's deformation, which may have inverted elements (see
    // CuttableMesh: those are subdivided in the rest configuration).
    ARREG_CHECK_INPUT(mesh_->num_vertices() == state.num_vertices() &&
                          mesh_->num_tetrahedra() == state.num_tetrahedra(),
                      "", "CutHandler::Apply", "the state has ", state.num_vertices(),
                      " vertices and ", state.num_tetrahedra(), " elements, the cut topology ",
                      mesh_->num_vertices(), " and ", mesh_->num_tetrahedra());
    mesh_->SetDeformation(state.positions(), state.velocities());
    const cutting::CuttableMesh before = *mesh_;
    const int pieces_before = options_.keep_connected ? Pieces(before) : 0;
    // Only the segments with a point not applied before are cut: the detector keeps its
    // cut points (p^t at insertion), so a segment between two applied points lies on the
    // crack already, and cutting it again with this frame's S (the model has moved since)
    // would cross the elements along the crack a second time.
    // A cut that is not applied leaves mesh_ unchanged; one that splits the body is undone.
    SurfaceMesh s;
    cutting::CutChange change;
    cutting::CutSummary cut;
    const double full_depth = ext.extent_away_from_camera_mm;
    double depth = 0.0;
    for (double fraction : kDepthFractions) {
      depth = fraction;
      ext.extent_away_from_camera_mm = depth * full_depth;
      s = NewPart(polyline_mm, eye_mm, ext);
      ARREG_CHECK_INPUT(s.faces.rows() > 0, "", "CutHandler::Apply",
                        "every segment of the polyline was applied before");
      cut = CutWithRetry(s, &change);
      if (cut.status != cutting::CutStatus::kCut || !options_.keep_connected ||
          Pieces(*mesh_) <= pieces_before)
        break;
      *mesh_ = before;
      cut.status = cutting::CutStatus::kRejected;
      cut.message = "S splits the body at every depth tried (cutting.keep_connected)";
    }
    const cutting::CutSurface cs{s.vertices, s.faces};
    ev.message = cut.message;
    if (cut.status == cutting::CutStatus::kCut) {
      ev.status = "cut";
      ev.depth_fraction = depth;
      const int v_before = state.num_vertices(), t_before = state.num_tetrahedra();
      std::vector<int> new_elements;
      try {
        // Throws only for elements of non-positive rest volume, which the cutter never makes.
        new_elements = cutting::ApplyCutChange(change, &state);
      } catch (const Error&) {
        *mesh_ = before;
        throw;
      }
      cutting::ReembedAfterCut(change, new_elements, state, *t.features_rest_mm,
                               t.feature_embedding);
      for (int r = 0; r < nf; ++r)
        if (features[r].spring >= 0)
          t.springs->SetAnchor(features[r].spring, (*t.feature_embedding)[r]);
      std::vector<SurfaceMesh>& internal = *t.internal;
      for (size_t k = 0; k < internal.size(); ++k) {
        cutting::ReembedAfterCut(change, new_elements, state, (*t.internal_rest_mm)[k],
                                 &(*t.internal_embedding)[k]);
        const RowMatX3d current =
            (*t.internal_embedding)[k].Positions(state.positions(), state.tetrahedra());
        const RowMatX3i kept = cutting::RemoveTrianglesCrossing(current, internal[k].faces, cs);
        ev.internal_triangles_removed += static_cast<int>(internal[k].faces.rows() - kept.rows());
        internal[k].faces = kept;
      }
      RowMatX3d anchors;
      t.feature_embedding->Positions(state.positions(), state.tetrahedra(), &anchors);
      for (int idx : cutting::PointsWithinMargin(s, anchors, options_.spring_margin_mm)) {
        FeatureView& v = features[idx];
        if (!v.spring_active) continue;
        t.springs->Remove(v.spring);
        v.spring_active = false;
        ++ev.springs_removed;
      }
      applied_points_.insert(applied_points_.end(), polyline_mm.begin(), polyline_mm.end());
      ev.new_vertices = state.num_vertices() - v_before;
      ev.new_tetrahedra = state.num_tetrahedra() - t_before;
    } else {
      ev.status = cut.status == cutting::CutStatus::kNoCrossing ? "no-crossing" : "rejected";
    }
    if (cut_surface) *cut_surface = cutting::ExtrudeCutPolyline(polyline_mm, eye_mm, ext);
  } catch (const Error& e) {
    ev.status = "failed";
    ev.message = e.what();
    ARREG_LOG_WARNING("run: frame ", frame, ": cut not applied: ", e.what());
  }
  return ev;
}

}  // namespace arreg::pipeline
