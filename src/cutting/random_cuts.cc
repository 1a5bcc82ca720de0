#include "cutting/random_cuts.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <exception>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <thread>

#include "core/error.h"
#include "core/file_util.h"
#include "core/mesh_io.h"
#include "core/mesh_ops.h"
#include "cutting/mechanics_update.h"
#include "cutting/mesh_checks.h"
#include "cutting/quadratic_cutter.h"
#include "cutting/structure_split.h"
#include "mechanics/curved_boundary.h"
#include "mechanics/elastic_energy.h"
#include "mechanics/integrator.h"
#include "mechanics/mechanical_state.h"
#include "mechanics/spring_energy.h"
#include "mechanics/tet_element.h"

namespace arreg::cutting {

namespace {

constexpr const char* kKindNames[kNumRandomCutKinds] = {"plane",        "sphere",     "cylinder",
                                                        "bent-sheet",   "partial",    "crack-front",
                                                        "graze-vertex", "graze-edge", "graze-face"};

// Relative weights of the kinds drawn by Next(mesh): the partial and crack-front cuts, the
// ones that leave and continue fronts, as often as planes.
constexpr double kKindWeights[kNumRandomCutKinds] = {2, 1, 1, 1, 2, 2, 1, 1, 1};

// SplitMix64: independent generator seeds from (seed, sequence).
std::uint64_t Mix(std::uint64_t x) {
  x += 0x9e3779b97f4a7c15ull;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
  return x ^ (x >> 31);
}

std::uint64_t SequenceSeed(std::uint64_t seed, int sequence) {
  return Mix(Mix(seed) ^ static_cast<std::uint64_t>(sequence));
}

struct MeshFrame {
  Eigen::Vector3d min, max;
  double diagonal = 0;
};

MeshFrame Frame(const CuttableMesh& mesh) {
  MeshFrame f;
  f.min = Eigen::Vector3d::Constant(1e300);
  f.max = Eigen::Vector3d::Constant(-1e300);
  for (const auto& t : mesh.tetrahedra())
    for (int v : t) {
      f.min = f.min.cwiseMin(mesh.positions()[v]);
      f.max = f.max.cwiseMax(mesh.positions()[v]);
    }
  f.diagonal = (f.max - f.min).norm();
  return f;
}

class Draw {
 public:
  explicit Draw(std::mt19937_64* rng) : rng_(rng) {}
  double Uniform(double lo, double hi) {
    return std::uniform_real_distribution<double>(lo, hi)(*rng_);
  }
  int Int(int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(*rng_); }
  bool Chance(double p) { return Uniform(0, 1) < p; }
  Eigen::Vector3d Direction() {
    std::normal_distribution<double> g;
    Eigen::Vector3d d;
    do d = Eigen::Vector3d(g(*rng_), g(*rng_), g(*rng_));
    while (d.norm() < 1e-6);
    return d.normalized();
  }
  // A unit vector perpendicular to `n` (unit), uniform on that circle.
  Eigen::Vector3d Perpendicular(const Eigen::Vector3d& n) {
    const Eigen::Vector3d e1 = n.unitOrthogonal(), e2 = n.cross(e1);
    const double a = Uniform(0, 2 * M_PI);
    return std::cos(a) * e1 + std::sin(a) * e2;
  }

