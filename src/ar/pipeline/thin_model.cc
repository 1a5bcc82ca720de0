#include "ar/pipeline/thin_model.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include "core/error.h"
#include "core/mesh_io.h"

namespace arreg::pipeline {

using mechanics::GeneralisedState;

namespace {

// Chains of the centreline graph between vertices of degree != 2 (ends and branch points).
std::vector<std::vector<int>> Branches(int num_vertices, const std::vector<Eigen::Vector2i>& seg,
                                       const std::string& file) {
  std::vector<std::vector<int>> adjacent(num_vertices);
  for (const Eigen::Vector2i& s : seg) {
    adjacent[s[0]].push_back(s[1]);
    adjacent[s[1]].push_back(s[0]);
  }
  std::set<std::pair<int, int>> used;
  auto key = [](int a, int b) { return std::make_pair(std::min(a, b), std::max(a, b)); };
  std::vector<std::vector<int>> branches;
  for (int start = 0; start < num_vertices; ++start) {
    if (adjacent[start].empty() || adjacent[start].size() == 2) continue;
    for (int next : adjacent[start]) {
      if (used.count(key(start, next))) continue;
      std::vector<int> chain = {start};
      int prev = start, cur = next;
      used.insert(key(prev, cur));
      while (adjacent[cur].size() == 2) {
        chain.push_back(cur);
        const int n = adjacent[cur][0] == prev ? adjacent[cur][1] : adjacent[cur][0];
        prev = cur;
        cur = n;
        used.insert(key(prev, cur));
      }
      chain.push_back(cur);
      branches.push_back(chain);
    }
  }
  if (used.size() != std::set<std::pair<int, int>>([&] {
                       std::set<std::pair<int, int>> all;
                       for (const Eigen::Vector2i& s : seg) all.insert(key(s[0], s[1]));
                       return all;
                     }())
                         .size())
    throw Error(file, "l", "the centreline has a closed loop (a vessel tree has none)");
  return branches;
}

}  // namespace

RowMatX3d PlaceInWorld(const RowMatX3d& points, const Scene& scene) {
  RowMatX3d out(points.rows(), 3);
  for (int i = 0; i < points.rows(); ++i)
    out.row(i) =
        (scene.world_from_model * (scene.mm_per_unit * points.row(i).transpose())).transpose();
  return out;
}

mechanics::Material ToMechanicsMaterial(const Material& m) {
  mechanics::Material out;
  out.youngs_modulus_pa = m.youngs_modulus_pa;
  out.poisson_ratio = m.poisson_ratio;
  out.density_kg_per_m3 = m.density_kg_m3;
  return out;
}

void ReadCentreline(const std::string& path, RowMatX3d* vertices,
                    std::vector<Eigen::Vector2i>* segments) {
  std::ifstream in(path);
  if (!in) throw Error(path, "", "cannot open the centreline file");
  std::vector<Eigen::Vector3d> v;
  std::vector<std::vector<long>> lines;
  std::vector<int> line_numbers;
  std::string line;
  int number = 0;
  while (std::getline(in, line)) {
    ++number;
    std::istringstream ss(line);
    std::string tag;
    ss >> tag;
    if (tag == "v") {
      Eigen::Vector3d p;
      if (!(ss >> p.x() >> p.y() >> p.z()) || !p.allFinite())
        throw Error(path, "line " + std::to_string(number), "expected `v x y z`");
      v.push_back(p);
    } else if (tag == "l") {
      std::vector<long> idx;
      std::string token;
      while (ss >> token) {
        try {
          idx.push_back(std::stol(token.substr(0, token.find('/'))));
        } catch (const std::exception&) {
          throw Error(path, "line " + std::to_string(number), "bad vertex index \"" + token + "\"");
        }
      }
      if (idx.size() < 2)
        throw Error(path, "line " + std::to_string(number), "an `l` line needs 2 or more vertices");
      lines.push_back(idx);
      line_numbers.push_back(number);
    }
  }
  vertices->resize(static_cast<int>(v.size()), 3);
  for (size_t i = 0; i < v.size(); ++i) vertices->row(i) = v[i].transpose();
  segments->clear();
  std::set<std::pair<int, int>> seen;
  for (size_t l = 0; l < lines.size(); ++l) {
    std::vector<int> idx;
    for (long i : lines[l]) {
      const long resolved = i > 0 ? i - 1 : static_cast<long>(v.size()) + i;
      if (i == 0 || resolved < 0 || resolved >= static_cast<long>(v.size()))
        throw Error(path, "line " + std::to_string(line_numbers[l]),
                    "vertex index " + std::to_string(i) + " out of range (" +
                        std::to_string(v.size()) + " vertices)");
      idx.push_back(static_cast<int>(resolved));
    }
    for (size_t k = 0; k + 1 < idx.size(); ++k) {
      if (idx[k] == idx[k + 1])
        throw Error(path, "line " + std::to_string(line_numbers[l]), "repeated vertex");
      const auto e = std::make_pair(std::min(idx[k], idx[k + 1]), std::max(idx[k], idx[k + 1]));
      if (seen.insert(e).second) segments->emplace_back(idx[k], idx[k + 1]);
    }
  }
  if (segments->empty()) throw Error(path, "", "no `l` polyline in the centreline file");
}

std::vector<LoadedThin> LoadThinStructures(const Scene& scene) {
  std::vector<LoadedThin> out;
  for (size_t i = 0; i < scene.thin_structures.size(); ++i) {
    const ThinStructure& t = scene.thin_structures[i];
    const std::string key = "thin_structures[" + std::to_string(i) + "]";
    LoadedThin l;
    l.spec = t;
    int num_vertices = 0;
    if (t.type == ThinStructureType::kShell) {
      const SurfaceMesh mesh = ReadSurfaceMesh(t.mesh_path);
      l.vertices = PlaceInWorld(mesh.vertices, scene);
      l.triangles = mesh.faces;
      num_vertices = mesh.num_vertices();
      if (!t.visual_mesh_path.empty()) {
        SurfaceMesh visual = ReadSurfaceMesh(t.visual_mesh_path);
        visual.vertices = PlaceInWorld(visual.vertices, scene);
        visual.normals.resize(0, 3);
        l.visual = std::move(visual);
      }
      ARREG_CHECK_INPUT(
          t.material.poisson_ratio >= 0.0, scene.path, key + ".material.poisson_ratio",
          "a shell needs a Poisson ratio in [0, 0.5), got ", t.material.poisson_ratio);
    } else {
      RowMatX3d v;
      ReadCentreline(t.centreline_path, &v, &l.segments);
      l.vertices = PlaceInWorld(v, scene);
      num_vertices = static_cast<int>(v.rows());
      Branches(num_vertices, l.segments, t.centreline_path);  // rejects loops early
    }
    for (int v : t.fixed_vertices)
      ARREG_CHECK_INPUT(v < num_vertices, scene.path, key + ".fixed_vertices", "index ", v,
                        " >= vertex count ", num_vertices);
    out.push_back(std::move(l));
  }
  return out;
}

// --- LinearTetTerms -----------------------------------------------------------------------

namespace {

// The body's vertex positions, velocities and fixed flags into their state nodes.
void CopyBodyToNodes(const mechanics::MechanicalState& body, const std::vector<int>& vertex_node,
                     GeneralisedState* state) {
  for (int v = 0; v < body.num_vertices(); ++v) {
    const int n = vertex_node[v];
    state->mutable_positions().row(n) = body.positions().row(v);
    state->mutable_velocities().row(n) = body.velocities().row(v);
    if (state->fixed_translation(n) != body.is_fixed(v))
      state->SetFixedTranslation(n, body.is_fixed(v));
  }
}

// The vertex nodes' positions and velocities back into the body.
void CopyNodesToBody(const GeneralisedState& state, const std::vector<int>& vertex_node,
                     mechanics::MechanicalState* body) {
  for (int v = 0; v < body->num_vertices(); ++v) {
    body->mutable_positions().row(v) = state.positions().row(vertex_node[v]);
    body->mutable_velocities().row(v) = state.velocities().row(vertex_node[v]);
  }
}

}  // namespace

LinearTetTerms::LinearTetTerms(const mechanics::CorotationalOptions& options,
                               mechanics::SpringEnergy* springs)
    : options_(options), springs_(springs) {}

bool LinearTetTerms::Sync(const mechanics::MechanicalState& body, GeneralisedState* state) {
  bool changed = false;
  for (int v = static_cast<int>(vertex_node_.size()); v < body.num_vertices(); ++v) {
    vertex_node_.push_back(state->AddPointNode(body.rest_position(v)));
    changed = true;
  }
  if (changed || !elastic_ || body_topology_ != body.topology_version()) {
    // The terms keep per-element data of the body (rest shapes, the springs' tetrahedra).
    elastic_ = std::make_unique<mechanics::TetElasticityTerm>(&body, vertex_node_, options_);
    springs_term_ = std::make_unique<mechanics::TetBodyTerm>(&body, vertex_node_, springs_);
    body_topology_ = body.topology_version();
    changed = true;
  }
  CopyBodyToNodes(body, vertex_node_, state);
  return changed;
}

void LinearTetTerms::CopyBack(const GeneralisedState& state,
                              mechanics::MechanicalState* body) const {
  CopyNodesToBody(state, vertex_node_, body);
}

std::vector<mechanics::GeneralisedEnergyTerm*> LinearTetTerms::elastic() {
  if (!elastic_ || elastic_->body().num_tetrahedra() == 0) return {};
  return {elastic_.get()};
}
std::vector<mechanics::GeneralisedEnergyTerm*> LinearTetTerms::others() {
  if (!springs_term_ || springs_term_->body().num_tetrahedra() == 0) return {};
  return {springs_term_.get()};
}
std::vector<const mechanics::InertiaSource*> LinearTetTerms::inertia() const {
  if (!elastic_ || elastic_->body().num_tetrahedra() == 0) return {};
  return {elastic_.get()};
}

// --- BernsteinTetTerms ----------------------------------------------------------------------

BernsteinTetTerms::BernsteinTetTerms(mechanics::HighOrderTetMesh mesh,
                                     const mechanics::BernsteinTetOptions& options,
                                     mechanics::SpringEnergy* springs)
    : mesh_(std::move(mesh)), options_(options), springs_(springs) {
  options_.Check();
}

bool BernsteinTetTerms::Sync(const mechanics::MechanicalState& body, GeneralisedState* state) {
  bool changed = false;
  state_ = state;
  if (!elastic_) {
    ARREG_CHECK_INPUT(
        body.num_vertices() == mesh_.num_vertices && body.num_tetrahedra() == mesh_.num_elements(),
        "", "model.degree", "the raised mesh has ", mesh_.num_vertices, " vertices and ",
        mesh_.num_elements(), " elements, the body ", body.num_vertices(), " and ",
        body.num_tetrahedra());
    node_ = mechanics::AddHighOrderNodes(mesh_, state);
    vertex_node_.assign(node_.begin(), node_.begin() + mesh_.num_vertices);
    rebuild_ = true;
  }
  if (rebuild_) {
    elastic_ = std::make_unique<mechanics::BernsteinTetTerm>(&mesh_, node_, options_);
    num_vertices_ = body.num_vertices();
    body_topology_ = body.topology_version();
    FixControlPoints(body, state);
    rebuild_ = false;
    changed = true;
  }
  ARREG_CHECK_INPUT(
      body.num_vertices() == num_vertices_ && body.topology_version() == body_topology_, "",
      "model.degree", "the organ's topology changed, and degree 3 elements cannot be cut");
  if (static_cast<int>(spring_nodes_.size()) < springs_->size()) {
    EmbedNewSprings(body);
    changed = true;
  }
  CopyBodyToNodes(body, vertex_node_, state);
  return changed;
}

void BernsteinTetTerms::FixControlPoints(const mechanics::MechanicalState& body,
                                         GeneralisedState* state) {
  // A control point is fixed when every corner spanning it is (an edge between two fixed
  // vertices stays put); the corners follow the body's flags (CopyBodyToNodes).
  const std::vector<std::array<int, 4>> indices = mechanics::BernsteinIndices(mesh_.degree);
  std::vector<char> free(mesh_.num_nodes(), 0);
  for (int e = 0; e < mesh_.num_elements(); ++e)
    for (size_t a = 0; a < indices.size(); ++a)
      for (int i = 0; i < 4; ++i)
        if (indices[a][i] > 0 && !body.is_fixed(mesh_.elements(e, i)))
          free[mesh_.elements(e, a)] = 1;
  for (int n = mesh_.num_vertices; n < mesh_.num_nodes(); ++n)
    state->SetFixedTranslation(node_[n], !free[n]);
}

void BernsteinTetTerms::FollowCut(const cutting::CutChange& change,
                                  const std::vector<std::array<int, 4>>& tetrahedra,
                                  const std::vector<Eigen::Vector3d>& reference,
                                  mechanics::MechanicalState* body) {
  ARREG_CHECK_INPUT(mesh_.degree == 2, "", "model.degree",
                    "the organ's topology changed, and degree 3 elements cannot be cut");
  ARREG_ASSERT(state_ != nullptr && elastic_, "FollowCut before the first Sync");
  // The configuration before the event: the state's (the body took the event already).
  const RowMatX3d x = NodePositions(*state_);
  RowMatX3d v(mesh_.num_nodes(), 3);
  for (int n = 0; n < mesh_.num_nodes(); ++n) v.row(n) = state_->velocities().row(node_[n]);
  if (!net_)
    net_.emplace(mesh_, x, v);
  else
    net_->SetDeformation(x, v);
  cutting::QuadraticCutChange q;
  net_->Follow(tetrahedra, reference, change, &q);
  const mechanics::HighOrderTetMesh mesh = net_->RestMesh();
  const RowMatX3d positions = net_->Positions(), velocities = net_->Velocities();
  std::vector<int> node(mesh.num_nodes(), -1);
  std::vector<char> kept(node_.size(), 0);
  for (size_t n = 0; n < q.node_from_old.size(); ++n)
    if (q.node_from_old[n] >= 0) {
      node[q.node_from_old[n]] = node_[n];
      kept[n] = 1;
    }
  for (int n = 0; n < mesh.num_nodes(); ++n) {
    if (node[n] < 0) node[n] = state_->AddPointNode(mesh.nodes.row(n).transpose());
    state_->mutable_positions().row(node[n]) = positions.row(n);
    state_->mutable_velocities().row(node[n]) = velocities.row(n);
  }
  // Control points of removed edges stay in the state, fixed: no term sees them.
  for (size_t n = 0; n < node_.size(); ++n)
    if (!kept[n]) {
      state_->SetFixedTranslation(node_[n], true);
      state_->mutable_velocities().row(node_[n]).setZero();
    }
  for (int c = mesh_.num_vertices; c < mesh.num_vertices; ++c) {
    body->mutable_positions().row(c) = positions.row(c);
    body->mutable_velocities().row(c) = velocities.row(c);
  }
  mesh_ = mesh;
  node_ = std::move(node);
  vertex_node_.assign(node_.begin(), node_.begin() + mesh_.num_vertices);
  spring_nodes_.clear();
  spring_weights_.clear();
  rebuild_ = true;
  ++cuts_followed_;
}

void BernsteinTetTerms::EmbedNewSprings(const mechanics::MechanicalState& body) {
  const int first = static_cast<int>(spring_nodes_.size());
  if (cuts_followed_ > 0) {
    // After a cut the element and coordinates of the body's anchor are the curved element's
    // (the cut mesh's elements are the body's, numbered alike, and the corner mesh's rest
    // positions are their reference space): no inverse map, and no doubt about the side of a
    // crack a spring is on.
    for (int id = first; id < springs_->size(); ++id) {
      const mechanics::EmbeddedPoint& a = springs_->spring(id).anchor;
      if (a.tet < 0) {  // not embedded (a removed spring): no nodes
        spring_nodes_.emplace_back();
        spring_weights_.emplace_back();
        continue;
      }
      const Eigen::VectorXd w = mechanics::BernsteinValues(mesh_.degree, a.barycentric);
      std::vector<int> nodes(w.size());
      for (int k = 0; k < w.size(); ++k) nodes[k] = node_[mesh_.elements(a.tet, k)];
      spring_nodes_.push_back(std::move(nodes));
      spring_weights_.emplace_back(w.data(), w.data() + w.size());
    }
    return;
  }
  RowMatX3d rest(springs_->size() - first, 3);
  for (int id = first; id < springs_->size(); ++id) {
    const mechanics::EmbeddedPoint& a = springs_->spring(id).anchor;
    Eigen::Vector3d p = Eigen::Vector3d::Zero();
    for (int i = 0; i < 4; ++i)
      p += a.barycentric[i] * body.rest_position(body.tetrahedra()(a.tet, i)).transpose();
    rest.row(id - first) = p.transpose();
  }
  const mechanics::HighOrderEmbedding embedded =
      mechanics::HighOrderEmbedding::Embed(mesh_, mesh_.nodes, rest);
  for (int k = 0; k < embedded.size(); ++k) {
    const Eigen::VectorXd w = mechanics::BernsteinValues(mesh_.degree, embedded.barycentric(k));
    std::vector<int> nodes(w.size());
    for (int a = 0; a < w.size(); ++a) nodes[a] = node_[mesh_.elements(embedded.element(k), a)];
    spring_nodes_.push_back(std::move(nodes));
    spring_weights_.emplace_back(w.data(), w.data() + w.size());
  }
}

void BernsteinTetTerms::CopyBack(const GeneralisedState& state,
                                 mechanics::MechanicalState* body) const {
  CopyNodesToBody(state, vertex_node_, body);
}

std::vector<mechanics::GeneralisedEnergyTerm*> BernsteinTetTerms::elastic() {
  if (!elastic_) return {};
  return {elastic_.get()};
}
std::vector<mechanics::GeneralisedEnergyTerm*> BernsteinTetTerms::others() {
  return {&springs_term_};
}
std::vector<const mechanics::InertiaSource*> BernsteinTetTerms::inertia() const {
  if (!elastic_) return {};
  return {elastic_.get()};
}

RowMatX3d BernsteinTetTerms::NodePositions(const GeneralisedState& state) const {
  RowMatX3d x(mesh_.num_nodes(), 3);
  for (int n = 0; n < x.rows(); ++n) x.row(n) = state.positions().row(node_[n]);
  return x;
}

Eigen::Vector3d BernsteinTetTerms::SpringAnchor(const GeneralisedState& state, int id) const {
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  const std::vector<int>& nodes = spring_nodes_.at(id);
  for (size_t a = 0; a < nodes.size(); ++a)
    p += spring_weights_[id][a] * state.positions().row(nodes[a]).transpose();
  return p;
}

void BernsteinTetTerms::Springs::AppendStencils(std::vector<std::vector<int>>* stencils) const {
  for (const std::vector<int>& nodes : owner_->spring_nodes_) stencils->push_back(nodes);
}

double BernsteinTetTerms::Springs::Value(const GeneralisedState& state) const {
  double e = 0;
  for (int id = 0; id < static_cast<int>(owner_->spring_nodes_.size()); ++id) {
    const mechanics::SpringEnergy::Spring& s = owner_->springs_->spring(id);
    if (!s.active) continue;
    e += 0.5 * s.stiffness_n_per_m * (owner_->SpringAnchor(state, id) - s.target_mm).squaredNorm();
  }
  return e;
}

void BernsteinTetTerms::Springs::AddGradient(const GeneralisedState& state,
                                             Eigen::VectorXd* gradient) const {
  for (int id = 0; id < static_cast<int>(owner_->spring_nodes_.size()); ++id) {
    const mechanics::SpringEnergy::Spring& s = owner_->springs_->spring(id);
    if (!s.active) continue;
    const Eigen::Vector3d f = s.stiffness_n_per_m * (owner_->SpringAnchor(state, id) - s.target_mm);
    const std::vector<int>& nodes = owner_->spring_nodes_[id];
    for (size_t a = 0; a < nodes.size(); ++a)
      gradient->segment<3>(state.dof_offset(nodes[a])) += owner_->spring_weights_[id][a] * f;
  }
}

void BernsteinTetTerms::Springs::AddHessian(const GeneralisedState& state, double scale,
                                            mechanics::HessianSink* sink) const {
  (void)state;
  for (int id = 0; id < static_cast<int>(owner_->spring_nodes_.size()); ++id) {
    const mechanics::SpringEnergy::Spring& s = owner_->springs_->spring(id);
    if (!s.active) continue;
    const std::vector<int>& nodes = owner_->spring_nodes_[id];
    const std::vector<double>& w = owner_->spring_weights_[id];
    // Each pair once: the sink adds the transposed block for a != b.
    for (size_t a = 0; a < nodes.size(); ++a)
      for (size_t b = a; b < nodes.size(); ++b) {
        const double k = s.stiffness_n_per_m * w[a] * w[b];
        if (k == 0) continue;
        sink->AddBlock(nodes[a], nodes[b], k * Eigen::Matrix3d::Identity(), scale);
      }
  }
}

// --- ShellPointSpringTerm -----------------------------------------------------------------

int ShellPointSpringTerm::Add(const Spring& spring) {
  ARREG_CHECK_INPUT(spring.shell != nullptr && spring.stiffness_n_per_m >= 0 &&
                        std::isfinite(spring.stiffness_n_per_m),
                    "", "shell spring", "needs a shell and a stiffness >= 0");
  springs_.push_back(spring);
  return static_cast<int>(springs_.size()) - 1;
}

void ShellPointSpringTerm::PointAndJacobian(const GeneralisedState& state, const Spring& s,
                                            Eigen::Vector3d* p,
                                            Eigen::Matrix<double, 3, 18>* jacobian) const {
  Eigen::Matrix<double, 10, 3> control;
  Eigen::Matrix<double, 30, 18> jac;
  s.shell->ControlPoints(state, s.point.element, &control, jacobian ? &jac : nullptr);
  const Eigen::Matrix<double, 10, 1> w = mechanics::BezierTriangleWeights(s.point.xi1, s.point.xi2);
  *p = control.transpose() * w;
  if (jacobian) {
    jacobian->setZero();
    for (int i = 0; i < 10; ++i) *jacobian += w[i] * jac.middleRows<3>(Eigen::Index{3} * i);
  }
}

Eigen::Vector3d ShellPointSpringTerm::Anchor(const GeneralisedState& state, int id) const {
  Eigen::Vector3d p;
  PointAndJacobian(state, springs_.at(id), &p, nullptr);
  return p;
}

void ShellPointSpringTerm::AppendStencils(std::vector<std::vector<int>>* stencils) const {
  for (const Spring& s : springs_) {
    if (!s.active) continue;
    const Eigen::Vector3i& t = s.shell->triangle(s.point.element);
    stencils->push_back({t[0], t[1], t[2]});
  }
}

double ShellPointSpringTerm::Value(const GeneralisedState& state) const {
  double e = 0;
  for (const Spring& s : springs_) {
    if (!s.active) continue;
    Eigen::Vector3d p;
    PointAndJacobian(state, s, &p, nullptr);
    e += 0.5 * s.stiffness_n_per_m * (p - s.target).squaredNorm();
  }
  return e;
}

void ShellPointSpringTerm::Update(const GeneralisedState&) {
  cached_state_ = mechanics::StateSnapshot();
}

void ShellPointSpringTerm::CachePoints(const GeneralisedState& state) const {
  bool same = cached_point_.size() == springs_.size() && cached_state_.Matches(state);
  for (size_t i = 0; same && i < springs_.size(); ++i)
    same = !springs_[i].active || (springs_[i].point.element == cached_at_[i].element &&
                                   springs_[i].point.xi1 == cached_at_[i].xi1 &&
                                   springs_[i].point.xi2 == cached_at_[i].xi2);
  if (same) return;
  cached_point_.resize(springs_.size());
  cached_jacobian_.resize(springs_.size());
  cached_at_.resize(springs_.size());
  for (size_t i = 0; i < springs_.size(); ++i) {
    if (!springs_[i].active) continue;
    PointAndJacobian(state, springs_[i], &cached_point_[i], &cached_jacobian_[i]);
    cached_at_[i] = springs_[i].point;
  }
  cached_state_.Take(state);
}

void ShellPointSpringTerm::AddGradient(const GeneralisedState& state,
                                       Eigen::VectorXd* gradient) const {
  CachePoints(state);
  for (size_t i = 0; i < springs_.size(); ++i) {
    const Spring& s = springs_[i];
    if (!s.active) continue;
    const Eigen::Matrix<double, 18, 1> g =
        s.stiffness_n_per_m * cached_jacobian_[i].transpose() * (cached_point_[i] - s.target);
    const Eigen::Vector3i& t = s.shell->triangle(s.point.element);
    for (int a = 0; a < 3; ++a)
      gradient->segment<6>(state.dof_offset(t[a])) += g.segment<6>(Eigen::Index{6} * a);
  }
}

void ShellPointSpringTerm::AddHessian(const GeneralisedState& state, double scale,
                                      mechanics::HessianSink* sink) const {
  CachePoints(state);
  for (size_t i = 0; i < springs_.size(); ++i) {
    const Spring& s = springs_[i];
    if (!s.active) continue;
    const Eigen::Matrix<double, 3, 18>& j = cached_jacobian_[i];
    const Eigen::Matrix<double, 18, 18> h = s.stiffness_n_per_m * j.transpose() * j;
    const Eigen::Vector3i& t = s.shell->triangle(s.point.element);
    for (int a = 0; a < 3; ++a)
      for (int b = a; b < 3; ++b)
        sink->AddBlock(t[a], t[b], h.block<6, 6>(Eigen::Index{6} * a, Eigen::Index{6} * b), scale);
  }
}

// --- EmbeddedTieTerm ----------------------------------------------------------------------

void EmbeddedTieTerm::Reembed() {
  if (ties_.empty()) return;
  RowMatX3d points(ties_.size(), 3);
  for (size_t i = 0; i < ties_.size(); ++i) points.row(i) = ties_[i].rest_mm.transpose();
  const mechanics::EmbeddedPoints e =
      mechanics::EmbeddedPoints::Embed(points, body_->rest_positions(), body_->tetrahedra());
  for (size_t i = 0; i < ties_.size(); ++i) ties_[i].embedded = e[static_cast<int>(i)];
}

Eigen::Vector3d EmbeddedTieTerm::Stretch(const GeneralisedState& state, const Tie& t) const {
  Eigen::Vector3d p = -state.position(t.node);
  for (int a = 0; a < 4; ++a)
    p += t.embedded.barycentric[a] *
         state.position(solid_->vertex_node()[body_->tetrahedra()(t.embedded.tet, a)]);
  return p;
}

void EmbeddedTieTerm::AppendStencils(std::vector<std::vector<int>>* stencils) const {
  for (const Tie& t : ties_) {
    std::vector<int> s = {t.node};
    for (int a = 0; a < 4; ++a)
      s.push_back(solid_->vertex_node()[body_->tetrahedra()(t.embedded.tet, a)]);
    stencils->push_back(s);
  }
}

double EmbeddedTieTerm::Value(const GeneralisedState& state) const {
  double e = 0;
  for (const Tie& t : ties_) e += 0.5 * t.stiffness_n_per_m * Stretch(state, t).squaredNorm();
  return e;
}

void EmbeddedTieTerm::AddGradient(const GeneralisedState& state, Eigen::VectorXd* gradient) const {
  for (const Tie& t : ties_) {
    const Eigen::Vector3d f = t.stiffness_n_per_m * Stretch(state, t);
    gradient->segment<3>(state.dof_offset(t.node)) -= f;
    for (int a = 0; a < 4; ++a) {
      const int n = solid_->vertex_node()[body_->tetrahedra()(t.embedded.tet, a)];
      gradient->segment<3>(state.dof_offset(n)) += t.embedded.barycentric[a] * f;
    }
  }
}

void EmbeddedTieTerm::AddHessian(const GeneralisedState& state, double scale,
                                 mechanics::HessianSink* sink) const {
  // d(stretch)/d(node) = -I, d/d(vertex a) = w_a I: H = k J^T J, blocks c_i c_j k I.
  for (const Tie& t : ties_) {
    int nodes[5];
    double c[5];
    nodes[0] = t.node;
    c[0] = -1.0;
    for (int a = 0; a < 4; ++a) {
      nodes[a + 1] = solid_->vertex_node()[body_->tetrahedra()(t.embedded.tet, a)];
      c[a + 1] = t.embedded.barycentric[a];
    }
    for (int i = 0; i < 5; ++i)
      for (int j = i; j < 5; ++j) {
        // Translation rows only (a frame node's rotation is not tied).
        Eigen::MatrixXd block =
            Eigen::MatrixXd::Zero(state.node_dofs(nodes[i]), state.node_dofs(nodes[j]));
        block.topLeftCorner<3, 3>().diagonal().setConstant(t.stiffness_n_per_m * c[i] * c[j]);
        sink->AddBlock(nodes[i], nodes[j], block, scale);
      }
  }
}

// --- ThinSystem ---------------------------------------------------------------------------

void ThinSystemOptions::Check() const {
  integrator.Check();
  ARREG_CHECK_INPUT(tie_stiffness_factor > 0 && std::isfinite(tie_stiffness_factor), "",
                    "tie_stiffness_factor", "must be positive, got ", tie_stiffness_factor);
}

ThinSystem::ThinSystem(const std::vector<LoadedThin>& thin, const Scene& scene,
                       mechanics::MechanicalState* body, mechanics::SpringEnergy* springs,
                       const ThinSystemOptions& options, std::unique_ptr<SolidTerms> solid)
    : options_(options),
      body_(body),
      solid_(solid ? std::move(solid) : std::make_unique<LinearTetTerms>(options.elastic, springs)),
      integrator_(options.integrator) {
  options.Check();
  solid_->Sync(*body, &state_);
  ties_ = std::make_unique<EmbeddedTieTerm>(solid_.get(), body_);
  const bool has_tets = body->num_tetrahedra() > 0;
  // Where each thin node lies relative to the organ (tie candidates).
  auto embed = [&](const RowMatX3d& points) {
    return mechanics::EmbeddedPoints::Embed(points, body->rest_positions(), body->tetrahedra());
  };

  for (size_t i = 0; i < thin.size(); ++i) {
    const LoadedThin& l = thin[i];
    const ThinStructure& t = l.spec;
    const std::string key = "thin_structures[" + std::to_string(i) + "]";
    names_.push_back(t.name);
    colors_.push_back(t.color);
    opacities_.push_back(t.opacity);
    if (t.type == ThinStructureType::kShell) {
      Shell s;
      s.structure = static_cast<int>(i);
      s.material.youngs_modulus_kpa = t.material.youngs_modulus_pa * 1e-3;
      s.material.poisson_ratio = t.material.poisson_ratio;
      s.material.thickness_mm = t.thickness_mm;
      s.material.density_kg_per_mm3 = t.material.density_kg_m3 * 1e-9;
      std::vector<Eigen::Vector3i> tri(l.triangles.rows());
      for (int f = 0; f < l.triangles.rows(); ++f) tri[f] = l.triangles.row(f).transpose();
      std::vector<Eigen::Matrix3d> rotations;
      try {
        rotations = mechanics::ShellVertexRotations(l.vertices, tri);
      } catch (const Error& e) {
        throw Error(t.mesh_path, "", e.what());
      }
      std::vector<int> node(l.vertices.rows());
      for (int v = 0; v < l.vertices.rows(); ++v)
        node[v] = state_.AddFrameNode(l.vertices.row(v).transpose(), rotations[v]);
      for (Eigen::Vector3i& f : tri)
        for (int a = 0; a < 3; ++a) f[a] = node[f[a]];
      for (int v : t.fixed_vertices) {
        state_.SetFixedTranslation(node[v], true);
        state_.SetFixedRotation(node[v], true);
      }
      mechanics::BezierShellOptions so;
      so.material = s.material;
      try {
        s.term = std::make_unique<mechanics::BezierShell>(state_, tri, so);
      } catch (const Error& e) {
        throw Error(t.mesh_path, "", e.what());
      }
      s.triangles = tri;
      if (l.visual) {
        s.visual.emplace(mechanics::ShellMapping::Project(*s.term, state_, l.visual->vertices));
        s.visual_faces = l.visual->faces;
      }
      // Frame-0 mid-surface for lifting.
      const int first = static_cast<int>(lift_nodes_.size());
      lift_nodes_.insert(lift_nodes_.end(), node.begin(), node.end());
      const int old_rows = static_cast<int>(lift_triangles_.rows());
      lift_triangles_.conservativeResize(old_rows + l.triangles.rows(), 3);
      for (int f = 0; f < l.triangles.rows(); ++f) {
        lift_triangles_.row(old_rows + f) = l.triangles.row(f).array() + first;
        lift_owner_.emplace_back(static_cast<int>(shells_.size()), f);
      }
      if (t.attach == ThinAttachment::kModel && has_tets) {
        const mechanics::EmbeddedPoints e = embed(l.vertices);
        const double k =
            options.tie_stiffness_factor * t.material.youngs_modulus_pa * t.thickness_mm * 1e-3;
        for (int v = 0; v < l.vertices.rows(); ++v)
          if (e.outside_distance()[v] <= t.attach_distance_mm)
            ties_->Add({node[v], l.vertices.row(v).transpose(), e[v], k});
      }
      shells_.push_back(std::move(s));
    } else {
      VesselPart part;
      part.structure = static_cast<int>(i);
      part.radius_mm = t.radius_mm;
      double mean = 0;
      for (const Eigen::Vector2i& s : l.segments)
        mean += (l.vertices.row(s[0]) - l.vertices.row(s[1])).norm();
      mean /= static_cast<double>(l.segments.size());
      mechanics::VesselOptions vo;
      vo.radius_mm = t.radius_mm;
      // The centreline's own resolution, not finer than the radius (a frame per cross-section
      // diameter or more resolves the bending of a slender tube).
      vo.frame_spacing_mm = std::max(mean, t.radius_mm);
      // Branch ends at one centreline vertex are tied by stiff zero-length springs (a ball
      // joint); the first frame at each vertex is the one others tie to.
      std::map<int, int> frame_at_vertex;
      const double k =
          options.tie_stiffness_factor * t.material.youngs_modulus_pa * M_PI * t.radius_mm * 1e-3;
      for (const std::vector<int>& chain :
           Branches(static_cast<int>(l.vertices.rows()), l.segments, t.centreline_path)) {
        RowMatX3d points(chain.size(), 3);
        for (size_t c = 0; c < chain.size(); ++c) points.row(c) = l.vertices.row(chain[c]);
        mechanics::Vessel vessel;
        try {
          vessel = mechanics::MakeVessel(points, ToMechanicsMaterial(t.material), vo, &state_);
        } catch (const Error& e) {
          throw Error(t.centreline_path, "", e.what());
        }
        const int ends[2] = {vessel.frame_nodes.front(), vessel.frame_nodes.back()};
        const int vertices[2] = {chain.front(), chain.back()};
        for (int end = 0; end < 2; ++end) {
          auto [it, inserted] = frame_at_vertex.emplace(vertices[end], ends[end]);
          if (!inserted)
            joints_.Add(mechanics::SpringAnchor::AtNode(it->second),
                        mechanics::SpringAnchor::AtNode(ends[end]), k);
        }
        part.branches.push_back(std::move(vessel));
      }
      // Fixed centreline vertices clamp the nearest frame.
      for (int v : t.fixed_vertices) {
        int best = -1;
        double best_d = std::numeric_limits<double>::infinity();
        for (const mechanics::Vessel& b : part.branches)
          for (int n : b.frame_nodes) {
            const double d = (state_.position(n) - l.vertices.row(v).transpose()).norm();
            if (d < best_d) best_d = d, best = n;
          }
        state_.SetFixedTranslation(best, true);
        state_.SetFixedRotation(best, true);
      }
      if (t.attach == ThinAttachment::kModel && has_tets) {
        std::vector<int> nodes;
        for (const mechanics::Vessel& b : part.branches)
          nodes.insert(nodes.end(), b.frame_nodes.begin(), b.frame_nodes.end());
        RowMatX3d points(nodes.size(), 3);
        for (size_t n = 0; n < nodes.size(); ++n) points.row(n) = state_.positions().row(nodes[n]);
        const mechanics::EmbeddedPoints e = embed(points);
        for (size_t n = 0; n < nodes.size(); ++n)
          if (e.outside_distance()[n] <= 1e-9)
            ties_->Add({nodes[n], points.row(n).transpose(), e[static_cast<int>(n)], k});
      }
      vessels_.push_back(std::move(part));
    }
  }
  if (options.gravity_mm_per_s2.squaredNorm() > 0)
    gravity_.emplace(std::vector<mechanics::NodeInertia>(state_.num_nodes()),
                     options.gravity_mm_per_s2);
  dirty_ = true;
}

void ThinSystem::CollectTerms() {
  elastic_terms_ = solid_->elastic();
  other_terms_ = solid_->others();
  std::vector<const mechanics::InertiaSource*> sources = solid_->inertia();
  for (Shell& s : shells_) {
    elastic_terms_.push_back(s.term.get());
    sources.push_back(s.term.get());
  }
  for (VesselPart& v : vessels_)
    for (mechanics::Vessel& b : v.branches) {
      elastic_terms_.push_back(b.model.get());
      sources.push_back(b.model.get());
    }
  if (features_.size() > 0) other_terms_.push_back(&features_);
  if (ties_->size() > 0) other_terms_.push_back(ties_.get());
  if (joints_.size() > 0) other_terms_.push_back(&joints_);
  inertia_ = mechanics::CollectNodeInertia(state_, sources);
  if (gravity_) {
    gravity_->SetMasses(inertia_);
    other_terms_.push_back(&*gravity_);
  }
  integrator_.InvalidatePattern();
  dirty_ = false;
}

int ThinSystem::num_shell_elements() const {
  int n = 0;
  for (const Shell& s : shells_) n += s.term->num_elements();
  return n;
}

RowMatX3d ThinSystem::LiftVertices() const {
  RowMatX3d out(lift_nodes_.size(), 3);
  for (size_t i = 0; i < lift_nodes_.size(); ++i)
    out.row(i) = state_.positions().row(lift_nodes_[i]);
  return out;
}

double ThinSystem::ShellArea() const {
  double a = 0;
  for (const Shell& s : shells_)
    for (int e = 0; e < s.term->num_elements(); ++e) a += s.term->rest_area(e);
  return a;
}

double ThinSystem::ShellVolume() const {
  double v = 0;
  for (const Shell& s : shells_)
    for (int e = 0; e < s.term->num_elements(); ++e)
      v += s.term->rest_area(e) * s.material.thickness_mm;
  return v;
}

double ThinSystem::ShellMeanModulusPa() const {
  double ev = 0, v = 0;
  for (const Shell& s : shells_)
    for (int e = 0; e < s.term->num_elements(); ++e) {
      const double vol = s.term->rest_area(e) * s.material.thickness_mm;
      ev += vol * s.material.youngs_modulus_kpa * 1e3;
      v += vol;
    }
  return v > 0 ? ev / v : 0.0;
}

namespace {

// Barycentric coordinates (of corners 1, 2) of the point of triangle (a, b, c) closest to p.
Eigen::Vector2d ClosestBarycentric(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                   const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                                   double* distance) {
  const Eigen::Vector3d e1 = b - a, e2 = c - a, d = p - a;
  Eigen::Matrix2d g;
  g << e1.dot(e1), e1.dot(e2), e1.dot(e2), e2.dot(e2);
  Eigen::Vector2d uv = g.ldlt().solve(Eigen::Vector2d(e1.dot(d), e2.dot(d)));
  // Clamp into the triangle (the closest point of a point near the plane is what matters).
  if (uv.x() < 0 || uv.y() < 0 || uv.sum() > 1) {
    Eigen::Vector2d best = uv;
    double best_d = std::numeric_limits<double>::infinity();
    const Eigen::Vector3d corners[3] = {a, b, c};
    const Eigen::Vector2d bary[3] = {{0, 0}, {1, 0}, {0, 1}};
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d s0 = corners[k], s1 = corners[(k + 1) % 3];
      const double t =
          std::clamp((p - s0).dot(s1 - s0) / std::max((s1 - s0).squaredNorm(), 1e-300), 0.0, 1.0);
      const double dd = (p - (s0 + t * (s1 - s0))).norm();
      if (dd < best_d) best_d = dd, best = (1 - t) * bary[k] + t * bary[(k + 1) % 3];
    }
    uv = best;
  }
  *distance = (p - (a + uv.x() * e1 + uv.y() * e2)).norm();
  return uv;
}

}  // namespace

