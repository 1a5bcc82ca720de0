#include "mechanics/generalised_terms.h"

#include <Eigen/Eigenvalues>
#include <cmath>
#include <utility>

#include "core/error.h"
#include "mechanics/so3.h"

namespace arreg::mechanics {

std::vector<int> AddTetVertexNodes(const MechanicalState& body, GeneralisedState* state) {
  std::vector<int> vertex_node(body.num_vertices());
  for (int v = 0; v < body.num_vertices(); ++v) {
    const int n = state->AddPointNode(body.rest_position(v));
    state->mutable_positions().row(n) = body.positions().row(v);
    state->mutable_velocities().row(n) = body.velocities().row(v);
    if (body.is_fixed(v)) state->SetFixedTranslation(n, true);
    vertex_node[v] = n;
  }
  return vertex_node;
}

std::vector<NodeInertia> CollectNodeInertia(const GeneralisedState& state,
                                            const std::vector<const InertiaSource*>& sources) {
  std::vector<NodeInertia> inertia(state.num_nodes());
  for (const InertiaSource* s : sources) s->AddNodeInertia(state, &inertia);
  return inertia;
}

// ---------------------------------------------------------------------------
// Terms of a tet body on point nodes.

TetBodyTerm::TetBodyTerm(const MechanicalState* body, std::vector<int> vertex_node,
                         EnergyTerm* term)
    : body_(body), vertex_node_(std::move(vertex_node)), term_(term) {
  ARREG_CHECK_INPUT(static_cast<int>(vertex_node_.size()) == body_->num_vertices(), "",
                    "tet term vertex_node", vertex_node_.size(), " entries for ",
                    body_->num_vertices(), " vertices");
}

void TetBodyTerm::CheckNodes(const GeneralisedState& state) const {
  ARREG_CHECK_INPUT(static_cast<int>(vertex_node_.size()) == body_->num_vertices(), "",
                    "tet term vertex_node", vertex_node_.size(), " entries for ",
                    body_->num_vertices(), " vertices (body changed: rebuild the term)");
  for (const int n : vertex_node_)
    ARREG_CHECK_INPUT(n >= 0 && n < state.num_nodes() && !state.is_frame(n), "",
                      "tet term vertex_node", "node ", n, " is not a point node of the state");
}

RowMatX3d TetBodyTerm::VertexPositions(const GeneralisedState& state) const {
  RowMatX3d x(body_->num_vertices(), 3);
  const RowMatX3d& p = state.positions();
  for (int v = 0; v < x.rows(); ++v) x.row(v) = p.row(vertex_node_[v]);
  return x;
}

void TetBodyTerm::AppendStencils(std::vector<std::vector<int>>* stencils) const {
  const RowMatX4i& tets = body_->tetrahedra();
  for (int t = 0; t < tets.rows(); ++t)
    stencils->push_back({vertex_node_[tets(t, 0)], vertex_node_[tets(t, 1)],
                         vertex_node_[tets(t, 2)], vertex_node_[tets(t, 3)]});
}

void TetBodyTerm::Update(const GeneralisedState& state) {
  CheckNodes(state);
  term_->Update(*body_, VertexPositions(state));
}

double TetBodyTerm::Value(const GeneralisedState& state) const {
  return term_->Value(*body_, VertexPositions(state));
}

void TetBodyTerm::AddGradient(const GeneralisedState& state, Eigen::VectorXd* gradient) const {
  RowMatX3d g = RowMatX3d::Zero(body_->num_vertices(), 3);
  term_->AddGradient(*body_, VertexPositions(state), &g);
  for (int v = 0; v < g.rows(); ++v)
    gradient->segment<3>(state.dof_offset(vertex_node_[v])) += g.row(v).transpose();
}

void TetBodyTerm::AddHessian(const GeneralisedState& state, double scale, HessianSink* sink) const {
  if (hessian_version_ != body_->topology_version() ||
      hessian_.num_vertices() != body_->num_vertices()) {
    hessian_ = SystemMatrix(body_->num_vertices(), body_->tetrahedra());
    hessian_version_ = body_->topology_version();
  }
  hessian_.SetZero();
  term_->AddHessian(*body_, VertexPositions(state), scale, &hessian_);
  // Each vertex pair once (the sink adds the transposed block); blocks the term left at
  // zero (a spring's few tetrahedra) are skipped.
  const SparseMatrixd& m = hessian_.matrix();
  const int* outer = m.outerIndexPtr();
  const int* inner = m.innerIndexPtr();
  const double* values = m.valuePtr();
  using BlockMap = Eigen::Map<const Eigen::Matrix3d, 0, Eigen::OuterStride<>>;
  for (int b = 0; b < body_->num_vertices(); ++b) {
    const int stride = hessian_.column_stride(b);
    for (int k = outer[3 * b]; k < outer[3 * b + 1]; k += 3) {
      const int a = inner[k] / 3;
      if (a > b) break;  // rows sorted by vertex
      const BlockMap block(values + k, Eigen::OuterStride<>(stride));
      if (block.cwiseAbs().maxCoeff() == 0) continue;
      sink->AddBlock(vertex_node_[a], vertex_node_[b], block, 1.0);
    }
  }
}

TetElasticityTerm::TetElasticityTerm(const MechanicalState* body, std::vector<int> vertex_node,
                                     const CorotationalOptions& options)
    : TetBodyTerm(body, std::move(vertex_node), &elastic_), elastic_(options) {}

void TetElasticityTerm::AddNodeInertia(const GeneralisedState& state,
                                       std::vector<NodeInertia>* inertia) const {
  CheckNodes(state);
  const Eigen::VectorXd masses = body().LumpedVertexMasses();
  for (int v = 0; v < masses.size(); ++v) (*inertia)[vertex_node()[v]].mass_kg += masses[v];
}

// ---------------------------------------------------------------------------
// Zero-length springs.

namespace {

// Spatial offset s = R r of an anchor on a frame node (r on a point node).
Eigen::Vector3d SpatialOffset(const GeneralisedState& state, const SpringAnchor& anchor) {
  return state.is_frame(anchor.node)
             ? Eigen::Vector3d(state.rotation(anchor.node) * anchor.point_mm)
             : anchor.point_mm;
}

// d p / d(x, phi) of an anchor on its node: [I, -[s]x] (the first 3 columns on a point node).
Eigen::Matrix<double, 3, 6> AnchorJacobian(const GeneralisedState& state,
                                           const SpringAnchor& anchor) {
  Eigen::Matrix<double, 3, 6> j;
  j.leftCols<3>().setIdentity();
  j.rightCols<3>() = state.is_frame(anchor.node)
                         ? Eigen::Matrix3d(-Skew(SpatialOffset(state, anchor)))
                         : Eigen::Matrix3d::Zero();
  return j;
}

// The second-order part of E along phi on an anchor's rotation, G = k (sym(d s^T) - (s . d) I),
// with its negative eigenvalues set to zero when `project` (see the header). In closed form:
// with a = |d||s| and c = s . d, G has the eigenvalues k (a - c)/2 >= 0 along d/|d| + s/|s|,
// -k (a + c)/2 <= 0 along d/|d| - s/|s| and -k c along d x s; the eigen-solver is only needed
// where d and s point the same way (the last two directions degenerate).
Eigen::Matrix3d RotationCurvature(const Eigen::Vector3d& s, const Eigen::Vector3d& d, double k,
                                  bool project) {
  const double c = s.dot(d);
  const Eigen::Matrix3d ds = d * s.transpose();
  Eigen::Matrix3d g = k * (0.5 * (ds + ds.transpose()) - c * Eigen::Matrix3d::Identity());
  const double a = d.norm() * s.norm();
  if (!project || a == 0) return g;
  const Eigen::Vector3d n = d.cross(s);
  if (c > 0 && n.squaredNorm() <= 1e-20 * a * a) {
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(g);
    return eig.eigenvectors() * eig.eigenvalues().cwiseMax(0.0).asDiagonal() *
           eig.eigenvectors().transpose();
  }
  const Eigen::Vector3d u = d / d.norm() - s / s.norm();
  const double negative = -0.5 * k * (a + c);
  if (negative < 0 && u.squaredNorm() > 0) g -= (negative / u.squaredNorm()) * u * u.transpose();
  if (c > 0) g += (k * c / n.squaredNorm()) * n * n.transpose();
  return g;
}

}  // namespace

Eigen::Vector3d ZeroLengthSpringTerm::AnchorPosition(const GeneralisedState& state,
                                                     const SpringAnchor& anchor) {
  if (anchor.node < 0) return anchor.point_mm;
  return state.position(anchor.node) + SpatialOffset(state, anchor);
}

int ZeroLengthSpringTerm::Add(const SpringAnchor& a, const SpringAnchor& b,
                              double stiffness_n_per_m) {
  ARREG_CHECK_INPUT(std::isfinite(stiffness_n_per_m) && stiffness_n_per_m >= 0, "",
                    "spring stiffness", "must be >= 0, got ", stiffness_n_per_m);
  ARREG_CHECK_INPUT(a.node >= 0 || b.node >= 0, "", "spring anchors",
                    "both anchors are fixed points");
  ARREG_CHECK_INPUT(a.node != b.node, "", "spring anchors", "both anchors on node ", a.node);
  ARREG_CHECK_INPUT(a.point_mm.allFinite() && b.point_mm.allFinite(), "", "spring anchors",
                    "non-finite point");
  springs_.push_back({a, b, stiffness_n_per_m, true});
  return size() - 1;
}

void ZeroLengthSpringTerm::CheckId(int id) const {
  ARREG_CHECK_INPUT(id >= 0 && id < size(), "", "spring id", id, " out of range (", size(),
                    " springs)");
}

void ZeroLengthSpringTerm::Remove(int id) {
  CheckId(id);
  springs_[id].active = false;
}

void ZeroLengthSpringTerm::SetFixedPoint(int id, const Eigen::Vector3d& world_mm, bool second) {
  CheckId(id);
  SpringAnchor& anchor = second ? springs_[id].b : springs_[id].a;
  ARREG_CHECK_INPUT(anchor.node < 0, "", "spring anchor", "spring ", id,
                    ": the anchor is on a node, not a fixed point");
  anchor.point_mm = world_mm;
}

void ZeroLengthSpringTerm::SetStiffness(int id, double stiffness_n_per_m) {
  CheckId(id);
  ARREG_CHECK_INPUT(std::isfinite(stiffness_n_per_m) && stiffness_n_per_m >= 0, "",
                    "spring stiffness", "must be >= 0, got ", stiffness_n_per_m);
  springs_[id].stiffness_n_per_m = stiffness_n_per_m;
}

void ZeroLengthSpringTerm::AppendStencils(std::vector<std::vector<int>>* stencils) const {
  for (const Spring& s : springs_) {
    if (s.a.node >= 0 && s.b.node >= 0)
      stencils->push_back({s.a.node, s.b.node});
    else
      stencils->push_back({s.a.node >= 0 ? s.a.node : s.b.node});
  }
}

double ZeroLengthSpringTerm::Value(const GeneralisedState& state) const {
  double e = 0;
  for (const Spring& s : springs_)
    if (s.active)
      e += 0.5 * s.stiffness_n_per_m *
           (AnchorPosition(state, s.a) - AnchorPosition(state, s.b)).squaredNorm();
  return e;
}

void ZeroLengthSpringTerm::AddGradient(const GeneralisedState& state,
                                       Eigen::VectorXd* gradient) const {
  for (const Spring& s : springs_) {
    if (!s.active) continue;
    const Eigen::Vector3d f =
        s.stiffness_n_per_m * (AnchorPosition(state, s.a) - AnchorPosition(state, s.b));
    for (const auto& [anchor, sign] : {std::pair{&s.a, 1.0}, std::pair{&s.b, -1.0}}) {
      if (anchor->node < 0) continue;
      const int o = state.dof_offset(anchor->node);
      gradient->segment<3>(o) += sign * f;
      // dE/dphi = (-[s]x)^T k d = s x (k d).
      if (state.is_frame(anchor->node))
        gradient->segment<3>(o + 3) += sign * SpatialOffset(state, *anchor).cross(f);
    }
  }
}

void ZeroLengthSpringTerm::AddHessian(const GeneralisedState& state, double scale,
                                      HessianSink* sink) const {
  for (const Spring& s : springs_) {
    if (!s.active || s.stiffness_n_per_m == 0) continue;
    const double k = s.stiffness_n_per_m;
    const Eigen::Vector3d d = AnchorPosition(state, s.a) - AnchorPosition(state, s.b);
    // Rows of the spring's anchors on nodes: J (3 x dofs) and the sign of d for each.
    const SpringAnchor* anchors[2];
    double signs[2];
    int count = 0;
    if (s.a.node >= 0) anchors[count] = &s.a, signs[count++] = 1.0;
    if (s.b.node >= 0) anchors[count] = &s.b, signs[count++] = -1.0;
    // Fixed-size blocks (no allocation per spring): dofs x dofs of each pair of anchors.
    Eigen::Matrix<double, 3, 6> jac[2];
    int dofs[2];
    for (int i = 0; i < count; ++i) {
      jac[i] = signs[i] * AnchorJacobian(state, *anchors[i]);
      dofs[i] = state.node_dofs(anchors[i]->node);
    }
    Eigen::Matrix<double, 6, 6> block;
    for (int i = 0; i < count; ++i)
      for (int j = i; j < count; ++j) {
        block.noalias() = k * jac[i].transpose() * jac[j];
        if (i == j && dofs[i] == 6)
          block.bottomRightCorner<3, 3>() +=
              RotationCurvature(SpatialOffset(state, *anchors[i]), signs[i] * d, k, project_psd_);
        sink->AddBlock(anchors[i]->node, anchors[j]->node, block.topLeftCorner(dofs[i], dofs[j]),
                       scale);
      }
  }
}

// ---------------------------------------------------------------------------
// Gravity.

GravityTerm::GravityTerm(const std::vector<NodeInertia>& inertia,
                         const Eigen::Vector3d& gravity_mm_per_s2)
    : gravity_(gravity_mm_per_s2) {
  ARREG_CHECK_INPUT(gravity_.allFinite(), "", "gravity", "non-finite acceleration");
  SetMasses(inertia);
}

void GravityTerm::SetMasses(const std::vector<NodeInertia>& inertia) {
  masses_.resize(static_cast<int>(inertia.size()));
  for (size_t n = 0; n < inertia.size(); ++n) masses_[n] = inertia[n].mass_kg;
}

void GravityTerm::CheckNodes(const GeneralisedState& state) const {
  ARREG_CHECK_INPUT(masses_.size() == state.num_nodes(), "", "gravity masses", masses_.size(),
                    " nodes, the state has ", state.num_nodes(), " (SetMasses after adding nodes)");
}

double GravityTerm::Value(const GeneralisedState& state) const {
  CheckNodes(state);
  return -masses_.dot(state.positions() * gravity_);
}

void GravityTerm::AddGradient(const GeneralisedState& state, Eigen::VectorXd* gradient) const {
  CheckNodes(state);
  for (int n = 0; n < state.num_nodes(); ++n)
    gradient->segment<3>(state.dof_offset(n)) -= masses_[n] * gravity_;
}

}  // namespace arreg::mechanics