 private:
  std::mt19937_64* rng_;
};

Eigen::Vector3d Centroid(const CuttableMesh& mesh, int t) {
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (int v : mesh.tetrahedra()[t]) c += mesh.positions()[v];
  return c / 4;
}

double EdgeLength(const CuttableMesh& mesh, int a, int b) {
  return (mesh.positions()[a] - mesh.positions()[b]).norm();
}

// The face of a tetrahedron opposite local vertex k (any orientation).
constexpr int kFaceOf[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};
constexpr int kEdgeOf[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};

// The remeshing options: both methods, snapping thresholds of the benchmark, the default and
// the pipeline's on-surface tolerances, moving front vertices mostly on.
CutOptions RandomOptions(Draw* draw) {
  CutOptions o;
  o.method = draw->Chance(0.2) ? RemeshMethod::kBielser : RemeshMethod::kFlips;
  static constexpr double kEps[] = {0.0, 0.05, 0.1, 0.2, 0.3};
  o.snap_epsilon = kEps[draw->Int(0, 4)];
  const double r = draw->Uniform(0, 1);
  o.on_surface_tolerance = r < 0.6 ? 1e-9 : r < 0.8 ? 1e-4 : 0.25;
  o.move_front_vertices = draw->Chance(0.9);
  return o;
}

// A strip from the segment [a, b] along `direction` for `length`, 4 x 4 cells; its grid row
// v = 0 is the segment itself.
CutSurface Strip(const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                 const Eigen::Vector3d& direction, double length) {
  return MakeGridSurface(
      [&](double u, double v) {
        return Eigen::Vector3d((1 - u) * a + u * b + v * length * direction);
      },
      4, 4);
}

}  // namespace

const char* RandomCutKindName(RandomCutKind kind) { return kKindNames[static_cast<int>(kind)]; }

RandomCutKind RandomCutKindFromName(const std::string& name, const std::string& where) {
  for (int k = 0; k < kNumRandomCutKinds; ++k)
    if (name == kKindNames[k]) return static_cast<RandomCutKind>(k);
  throw Error("", where, "unknown random cut kind '" + name + "'");
}

void RandomCutOptions::Check() const {
  ARREG_CHECK_INPUT(max_cuts_per_sequence >= 1, "", "max_cuts_per_sequence", "must be >= 1");
  ARREG_CHECK_INPUT(min_graze_fraction > 0, "", "min_graze_fraction", "must be > 0");
  ARREG_CHECK_INPUT(max_graze_fraction >= min_graze_fraction, "", "max_graze_fraction",
                    "must be >= min_graze_fraction");
}

void KindCounts::Add(const KindCounts& other) {
  cuts += other.cuts;
  crossed += other.crossed;
  no_crossing += other.no_crossing;
  rejected += other.rejected;
  violations += other.violations;
  seconds += other.seconds;
}

void SweepOptions::Check() const {
  ARREG_CHECK_INPUT(num_cuts >= 1, "", "num_cuts", "must be >= 1");
  ARREG_CHECK_INPUT(max_tetrahedra >= 1, "", "max_tetrahedra", "must be >= 1");
  ARREG_CHECK_INPUT(threads >= 1, "", "threads", "must be >= 1");
  ARREG_CHECK_INPUT(degree == 1 || degree == 2, "", "degree", "must be 1 or 2, got ", degree);
  cuts.Check();
}

RandomCutGenerator::RandomCutGenerator(std::uint64_t seed, const RandomCutOptions& options)
    : options_(options), rng_(seed) {
  options_.Check();
}

RandomCut RandomCutGenerator::Next(const CuttableMesh& mesh) {
  double total = 0;
  for (double w : kKindWeights) total += w;
  double r = std::uniform_real_distribution<double>(0, total)(rng_);
  int k = 0;
  while (k + 1 < kNumRandomCutKinds && r >= kKindWeights[k]) r -= kKindWeights[k++];
  return Next(mesh, static_cast<RandomCutKind>(k));
}

RandomCut RandomCutGenerator::Next(const CuttableMesh& mesh, RandomCutKind kind) {
  ARREG_CHECK_INPUT(mesh.num_tetrahedra() > 0, "", "random cut", "the mesh has no elements");
  Draw draw(&rng_);
  if (kind == RandomCutKind::kCrackFront && fronts_.empty()) kind = RandomCutKind::kPartial;
  RandomCut cut;
  cut.kind = kind;
  cut.options = RandomOptions(&draw);
  const MeshFrame frame = Frame(mesh);
  const double D = frame.diagonal;
  // A point of the body: the centroid of a random element.
  const Eigen::Vector3d inside = Centroid(mesh, draw.Int(0, mesh.num_tetrahedra() - 1));
  const Eigen::Vector3d n = draw.Direction();
  switch (kind) {
    case RandomCutKind::kPlane:
      cut.surface = MakePlaneSurface(inside, n, D, D, draw.Direction(), draw.Int(1, 3));
      break;
    case RandomCutKind::kSphere: {
      // Radius from a tenth to over half the body: from a ball inside it to a shell through it.
      const double radius = draw.Uniform(0.1, 0.6) * D;
      const Eigen::Vector3d centre = inside + draw.Uniform(0, radius) * n;
      const Eigen::Vector3d e1 = n.unitOrthogonal(), e2 = n.cross(e1);
      cut.surface = MakeGridSurface(
          [&](double a, double b) {
            const double phi = 2 * M_PI * a, theta = M_PI * b;
            return Eigen::Vector3d(centre + radius * (std::sin(theta) * std::cos(phi) * e1 +
                                                      std::sin(theta) * std::sin(phi) * e2 +
                                                      std::cos(theta) * n));
          },
          32, 16);
      break;
    }
    case RandomCutKind::kCylinder: {
      const double radius = draw.Uniform(0.1, 0.6) * D;
      const Eigen::Vector3d axis = n, e1 = draw.Perpendicular(axis), e2 = axis.cross(e1);
      const Eigen::Vector3d centre = inside + draw.Uniform(0, radius) * e1;
      cut.surface = MakeGridSurface(
          [&](double a, double b) {
            const double phi = 2 * M_PI * a;
            return Eigen::Vector3d(centre + radius * (std::cos(phi) * e1 + std::sin(phi) * e2) +
                                   (2 * b - 1) * D * axis);
          },
          32, 2);
      break;
    }
    case RandomCutKind::kBentSheet: {
      const Eigen::Vector3d e1 = draw.Perpendicular(n), e2 = n.cross(e1);
      const double amplitude = draw.Uniform(0.02, 0.2) * D;
      const double wavelength = draw.Uniform(0.3, 1.5) * D, phase = draw.Uniform(0, 2 * M_PI);
      cut.surface = MakeGridSurface(
          [&](double a, double b) {
            const double u = (2 * a - 1) * D, v = (2 * b - 1) * D;
            return Eigen::Vector3d(inside + u * e1 + v * e2 +
                                   amplitude * std::sin(2 * M_PI * u / wavelength + phase) * n);
          },
          48, 2);
      break;
    }
    case RandomCutKind::kPartial: {
      // Half a plane: from beyond the body up to the line through `inside` along `along`.
      const Eigen::Vector3d forward = draw.Perpendicular(n), along = n.cross(forward);
      cut.has_front = true;
      cut.front = {inside - D * along, inside + D * along};
      cut.front_direction = forward;
      cut.surface = Strip(cut.front[0] - D * forward, cut.front[1] - D * forward, forward, D);
      break;
    }
    case RandomCutKind::kCrackFront: {
      // Continues an earlier front: starts on a part of its segment (at least the middle
      // fifth) and advances at an angle to the earlier S (straight on a third of the time),
      // ending inside the body (a new front) or beyond it.
      const RandomCut& previous = fronts_[draw.Int(0, num_fronts() - 1)];
      const double s0 = draw.Uniform(0, 0.4), s1 = draw.Uniform(0.6, 1);
      const Eigen::Vector3d a = previous.front[0] + s0 * (previous.front[1] - previous.front[0]);
      const Eigen::Vector3d b = previous.front[0] + s1 * (previous.front[1] - previous.front[0]);
      const Eigen::Vector3d edge = (b - a).normalized();
      const double angle = draw.Chance(1.0 / 3) ? 0.0 : draw.Uniform(-M_PI / 3, M_PI / 3);
      const Eigen::Vector3d forward =
          Eigen::AngleAxisd(angle, edge) * previous.front_direction.normalized();
      const double length =
          draw.Chance(0.5) ? D : draw.Uniform(0.5, 4) * mesh.mean_rest_edge_length();
      cut.start = {a, b};
      cut.has_front = length < D;
      cut.front = {a + length * forward, b + length * forward};
      cut.front_direction = forward;
      cut.surface = Strip(a, b, forward, length);
      break;
    }
    case RandomCutKind::kGrazeVertex:
    case RandomCutKind::kGrazeEdge:
    case RandomCutKind::kGrazeFace: {
      const std::array<int, 4>& tet = mesh.tetrahedra()[draw.Int(0, mesh.num_tetrahedra() - 1)];
      Eigen::Vector3d anchor, normal;
      double reference = 0;
      if (kind == RandomCutKind::kGrazeVertex) {
        const int k = draw.Int(0, 3);
        cut.grazed = {tet[k]};
        for (int j = 0; j < 4; ++j)
          if (j != k) reference += EdgeLength(mesh, tet[k], tet[j]) / 3;
        anchor = mesh.positions()[tet[k]];
        normal = n;
      } else if (kind == RandomCutKind::kGrazeEdge) {
        const int e = draw.Int(0, 5);
        const int a = tet[kEdgeOf[e][0]], b = tet[kEdgeOf[e][1]];
        cut.grazed = {a, b};
        reference = EdgeLength(mesh, a, b);
        anchor = 0.5 * (mesh.positions()[a] + mesh.positions()[b]);
        normal = draw.Perpendicular((mesh.positions()[b] - mesh.positions()[a]).normalized());
      } else {
        const int f = draw.Int(0, 3);
        const int a = tet[kFaceOf[f][0]], b = tet[kFaceOf[f][1]], c = tet[kFaceOf[f][2]];
        cut.grazed = {a, b, c};
        reference = (EdgeLength(mesh, a, b) + EdgeLength(mesh, b, c) + EdgeLength(mesh, c, a)) / 3;
        const Eigen::Vector3d &pa = mesh.positions()[a], &pb = mesh.positions()[b],
                              &pc = mesh.positions()[c];
        anchor = (pa + pb + pc) / 3;
        normal = (pb - pa).cross(pc - pa).normalized();
      }
      const double fraction = std::exp(draw.Uniform(std::log(options_.min_graze_fraction),
                                                    std::log(options_.max_graze_fraction)));
      cut.graze_reference_mm = reference;
      cut.graze_distance_mm = fraction * reference;
      if (draw.Chance(0.5)) normal = -normal;
      // The plane's own point is the grazed feature moved off it, so that the triangles' planes
      // pass at the drawn distance up to the rounding of their vertices (relative 1e-16 of D).
      cut.surface = MakePlaneSurface(anchor + cut.graze_distance_mm * normal, normal, D, D,
                                     draw.Direction(), 1);
      break;
    }
  }
  return cut;
}

RowMatX3d BulgedBoxQuadraticNodes(const TetMesh& box, const Eigen::Vector3d& size,
                                  double bulge_mm) {
  mechanics::SurfaceRaiseOptions o;
  o.project = [size, bulge_mm](const Eigen::Vector3d& p) {
    Eigen::Vector3d q = p;
    for (int axis = 0; axis < 3; ++axis)
      for (int side = 0; side < 2; ++side) {
        if (std::abs(p[axis] - side * size[axis]) > 1e-9 * size.norm()) continue;
        double bump = bulge_mm;
        for (int other = 0; other < 3; ++other)
          if (other != axis) bump *= std::sin(M_PI * p[other] / size[other]);
        q[axis] += (side == 1 ? 1 : -1) * bump;
      }
    return q;
  };
  return mechanics::RaiseTetMeshOntoSurface(box, 2, o).nodes;
}

void RandomCutGenerator::Record(const RandomCut& cut, CutStatus status) {
  if (status == CutStatus::kCut && cut.has_front) fronts_.push_back(cut);
}

namespace {

using Failure = std::optional<std::pair<std::string, std::string>>;

// The checks of a linear mesh after a cut: positive, conforming, manifold, every element's rest
// volume positive as the mechanics compute it, and the rest volume kept.
Failure CheckCutCorners(const TetMesh& rest, double volume, MeshInvariants* invariants) {
  const MeshInvariants inv = CheckMeshInvariants(rest);
  *invariants = inv;
  if (inv.num_nonpositive > 0 || inv.num_repeated_vertex > 0)
    return std::make_pair(std::string("positive"), inv.ToString());
  if (inv.num_overshared_faces > 0 || inv.num_duplicate_elements > 0)
    return std::make_pair(std::string("conforming"), inv.ToString());
  if (!inv.ok()) return std::make_pair(std::string("manifold"), inv.ToString());
  // Positive exact orientation is not enough for the simulation: it needs a positive rest
  // volume as it computes it (ComputeTetRestData), e.g. ApplyCutChange refuses the element.
  for (int t = 0; t < rest.num_tetrahedra(); ++t) {
    mechanics::TetRestData data;
    const auto x = [&](int k) { return Eigen::Vector3d(rest.vertices.row(rest.tetrahedra(t, k))); };
    if (!mechanics::ComputeTetRestData(x(0), x(1), x(2), x(3), mechanics::Material(), &data)) {
      std::ostringstream s;
      s << "element " << t << " has rest volume " << data.volume_mm3
        << " mm^3 in floating point (exact orientation positive)";
      return std::make_pair(std::string("zero-volume"), s.str());
    }
  }
  if (!(std::abs(inv.total_volume - volume) <= 1e-9 * std::abs(volume))) {
    std::ostringstream s;
    s.precision(17);
    s << "rest volume " << inv.total_volume << " against " << volume << " (relative change "
      << (inv.total_volume - volume) / volume << ")";
    return std::make_pair(std::string("volume"), s.str());
  }
  return std::nullopt;
}

// The checks after every cut on one mesh of a sequence: the cutter, a mechanical state that
// follows it, the structure split along the crack.
class SequenceRunner {
 public:
  explicit SequenceRunner(const SweepMesh& mesh)
      : source_(mesh), mesh_(mesh.mesh), state_(mesh.mesh, mechanics::Material()) {
    volume_ = CheckMeshInvariants(mesh.mesh).total_volume;
    // The mesh hangs from its 10 % lowest along x: gravity then bends it, and pieces cut loose
    // fall (their mass matrix keeps the step well posed).
    const double x0 = mesh.mesh.vertices.col(0).minCoeff();
    const double x1 = mesh.mesh.vertices.col(0).maxCoeff();
    for (int v = 0; v < mesh.mesh.num_vertices(); ++v)
      if (mesh.mesh.vertices(v, 0) <= x0 + 0.1 * (x1 - x0)) state_.SetFixed(v, true);
  }