int ThinSystem::AddFeatureSpring(int lift_triangle, const Eigen::Vector3d& point_mm,
                                 const Eigen::Vector3d& target_mm, double stiffness_n_per_m) {
  const auto [shell_index, element0] = lift_owner_.at(lift_triangle);
  Shell& shell = shells_[shell_index];
  // The hit point in the frame-0 triangle (current positions), carried to the rest shape.
  const Eigen::Vector3i lift = lift_triangles_.row(lift_triangle).transpose();
  const int n[3] = {lift_nodes_[lift[0]], lift_nodes_[lift[1]], lift_nodes_[lift[2]]};
  double d = 0;
  const Eigen::Vector2d uv = ClosestBarycentric(point_mm, state_.position(n[0]),
                                                state_.position(n[1]), state_.position(n[2]), &d);
  const auto rest = [&](int node) { return Eigen::Vector3d(state_.rest_positions().row(node)); };
  const Eigen::Vector3d rest_point =
      (1 - uv.sum()) * rest(n[0]) + uv.x() * rest(n[1]) + uv.y() * rest(n[2]);
  // The element that holds it now: the frame-0 one until a cut split it.
  int element = element0;
  Eigen::Vector2d local = uv;
  const Eigen::Vector3i& t0 = shell.term->triangle(element0);
  if (!(t0[0] == n[0] && t0[1] == n[1] && t0[2] == n[2])) {
    double best = std::numeric_limits<double>::infinity();
    for (int e = 0; e < shell.term->num_elements(); ++e) {
      const Eigen::Vector3i& t = shell.term->triangle(e);
      double dist = 0;
      const Eigen::Vector2d b =
          ClosestBarycentric(rest_point, rest(t[0]), rest(t[1]), rest(t[2]), &dist);
      if (dist < best) best = dist, element = e, local = b;
    }
  }
  // ShellSurfacePoint's xi1, xi2 are the weights of corners 1 and 2 (xi3 = 1 - xi1 - xi2).
  mechanics::ShellSurfacePoint sp;
  sp.element = element;
  sp.xi1 = 1 - local.sum();
  sp.xi2 = local.x();
  ShellPointSpringTerm::Spring s;
  s.shell = shell.term.get();
  s.point = sp;
  s.target = target_mm;
  s.stiffness_n_per_m = stiffness_n_per_m;
  dirty_ = true;
  return features_.Add(s);
}

