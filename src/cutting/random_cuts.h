// Random cut sequences that stress the remesher: a seeded generator of cut surfaces of many
// kinds, each made for the mesh the previous cuts left, and a sweep that checks the mesh, its
// volume, its internal structure and one implicit mechanics step after every cut.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <functional>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "core/mesh.h"
#include "cutting/cut_surface.h"
#include "cutting/tet_cutter.h"

namespace arreg::cutting {

enum class RandomCutKind {
  kPlane,        // a plane through the body
  kSphere,       // a sphere around a point of the body
  kCylinder,     // a cylinder around an axis through the body
  kBentSheet,    // a sheet bent like a sine wave along one direction
  kPartial,      // half a plane: S ends inside the body (a crack front)
  kCrackFront,   // a strip that starts on the front of an earlier partial cut of the sequence
  kGrazeVertex,  // a plane at 1e-9..1e-3 edge lengths from a vertex
  kGrazeEdge,    // a plane parallel to an edge at 1e-9..1e-3 of its length from it
  kGrazeFace,    // a plane parallel to a face at 1e-9..1e-3 of its mean edge length from it
};
constexpr int kNumRandomCutKinds = 9;
const char* RandomCutKindName(RandomCutKind kind);
// Throws arreg::Error naming the field `where` for an unknown name.
RandomCutKind RandomCutKindFromName(const std::string& name, const std::string& where);

struct RandomCutOptions {
  int max_cuts_per_sequence = 20;  // sequences have 1..this many cuts (>= 1); default 20
  // Grazing cuts: the distance of S to the grazed vertex/edge/face is log-uniform in
  // [min, max] x the reference edge length (0 < min <= max; defaults 1e-9 and 1e-3).
  double min_graze_fraction = 1e-9;
  double max_graze_fraction = 1e-3;
  void Check() const;  // throws arreg::Error naming the field
};

// One generated cut, with what the generator meant by it (for the tests and the saved cases).
struct RandomCut {
  RandomCutKind kind = RandomCutKind::kPlane;
  CutSurface surface;
  CutOptions options;
  // Grazing kinds: the grazed vertex (1 index), edge (2) or face (3), the distance of S's plane
  // to each of them (mm) and the edge length that distance is a fraction of (mm).
  std::vector<int> grazed;
  double graze_distance_mm = 0;
  double graze_reference_mm = 0;
  // Partial and crack-front cuts: the free edge of S (where it ends inside the body) and the
  // direction S advances across it (in S, perpendicular to the edge).
  bool has_front = false;
  std::array<Eigen::Vector3d, 2> front{Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero()};
  Eigen::Vector3d front_direction = Eigen::Vector3d::Zero();
  // Crack-front cuts: the earlier front S starts on (S's first row of grid vertices lies on it).
  std::array<Eigen::Vector3d, 2> start{Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero()};
};

// Draws cuts for one sequence. Surfaces are placed with the mesh's current positions (the
// frame CuttableMesh::Cut works in) and sized from its bounding box and edge lengths.
class RandomCutGenerator {
 public:
  explicit RandomCutGenerator(std::uint64_t seed, const RandomCutOptions& options = {});
  // A cut of a random kind (a crack-front cut needs an earlier partial cut: without one it
  // becomes a partial cut), with random remeshing options.
  RandomCut Next(const CuttableMesh& mesh);
  RandomCut Next(const CuttableMesh& mesh, RandomCutKind kind);
  // Tells the generator how the cut went: the front of a cut made (kCut) is remembered for
  // later crack-front cuts.
  void Record(const RandomCut& cut, CutStatus status);
  int num_fronts() const { return static_cast<int>(fronts_.size()); }