  const CuttableMesh& mesh() const { return mesh_; }

  // Makes the cut and checks; returns the failed check and its detail, if any.
  std::optional<std::pair<std::string, std::string>> Apply(const RandomCut& cut,
                                                           CutStatus* status) {
    CutChange change;
    CutSummary summary;
    try {
      summary = mesh_.Cut(cut.surface, cut.options, &change);
    } catch (const std::exception& e) {
      return std::make_pair(std::string("exception"), std::string(e.what()));
    }
    *status = summary.status;
    if (summary.status != CutStatus::kCut) return std::nullopt;
    const TetMesh rest = mesh_.RestMesh();
    MeshInvariants inv;
    if (auto failed = CheckCutCorners(rest, volume_, &inv)) return failed;
    // The mechanical state follows the change and gives the cutter's mesh.
    try {
      ApplyCutChange(change, &state_);
    } catch (const std::exception& e) {
      return std::make_pair(std::string("mechanics-state"), std::string(e.what()));
    }
    if (state_.num_vertices() != rest.num_vertices() ||
        state_.num_tetrahedra() != rest.num_tetrahedra() ||
        state_.tetrahedra() != rest.tetrahedra ||
        (state_.rest_positions() - rest.vertices).cwiseAbs().maxCoeff() > 1e-9 * volume_scale())
      return std::make_pair(std::string("mechanics-state"),
                            std::string("the state after ApplyCutChange is not the cut mesh"));
    if (auto failed = StepMechanics()) {
      std::ostringstream s;
      s << "; smallest normalised volume " << inv.min_quality;
      failed->second += s.str();
      return failed;
    }
    if (source_.structure.num_faces() > 0)
      if (auto failed = SplitStructure(rest)) return failed;
    return std::nullopt;
  }