void ThinSystem::SetFeatureTarget(int id, const Eigen::Vector3d& target_mm) {
  features_.spring(id).target = target_mm;
}
void ThinSystem::RemoveFeatureSpring(int id) {
  // An inactive spring adds nothing; the system keeps its pattern (a superset of what the
  // remaining stencils need), so the solver keeps its symbolic factorisation and its factor.
  features_.spring(id).active = false;
}
Eigen::Vector3d ThinSystem::FeatureAnchor(int id) const { return features_.Anchor(state_, id); }
Eigen::Vector3d ThinSystem::FeatureRestAnchor(int id) const {
  const ShellPointSpringTerm::Spring& s = features_.spring(id);
  const Eigen::Vector3i& t = s.shell->triangle(s.point.element);
  const double w3 = 1 - s.point.xi1 - s.point.xi2;
  return s.point.xi1 * state_.rest_positions().row(t[0]).transpose() +
         s.point.xi2 * state_.rest_positions().row(t[1]).transpose() +
         w3 * state_.rest_positions().row(t[2]).transpose();
}

mechanics::GeneralisedSummary ThinSystem::Step(mechanics::MechanicalState* body) {
  if (solid_->Sync(*body, &state_)) {
    ties_->Reembed();
    dirty_ = true;
  }
  if (dirty_) CollectTerms();
  mechanics::GeneralisedSummary summary =
      integrator_.Step(&state_, elastic_terms_, other_terms_, inertia_);
  solid_->CopyBack(state_, body);
  return summary;
}

