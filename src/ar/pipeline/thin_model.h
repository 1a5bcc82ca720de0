// Thin structures (shells and vessels of the scene, docs/scene-format.md) in the mechanics
// stage of `arreg run`: one generalised system (mechanics/generalised_*.h) holding the organ's
// tetrahedra, the Bezier shells, the vessels' frame chains and the springs that pull them
// (image features) or tie them (to the organ, between vessel branches), advanced per video
// frame by GeneralisedImplicitEuler. docs/pipeline.md, "Thin structures".
#pragma once

#include <Eigen/Core>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/mesh.h"
#include "core/scene.h"
#include "cutting/quadratic_cutter.h"
#include "cutting/tet_cutter.h"
#include "mechanics/bernstein_tet.h"
#include "mechanics/bezier_shell.h"
#include "mechanics/curved_tet.h"
#include "mechanics/elastic_energy.h"
#include "mechanics/embedding.h"
#include "mechanics/generalised_solver.h"
#include "mechanics/generalised_terms.h"
#include "mechanics/high_order_mesh.h"
#include "mechanics/mechanical_state.h"
#include "mechanics/shell_cutting.h"
#include "mechanics/shell_mapping.h"
#include "mechanics/spring_energy.h"
#include "mechanics/vessel.h"

namespace arreg::pipeline {

// One thin structure as loaded for frame 0: world frame, millimetres.
struct LoadedThin {
  ThinStructure spec;  // the scene's entry
  // Shell: mid-surface vertices and triangles; vessel: centreline vertices and its segments.
  RowMatX3d vertices;
  RowMatX3i triangles;
  std::vector<Eigen::Vector2i> segments;
  std::optional<SurfaceMesh> visual;  // shell's visual_mesh, when given
};
// Mesh-file coordinates to the world: scaled by the scene's mm_per_unit, then world_from_model.
RowMatX3d PlaceInWorld(const RowMatX3d& points, const Scene& scene);
// The scene's tissue parameters as the mechanics module's material.
mechanics::Material ToMechanicsMaterial(const Material& m);

// Reads the scene's thin structures (meshes scaled by mm_per_unit, world_from_model applied).
// Throws arreg::Error naming the mesh file or the scene key (fixed vertex out of range, a
// centreline that is not a tree, a shell with a negative Poisson ratio).
std::vector<LoadedThin> LoadThinStructures(const Scene& scene);
// The centreline OBJ of a vessel: `v x y z` and `l i j ...` lines (1-based, negative =
// relative); other lines are ignored. Throws arreg::Error naming the file and line.
void ReadCentreline(const std::string& path, RowMatX3d* vertices,
                    std::vector<Eigen::Vector2i>* segments);

// What the organ's solid model contributes to the generalised system. Today the linear
// corotational tetrahedra (LinearTetTerms); a higher-order model (mechanics/bernstein_tet.h)
// plugs in by implementing the same calls.
class SolidTerms {
 public:
  virtual ~SolidTerms() = default;
  // Makes the state's nodes and the terms follow `body`: a node per body vertex (new ones
  // after a cut), terms rebuilt when the body's topology changed, current positions,
  // velocities and fixed flags copied in. Returns true when nodes or terms changed.
  virtual bool Sync(const mechanics::MechanicalState& body, mechanics::GeneralisedState* state) = 0;
  // Copies the nodes' positions and velocities back into the body.
  virtual void CopyBack(const mechanics::GeneralisedState& state,
                        mechanics::MechanicalState* body) const = 0;
  virtual std::vector<mechanics::GeneralisedEnergyTerm*> elastic() = 0;  // Rayleigh-damped
  virtual std::vector<mechanics::GeneralisedEnergyTerm*> others() = 0;   // feature springs ...
  virtual std::vector<const mechanics::InertiaSource*> inertia() const = 0;
  virtual const std::vector<int>& vertex_node() const = 0;  // body vertex -> state node
};

// Linear corotational tetrahedra (TetElasticityTerm) and the body's feature springs
// (SpringEnergy with embedded anchors, through TetBodyTerm).
class LinearTetTerms : public SolidTerms {
 public:
  // `springs` must outlive this.
  LinearTetTerms(const mechanics::CorotationalOptions& options, mechanics::SpringEnergy* springs);
  bool Sync(const mechanics::MechanicalState& body, mechanics::GeneralisedState* state) override;
  void CopyBack(const mechanics::GeneralisedState& state,
                mechanics::MechanicalState* body) const override;
  std::vector<mechanics::GeneralisedEnergyTerm*> elastic() override;
  std::vector<mechanics::GeneralisedEnergyTerm*> others() override;
  std::vector<const mechanics::InertiaSource*> inertia() const override;
  const std::vector<int>& vertex_node() const override { return vertex_node_; }