 private:
  double volume_scale() const { return std::cbrt(std::abs(volume_)); }

  std::optional<std::pair<std::string, std::string>> StepMechanics() {
    mechanics::ImplicitEulerOptions options;
    mechanics::ImplicitEulerIntegrator integrator(options);
    mechanics::CorotationalElasticity elastic;
    mechanics::GravityEnergy gravity(Eigen::Vector3d(0, 0, -9810));
    const mechanics::StepSummary s = integrator.Step(&state_, &elastic, {&elastic, &gravity});
    const bool finite = state_.positions().allFinite() && state_.velocities().allFinite();
    // Back to rest, where the cutter's current positions are.
    state_.mutable_positions() = state_.rest_positions();
    state_.mutable_velocities().setZero();
    if (s.status != mechanics::StepStatus::kConverged || !finite)
      return std::make_pair(std::string("mechanics"),
                            std::string(mechanics::StepStatusName(s.status)) +
                                (finite ? "" : ", non-finite positions") +
                                (s.message.empty() ? "" : ": " + s.message));
    return std::nullopt;
  }

  std::optional<std::pair<std::string, std::string>> SplitStructure(const TetMesh& rest) {
    SurfaceMesh surface;
    try {
      const SurfaceMesh crack = CrackSurface(rest);
      if (crack.num_faces() == 0) return std::nullopt;
      surface =
          SplitAlongCrack(source_.structure, crack, 1e-4 * mesh_.mean_rest_edge_length()).surface;
    } catch (const std::exception& e) {
      return std::make_pair(std::string("structure"), std::string(e.what()));
    }
    // Each piece (faces connected through vertices) must close on its own: the pieces of a
    // body cut through move apart.
    int parts = 0;
    const Eigen::VectorXi part = ConnectedComponents(surface, Adjacency::kVertex, &parts);
    for (int p = 0; p < parts; ++p) {
      SurfaceMesh piece;
      piece.vertices = surface.vertices;
      std::vector<int> faces;
      for (int f = 0; f < surface.num_faces(); ++f)
        if (part[f] == p) faces.push_back(f);
      piece.faces.resize(static_cast<int>(faces.size()), 3);
      for (size_t k = 0; k < faces.size(); ++k) piece.faces.row(k) = surface.faces.row(faces[k]);
      const SurfaceTopology t = AnalyzeSurface(piece);
      if (!t.closed_oriented_manifold()) {
        std::ostringstream s;
        s << "piece " << p << " of " << parts << " is not a closed oriented manifold ("
          << t.num_boundary_edges << " boundary, " << t.num_nonmanifold_edges << " non-manifold, "
          << t.num_misoriented_edges << " misoriented edges, " << t.num_degenerate_faces
          << " degenerate faces)";
        return std::make_pair(std::string("structure"), s.str());
      }
    }
    return std::nullopt;
  }

