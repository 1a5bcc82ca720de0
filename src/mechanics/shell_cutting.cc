#include "mechanics/shell_cutting.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>
#include <string>
#include <utility>

#include "core/error.h"
#include "mechanics/so3.h"

namespace arreg::mechanics {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

using Edge = std::pair<int, int>;  // (min, max) node ids
Edge Key(int a, int b) { return a < b ? Edge(a, b) : Edge(b, a); }

Eigen::Vector3d Rest(const GeneralisedState& s, int n) {
  return s.rest_positions().row(n).transpose();
}

void CheckTriangles(const GeneralisedState& state, const std::vector<Eigen::Vector3i>& triangles) {
  for (size_t t = 0; t < triangles.size(); ++t)
    for (int i = 0; i < 3; ++i) {
      const int n = triangles[t][i];
      if (n < 0 || n >= state.num_nodes() || !state.is_frame(n))
        throw Error("", "shell triangle " + std::to_string(t),
                    "node " + std::to_string(n) + " is not a frame node");
    }
}

// A node at parameter t on the edge (a, b): positions and velocities linear,
// rest axes interpolated and re-orthonormalised, the current rotation the rest
// one turned by the edge's relative rotation interpolated on SO(3).
int InsertEdgeNode(GeneralisedState* state, int a, int b, double t) {
  const Eigen::Matrix3d ra = state->rest_rotation(a), rb = state->rest_rotation(b);
  const Eigen::Vector3d z = ((1 - t) * ra.col(2) + t * rb.col(2)).normalized();
  Eigen::Vector3d x = (1 - t) * ra.col(0) + t * rb.col(0);
  x = (x - x.dot(z) * z).normalized();
  Eigen::Matrix3d rest;
  rest.col(0) = x;
  rest.col(1) = z.cross(x);
  rest.col(2) = z;
  const int n = state->AddFrameNode((1 - t) * Rest(*state, a) + t * Rest(*state, b), rest);
  auto lerp = [&](const RowMatX3d& m) { return ((1 - t) * m.row(a) + t * m.row(b)).eval(); };
  state->mutable_positions().row(n) = lerp(state->positions());
  state->mutable_velocities().row(n) = lerp(state->velocities());
  state->mutable_angular_velocities().row(n) = lerp(state->angular_velocities());
  const Eigen::Matrix3d da = state->rotation(a) * ra.transpose();
  const Eigen::Matrix3d db = state->rotation(b) * rb.transpose();
  state->mutable_rotation(n) = da * ExpSO3(t * LogSO3(da.transpose() * db)) * rest;
  state->SetFixedTranslation(n, state->fixed_translation(a) && state->fixed_translation(b));
  state->SetFixedRotation(n, state->fixed_rotation(a) && state->fixed_rotation(b));
  return n;
}

// Distance from p to segment [a, b] (2D) and the segment parameter of the closest point.
double SegmentDistance(const Eigen::Vector2d& p, const Eigen::Vector2d& a, const Eigen::Vector2d& b,
                       double* s) {
  const Eigen::Vector2d ab = b - a;
  const double l2 = ab.squaredNorm();
  *s = l2 > 0 ? std::clamp((p - a).dot(ab) / l2, 0.0, 1.0) : 0.0;
  return (a + *s * ab - p).norm();
}

// The cut line seen along the projection direction: 2D points and their depths.
struct Line {
  Eigen::Vector3d e1, e2, d;
  std::vector<Eigen::Vector2d> p;
  std::vector<double> depth;
  Eigen::Vector2d Project(const Eigen::Vector3d& x) const { return {x.dot(e1), x.dot(e2)}; }
  // Distance (2D) from x to the line among the segments whose depth there is
  // within max_depth of x's; kInf if none.
  double Distance(const Eigen::Vector3d& x, double max_depth) const {
    const Eigen::Vector2d q = Project(x);
    double best = kInf, s = 0;
    for (size_t k = 0; k + 1 < p.size(); ++k) {
      const double dist = SegmentDistance(q, p[k], p[k + 1], &s);
      const double z = (1 - s) * depth[k] + s * depth[k + 1];
      if (dist < best && std::abs(z - x.dot(d)) <= max_depth) best = dist;
    }
    return best;
  }
};

// Crossing of the edge [xa, xb] with the line: the edge parameter t in [0, 1]
// of the first crossing within max_depth; false if none.
bool Crossing(const Line& line, const Eigen::Vector3d& xa, const Eigen::Vector3d& xb,
              double max_depth, double* t) {
  const Eigen::Vector2d a = line.Project(xa), b = line.Project(xb);
  for (size_t k = 0; k + 1 < line.p.size(); ++k) {
    const Eigen::Vector2d c = line.p[k], r = line.p[k + 1] - c, e = b - a;
    const double den = e.x() * r.y() - e.y() * r.x();
    if (std::abs(den) < 1e-300) continue;  // parallel
    const Eigen::Vector2d ac = c - a;
    const double te = (ac.x() * r.y() - ac.y() * r.x()) / den;
    const double s = (ac.x() * e.y() - ac.y() * e.x()) / den;
    if (te < 0 || te > 1 || s < 0 || s > 1) continue;
    const double z = (1 - s) * line.depth[k] + s * line.depth[k + 1];
    const double ze = ((1 - te) * xa + te * xb).dot(line.d);
    if (std::abs(z - ze) > max_depth) continue;
    *t = te;
    return true;
  }
  return false;
}

// Duplicates the nodes along `crack` (edges keyed by node ids of `triangles`):
// around each crack node, the incident triangles connected across non-crack
// edges form one side; the first side keeps the node, each other side gets a copy.
void Separate(GeneralisedState* state, std::vector<Eigen::Vector3i>* triangles,
              const std::vector<std::array<int, 2>>& crack, ShellCutResult* result) {
  std::map<Edge, int> is_crack;
  std::vector<int> nodes;
  for (const auto& e : crack) {
    is_crack[Key(e[0], e[1])] = 1;
    nodes.push_back(e[0]);
    nodes.push_back(e[1]);
  }
  std::sort(nodes.begin(), nodes.end());
  nodes.erase(std::unique(nodes.begin(), nodes.end()), nodes.end());
  std::map<int, std::vector<int>> incident;  // crack node -> triangles
  for (size_t t = 0; t < triangles->size(); ++t)
    for (int i = 0; i < 3; ++i) {
      const int n = (*triangles)[t][i];
      if (std::binary_search(nodes.begin(), nodes.end(), n)) incident[n].push_back(int(t));
    }
  // (triangle, corner) -> new node, applied after every side is known.
  std::vector<std::pair<std::pair<int, int>, int>> replace;
  for (const int v : nodes) {
    const std::vector<int>& tris = incident[v];
    std::vector<int> parent(tris.size());
    std::iota(parent.begin(), parent.end(), 0);
    auto find = [&](int i) {
      while (parent[i] != i) i = parent[i] = parent[parent[i]];
      return i;
    };
    // Triangles around v sharing an edge (v, w) that is not cracked are on one side.
    std::map<int, int> first_with;  // w -> a triangle index in tris
    for (size_t i = 0; i < tris.size(); ++i) {
      const Eigen::Vector3i& tri = (*triangles)[tris[i]];
      for (int c = 0; c < 3; ++c) {
        const int w = tri[c];
        if (w == v || is_crack.count(Key(v, w))) continue;
        auto [it, inserted] = first_with.emplace(w, int(i));
        if (!inserted) parent[find(int(i))] = find(it->second);
      }
    }
    std::map<int, int> side_node;  // root -> node
    for (size_t i = 0; i < tris.size(); ++i) {
      const int root = find(int(i));
      auto it = side_node.find(root);
      int node = v;
      if (it == side_node.end()) {
        if (!side_node.empty()) {
          node = state->DuplicateNode(v);
          result->node_copies[v].push_back(node);
          ++result->duplicated_nodes;
        }
        side_node[root] = node;
      } else {
        node = it->second;
      }
      if (node == v) continue;
      const Eigen::Vector3i& tri = (*triangles)[tris[i]];
      for (int c = 0; c < 3; ++c)
        if (tri[c] == v) replace.push_back({{tris[i], c}, node});
    }
  }
  for (const auto& [where, node] : replace) (*triangles)[where.first][where.second] = node;
}

void InitResult(const GeneralisedState& state, const std::vector<Eigen::Vector3i>& triangles,
                ShellCutResult* result) {
  result->old_triangles = triangles;
  result->node_copies.resize(state.num_nodes());
  for (int n = 0; n < state.num_nodes(); ++n) result->node_copies[n] = {n};
  result->element_children.resize(triangles.size());
  for (size_t e = 0; e < triangles.size(); ++e) result->element_children[e] = {int(e)};
}

double MinAngle(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  auto angle = [](const Eigen::Vector3d& u, const Eigen::Vector3d& v) {
    return std::atan2(u.cross(v).norm(), u.dot(v));
  };
  return std::min({angle(b - a, c - a), angle(a - b, c - b), angle(a - c, b - c)});
}

}  // namespace