 private:
  mechanics::CorotationalOptions options_;
  mechanics::SpringEnergy* springs_;
  std::vector<int> vertex_node_;
  std::uint64_t body_topology_ = 0;
  std::unique_ptr<mechanics::TetElasticityTerm> elastic_;
  std::unique_ptr<mechanics::TetBodyTerm> springs_term_;
};

// Bernstein-Bezier tetrahedra of degree 2 or 3 (mechanics/bernstein_tet.h, scene key
// model.degree) for the organ: every control point of `mesh` is a state node, the first
// mesh.num_vertices of them the body's vertices (the body mirrors the corner positions,
// which lie on the curved surface); the body's feature springs anchored by the curved map.
// At degree 2 the body's topology changes only through FollowCut (the quadratic remesher's
// control net, docs/quadratic-cutting.md); otherwise Sync throws arreg::Error naming
// "model.degree" when it changed.
class BernsteinTetTerms : public SolidTerms {
 public:
  // `mesh`: the body's rest mesh raised to the degree (its elements in the body's
  // tetrahedron order, its first nodes the body's vertices). `springs` must outlive this.
  BernsteinTetTerms(mechanics::HighOrderTetMesh mesh, const mechanics::BernsteinTetOptions& options,
                    mechanics::SpringEnergy* springs);
  bool Sync(const mechanics::MechanicalState& body, mechanics::GeneralisedState* state) override;
  void CopyBack(const mechanics::GeneralisedState& state,
                mechanics::MechanicalState* body) const override;
  std::vector<mechanics::GeneralisedEnergyTerm*> elastic() override;
  std::vector<mechanics::GeneralisedEnergyTerm*> others() override;
  std::vector<const mechanics::InertiaSource*> inertia() const override;
  const std::vector<int>& vertex_node() const override { return vertex_node_; }

  // Degree 2: follows a cut of the body's corner mesh. `change` is the event the body took
  // (ApplyCutChange), `tetrahedra` and `reference` the cutter's elements and rest positions
  // after it (the reference space of docs/quadratic-cutting.md). New control points go on the
  // old elements' maps, the state gets nodes for them (those of removed edges are fixed and
  // left out), the terms are rebuilt at the next Sync, the springs embedded again at their
  // elements' coordinates, and the body's new corners moved onto the curved elements. Throws
  // arreg::Error naming "model.degree" at degree 3, and before the first Sync.
  void FollowCut(const cutting::CutChange& change,
                 const std::vector<std::array<int, 4>>& tetrahedra,
                 const std::vector<Eigen::Vector3d>& reference, mechanics::MechanicalState* body);
  // The number of cuts followed (the curved boundary must be tessellated again after each).
  int cuts_followed() const { return cuts_followed_; }

  const mechanics::HighOrderTetMesh& mesh() const { return mesh_; }
  // Positions of the mesh's control points (#N x 3) in `state`.
  RowMatX3d NodePositions(const mechanics::GeneralisedState& state) const;
  // Current anchor of feature spring `id` (on the curved map of its element).
  Eigen::Vector3d SpringAnchor(const mechanics::GeneralisedState& state, int id) const;

 private:
  // Zero-length springs E = sum k/2 |sum_a w_a x_a - t|^2 over the body's SpringEnergy
  // (targets, stiffness, active flags), each anchor a fixed Bernstein-weighted sum of its
  // element's control points. Exact Hessian (constant).
  class Springs : public mechanics::GeneralisedEnergyTerm {
   public:
    explicit Springs(const BernsteinTetTerms* owner) : owner_(owner) {}
    std::string name() const override { return "springs"; }
    void AppendStencils(std::vector<std::vector<int>>* stencils) const override;
    double Value(const mechanics::GeneralisedState& state) const override;
    void AddGradient(const mechanics::GeneralisedState& state,
                     Eigen::VectorXd* gradient) const override;
    void AddHessian(const mechanics::GeneralisedState& state, double scale,
                    mechanics::HessianSink* sink) const override;