  const SweepMesh& source_;
  CuttableMesh mesh_;
  mechanics::MechanicalState state_;
  double volume_ = 0;
};

// The checks after every cut of a degree-2 sequence: the corner mesh's (CheckCutCorners), one
// control point per edge, positive Jacobians and the quadratic rest volume.
class QuadraticSequenceRunner {
 public:
  explicit QuadraticSequenceRunner(const SweepMesh& mesh) : mesh_(Raise(mesh)) {
    const mechanics::HighOrderTetMesh rest = mesh_.RestMesh();
    volume_ = CheckQuadraticMesh(rest).volume;
    corner_volume_ = CheckMeshInvariants(mesh_.skeleton().RestMesh()).total_volume;
  }

  const CuttableMesh& mesh() const { return mesh_.skeleton(); }

  Failure Apply(const RandomCut& cut, CutStatus* status) {
    CutSummary summary;
    try {
      summary = mesh_.Cut(cut.surface, cut.options);
    } catch (const std::exception& e) {
      return std::make_pair(std::string("exception"), std::string(e.what()));
    }
    *status = summary.status;
    if (summary.status != CutStatus::kCut) return std::nullopt;
    MeshInvariants inv;
    if (auto failed = CheckCutCorners(mesh_.skeleton().RestMesh(), corner_volume_, &inv))
      return failed;
    const QuadraticMeshInvariants q = CheckQuadraticMesh(mesh_.RestMesh());
    std::ostringstream s;
    s.precision(17);
    if (q.num_edge_mismatches > 0 || q.num_shared_edge_nodes > 0) {
      s << q.num_edge_mismatches << " edges with differing control points, "
        << q.num_shared_edge_nodes << " control points on two edges";
      return std::make_pair(std::string("quadratic-conforming"), s.str());
    }
    if (q.num_nonpositive_jacobians > 0) {
      s << q.num_nonpositive_jacobians << " elements with det J <= 0 at a sampled point";
      return std::make_pair(std::string("jacobian"), s.str());
    }
    if (!(std::abs(q.volume - volume_) <= 1e-9 * std::abs(volume_))) {
      s << "quadratic rest volume " << q.volume << " against " << volume_ << " (relative change "
        << (q.volume - volume_) / volume_ << ")";
      return std::make_pair(std::string("volume"), s.str());
    }
    return std::nullopt;
  }