std::vector<char> ShellCutResult::ReusableElements(int num_new_elements) const {
  std::vector<char> reuse(num_new_elements, 0);
  for (size_t e = 0; e < element_children.size() && int(e) < num_new_elements; ++e)
    reuse[e] = element_children[e].size() == 1;
  return reuse;
}

void ShellCutOptions::Check() const {
  if (!(snap_fraction >= 0 && snap_fraction < 0.5))
    throw Error("", "shell_cut.snap_fraction", "must be in [0, 0.5)");
  if (!(max_depth_mm > 0)) throw Error("", "shell_cut.max_depth_mm", "must be > 0");
}

void ShellTearOptions::Check() const {
  if (!(strength_kpa > 0)) throw Error("", "shell_tear.strength_kpa", "must be > 0");
  if (!(crack_length_factor > 0)) throw Error("", "shell_tear.crack_length_factor", "must be > 0");
  if (!(max_edge_angle_deg > 0 && max_edge_angle_deg <= 90))
    throw Error("", "shell_tear.max_edge_angle_deg", "must be in (0, 90]");
  cut.Check();
}

ShellCutResult CutShell(GeneralisedState* state, std::vector<Eigen::Vector3i>* triangles,
                        const std::vector<Eigen::Vector3d>& polyline,
                        const Eigen::Vector3d& direction, const ShellCutOptions& options) {
  options.Check();
  if (polyline.size() < 2) throw Error("", "cut polyline", "needs at least 2 points");
  if (!(direction.norm() > 0)) throw Error("", "cut direction", "must be non-zero");
  CheckTriangles(*state, *triangles);
  ShellCutResult result;
  InitResult(*state, *triangles, &result);

  Line line;
  line.d = direction.normalized();
  line.e1 = line.d.unitOrthogonal();
  line.e2 = line.d.cross(line.e1);
  for (const Eigen::Vector3d& q : polyline) {
    line.p.push_back(line.Project(q));
    line.depth.push_back(q.dot(line.d));
  }
  const double f = options.snap_fraction, max_depth = options.max_depth_mm;

  // Edges, and each vertex's shortest incident edge.
  std::map<Edge, int> edge_crossing;  // edge -> inserted node (or -1)
  std::map<int, double> shortest;
  for (const Eigen::Vector3i& tri : *triangles)
    for (int i = 0; i < 3; ++i) {
      const int a = tri[i], b = tri[(i + 1) % 3];
      edge_crossing[Key(a, b)] = -1;
      const double l = (Rest(*state, a) - Rest(*state, b)).norm();
      for (int n : {a, b}) {
        auto [it, inserted] = shortest.emplace(n, l);
        if (!inserted) it->second = std::min(it->second, l);
      }
    }
  // Vertices on the cut: near the line, or next to a crossing close to them.
  std::map<int, double> on_cut;  // node -> its distance to the line
  for (const auto& [n, l] : shortest) {
    const double dist = line.Distance(Rest(*state, n), max_depth);
    if (dist < f * l) on_cut[n] = dist;
  }
  std::map<Edge, double> crossing_t;
  for (const auto& [e, unused] : edge_crossing) {
    double t = 0;
    if (!Crossing(line, Rest(*state, e.first), Rest(*state, e.second), max_depth, &t)) continue;
    if (t < f || t > 1 - f) {
      const int n = t < f ? e.first : e.second;
      if (!on_cut.count(n)) on_cut[n] = line.Distance(Rest(*state, n), max_depth);
    } else {
      crossing_t[e] = t;
    }
  }
  // Split the edges crossed away from their (snapped) ends.
  for (const auto& [e, t] : crossing_t) {
    if (on_cut.count(e.first) || on_cut.count(e.second)) continue;
    const int n = InsertEdgeNode(state, e.first, e.second, t);
    edge_crossing[e] = n;
    on_cut[n] = 0;
    result.inserted_nodes.push_back(n);
    result.node_copies.push_back({n});
  }
  // Split the triangles whose edges were split.
  const size_t old_count = triangles->size();
  auto split_quality = [&](const Eigen::Vector3i& t) {
    return MinAngle(Rest(*state, t[0]), Rest(*state, t[1]), Rest(*state, t[2]));
  };
  for (size_t e = 0; e < old_count; ++e) {
    const Eigen::Vector3i v = (*triangles)[e];
    int p[3], k = 0;
    for (int i = 0; i < 3; ++i) {
      p[i] = edge_crossing[Key(v[i], v[(i + 1) % 3])];
      k += p[i] >= 0;
    }
    if (k == 0) continue;
    std::vector<Eigen::Vector3i> pieces;
    if (k == 1) {
      int i = 0;
      while (p[i] < 0) ++i;
      pieces = {{v[i], p[i], v[(i + 2) % 3]}, {p[i], v[(i + 1) % 3], v[(i + 2) % 3]}};
    } else if (k == 2) {
      // Edges i and i+1 crossed: corner s = v[i+1] cut off, the quad split by
      // the diagonal that gives the larger smallest angle.
      int i = 0;
      while (!(p[i] >= 0 && p[(i + 1) % 3] >= 0)) ++i;
      const int a = v[i], s = v[(i + 1) % 3], c = v[(i + 2) % 3], pa = p[i], pc = p[(i + 1) % 3];
      pieces = {{pa, s, pc}};
      const Eigen::Vector3i d1a(a, pa, pc), d1b(a, pc, c), d2a(a, pa, c), d2b(pa, pc, c);
      if (std::min(split_quality(d1a), split_quality(d1b)) >=
          std::min(split_quality(d2a), split_quality(d2b))) {
        pieces.push_back(d1a);
        pieces.push_back(d1b);
      } else {
        pieces.push_back(d2a);
        pieces.push_back(d2b);
      }
    } else {
      pieces = {{v[0], p[0], p[2]}, {p[0], v[1], p[1]}, {p[2], p[1], v[2]}, {p[0], p[1], p[2]}};
    }
    (*triangles)[e] = pieces[0];
    for (size_t j = 1; j < pieces.size(); ++j) {
      result.element_children[e].push_back(int(triangles->size()));
      triangles->push_back(pieces[j]);
    }
  }
  // Crack edges: both ends on the cut and the middle on the line (within the
  // ends' own distances plus snap_fraction of the edge).
  std::map<Edge, int> seen;
  for (const Eigen::Vector3i& tri : *triangles)
    for (int i = 0; i < 3; ++i) {
      const int a = tri[i], b = tri[(i + 1) % 3];
      auto ia = on_cut.find(a), ib = on_cut.find(b);
      if (ia == on_cut.end() || ib == on_cut.end() || !seen.emplace(Key(a, b), 1).second) continue;
      const Eigen::Vector3d xa = Rest(*state, a), xb = Rest(*state, b);
      const double tol = std::max(ia->second, ib->second) + f * (xa - xb).norm() + 1e-12;
      if (line.Distance(0.5 * (xa + xb), max_depth) <= tol)
        result.crack_edges.push_back({Key(a, b).first, Key(a, b).second});
    }
  Separate(state, triangles, result.crack_edges, &result);
  return result;
}

