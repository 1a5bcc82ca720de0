// The pipeline's cut application (CutHandler): successive events on one persistent topology
// while the model moves between them, springs and internal structures following.
#include "ar/pipeline/cut_handler.h"

#include <gtest/gtest.h>

#include <cmath>

#include "ar/synth/shapes.h"
#include "core/error.h"
#include "core/mesh_generators.h"
#include "core/mesh_io.h"
#include "core/mesh_ops.h"
#include "cutting/mesh_checks.h"
#include "cutting/structure_split.h"
#include "test_util.h"

namespace arreg::pipeline {
namespace {

struct Model {
  mechanics::MechanicalState state;
  mechanics::SpringEnergy springs;
  FeatureRows rows;
  EmbeddedStructures structures;
  // The members the tests read, by short names.
  std::vector<FeatureView>& features = rows.views;
  RowMatX3d& features_rest = rows.rest_mm;
  mechanics::EmbeddedPoints& feature_embedding = rows.embedding;
  std::vector<SurfaceMesh>& internal = structures.surfaces;
  std::vector<RowMatX3d>& internal_rest = structures.rest_mm;
  std::vector<mechanics::EmbeddedPoints>& internal_embedding = structures.embedding;

  // top_mm: z of the model's top face (features 0.5 mm below it, the sheet 10 mm below).
  explicit Model(const TetMesh& mesh, double top_mm = 20.0) : state(mesh, mechanics::Material()) {
    // Features on a grid under the top face, one spring each.
    for (double x = 2; x < 40; x += 4)
      for (double y = 2; y < 40; y += 4) {
        features_rest.conservativeResize(features_rest.rows() + 1, 3);
        features_rest.row(features_rest.rows() - 1) << x, y, top_mm - 0.5;
      }
    feature_embedding =
        mechanics::EmbeddedPoints::Embed(features_rest, state.rest_positions(), state.tetrahedra());
    for (int r = 0; r < features_rest.rows(); ++r) {
      FeatureView v;
      v.id = r;
      v.spring = springs.Add(feature_embedding[r], features_rest.row(r).transpose(), 100.0);
      v.alive = v.spring_active = true;
      features.push_back(v);
    }
    // One internal structure: a horizontal sheet of triangles at z = 10.
    SurfaceMesh sheet;
    sheet.vertices.resize(0, 3);
    const int n = 9;
    sheet.vertices.resize(static_cast<Eigen::Index>(n) * n, 3);
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j)
        sheet.vertices.row(i * n + j) << 4 + 4 * i, 4 + 4 * j, std::max(top_mm - 9.9, 0.5 * top_mm);
    sheet.faces.resize(static_cast<Eigen::Index>(2) * (n - 1) * (n - 1), 3);
    int f = 0;
    for (int i = 0; i + 1 < n; ++i)
      for (int j = 0; j + 1 < n; ++j) {
        const int a = i * n + j;
        sheet.faces.row(f++) << a, a + n, a + 1;
        sheet.faces.row(f++) << a + 1, a + n, a + n + 1;
      }
    internal.push_back(sheet);
    internal_rest.push_back(sheet.vertices);
    internal_embedding.push_back(mechanics::EmbeddedPoints::Embed(
        sheet.vertices, state.rest_positions(), state.tetrahedra()));
  }

  CutTargets Targets() { return {&state, &springs, &rows, &structures}; }