 private:
  static mechanics::HighOrderTetMesh Raise(const SweepMesh& mesh) {
    mechanics::HighOrderTetMesh q = mechanics::RaiseTetMesh(mesh.mesh, 2);
    if (mesh.quadratic_nodes.rows() > 0) {
      ARREG_CHECK_INPUT(mesh.quadratic_nodes.rows() == q.num_nodes(), "", "quadratic_nodes",
                        mesh.name, ": expected ", q.num_nodes(), " rows, got ",
                        mesh.quadratic_nodes.rows());
      q.nodes = mesh.quadratic_nodes;
    }
    return q;
  }

  QuadraticCuttableMesh mesh_;
  double volume_ = 0, corner_volume_ = 0;
};

std::string Pad3(int k) {
  char buf[16];
  std::snprintf(buf, sizeof(buf), "%03d", k);
  return buf;
}

nlohmann::json OptionsJson(const CutOptions& o) {
  return {{"method", RemeshMethodName(o.method)},
          {"snap_epsilon", o.snap_epsilon},
          {"on_surface_tolerance", o.on_surface_tolerance},
          {"min_barycentric", o.min_barycentric},
          {"min_flip_quality", o.min_flip_quality},
          {"min_element_quality", o.min_element_quality},
          {"feature_angle_deg", o.feature_angle_deg},
          {"separate", o.separate},
          {"move_front_vertices", o.move_front_vertices}};
}

}  // namespace

namespace {

// One sequence's share of the sweep's result.
struct SequenceResult {
  std::map<std::string, KindCounts> counts;  // kind -> counts
  std::vector<Violation> violations;
  int cuts = 0;
  bool stopped_by_growth = false;
};

template <class Runner>
SequenceResult RunSequence(const SweepMesh& source, const SweepOptions& options, int s,
                           int length) {
  using Clock = std::chrono::steady_clock;
  SequenceResult result;
  RandomCutGenerator generator(SequenceSeed(options.seed, s), options.cuts);
  Runner runner(source);
  std::vector<RandomCut> made;
  for (int i = 0; i < length; ++i) {
    if (runner.mesh().num_tetrahedra() > options.max_tetrahedra) {
      result.stopped_by_growth = true;
      break;
    }
    const auto t0 = Clock::now();
    RandomCut cut = generator.Next(runner.mesh());
    const TetMesh before = options.save_failures_dir.empty() ? TetMesh() : runner.mesh().RestMesh();
    CutStatus status = CutStatus::kNoCrossing;
    const auto failed = runner.Apply(cut, &status);
    generator.Record(cut, status);
    KindCounts& c = result.counts[RandomCutKindName(cut.kind)];
    ++c.cuts;
    ++result.cuts;
    c.crossed += status == CutStatus::kCut;
    c.no_crossing += status == CutStatus::kNoCrossing;
    c.rejected += status == CutStatus::kRejected;
    made.push_back(std::move(cut));
    if (failed) {
      ++c.violations;
      Violation v;
      v.mesh = source.name;
      v.seed = options.seed;
      v.sequence = s;
      v.index = i;
      v.kind = made.back().kind;
      v.check = failed->first;
      v.detail = failed->second;
      if (!options.save_failures_dir.empty()) {
        v.saved_dir = options.save_failures_dir + "/" + source.name + "_seed" +
                      std::to_string(options.seed) + "_seq" + std::to_string(s) + "_cut" +
                      std::to_string(i);
        SaveCase(v.saved_dir, source, made, v, options.degree);
        WriteTetMesh(v.saved_dir + "/before.vtk", before);
      }
      result.violations.push_back(v);
    }
    c.seconds += std::chrono::duration<double>(Clock::now() - t0).count();
    if (failed) break;  // the rest of the sequence would cut a broken mesh
  }
  return result;
}

}  // namespace

SweepResult RunRandomCutSweep(const std::vector<SweepMesh>& meshes, const SweepOptions& options,
                              const std::function<void(int, int)>& progress) {
  options.Check();
  ARREG_CHECK_INPUT(!meshes.empty(), "", "random cut sweep", "no meshes");
  using Clock = std::chrono::steady_clock;
  const auto start = Clock::now();
  // The sequences and their lengths are drawn first, so that they do not depend on how the
  // cuts went (nor on the threads): sequence s has length drawn from (seed, s), the last one
  // cut to num_cuts in all.
  std::vector<int> lengths;
  for (int total = 0, s = 0; total < options.num_cuts; ++s) {
    std::mt19937_64 length_rng(SequenceSeed(options.seed, s) ^ 0x5eedull);
    const int length = std::min(
        options.num_cuts - total,
        std::uniform_int_distribution<int>(1, options.cuts.max_cuts_per_sequence)(length_rng));
    lengths.push_back(length);
    total += length;
  }
  std::vector<SequenceResult> results(lengths.size());
  std::atomic<int> next{0};
  std::mutex progress_mutex;
  int done = 0;
  std::exception_ptr error;
  const auto work = [&]() {
    for (int s = next++; s < static_cast<int>(lengths.size()); s = next++) {
      try {
        const SweepMesh& mesh = meshes[s % meshes.size()];
        results[s] = options.degree == 2
                         ? RunSequence<QuadraticSequenceRunner>(mesh, options, s, lengths[s])
                         : RunSequence<SequenceRunner>(mesh, options, s, lengths[s]);
      } catch (...) {
        std::lock_guard<std::mutex> lock(progress_mutex);
        if (!error) error = std::current_exception();
      }
      std::lock_guard<std::mutex> lock(progress_mutex);
      done += lengths[s];
      if (progress) progress(done, options.num_cuts);
    }
  };
  std::vector<std::thread> threads;
  for (int k = 1; k < options.threads; ++k) threads.emplace_back(work);
  work();
  for (std::thread& t : threads) t.join();
  if (error) std::rethrow_exception(error);
  SweepResult result;
  for (size_t s = 0; s < results.size(); ++s) {
    const SequenceResult& r = results[s];
    ++result.sequences;
    result.cuts += r.cuts;
    result.stopped_by_growth += r.stopped_by_growth;
    for (const auto& [kind, c] : r.counts) {
      result.counts[meshes[s % meshes.size()].name][kind].Add(c);
    }
    result.violations.insert(result.violations.end(), r.violations.begin(), r.violations.end());
  }
  result.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return result;
}

void SaveCase(const std::string& dir, const SweepMesh& mesh, const std::vector<RandomCut>& cuts,
              const Violation& violation, int degree) {
  CreateDirectories(dir);
  WriteTetMesh(dir + "/initial.vtk", mesh.mesh);
  if (mesh.structure.num_faces() > 0) WriteSurfaceMesh(dir + "/structure.obj", mesh.structure);
  nlohmann::json j;
  j["mesh"] = violation.mesh;
  j["seed"] = violation.seed;
  j["sequence"] = violation.sequence;
  j["index"] = violation.index;
  j["check"] = violation.check;
  j["detail"] = violation.detail;
  j["degree"] = degree;
  if (degree == 2 && mesh.quadratic_nodes.rows() > 0) {
    j["quadratic_nodes"] = nlohmann::json::array();
    for (Eigen::Index n = 0; n < mesh.quadratic_nodes.rows(); ++n)
      j["quadratic_nodes"].push_back(
          {mesh.quadratic_nodes(n, 0), mesh.quadratic_nodes(n, 1), mesh.quadratic_nodes(n, 2)});
  }
  j["cuts"] = nlohmann::json::array();
  for (size_t k = 0; k < cuts.size(); ++k) {
    const std::string file = "cut_" + Pad3(static_cast<int>(k)) + ".obj";
    SurfaceMesh s;
    s.vertices = cuts[k].surface.vertices;
    s.faces = cuts[k].surface.triangles;
    WriteSurfaceMesh(std::string(dir).append("/").append(file), s);
    j["cuts"].push_back({{"kind", RandomCutKindName(cuts[k].kind)},
                         {"surface", file},
                         {"options", OptionsJson(cuts[k].options)}});
  }
  WriteFileAtomic(dir + "/case.json", [&](std::ostream& out) { out << j.dump(2) << "\n"; });
}

namespace {

template <class Runner>
std::vector<Violation> Replay(const SweepMesh& mesh, const std::vector<RandomCut>& cuts,
                              const nlohmann::json& j) {
  Runner runner(mesh);
  std::vector<Violation> found;
  for (size_t k = 0; k < cuts.size(); ++k) {
    CutStatus status = CutStatus::kNoCrossing;
    if (const auto failed = runner.Apply(cuts[k], &status)) {
      Violation v;
      v.mesh = mesh.name;
      v.seed = j.value("seed", std::uint64_t{0});
      v.sequence = j.value("sequence", 0);
      v.index = static_cast<int>(k);
      v.kind = cuts[k].kind;
      v.check = failed->first;
      v.detail = failed->second;
      found.push_back(v);
      break;
    }
  }
  return found;
}

}  // namespace

std::vector<Violation> ReplayCase(const std::string& dir) {
  const std::string json_path = dir + "/case.json";
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(ReadFileToString(json_path));
  } catch (const nlohmann::json::exception& e) {
    throw Error(json_path, "", std::string("malformed JSON: ") + e.what());
  }
  SweepMesh mesh;
  std::vector<RandomCut> cuts;
  int degree = 1;
  std::vector<std::array<double, 3>> quadratic_nodes;
  try {
    mesh.name = j.at("mesh").get<std::string>();
    degree = j.value("degree", 1);
    if (j.contains("quadratic_nodes"))
      quadratic_nodes = j.at("quadratic_nodes").get<std::vector<std::array<double, 3>>>();
    for (const auto& c : j.at("cuts")) {
      RandomCut cut;
      cut.kind = RandomCutKindFromName(c.at("kind").get<std::string>(), json_path);
      const SurfaceMesh s = ReadSurfaceMesh(dir + "/" + c.at("surface").get<std::string>());
      cut.surface.vertices = s.vertices;
      cut.surface.triangles = s.faces;
      const auto& o = c.at("options");
      cut.options.method =
          ParseRemeshMethod(o.at("method").get<std::string>(), json_path, "cuts[].options.method");
      cut.options.snap_epsilon = o.at("snap_epsilon").get<double>();
      cut.options.on_surface_tolerance = o.at("on_surface_tolerance").get<double>();
      cut.options.min_barycentric = o.at("min_barycentric").get<double>();
      cut.options.min_flip_quality = o.at("min_flip_quality").get<double>();
      // Cases saved before the option existed replay with its default.
      if (o.contains("min_element_quality"))
        cut.options.min_element_quality = o.at("min_element_quality").get<double>();
      cut.options.feature_angle_deg = o.at("feature_angle_deg").get<double>();
      cut.options.separate = o.at("separate").get<bool>();
      cut.options.move_front_vertices = o.at("move_front_vertices").get<bool>();
      cuts.push_back(std::move(cut));
    }
  } catch (const nlohmann::json::exception& e) {
    throw Error(json_path, "", std::string("missing or mistyped field: ") + e.what());
  }
  mesh.mesh = ReadTetMesh(dir + "/initial.vtk");
  if (FileExists(dir + "/structure.obj")) mesh.structure = ReadSurfaceMesh(dir + "/structure.obj");
  ARREG_CHECK_INPUT(degree == 1 || degree == 2, json_path, "degree", "must be 1 or 2, got ",
                    degree);
  mesh.quadratic_nodes.resize(static_cast<Eigen::Index>(quadratic_nodes.size()), 3);
  for (size_t n = 0; n < quadratic_nodes.size(); ++n)
    for (int c = 0; c < 3; ++c) mesh.quadratic_nodes(n, c) = quadratic_nodes[n][c];
  return degree == 2 ? Replay<QuadraticSequenceRunner>(mesh, cuts, j)
                     : Replay<SequenceRunner>(mesh, cuts, j);
}

}  // namespace arreg::cutting