ShellCutResult SeparateEdges(GeneralisedState* state, std::vector<Eigen::Vector3i>* triangles,
                             const std::vector<std::array<int, 2>>& edges) {
  CheckTriangles(*state, *triangles);
  ShellCutResult result;
  InitResult(*state, *triangles, &result);
  std::map<Edge, int> present;
  for (const Eigen::Vector3i& tri : *triangles)
    for (int i = 0; i < 3; ++i) present[Key(tri[i], tri[(i + 1) % 3])] = 1;
  for (const auto& e : edges)
    if (!present.count(Key(e[0], e[1])))
      throw Error(
          "", "separated edge",
          std::to_string(e[0]) + "-" + std::to_string(e[1]) + " is not an edge of the shell");
  result.crack_edges = edges;
  Separate(state, triangles, edges, &result);
  return result;
}

ShellSurfacePoint RemapSurfacePoint(const ShellCutResult& cut,
                                    const std::vector<Eigen::Vector3i>& triangles,
                                    const GeneralisedState& state, const ShellSurfacePoint& point) {
  if (point.element < 0 || point.element >= int(cut.element_children.size()))
    throw Error("", "shell surface point",
                "element " + std::to_string(point.element) + " out of range");
  const Eigen::Vector3i& old = cut.old_triangles[point.element];
  const double xi3 = 1 - point.xi1 - point.xi2;
  const Eigen::Vector3d x =
      point.xi1 * Rest(state, old[0]) + point.xi2 * Rest(state, old[1]) + xi3 * Rest(state, old[2]);
  ShellSurfacePoint best;
  double best_min = -kInf;
  for (const int child : cut.element_children[point.element]) {
    const Eigen::Vector3i& t = triangles[child];
    const Eigen::Vector3d a = Rest(state, t[0]), b = Rest(state, t[1]), c = Rest(state, t[2]);
    Eigen::Matrix<double, 3, 2> m;
    m << a - c, b - c;
    const Eigen::Vector2d l = m.colPivHouseholderQr().solve(x - c);
    const double lowest = std::min({l[0], l[1], 1 - l[0] - l[1]});
    if (lowest > best_min) {
      best_min = lowest;
      best.element = child;
      // Clamped into the triangle (round-off on a shared edge).
      Eigen::Vector3d w(std::max(l[0], 0.0), std::max(l[1], 0.0), std::max(1 - l[0] - l[1], 0.0));
      w /= w.sum();
      best.xi1 = w[0];
      best.xi2 = w[1];
    }
  }
  return best;
}