   private:
    const BernsteinTetTerms* owner_;
  };
  // Embeds the springs added since the last call: their rest anchors (the body's rest
  // mesh at the spring's tetrahedron and barycentric coordinates) located in the curved
  // rest mesh by Newton (HighOrderEmbedding).
  void EmbedNewSprings(const mechanics::MechanicalState& body);
  // Fixes the edge and face control points whose spanning corners are all fixed in `body`.
  void FixControlPoints(const mechanics::MechanicalState& body, mechanics::GeneralisedState* state);

  mechanics::HighOrderTetMesh mesh_;
  mechanics::BernsteinTetOptions options_;
  mechanics::SpringEnergy* springs_;
  std::vector<int> node_;         // mesh node -> state node
  std::vector<int> vertex_node_;  // body vertex -> state node (the first mesh nodes)
  int num_vertices_ = -1;
  std::uint64_t body_topology_ = 0;
  std::unique_ptr<mechanics::BernsteinTetTerm> elastic_;
  mechanics::GeneralisedState* state_ = nullptr;  // the state Sync was given
  // Degree 2 after the first cut: the control net following the corner mesh's cuts.
  std::optional<cutting::QuadraticControlNet> net_;
  int cuts_followed_ = 0;
  bool rebuild_ = false;  // FollowCut changed the mesh: the next Sync rebuilds the terms
  Springs springs_term_{this};
  // Per embedded spring: its element's state nodes and Bernstein weights.
  std::vector<std::vector<int>> spring_nodes_;
  std::vector<std::vector<double>> spring_weights_;
};

// Zero-length springs from points on Bezier shell surfaces (an element and barycentric
// coordinates, followed on the element's cubic surface as ShellMapping does) to targets:
// E = sum k/2 |p(q) - t|^2. Gradient exact; Hessian the Gauss-Newton part k J^T J
// (positive semi-definite; the dropped part is the surface's curvature times the spring's
// stretch, small for springs much shorter than the surface's radius of curvature).
class ShellPointSpringTerm : public mechanics::GeneralisedEnergyTerm {
 public:
  struct Spring {
    const mechanics::BezierShell* shell = nullptr;
    mechanics::ShellSurfacePoint point;
    Eigen::Vector3d target = Eigen::Vector3d::Zero();  // mm
    double stiffness_n_per_m = 0;                      // = mN/mm
    bool active = true;
  };
  std::string name() const override { return "shell-feature-springs"; }
  int Add(const Spring& spring);  // returns the id (ids are stable)
  Spring& spring(int id) { return springs_.at(id); }
  const Spring& spring(int id) const { return springs_.at(id); }
  int size() const { return static_cast<int>(springs_.size()); }
  // Current position of the spring's surface point (mm).
  Eigen::Vector3d Anchor(const mechanics::GeneralisedState& state, int id) const;

  void AppendStencils(std::vector<std::vector<int>>* stencils) const override;
  double Value(const mechanics::GeneralisedState& state) const override;
  void AddGradient(const mechanics::GeneralisedState& state,
                   Eigen::VectorXd* gradient) const override;
  void AddHessian(const mechanics::GeneralisedState& state, double scale,
                  mechanics::HessianSink* sink) const override;
  // Drops the points and Jacobians cached for AddGradient and AddHessian.
  void Update(const mechanics::GeneralisedState& state) override;