void ThinSystem::SyncSolid(const mechanics::MechanicalState* body) {
  if (solid_->Sync(*body, &state_)) {
    ties_->Reembed();
    dirty_ = true;
  }
}

ThinCutEvent ThinSystem::Cut(const std::vector<Eigen::Vector3d>& polyline_rest,
                             const std::vector<Eigen::Vector3d>& polyline_current,
                             const Eigen::Vector3d& direction) {
  ThinCutEvent ev;
  if (polyline_rest.size() >= 2) {
    for (int si = 0; si < num_shells(); ++si) {
      Shell& s = shells_[si];
      const mechanics::ShellCutResult cut = mechanics::CutShell(
          &state_, &s.triangles, polyline_rest, direction, mechanics::ShellCutOptions());
      if (!cut.changed()) continue;
      s.term->ReplaceElements(state_, s.triangles,
                              cut.ReusableElements(static_cast<int>(s.triangles.size())));
      for (int id = 0; id < features_.size(); ++id) {
        ShellPointSpringTerm::Spring& f = features_.spring(id);
        if (f.shell == s.term.get())
          f.point = mechanics::RemapSurfacePoint(cut, s.triangles, state_, f.point);
      }
      if (s.visual) s.visual.emplace(mechanics::RemapShellMapping(*s.visual, cut, *s.term, state_));
      ++ev.shells_cut;
      ev.shell_nodes_added += static_cast<int>(cut.inserted_nodes.size()) + cut.duplicated_nodes;
      dirty_ = true;
    }
  }
  if (polyline_current.size() >= 2 && !vessels_.empty()) {
    // The cut surface near the vessels: the plane through the polyline's chord that contains
    // the viewing direction, limited to the polyline's extent.
    const Eigen::Vector3d& a = polyline_current.front();
    const Eigen::Vector3d& b = polyline_current.back();
    Eigen::Vector3d normal = (b - a).cross(direction);
    if (normal.norm() > 1e-12) {
      mechanics::VesselCutPlane plane;
      plane.point = 0.5 * (a + b);
      plane.normal = normal.normalized();
      plane.radius_mm = 0.5 * (b - a).norm();
      for (VesselPart& v : vessels_)
        for (mechanics::Vessel& branch : v.branches) {
          const mechanics::VesselCutResult r = mechanics::CutVessel(plane, &state_, &branch);
          if (r.duplicated.empty()) continue;
          ++ev.vessels_cut;
          ev.vessel_frames_added += static_cast<int>(r.duplicated.size());
          dirty_ = true;
        }
    }
  }
  return ev;
}