ShellMapping RemapShellMapping(const ShellMapping& mapping, const ShellCutResult& cut,
                               const BezierShell& new_shell, const GeneralisedState& state) {
  std::vector<Eigen::Vector3i> triangles(new_shell.num_elements());
  for (int e = 0; e < new_shell.num_elements(); ++e) triangles[e] = new_shell.triangle(e);
  std::vector<ShellSurfacePoint> points(mapping.size());
  for (int p = 0; p < mapping.size(); ++p)
    points[p] = RemapSurfacePoint(cut, triangles, state, mapping.point(p));
  return ShellMapping(new_shell, std::move(points));
}

ShellStress ElementMembraneStress(const GeneralisedState& state, const Eigen::Vector3i& triangle,
                                  const ShellMaterial& material) {
  const Eigen::Vector3d x0 = Rest(state, triangle[0]);
  const Eigen::Vector3d u = Rest(state, triangle[1]) - x0, w = Rest(state, triangle[2]) - x0;
  // Rest in-plane basis (b1, b2) and the corner triangle's map A from it to current.
  const Eigen::Vector3d b1 = u.normalized();
  const Eigen::Vector3d b2 = (w - w.dot(b1) * b1).normalized();
  Eigen::Matrix2d rest_edges;
  rest_edges << u.dot(b1), w.dot(b1), u.dot(b2), w.dot(b2);
  Eigen::Matrix<double, 3, 2> current_edges;
  current_edges.col(0) = state.position(triangle[1]) - state.position(triangle[0]);
  current_edges.col(1) = state.position(triangle[2]) - state.position(triangle[0]);
  const Eigen::Matrix<double, 3, 2> a = current_edges * rest_edges.inverse();
  // Stretch S = sqrt(A^T A) in the rest basis, strain e = S - I.
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(a.transpose() * a);
  const Eigen::Matrix2d s = eig.eigenvectors() *
                            eig.eigenvalues().cwiseMax(0).cwiseSqrt().asDiagonal() *
                            eig.eigenvectors().transpose();
  const Eigen::Matrix2d e = s - Eigen::Matrix2d::Identity();
  const double nu = material.poisson_ratio;
  const double c = material.youngs_modulus_kpa / (1 - nu * nu);
  const double s11 = c * (e(0, 0) + nu * e(1, 1)), s22 = c * (e(1, 1) + nu * e(0, 0));
  const double s12 = c * (1 - nu) * e(0, 1);
  ShellStress out;
  const double mean = 0.5 * (s11 + s22), radius = std::hypot(0.5 * (s11 - s22), s12);
  out.principal_kpa = mean + radius;  // eq. 6.2
  out.minor_kpa = mean - radius;
  const double theta = 0.5 * std::atan2(2 * s12, s11 - s22);  // eq. 6.1
  out.direction_rest = std::cos(theta) * b1 + std::sin(theta) * b2;
  return out;
}