 private:
  // Position and its Jacobian (3 x 18, the element's 3 corner nodes) of a spring's point.
  void PointAndJacobian(const mechanics::GeneralisedState& state, const Spring& s,
                        Eigen::Vector3d* p, Eigen::Matrix<double, 3, 18>* jacobian) const;
  // Fills the caches below for `state` unless they hold it already: AddGradient and
  // AddHessian at one state need the same points and Jacobians (each a control net and its
  // 30 x 18 derivative).
  void CachePoints(const mechanics::GeneralisedState& state) const;
  std::vector<Spring> springs_;
  mutable std::vector<Eigen::Vector3d> cached_point_;
  mutable std::vector<Eigen::Matrix<double, 3, 18>> cached_jacobian_;
  mutable std::vector<mechanics::ShellSurfacePoint> cached_at_;  // the points they are for
  mutable mechanics::StateSnapshot cached_state_;
};

// Zero-length springs tying a node (a shell node, a vessel frame) to the material point of
// the organ's tetrahedra it was embedded at: E = sum k/2 |sum_a w_a x_{v_a} - x_n|^2, exact
// Hessian (constant). Vertices are state nodes through SolidTerms::vertex_node().
class EmbeddedTieTerm : public mechanics::GeneralisedEnergyTerm {
 public:
  struct Tie {
    int node = -1;
    Eigen::Vector3d rest_mm = Eigen::Vector3d::Zero();  // embedding point in the rest mesh
    mechanics::EmbeddedPoint embedded;
    double stiffness_n_per_m = 0;
  };
  explicit EmbeddedTieTerm(const SolidTerms* solid, const mechanics::MechanicalState* body)
      : solid_(solid), body_(body) {}
  std::string name() const override { return "thin-ties"; }
  void Add(const Tie& tie) { ties_.push_back(tie); }
  int size() const { return static_cast<int>(ties_.size()); }
  // Embeds the ties anew in the body's rest mesh (after a cut of the organ).
  void Reembed();

  void AppendStencils(std::vector<std::vector<int>>* stencils) const override;
  double Value(const mechanics::GeneralisedState& state) const override;
  void AddGradient(const mechanics::GeneralisedState& state,
                   Eigen::VectorXd* gradient) const override;
  void AddHessian(const mechanics::GeneralisedState& state, double scale,
                  mechanics::HessianSink* sink) const override;

 private:
  Eigen::Vector3d Stretch(const mechanics::GeneralisedState& state, const Tie& t) const;
  const SolidTerms* solid_;
  const mechanics::MechanicalState* body_;
  std::vector<Tie> ties_;
};

struct ThinSystemOptions {
  mechanics::GeneralisedImplicitEulerOptions integrator;  // dt, iterations, damping, solver
  mechanics::CorotationalOptions elastic;                 // the organ's tetrahedra
  Eigen::Vector3d gravity_mm_per_s2 = Eigen::Vector3d::Zero();
  // Stiffness of the ties (to the organ, between vessel branches) relative to the tied
  // structure's own stiffness scale E t (shell) or E pi r (vessel) [dimensionless, > 0]:
  // 100 keeps a tie's stretch at about 1 % of the structure's own deformation under the
  // same force. Default 100.
  double tie_stiffness_factor = 100.0;
  void Check() const;  // throws arreg::Error naming the field
};

// What a cut did to the thin structures.
struct ThinCutEvent {
  int shells_cut = 0;         // shells whose elements the cut separated
  int shell_nodes_added = 0;  // inserted and duplicated shell nodes
  int vessels_cut = 0;        // vessels (branches) separated
  int vessel_frames_added = 0;
};

// The generalised system of a run with thin structures. Body vertices are the state's first
// nodes only at construction; use solid().vertex_node().
class ThinSystem {
 public:
  // `body` (the organ; may have no tetrahedra) and `springs` (its feature springs) must
  // outlive this. Throws arreg::Error for bad options or meshes the models reject.
  // `solid`: the organ's model; null for LinearTetTerms (options.elastic, springs).
  ThinSystem(const std::vector<LoadedThin>& thin, const Scene& scene,
             mechanics::MechanicalState* body, mechanics::SpringEnergy* springs,
             const ThinSystemOptions& options, std::unique_ptr<SolidTerms> solid = nullptr);

  int num_shells() const { return static_cast<int>(shells_.size()); }
  int num_vessels() const { return static_cast<int>(vessels_.size()); }
  const std::vector<std::string>& names() const { return names_; }
  const std::vector<Eigen::Vector3d>& colors() const { return colors_; }
  const std::vector<double>& opacities() const { return opacities_; }
  int num_shell_elements() const;