std::vector<SurfaceMesh> ThinSystem::Surfaces() const {
  std::vector<SurfaceMesh> out(names_.size());
  for (const Shell& s : shells_) {
    SurfaceMesh& m = out[s.structure];
    if (s.visual) {
      s.visual->Positions(state_, &m.vertices);
      m.faces = s.visual_faces;
      continue;
    }
    std::map<int, int> index;
    for (const Eigen::Vector3i& t : s.triangles)
      for (int a = 0; a < 3; ++a) index.emplace(t[a], 0);
    m.vertices.resize(static_cast<int>(index.size()), 3);
    int k = 0;
    for (auto& [node, i] : index) {
      i = k;
      m.vertices.row(k++) = state_.positions().row(node);
    }
    m.faces.resize(static_cast<int>(s.triangles.size()), 3);
    for (size_t f = 0; f < s.triangles.size(); ++f)
      for (int a = 0; a < 3; ++a) m.faces(f, a) = index.at(s.triangles[f][a]);
  }
  for (const VesselPart& v : vessels_) {
    SurfaceMesh& m = out[v.structure];
    std::vector<Eigen::Vector3d> vertices;
    std::vector<Eigen::Vector3i> faces;
    for (const mechanics::Vessel& b : v.branches) {
      const int first = static_cast<int>(vertices.size());
      for (int n : b.frame_nodes) {
        const Eigen::Matrix3d& r = state_.rotation(n);
        for (int k = 0; k < kTubeSides; ++k) {
          const double angle = 2 * M_PI * k / kTubeSides;
          vertices.push_back(state_.position(n) + v.radius_mm * (std::cos(angle) * r.col(0) +
                                                                 std::sin(angle) * r.col(1)));
        }
      }
      for (const Eigen::Vector2i& e : b.elements) {
        const int ra = first + kTubeSides * e[0], rb = first + kTubeSides * e[1];
        for (int k = 0; k < kTubeSides; ++k) {
          const int k1 = (k + 1) % kTubeSides;
          faces.emplace_back(ra + k, ra + k1, rb + k1);
          faces.emplace_back(ra + k, rb + k1, rb + k);
        }
      }
    }
    m.vertices.resize(static_cast<int>(vertices.size()), 3);
    for (size_t i = 0; i < vertices.size(); ++i) m.vertices.row(i) = vertices[i].transpose();
    m.faces.resize(static_cast<int>(faces.size()), 3);
    for (size_t i = 0; i < faces.size(); ++i) m.faces.row(i) = faces[i].transpose();
  }
  return out;
}

}  // namespace arreg::pipeline