std::vector<ShellStress> NodeMembraneStresses(const GeneralisedState& state,
                                              const std::vector<Eigen::Vector3i>& triangles,
                                              const ShellMaterial& material,
                                              NodeStressSmoothing smoothing) {
  const int n_nodes = state.num_nodes();
  std::vector<ShellStress> nodes(n_nodes), most(n_nodes);
  std::vector<Eigen::Matrix3d> sum(n_nodes, Eigen::Matrix3d::Zero());
  std::vector<double> weight(n_nodes, 0);
  for (size_t t = 0; t < triangles.size(); ++t) {
    ShellStress s = ElementMembraneStress(state, triangles[t], material);
    s.element = int(t);
    // The element's tensor in rest coordinates from its principal pair.
    const Eigen::Vector3d& d1 = s.direction_rest;
    const Eigen::Vector3d x0 = Rest(state, triangles[t][0]);
    const Eigen::Vector3d normal =
        (Rest(state, triangles[t][1]) - x0).cross(Rest(state, triangles[t][2]) - x0);
    const double area = 0.5 * normal.norm();
    const Eigen::Vector3d d2 = normal.normalized().cross(d1);
    const Eigen::Matrix3d tensor =
        s.principal_kpa * d1 * d1.transpose() + s.minor_kpa * d2 * d2.transpose();
    for (int i = 0; i < 3; ++i) {
      const int n = triangles[t][i];
      if (most[n].element < 0 || s.principal_kpa > most[n].principal_kpa) most[n] = s;
      sum[n] += area * tensor;
      weight[n] += area;
    }
  }
  if (smoothing == NodeStressSmoothing::kMaxElement) return most;
  for (int n = 0; n < n_nodes; ++n) {
    if (most[n].element < 0) continue;
    // Principal values of the mean tensor in the node's rest tangent plane.
    const Eigen::Matrix3d r = state.rest_rotation(n);
    const Eigen::Matrix2d plane =
        r.leftCols<2>().transpose() * (sum[n] / weight[n]) * r.leftCols<2>();
    const double s11 = plane(0, 0), s22 = plane(1, 1), s12 = 0.5 * (plane(0, 1) + plane(1, 0));
    const double mean = 0.5 * (s11 + s22), radius = std::hypot(0.5 * (s11 - s22), s12);
    const double theta = 0.5 * std::atan2(2 * s12, s11 - s22);  // eq. 6.1
    nodes[n].principal_kpa = mean + radius;                     // eq. 6.2
    nodes[n].minor_kpa = mean - radius;
    nodes[n].direction_rest = std::cos(theta) * r.col(0) + std::sin(theta) * r.col(1);
    nodes[n].element = most[n].element;
  }
  return nodes;
}