  // The targets with the internal structures replaced by `*original` (at rest as loaded), which
  // the events split along the crack.
  CutTargets TargetsSplitting(const std::vector<SurfaceMesh>* original) {
    internal = *original;
    internal_rest.clear();
    internal_embedding.clear();
    for (const SurfaceMesh& structure : *original) {
      internal_rest.push_back(structure.vertices);
      internal_embedding.push_back(mechanics::EmbeddedPoints::Embed(
          structure.vertices, state.rest_positions(), state.tetrahedra()));
    }
    structures.original = original;
    return Targets();
  }
};

// The rest mesh after a cut: conforming, positive, with the rest volume v0 kept; returns its
// pieces (elements connected through vertices).
int CheckedPieces(const TetMesh& rest, double v0) {
  const cutting::MeshInvariants inv = cutting::CheckMeshInvariants(rest);
  EXPECT_TRUE(inv.ok()) << inv.ToString();
  EXPECT_NEAR(inv.total_volume, v0, 1e-9 * v0);
  int pieces = 0;
  ConnectedComponents(rest, Adjacency::kVertex, &pieces);
  return pieces;
}

// One event across the whole 40 x 40 x 20 mm block seen from above, the block moved since
// the handler was made. The S that spans the block's depth along the rays cuts it in two;
// with keep_connected (the default) S is cut again shallower (each try from this frame's
// state) and the block stays in one piece, open from the top, the rest volume kept. Both
// configurations.
TEST(CutHandler, KeepConnectedCutsShallowerInsteadOfSplitting) {
  const TetMesh block =
      MakeBoxTetMesh(Eigen::Vector3d(40, 40, 20), Eigen::Vector3i(8, 8, 4), BoxTetSplit::kSix);
  const double v0 = cutting::CheckMeshInvariants(block).total_volume;
  const Eigen::Vector3d eye(20, 20, 200), moved(6, -4, 0);
  const std::vector<Eigen::Vector3d> rest_line = {Eigen::Vector3d(-5, 20.3, 20),
                                                  Eigen::Vector3d(45, 20.3, 20)};
  const std::vector<Eigen::Vector3d> line = {rest_line[0] + moved, rest_line[1] + moved};
  for (int k = 0; k < 4; ++k) {
    const bool keep = k < 2;
    const char* configuration = k % 2 ? "current" : "rest";
    SCOPED_TRACE(::testing::Message()
                 << (keep ? "keep_connected, " : "transection, ") << configuration);
    Model model(block);
    CuttingStageOptions options;
    EXPECT_TRUE(options.keep_connected);
    options.keep_connected = keep;
    options.cut_configuration = ParseCutConfiguration(configuration, "test");
    CutHandler handler(options, model.state);
    model.state.mutable_positions().rowwise() += moved.transpose();
    const CutEvent ev = handler.Apply(0, line, rest_line, eye, model.Targets());
    EXPECT_EQ(ev.configuration, ParseCutConfiguration(configuration, "test"));
    ASSERT_EQ(ev.status, CutEventStatus::kCut) << ev.message;
    const TetMesh rest = model.state.RestMesh();
    EXPECT_EQ(CheckedPieces(rest, v0), keep ? 1 : 2);
    if (keep) {
      EXPECT_GT(ev.depth_fraction, 0.0);
      EXPECT_LT(ev.depth_fraction, 1.0);
    } else {
      EXPECT_EQ(ev.depth_fraction, 1.0);
    }
    // The top is open along the whole line: its 9 vertices on y = 20 (within the on-surface
    // tolerance of S) are duplicated, one copy on each lip; the bottom's only when split.
    auto on_line = [&](double z) {
      int count = 0;
      for (int v = 0; v < rest.num_vertices(); ++v)
        count +=
            std::abs(rest.vertices(v, 2) - z) < 1e-9 && std::abs(rest.vertices(v, 1) - 20.3) < 0.5;
      return count;
    };
    EXPECT_EQ(on_line(20), 18);
    EXPECT_EQ(on_line(0), keep ? 9 : 18);
  }
}

// SplitsTheModel answers whether Apply would reject the event because S splits the model at
// every depth (keep_connected), without changing the topology. A line across the 20 mm block
// seen from above is cut shallower (no); across a slab one element thick, S cuts it through at
// every depth tried (yes, and Apply rejects it; the stem of the synthetic bands is such a slab,
// docs/detection.md "Segments that would split the model"); a line ending inside the slab does
// not split it (no); without keep_connected nothing is refused (no).
TEST(CutHandler, SplitsTheModelForeseesTheRejectionOfKeepConnected) {
  const Eigen::Vector3d eye(20, 20, 200);
  const auto line = [](double z, double x1) {
    return std::vector<Eigen::Vector3d>{Eigen::Vector3d(-5, 20.3, z), Eigen::Vector3d(x1, 20.3, z)};
  };
  struct Case {
    const char* name;
    double height_mm;
    int layers;
    double x1;
    bool keep_connected;
    bool splits;
  };
  for (const Case& c : {Case{"block", 20, 4, 45, true, false}, Case{"slab", 4, 1, 45, true, true},
                        Case{"slab, partial line", 4, 1, 20, true, false},
                        Case{"slab, transection", 4, 1, 45, false, false}}) {
    SCOPED_TRACE(c.name);
    const TetMesh mesh = MakeBoxTetMesh(Eigen::Vector3d(40, 40, c.height_mm),
                                        Eigen::Vector3i(8, 8, c.layers), BoxTetSplit::kSix);
    Model model(mesh, c.height_mm);
    CuttingStageOptions options;
    options.keep_connected = c.keep_connected;
    CutHandler handler(options, model.state);
    const std::vector<Eigen::Vector3d> l = line(c.height_mm, c.x1);
    EXPECT_EQ(handler.SplitsTheModel(l, l, eye, model.state), c.splits);
    EXPECT_EQ(handler.mesh().num_tetrahedra(), mesh.num_tetrahedra());
    EXPECT_EQ(handler.mesh().num_vertices(), mesh.num_vertices());
    const CutEvent ev = handler.Apply(0, l, l, eye, model.Targets());
    EXPECT_EQ(ev.status, c.splits ? CutEventStatus::kRejected : CutEventStatus::kCut) << ev.message;
    // Apply takes the cut SplitsTheModel planned: the same as a handler that was not asked.
    Model fresh(mesh, c.height_mm);
    CutHandler unasked(options, fresh.state);
    const CutEvent same = unasked.Apply(0, l, l, eye, fresh.Targets());
    EXPECT_EQ(same.status, ev.status);
    EXPECT_EQ(same.depth_fraction, ev.depth_fraction);
    EXPECT_EQ(same.new_vertices, ev.new_vertices);
    EXPECT_EQ(same.new_tetrahedra, ev.new_tetrahedra);
    EXPECT_TRUE(fresh.state.rest_positions() == model.state.rest_positions());
    EXPECT_TRUE(fresh.state.tetrahedra() == model.state.tetrahedra());
  }
  // A plan is taken only for the arguments it was made with: asked about a line ending inside
  // the block, then applied with a line across it, the handler cuts the line across it.
  const TetMesh block =
      MakeBoxTetMesh(Eigen::Vector3d(40, 40, 20), Eigen::Vector3i(8, 8, 4), BoxTetSplit::kSix);
  Model a(block), b(block);
  CutHandler asked(CuttingStageOptions(), a.state), unasked(CuttingStageOptions(), b.state);
  const std::vector<Eigen::Vector3d> partial = line(20, 20), across = line(20, 45);
  EXPECT_FALSE(asked.SplitsTheModel(partial, partial, eye, a.state));
  const CutEvent ea = asked.Apply(0, across, across, eye, a.Targets());
  const CutEvent eb = unasked.Apply(0, across, across, eye, b.Targets());
  ASSERT_EQ(ea.status, CutEventStatus::kCut);
  EXPECT_EQ(ea.new_tetrahedra, eb.new_tetrahedra);
  EXPECT_EQ(ea.depth_fraction, eb.depth_fraction);
  EXPECT_TRUE(a.state.rest_positions() == b.state.rest_positions());
}

// An event whose S splits the model at every depth in the rest configuration is rejected, and
// not cut in the current one instead: there only this frame's strip is cut, and where it meets
// the earlier crack off its line (the model has moved since, and the detector's points with
// it) the two stay sewn, so the model held together only by that seam. A slab one element
// thick, cut from its left edge to the middle; the next event's polyline crosses the whole
// slab, its new point 1.5 mm off the crack's line in this frame.
TEST(CutHandler, ASplittingEventIsNotCutInTheCurrentConfigurationInstead) {
  const TetMesh slab =
      MakeBoxTetMesh(Eigen::Vector3d(40, 40, 4), Eigen::Vector3i(8, 8, 1), BoxTetSplit::kSix);
  const double v0 = cutting::CheckMeshInvariants(slab).total_volume;
  const Eigen::Vector3d eye(20, 20, 200);
  Model model(slab, 4.0);
  CutHandler handler(CuttingStageOptions(), model.state);
  const std::vector<Eigen::Vector3d> first = {Eigen::Vector3d(-5, 20.3, 4),
                                              Eigen::Vector3d(20, 20.3, 4)};
  const CutEvent a = handler.Apply(0, first, first, eye, model.Targets());
  ASSERT_EQ(a.status, CutEventStatus::kCut) << a.message;
  std::vector<Eigen::Vector3d> rest = first, current = first;
  rest.push_back(Eigen::Vector3d(45, 20.3, 4));
  current.push_back(Eigen::Vector3d(45, 21.8, 4));
  EXPECT_TRUE(handler.SplitsTheModel(current, rest, eye, model.state));
  const CutEvent b = handler.Apply(1, current, rest, eye, model.Targets());
  EXPECT_EQ(b.status, CutEventStatus::kRejected)
      << (b.configuration ? CutConfigurationName(*b.configuration) : "");
  EXPECT_EQ(CheckedPieces(model.state.RestMesh(), v0), 1);
}

// A cut seen early: its first event's polyline ends 6 mm inside the block's outline on both
// sides, so the S that spans the block's depth along it keeps the block in one piece and was
// applied whole. With foresight (CuttingStageOptions::foresight_mm, r_F in the pipeline) the
// depth is chosen as if the ends reached the outline, where the full depth would split the
// block: the depth keep_connected gives a line across the whole block. The next event, whose
// polyline turns away inside the block (at full depth it would keep the block whole too), goes
// no deeper than the first.
TEST(CutHandler, FirstEventDepthForeseesThePolylineReachingTheOutline) {
  const TetMesh block =
      MakeBoxTetMesh(Eigen::Vector3d(40, 40, 20), Eigen::Vector3i(8, 8, 4), BoxTetSplit::kSix);
  const double v0 = cutting::CheckMeshInvariants(block).total_volume;
  const Eigen::Vector3d eye(20, 20, 200);
  const std::vector<Eigen::Vector3d> across = {Eigen::Vector3d(-5, 20.3, 20),
                                               Eigen::Vector3d(45, 20.3, 20)};
  const std::vector<Eigen::Vector3d> first = {Eigen::Vector3d(6, 20.3, 20),
                                              Eigen::Vector3d(34, 20.3, 20)};
  std::vector<Eigen::Vector3d> second = first;
  second.push_back(Eigen::Vector3d(34.3, 29.7, 20));
  double across_depth = 0;
  {
    Model model(block);
    CutHandler handler(CuttingStageOptions(), model.state);
    const CutEvent ev = handler.Apply(0, across, across, eye, model.Targets());
    ASSERT_EQ(ev.status, CutEventStatus::kCut) << ev.message;
    across_depth = ev.depth_fraction;
    ASSERT_LT(across_depth, 1.0);
  }
  for (const double foresight_mm : {0.0, 10.0}) {
    SCOPED_TRACE(::testing::Message() << "foresight " << foresight_mm << " mm");
    Model model(block);
    CuttingStageOptions options;
    options.foresight_mm = foresight_mm;
    CutHandler handler(options, model.state);
    const CutEvent a = handler.Apply(0, first, first, eye, model.Targets());
    ASSERT_EQ(a.status, CutEventStatus::kCut) << a.message;
    EXPECT_EQ(a.depth_fraction, foresight_mm > 0 ? across_depth : 1.0);
    const CutEvent b = handler.Apply(1, second, second, eye, model.Targets());
    ASSERT_EQ(b.status, CutEventStatus::kCut) << b.message;
    EXPECT_EQ(b.depth_fraction, foresight_mm > 0 ? across_depth : 1.0);
    EXPECT_EQ(CheckedPieces(model.state.RestMesh(), v0), 1);
  }
  CuttingStageOptions bad;
  bad.foresight_mm = -1;
  EXPECT_THROW(bad.Check(), Error);
}

// A cut growing across a 40 x 40 x 20 mm block seen from above, one cut point per event
// (the detector's polyline with a 7 mm look-ahead), while the block moves and bends a little
// between events: every event applies on the persistent topology, the state stays numbered
// like it, the rest volume is kept, the growth stays that of one cut (the crack is not cut
// again), and at the end the block is in two pieces, the sheet inside cut along the line (a
// transection: keep_connected off). Both configurations.
TEST(CutHandler, ProgressiveCutOnAMovingModel) {
  for (const char* configuration : {"rest", "current"}) {
    SCOPED_TRACE(configuration);
    const TetMesh block =
        MakeBoxTetMesh(Eigen::Vector3d(40, 40, 20), Eigen::Vector3i(8, 8, 4), BoxTetSplit::kSix);
    Model model(block);
    const double v0 = cutting::CheckMeshInvariants(block).total_volume;
    CuttingStageOptions options;
    options.keep_connected = false;
    options.cut_configuration = ParseCutConfiguration(configuration, "test");
    CutHandler handler(options, model.state);
    const Eigen::Vector3d eye(20, 20, 200);
    std::vector<Eigen::Vector3d> cut_points, rest_points;  // this frame's, frame 0's
    int applied = 0;
    const int sheet_faces = static_cast<int>(model.internal[0].faces.rows());
    for (int event = 0; event < 12; ++event) {
      // The model moves: a translation and a slight bend, different at every event.
      const double s = 0.3 * event;
      for (int v = 0; v < model.state.num_vertices(); ++v) {
        const Eigen::Vector3d r = model.state.rest_position(v);
        model.state.mutable_positions().row(v) =
            (r + Eigen::Vector3d(s, -0.5 * s, 0.002 * s * (r.x() - 20) * (r.x() - 20) / 10))
                .transpose();
      }
      // Cut points follow the deformed top surface along y ~ 20.
      const double x = -4 + 4.0 * event;
      const Eigen::Vector3d rest_point(x, 20.3 + 0.4 * std::sin(event), 20);
      cut_points.push_back(rest_point + Eigen::Vector3d(s, -0.5 * s, 0));
      rest_points.push_back(rest_point);
      if (cut_points.size() < 2) continue;
      auto extend = [](std::vector<Eigen::Vector3d> line) {
        const Eigen::Vector3d dir = (line.back() - line[line.size() - 2]).normalized();
        line.push_back(line.back() + 7.0 * dir);
        return line;
      };
      const std::vector<Eigen::Vector3d> extended = extend(cut_points);
      const int before = model.state.num_vertices();
      const CutEvent ev = handler.Apply(event, extended, extend(rest_points), eye, model.Targets());
      ASSERT_TRUE(ev.status == CutEventStatus::kCut || ev.status == CutEventStatus::kNoCrossing)
          << "event " << event << ": " << CutEventStatusName(ev.status) << " " << ev.message;
      if (ev.status == CutEventStatus::kCut) ++applied;
      EXPECT_LT(model.state.num_vertices() - before, 120) << "event " << event;
      ASSERT_EQ(model.state.num_vertices(), handler.mesh().num_vertices());
      ASSERT_EQ(model.state.num_tetrahedra(), handler.mesh().num_tetrahedra());
      const cutting::MeshInvariants inv = cutting::CheckMeshInvariants(model.state.RestMesh());
      ASSERT_TRUE(inv.ok()) << "event " << event << ": " << inv.ToString();
      ASSERT_NEAR(inv.total_volume, v0, 1e-9 * v0);
    }
    EXPECT_GE(applied, 9);
    int pieces = 0;
    ConnectedComponents(model.state.RestMesh(), Adjacency::kVertex, &pieces);
    EXPECT_EQ(pieces, 2);
    // Springs near the cut line were removed; those far from it act still.
    int removed_near = 0, kept_far = 0, near = 0, far = 0;
    for (int r = 0; r < model.features_rest.rows(); ++r) {
      const double d = std::abs(model.features_rest(r, 1) - 20.3);
      if (d < 1.5) {
        ++near;
        removed_near += !model.features[r].spring_active;
      } else if (d > 6) {
        ++far;
        kept_far += model.features[r].spring_active;
      }
    }
    EXPECT_EQ(removed_near, near);
    EXPECT_EQ(kept_far, far);
    // The internal sheet lost the triangles across the cut (one row of cells: 16 triangles).
    const int removed = sheet_faces - static_cast<int>(model.internal[0].faces.rows());
    EXPECT_GE(removed, 16);
    EXPECT_LE(removed, 32);
  }
}

// A closed internal structure (a ball inside the block) crossed by a crack grown over several
// events: every event splits the structure as loaded along the whole crack and caps both
// sides, so in the rest frame it stays a closed oriented manifold holding the ball's volume
// and no triangle is deleted; at the end (a transection) its halves follow the block's two
// pieces apart, each closed. With internal_caps off the triangles crossing S are deleted
// (eq. 7.12) and the surface is left open.
TEST(CutHandler, InternalStructureIsSplitAndCappedAlongTheCrack) {
  const TetMesh block =
      MakeBoxTetMesh(Eigen::Vector3d(40, 40, 20), Eigen::Vector3i(8, 8, 4), BoxTetSplit::kSix);
  const SurfaceMesh ball = MakeUvSphere(Eigen::Vector3d(20, 20.6, 10), 6, 12, 24);
  const double v_ball = EnclosedVolume(ball);
  const std::vector<SurfaceMesh> original = {ball};
  for (bool caps : {true, false}) {
    SCOPED_TRACE(caps ? "caps" : "deletion");
    Model model(block);
    CutTargets targets = model.TargetsSplitting(&original);
    CuttingStageOptions options;
    options.keep_connected = false;
    options.internal_caps = caps;
    CutHandler handler(options, model.state);
    std::vector<Eigen::Vector3d> points;
    int cap_faces = 0, removed = 0;
    for (int event = 0; event < 12; ++event) {
      points.emplace_back(-4 + 4.0 * event, 20.3 + 0.4 * std::sin(event), 20);
      if (points.size() < 2) continue;
      std::vector<Eigen::Vector3d> line = points;
      line.push_back(line.back() + 7.0 * (line.back() - line[line.size() - 2]).normalized());
      const CutEvent ev = handler.Apply(event, line, line, Eigen::Vector3d(20, 20, 200), targets);
      ASSERT_TRUE(ev.status == CutEventStatus::kCut || ev.status == CutEventStatus::kNoCrossing)
          << "event " << event << ": " << CutEventStatusName(ev.status) << " " << ev.message;
      cap_faces += ev.internal_cap_faces;
      removed += ev.internal_triangles_removed;
      SurfaceMesh at_rest = model.internal[0];
      at_rest.vertices = model.internal_embedding[0].Positions(model.state.rest_positions(),
                                                               model.state.tetrahedra());
      ASSERT_LT((at_rest.vertices - model.internal_rest[0]).cwiseAbs().maxCoeff(), 1e-9);
      if (!caps) continue;
      ASSERT_TRUE(AnalyzeSurface(at_rest).closed_oriented_manifold()) << "event " << event;
      EXPECT_NEAR(EnclosedVolume(at_rest), v_ball, 1e-9 * v_ball) << "event " << event;
    }
    // The block's piece on the far side of the crack moves 15 mm away.
    int pieces = 0;
    const TetMesh rest = model.state.RestMesh();
    const Eigen::VectorXi piece = ConnectedComponents(rest, Adjacency::kVertex, &pieces);
    ASSERT_EQ(pieces, 2);
    RowMatX3d moved = rest.vertices;
    for (int t = 0; t < rest.num_tetrahedra(); ++t)
      for (int k = 0; k < 4; ++k)
        if (piece(t) == piece(0))
          moved(rest.tetrahedra(t, k), 1) = rest.vertices(rest.tetrahedra(t, k), 1) + 15;
    SurfaceMesh opened = model.internal[0];
    opened.vertices = model.internal_embedding[0].Positions(moved, rest.tetrahedra);
    if (caps) {
      EXPECT_EQ(removed, 0);
      EXPECT_GT(cap_faces, 0);
      int parts = 0;
      const Eigen::VectorXi part = ConnectedComponents(opened, Adjacency::kVertex, &parts);
      ASSERT_EQ(parts, 2);
      double total = 0;
      for (int k = 0; k < 2; ++k) {
        const SurfaceMesh half = testing::FacesWithLabel(opened, part, k);
        EXPECT_TRUE(AnalyzeSurface(half).closed_oriented_manifold());
        EXPECT_GT(EnclosedVolume(half), 0.3 * v_ball);
        total += EnclosedVolume(half);
      }
      EXPECT_NEAR(total, v_ball, 1e-9 * v_ball);
    } else {
      EXPECT_EQ(cap_faces, 0);
      EXPECT_GT(removed, 0);
      EXPECT_FALSE(AnalyzeSurface(opened).closed());
    }
  }
}

// A structure whose split is refused (its faces alternate in orientation, which no halfedge mesh
// holds) loses its triangles crossing S, and with refused_split_dir set the split's inputs are
// written there: the structure as loaded and the model's crack, on which SplitAlongCrack refuses
// again, so the refusal can be reproduced without the video.
TEST(CutHandler, RefusedSplitWritesItsInputs) {
  const TetMesh block =
      MakeBoxTetMesh(Eigen::Vector3d(40, 40, 20), Eigen::Vector3i(8, 8, 4), BoxTetSplit::kSix);
  SurfaceMesh ball = MakeUvSphere(Eigen::Vector3d(20, 20.6, 10), 6, 12, 24);
  for (int f = 1; f < ball.num_faces(); f += 2) std::swap(ball.faces(f, 1), ball.faces(f, 2));
  const std::vector<SurfaceMesh> original = {ball};
  Model model(block);
  CutTargets targets = model.TargetsSplitting(&original);
  CuttingStageOptions options;
  options.refused_split_dir = testing::ScratchDir("refused_split");
  CutHandler handler(options, model.state);
  const std::vector<Eigen::Vector3d> line = {{-4, 20.3, 20}, {20, 20.3, 20}};
  const CutEvent ev = handler.Apply(7, line, line, Eigen::Vector3d(20, 20, 200), targets);
  ASSERT_EQ(ev.status, CutEventStatus::kCut) << ev.message;
  EXPECT_GT(ev.internal_triangles_removed, 0);
  EXPECT_EQ(ev.internal_cap_faces, 0);
  const std::string path = options.refused_split_dir + "/000007_split_0_";
  const SurfaceMesh structure = ReadSurfaceMesh(path + "structure.obj");
  const SurfaceMesh crack = ReadSurfaceMesh(path + "crack.obj");
  EXPECT_EQ(structure.faces, ball.faces);
  EXPECT_EQ(structure.vertices, ball.vertices);  // written with round-trip precision
  const SurfaceMesh model_crack = cutting::CrackSurface(model.state.RestMesh());
  EXPECT_GT(crack.num_faces(), 0);
  EXPECT_EQ(crack.faces, model_crack.faces);
  EXPECT_EQ(crack.vertices, model_crack.vertices);
  EXPECT_THROW(cutting::SplitAlongCrack(structure, crack, 1e-3), arreg::Error);
  // Without the folder the event is the same.
  Model again(block);
  CutTargets again_targets = again.TargetsSplitting(&original);
  CutHandler plain(CuttingStageOptions{}, again.state);
  const CutEvent ev2 = plain.Apply(7, line, line, Eigen::Vector3d(20, 20, 200), again_targets);
  EXPECT_EQ(ev2.internal_triangles_removed, ev.internal_triangles_removed);
}

// A crack grown across a block while the model shears differently between events, as the lips
// of a tear move: in the rest configuration each event cuts the whole polyline there, S of the
// applied part is the surface cut before, and the crack runs on through the block (two pieces
// at the end, keep_connected off). The current configuration cuts each new strip in its own
// frame, where the sheared S meets the last one only along a line.
TEST(CutHandler, RestConfigurationContinuesTheCrackAcrossAShearingModel) {
  const TetMesh block =
      MakeBoxTetMesh(Eigen::Vector3d(40, 40, 20), Eigen::Vector3i(8, 8, 4), BoxTetSplit::kSix);
  const double v0 = cutting::CheckMeshInvariants(block).total_volume;
  const Eigen::Vector3d eye(20, 20, 200);
  int pieces[2] = {0, 0};
  for (int c = 0; c < 2; ++c) {
    const char* configuration = c == 0 ? "rest" : "current";
    SCOPED_TRACE(configuration);
    Model model(block);
    CuttingStageOptions options;
    options.keep_connected = false;
    options.cut_configuration = ParseCutConfiguration(configuration, "test");
    CutHandler handler(options, model.state);
    std::vector<Eigen::Vector3d> current_points, rest_points;
    for (int event = 0; event < 7; ++event) {
      // Shear across the cut line, changing sign from event to event.
      const double shear = 0.15 * (event % 3 - 1);
      auto deform = [&](const Eigen::Vector3d& r) {
        return Eigen::Vector3d(r.x(), r.y() + shear * (r.z() - 10), r.z());
      };
      for (int v = 0; v < model.state.num_vertices(); ++v)
        model.state.mutable_positions().row(v) = deform(model.state.rest_position(v)).transpose();
      const Eigen::Vector3d rest_point(-5 + 8.0 * event, 25.3, 20);
      rest_points.push_back(rest_point);
      current_points.clear();
      for (const Eigen::Vector3d& p : rest_points) current_points.push_back(deform(p));
      if (rest_points.size() < 2) continue;
      const CutEvent ev = handler.Apply(event, current_points, rest_points, eye, model.Targets());
      ASSERT_TRUE(ev.status == CutEventStatus::kCut || ev.status == CutEventStatus::kNoCrossing)
          << "event " << event << ": " << CutEventStatusName(ev.status) << " " << ev.message;
      if (ev.status == CutEventStatus::kCut) {
        EXPECT_EQ(ev.configuration, ParseCutConfiguration(configuration, "test"));
      }
      const cutting::MeshInvariants inv = cutting::CheckMeshInvariants(model.state.RestMesh());
      ASSERT_TRUE(inv.ok()) << "event " << event << ": " << inv.ToString();
      ASSERT_NEAR(inv.total_volume, v0, 1e-9 * v0);
    }
    ConnectedComponents(model.state.RestMesh(), Adjacency::kVertex, &pieces[c]);
  }
  EXPECT_EQ(pieces[0], 2);
  // The limitation the rest configuration removes (measured: one piece).
  EXPECT_EQ(pieces[1], 1);
}

// A cut whose polyline stops half a millimetre short of the block's edge, between two rows of
// 10 mm elements (out of the on-surface tolerance's reach): in the rest configuration the end
// is carried across the outline the camera sees, so the edge opens and the block comes apart
// (keep_connected off); a crack stopping a fraction of an element short keeps its lips sewn.
TEST(CutHandler, CrackEndsNearTheOutlineAreCarriedAcrossIt) {
  const TetMesh block =
      MakeBoxTetMesh(Eigen::Vector3d(40, 40, 20), Eigen::Vector3i(4, 4, 2), BoxTetSplit::kSix);
  const Eigen::Vector3d eye(20, 20, 200);
  const std::vector<Eigen::Vector3d> line = {Eigen::Vector3d(-5, 25.3, 20),
                                             Eigen::Vector3d(39.5, 25.3, 20)};
  int pieces[2] = {0, 0};
  for (int c = 0; c < 2; ++c) {
    Model model(block);
    CuttingStageOptions options;
    options.keep_connected = false;
    options.cut_configuration = c == 0 ? CutConfiguration::kRest : CutConfiguration::kCurrent;
    CutHandler handler(options, model.state);
    const CutEvent ev = handler.Apply(0, line, line, eye, model.Targets());
    ASSERT_EQ(ev.status, CutEventStatus::kCut) << ev.message;
    ConnectedComponents(model.state.RestMesh(), Adjacency::kVertex, &pieces[c]);
    // The event records the line S was extruded from, in rest coordinates: in the rest
    // configuration with its end carried across the outline at x = 40, in the current one the
    // given frame-0 points.
    ASSERT_GE(ev.polyline_rest_mm.size(), line.size());
    EXPECT_EQ(ev.polyline_rest_mm.front(), line.front());
    if (c == 0)
      EXPECT_GT(ev.polyline_rest_mm.back().x(), 40.0);
    else
      EXPECT_EQ(ev.polyline_rest_mm, line);
  }
  EXPECT_EQ(pieces[0], 2);
  EXPECT_EQ(pieces[1], 1);  // the current configuration does not carry the end
}

// Two events on the coarse synthetic band (10 x 10 x 8 mm cells of 5 elements, oblique rays as
// in band-cut-v): the first crack's border extension runs 18.5 mm on, the second turns 22
// degrees away from it at the same point. The elements between the two cracks near the turn
// are cut off as debris (a few mm^3), which once refused the rest configuration (the event
// fell back to the current one and its junction stayed sewn). The debris is now welded: the
// event is cut in the rest configuration, every vertex of a piece below 0.5 % of the volume
// is fixed and follows an element of the band, so an affine motion of the band moves it
// exactly as the same motion would.
TEST(CutHandler, DebrisBetweenTwoCracksIsWeldedToTheBody) {
  synth::BoxUnionMeshOptions coarse;
  coarse.cell_mm = Eigen::Vector3d(10, 10, 8);
  coarse.tets_per_cell = 5;
  const TetMesh band =
      synth::MeshBoxUnion(
          {Eigen::AlignedBox3d(Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(100, 100, 8)),
           Eigen::AlignedBox3d(Eigen::Vector3d(30, -20, 0), Eigen::Vector3d(70, 0, 8))},
          coarse)
          .mesh;
  const double v0 = cutting::CheckMeshInvariants(band).total_volume;
  const Eigen::Vector3d eye(80, 5, 230);
  Model model(band, 8.0);
  CutHandler handler(CuttingStageOptions(), model.state);
  const std::vector<Eigen::Vector3d> first = {
      {44.6, 114.6, 8}, {48.1, 95.4, 8}, {51.5, 77.5, 8}, {55.0, 59.3, 8}};
  const CutEvent e1 = handler.Apply(0, first, first, eye, model.Targets());
  ASSERT_EQ(e1.status, CutEventStatus::kCut) << e1.message;
  EXPECT_EQ(e1.welded_vertices, 0);
  const std::vector<Eigen::Vector3d> second = {
      {44.6, 114.6, 8}, {48.1, 95.4, 8}, {51.5, 77.5, 8}, {48.3, 61.0, 8}, {46.5, 52.1, 8}};
  const CutEvent e2 = handler.Apply(1, second, second, eye, model.Targets());
  ASSERT_EQ(e2.status, CutEventStatus::kCut) << e2.message;
  EXPECT_EQ(e2.configuration, CutConfiguration::kRest);
  EXPECT_GT(e2.welded_vertices, 0);
  EXPECT_EQ(handler.num_welded_vertices(), e2.welded_vertices);
  const cutting::MeshInvariants inv = cutting::CheckMeshInvariants(model.state.RestMesh());
  ASSERT_TRUE(inv.ok()) << inv.ToString();
  EXPECT_NEAR(inv.total_volume, v0, 1e-9 * v0);

  // Every vertex of a piece below 0.5 % of the volume is welded (fixed), and no other.
  const TetMesh rest = model.state.RestMesh();
  int count = 0;
  const Eigen::VectorXi piece = ConnectedComponents(rest, Adjacency::kVertex, &count);
  const Eigen::VectorXd volumes = TetVolumes(rest);
  std::vector<double> volume(count, 0.0);
  for (int t = 0; t < rest.num_tetrahedra(); ++t) volume[piece(t)] += volumes(t);
  std::vector<char> in_debris(model.state.num_vertices(), 0);
  for (int t = 0; t < rest.num_tetrahedra(); ++t)
    for (int a = 0; a < 4; ++a) in_debris[rest.tetrahedra(t, a)] |= volume[piece(t)] < 0.005 * v0;
  int debris_vertices = 0;
  for (int v = 0; v < model.state.num_vertices(); ++v) {
    debris_vertices += in_debris[v];
    EXPECT_EQ(model.state.is_fixed(v), in_debris[v] != 0) << "vertex " << v;
  }
  EXPECT_EQ(debris_vertices, e2.welded_vertices);

  // An affine motion of the body: the welded vertices follow it exactly.
  Eigen::Matrix3d a;
  a << 1.2, -0.3, 0.1, 0.25, 0.9, 0.0, 0.05, 0.1, 1.1;
  const Eigen::Vector3d shift(3, -7, 11);
  RowMatX3d& x = model.state.mutable_positions();
  for (int v = 0; v < model.state.num_vertices(); ++v)
    x.row(v) = in_debris[v] ? Eigen::RowVector3d(1e3, 1e3, 1e3)
                            : (a * model.state.rest_position(v) + shift).transpose();
  handler.FollowWelds(&model.state);
  for (int v = 0; v < model.state.num_vertices(); ++v) {
    if (!in_debris[v]) continue;
    EXPECT_LT((model.state.position(v) - (a * model.state.rest_position(v) + shift)).norm(), 1e-9)
        << "vertex " << v;
  }
}

}  // namespace
}  // namespace arreg::pipeline
