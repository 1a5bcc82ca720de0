// Geometry and topology of tetrahedral and triangle meshes: volumes, boundary
// extraction, connected components, element quality and orientation repair.
#pragma once

#include <Eigen/Core>
#include <limits>

#include "core/mesh.h"

namespace arreg {

// ---- Tetrahedra -------------------------------------------------------------

// Signed volume of tetrahedron (a, b, c, d): ((b-a) x (c-a)) . (d-a) / 6.
// Positive for the orientation convention of TetMesh (units: length^3).
double SignedVolume(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                    const Eigen::Vector3d& d);

// (#T) signed volume of every tetrahedron. Indices must be valid.
Eigen::VectorXd TetVolumes(const TetMesh& mesh);

// Smallest of the six interior dihedral angles, in radians (regular
// tetrahedron: acos(1/3) ~ 70.53 deg; 0 for a degenerate one). Independent of
// orientation.
double MinDihedralAngle(const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                        const Eigen::Vector3d& c, const Eigen::Vector3d& d);

// Radius ratio 3 * inradius / circumradius, in [0, 1] for positively oriented
// tetrahedra (1 for the regular one). Negative for inverted ones (signed
// volume enters), 0 for degenerate ones.
double RadiusRatio(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                   const Eigen::Vector3d& d);

// Quality figures over a whole tetrahedral mesh.
struct TetQualitySummary {
  int num_tetrahedra = 0;
  int num_inverted = 0;     // signed volume < 0
  int num_degenerate = 0;   // |volume| <= 1e-12 * (mean edge length)^3
  double total_volume = 0;  // sum of signed volumes (length^3)
  double min_volume = 0;    // smallest signed volume (length^3)
  double max_volume = 0;    // largest signed volume (length^3)
  double min_dihedral_angle_rad = 0;
  double max_dihedral_angle_rad = 0;
  double min_radius_ratio = 0;
  double mean_radius_ratio = 0;
};
// All fields are 0 for a mesh without tetrahedra.
TetQualitySummary ComputeTetQuality(const TetMesh& mesh);

// Largest of the six interior dihedral angles, in radians.
double MaxDihedralAngle(const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                        const Eigen::Vector3d& c, const Eigen::Vector3d& d);

// Swaps the last two vertices of every tetrahedron with negative signed
// volume (and reorders its high-order edge nodes to match). Returns how many
// were flipped. Degenerate (zero-volume) tetrahedra are left as they are.
int FixOrientation(TetMesh* mesh);

// Boundary of a tetrahedral mesh: every face that belongs to exactly one
// tetrahedron, oriented outward (counter-clockwise seen from outside, using
// each tetrahedron's own orientation). `vertices` is a copy of the tet mesh's
// vertices, so face indices refer to the tet mesh; unreferenced (interior)
// vertices stay in the array. uvs/normals/colors are empty.
SurfaceMesh ExtractBoundary(const TetMesh& mesh);

// Which elements count as connected.
enum class Adjacency {
  kFace,    // tetrahedra sharing a triangle / triangles sharing an edge
  kVertex,  // elements sharing at least one vertex
};

// Component label (0 .. count-1, numbered by first element) of every
// tetrahedron; *num_components receives the count when not null.
Eigen::VectorXi ConnectedComponents(const TetMesh& mesh, Adjacency adjacency,
                                    int* num_components = nullptr);
// Same for the faces of a surface mesh (kFace means sharing an edge).
Eigen::VectorXi ConnectedComponents(const SurfaceMesh& mesh, Adjacency adjacency,
                                    int* num_components = nullptr);

// ---- Surfaces ---------------------------------------------------------------

// Sum of triangle areas (length^2).
double SurfaceArea(const SurfaceMesh& mesh);

// Volume enclosed by a closed, consistently oriented surface (divergence
// theorem: sum over faces of a . (b x c) / 6); positive when the faces are
// counter-clockwise seen from outside. Meaningless for open surfaces.
double EnclosedVolume(const SurfaceMesh& mesh);

// Edge-based topology of a triangle surface.
struct SurfaceTopology {
  int num_referenced_vertices = 0;  // vertices used by at least one face
  int num_edges = 0;                // distinct undirected edges
  int num_faces = 0;
  int num_boundary_edges = 0;     // edges with one incident face
  int num_nonmanifold_edges = 0;  // edges with more than two incident faces
  int num_misoriented_edges = 0;  // interior edges traversed twice in the same direction
  int num_degenerate_faces = 0;   // faces that repeat a vertex index
  int euler_characteristic = 0;   // V - E + F over referenced vertices
  bool closed() const { return num_faces > 0 && num_boundary_edges == 0; }
  // Every edge has exactly two faces, traversed in opposite directions.
  bool closed_oriented_manifold() const {
    return closed() && num_nonmanifold_edges == 0 && num_misoriented_edges == 0 &&
           num_degenerate_faces == 0;
  }
};
SurfaceTopology AnalyzeSurface(const SurfaceMesh& mesh);

// Removes vertices no face refers to (keeping the per-vertex normals/colors in
// step and leaving uvs alone). old_to_new (#V_old) gets -1 for removed ones.
void RemoveUnreferencedVertices(SurfaceMesh* mesh, Eigen::VectorXi* old_to_new = nullptr);

// Axis-aligned bounds of a (#V x 3) point set; min > max when it is empty.
struct BoundingBox {
  Eigen::Vector3d min = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector3d max = Eigen::Vector3d::Constant(-std::numeric_limits<double>::infinity());
  bool empty() const { return (min.array() > max.array()).any(); }
  Eigen::Vector3d size() const {
    return empty() ? Eigen::Vector3d::Zero() : Eigen::Vector3d(max - min);
  }
};
BoundingBox ComputeBoundingBox(const RowMatX3d& points);

}  // namespace arreg