ShellTearResult TearShell(GeneralisedState* state, std::vector<Eigen::Vector3i>* triangles,
                          const ShellMaterial& material, const ShellTearOptions& options) {
  options.Check();
  CheckTriangles(*state, *triangles);
  ShellTearResult result;
  const std::vector<ShellStress> stress =
      NodeMembraneStresses(*state, *triangles, material, options.smoothing);
  // Candidates above the strength, most stressed first.
  std::vector<int> candidates;
  for (int n = 0; n < int(stress.size()); ++n)
    if (stress[n].element >= 0 && stress[n].principal_kpa > options.strength_kpa &&
        !(options.skip_held_nodes && state->fixed_translation(n)))
      candidates.push_back(n);
  std::stable_sort(candidates.begin(), candidates.end(),
                   [&](int a, int b) { return stress[a].principal_kpa > stress[b].principal_kpa; });
  for (const int node : candidates) {
    // Crack line: in the plane of the principal direction (the failing
    // element's rest plane, or the node's tangent plane), perpendicular to sigma_P+.
    const Eigen::Vector3i& tri = (*triangles)[stress[node].element];
    Eigen::Vector3d normal = (Rest(*state, tri[1]) - Rest(*state, tri[0]))
                                 .cross(Rest(*state, tri[2]) - Rest(*state, tri[0]))
                                 .normalized();
    if (options.smoothing == NodeStressSmoothing::kAreaAverage)
      normal = state->rest_rotation(node).col(2);
    const Eigen::Vector3d crack = normal.cross(stress[node].direction_rest).normalized();
    const Eigen::Vector3d x = Rest(*state, node);
    // Edges at the node; an edge of one triangle is on the boundary (already open).
    std::map<int, int> edge_count;  // other end -> triangles sharing (node, other)
    for (const Eigen::Vector3i& t : *triangles)
      for (int i = 0; i < 3; ++i)
        if (t[i] == node) {
          ++edge_count[t[(i + 1) % 3]];
          ++edge_count[t[(i + 2) % 3]];
        }
    ShellCutResult cut;
    if (options.snap) {
      double mean = 0;
      for (const auto& [w, count] : edge_count) mean += (Rest(*state, w) - x).norm();
      mean /= edge_count.size();
      const double half = options.crack_length_factor * mean;
      // On copies: a line along the boundary opens nothing, and then the next candidate is tried.
      GeneralisedState trial_state = *state;
      std::vector<Eigen::Vector3i> trial_triangles = *triangles;
      cut = CutShell(&trial_state, &trial_triangles, {x - half * crack, x + half * crack}, normal,
                     options.cut);
      if (cut.duplicated_nodes == 0) continue;
      *state = std::move(trial_state);
      *triangles = std::move(trial_triangles);
    } else {
      // On each side of the node, the interior edge at the smallest angle to the
      // crack line (thesis fig. 6.13), within max_edge_angle_deg.
      const double min_cos = std::cos(options.max_edge_angle_deg * M_PI / 180);
      std::vector<std::array<int, 2>> edges;
      for (const double sign : {1.0, -1.0}) {
        int best = -1;
        double best_cos = min_cos;
        for (const auto& [w, count] : edge_count) {
          if (count < 2) continue;
          const double cosine = sign * crack.dot((Rest(*state, w) - x).normalized());
          if (cosine > best_cos) best_cos = cosine, best = w;
        }
        if (best >= 0) edges.push_back({node, best});
      }
      // An interior node needs an edge on each side to open; SeparateEdges tells.
      if (edges.empty()) continue;
      GeneralisedState trial_state = *state;
      std::vector<Eigen::Vector3i> trial_triangles = *triangles;
      cut = SeparateEdges(&trial_state, &trial_triangles, edges);
      if (cut.duplicated_nodes == 0) continue;
      *state = std::move(trial_state);
      *triangles = std::move(trial_triangles);
    }
    result.torn = true;
    result.node = node;
    result.principal_kpa = stress[node].principal_kpa;
    result.crack_direction_rest = crack;
    result.cut = std::move(cut);
    return result;
  }
  return result;
}

}  // namespace arreg::mechanics
