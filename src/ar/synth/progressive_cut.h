// A cut as a real separation in a tetrahedral mesh: the faces approximating a
// cut surface are made conforming (vertices snapped onto it) and opened as the
// cut advances, duplicating the vertices around which the mesh comes apart.
#pragma once

#include <Eigen/Core>
#include <functional>
#include <limits>
#include <vector>

#include "core/mesh.h"

namespace arreg::synth {

// Cut surface in rest coordinates (mm).
struct CutSurfaceSpec {
  // Signed function whose zero set is the cut surface; tetrahedra are assigned
  // to the side of the sign at their rest centroid.
  std::function<double(const Eigen::Vector3d&)> level_set;
  // How far (mm along the cut's path) the cut must have advanced to reach a
  // point; +infinity outside the part of the surface that is ever cut.
  std::function<double(const Eigen::Vector3d&)> progress_mm;
};

struct ProgressiveCutOptions {
  // Vertices of cut faces closer to the surface than this fraction of their
  // shortest incident edge are moved onto it, default 0.45.
  double snap_fraction = 0.45;
  // When > 0, the length (mm) the snap fraction applies to instead of the shortest incident edge:
  // for thin slabs, whose through-thickness edges are much shorter than the in-plane ones the
  // (in-plane) snaps move along. Default 0.
  double snap_reference_mm = 0;
  // A snap is undone when it shrinks an incident tetrahedron below this fraction
  // of its volume, default 0.2.
  double min_volume_fraction_after_snap = 0.2;
  void Check() const;
};

class ProgressiveCut {
 public:
  // Finds the faces between tetrahedra on opposite sides of the cut surface
  // within its extent, snaps their vertices onto the surface (changes
  // `rest_mesh->vertices`) and starts with every face closed.
  ProgressiveCut(TetMesh* rest_mesh, const CutSurfaceSpec& spec,
                 const ProgressiveCutOptions& options = {});

  // Opens every cut face whose progress is <= advance_mm. Returns true when
  // new faces opened (the split topology changed).
  bool Advance(double advance_mm);

  // Split topology for the current opening: tetrahedra over split vertex ids
  // (#T x 4) and, per split vertex, its original vertex. Vertex ids of one
  // split differ from another's; carry positions per tetrahedron corner.
  struct Split {
    RowMatX4i tetrahedra;
    std::vector<int> origin;  // (#V') original vertex of each split vertex
  };
  Split ComputeSplit() const;

  int num_faces() const { return static_cast<int>(faces_.size()); }
  int num_open_faces() const;
  int num_snapped_vertices() const { return snapped_; }
  // Cut faces in rest coordinates (#F x 3 original vertex ids), oriented from
  // the negative towards the positive side, with their opening progress (mm).
  RowMatX3i FaceTriangles() const;
  std::vector<double> FaceProgress() const;
  std::vector<bool> FaceOpen() const;
  // Tetrahedron side: +1 or -1.
  const std::vector<int>& tet_side() const { return side_; }

 private:
  struct Face {
    int tet_a, tet_b;              // tet_a on the negative side
    int local_a;                   // local face index in tet_a (TetFace)
    int corner_a[3], corner_b[3];  // local vertex index of the face's vertices in a and b
    double progress_mm;
    bool open = false;
  };
  RowMatX4i tets_;
  int num_vertices_ = 0;
  std::vector<int> side_;
  std::vector<Face> faces_;            // cut faces
  std::vector<Face> closed_interior_;  // every other interior face (never opens)
  int snapped_ = 0;
};

}  // namespace arreg::synth