 private:
  RandomCutOptions options_;
  std::mt19937_64 rng_;
  std::vector<RandomCut> fronts_;  // cuts made with a front
};

// A mesh the sweep cuts: rest = current positions, positively oriented elements.
struct SweepMesh {
  std::string name;
  TetMesh mesh;
  SurfaceMesh structure;  // an internal structure (closed, outward), or no faces
  // Degree-2 sweeps: the control points of mechanics::RaiseTetMesh(mesh, 2) (#N x 3, that
  // numbering), e.g. a raise onto a smooth surface; empty for the straight raise.
  RowMatX3d quadratic_nodes;
};

// The control points of mechanics::RaiseTetMesh(box, 2) with the faces of the box [0, size]
// bulged outwards by bulge_mm x sin(pi u) sin(pi v) (u, v the face's coordinates over [0, 1]: zero
// on the box's edges), the interior ones relaxed (RaiseTetMeshOntoSurface): a mesh with curved rest
// elements for the degree-2 sweep and tests. `box` spans [0, size].
RowMatX3d BulgedBoxQuadraticNodes(const TetMesh& box, const Eigen::Vector3d& size, double bulge_mm);

struct SweepOptions {
  // Cuts drawn (>= 1; default 1000): the sequences' lengths sum to it. Fewer are made when
  // sequences end early (max_tetrahedra, a violation).
  int num_cuts = 1000;
  std::uint64_t seed = 1;  // default 1
  RandomCutOptions cuts;
  // Directory for the offending cases (one folder each, see SaveCase); "" = none. Default "".
  std::string save_failures_dir;
  // A sequence ends early once its mesh has more elements than this (>= 1; default 10,000):
  // repeated cuts refine the mesh (docs/cutting.md, "Limits"), and a model of that size is
  // beyond the real-time budget the remesher is made for.
  int max_tetrahedra = 10000;
  int threads = 1;  // sequences cut in parallel (>= 1; the result does not depend on it)
  // Element degree: 1 (CuttableMesh) or 2 (QuadraticCuttableMesh on the meshes raised to degree
  // 2); default 1.
  int degree = 1;
  void Check() const;  // throws arreg::Error naming the field
};

// A check that failed after a cut.
struct Violation {
  std::string mesh;
  std::uint64_t seed = 0;  // the sweep's seed
  int sequence = 0;        // sequence number within the sweep
  int index = 0;           // cut number within the sequence (0-based)
  RandomCutKind kind = RandomCutKind::kPlane;
  std::string check;  // exception, positive, conforming, manifold, zero-volume, volume,
                      // mechanics-state, mechanics, structure; degree 2: quadratic-conforming,
                      // jacobian
  std::string detail;
  std::string saved_dir;  // where the case was written, or ""
};

struct KindCounts {
  int cuts = 0;         // cuts generated (and made)
  int crossed = 0;      // status kCut
  int no_crossing = 0;  // status kNoCrossing
  int rejected = 0;     // status kRejected (mesh unchanged: not a violation)
  int violations = 0;
  double seconds = 0;  // cutting and checking
  void Add(const KindCounts& other);
};

struct SweepResult {
  int cuts = 0;  // cuts made (a violation ends its sequence, so it can be < num_cuts)
  int sequences = 0;
  int stopped_by_growth = 0;  // sequences ended early by max_tetrahedra
  double seconds = 0;
  std::vector<Violation> violations;
  std::map<std::string, std::map<std::string, KindCounts>> counts;  // mesh -> kind -> counts
};

// Cuts the meshes in turn, in sequences of 1..max_cuts_per_sequence cuts (each on the mesh the
// previous ones left), num_cuts drawn in all. Sequence s runs on mesh s mod #meshes with its length
// and generator seeded from (seed, s), so (seed, s) reproduces it. After every cut:
// CheckMeshInvariants (positive elements, conforming, manifold boundary), every element's rest
// volume positive as the mechanics compute it (zero-volume), rest volume to 1e-9
// relative, a mechanical state that follows the change (ApplyCutChange) gives the cut mesh,
// one implicit Euler step under gravity (the 10 % of the mesh lowest along x held fixed)
// converges with finite positions, and, for a mesh with a structure, SplitAlongCrack succeeds
// and each connected piece of the split is a closed oriented manifold. A violation ends its
// sequence (later cuts would cut a broken mesh). With degree 2 the cutter is a
// QuadraticCuttableMesh and the checks are the corner mesh's above (mechanics and structure
// aside), CheckQuadraticMesh (one control point per edge: quadratic-conforming; det J > 0 at the
// sampled points: jacobian) and the quadratic elements' rest volume to 1e-9 relative (volume).
// `progress` (optional) is called after every sequence, from one thread at a time.
SweepResult RunRandomCutSweep(const std::vector<SweepMesh>& meshes, const SweepOptions& options,
                              const std::function<void(int done, int total)>& progress = {});

// Writes an offending case to `dir` (created): initial.vtk (the sweep mesh), structure.obj
// (when it has one), before.vtk (the rest mesh before the failing cut), cut_NNN.obj (every cut
// of the sequence up to the failing one, in order) and case.json (mesh, seed, sequence, index,
// check, detail, degree, the mesh's quadratic_nodes when it has them, and per cut its kind and
// CutOptions). Files are written atomically.
void SaveCase(const std::string& dir, const SweepMesh& mesh, const std::vector<RandomCut>& cuts,
              const Violation& violation, int degree = 1);

// Replays a case written by SaveCase: the cuts in order on initial.vtk with every check. Returns
// the violations found (at most one: a sequence stops at its first); throws arreg::Error naming
// the file for a missing or malformed case.
std::vector<Violation> ReplayCase(const std::string& dir);

}  // namespace arreg::cutting