  // Shells' frame-0 mid-surfaces for lifting: triangles over "lift vertices" (the shells'
  // frame-0 nodes, in LiftVertices order), each with its shell and element.
  const RowMatX3i& lift_triangles() const { return lift_triangles_; }
  int num_lift_vertices() const { return static_cast<int>(lift_nodes_.size()); }
  // Current positions of the lift vertices (#lift x 3).
  RowMatX3d LiftVertices() const;
  // Visible area of the shells (both sides count: a sheet is seen from one side) in mm^2, and
  // their volume (area x thickness) in mm^3 and mean Young's modulus weighted by volume (Pa).
  double ShellArea() const;
  double ShellVolume() const;
  double ShellMeanModulusPa() const;

  // A feature spring from the point `point_mm` on lift triangle `lift_triangle` to `target`.
  // Returns its id.
  int AddFeatureSpring(int lift_triangle, const Eigen::Vector3d& point_mm,
                       const Eigen::Vector3d& target_mm, double stiffness_n_per_m);
  void SetFeatureTarget(int id, const Eigen::Vector3d& target_mm);
  void RemoveFeatureSpring(int id);
  Eigen::Vector3d FeatureAnchor(int id) const;
  // Rest position of a feature's surface point (its side after cuts).
  Eigen::Vector3d FeatureRestAnchor(int id) const;

  // One frame: the organ's nodes follow `body` (SolidTerms::Sync), one implicit Euler step of
  // the whole system, positions and velocities back into `body`.
  mechanics::GeneralisedSummary Step(mechanics::MechanicalState* body);
  // The organ's nodes follow `body` now (SolidTerms::Sync): new feature springs are
  // embedded before the next Step (their anchors are read between steps).
  void SyncSolid(const mechanics::MechanicalState* body);

  // Cuts the shells along `polyline_rest` (rest coordinates, world mm) seen along `direction`,
  // and the vessels by the plane through `polyline_current` containing `direction` (current
  // configuration); feature springs, ties and visual surfaces are re-anchored.
  ThinCutEvent Cut(const std::vector<Eigen::Vector3d>& polyline_rest,
                   const std::vector<Eigen::Vector3d>& polyline_current,
                   const Eigen::Vector3d& direction);

  // Current surfaces, one per structure in scene order (world mm): a shell's visual surface
  // (its mid-surface triangles when it has none), a vessel's tube (a ring of kTubeSides
  // vertices per frame, no caps).
  std::vector<SurfaceMesh> Surfaces() const;
  static constexpr int kTubeSides = 10;

  const mechanics::GeneralisedState& state() const { return state_; }
  const SolidTerms& solid() const { return *solid_; }

 private:
  struct Shell {
    std::vector<Eigen::Vector3i> triangles;  // state nodes
    std::unique_ptr<mechanics::BezierShell> term;
    mechanics::ShellMaterial material;
    std::optional<mechanics::ShellMapping> visual;
    RowMatX3i visual_faces;
    int structure = 0;  // index in scene order
  };
  struct VesselPart {
    std::vector<mechanics::Vessel> branches;
    double radius_mm = 0;
    int structure = 0;
  };
  void CollectTerms();

  ThinSystemOptions options_;
  mechanics::MechanicalState* body_;
  std::unique_ptr<SolidTerms> solid_;
  mechanics::GeneralisedState state_;
  std::vector<Shell> shells_;
  std::vector<VesselPart> vessels_;
  std::vector<std::string> names_;
  std::vector<Eigen::Vector3d> colors_;
  std::vector<double> opacities_;
  ShellPointSpringTerm features_;
  std::unique_ptr<EmbeddedTieTerm> ties_;
  mechanics::ZeroLengthSpringTerm joints_;  // vessel branches meeting at a centreline vertex
  std::optional<mechanics::GravityTerm> gravity_;
  mechanics::GeneralisedImplicitEuler integrator_;
  std::vector<mechanics::GeneralisedEnergyTerm*> elastic_terms_, other_terms_;
  std::vector<mechanics::NodeInertia> inertia_;
  std::vector<int> lift_nodes_;
  RowMatX3i lift_triangles_;
  std::vector<std::pair<int, int>> lift_owner_;  // (shell, element at frame 0)
  bool dirty_ = true;                            // terms/inertia to collect again
};

}  // namespace arreg::pipeline
