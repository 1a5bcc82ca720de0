// Invariants a cut must keep (conforming, positive elements, manifold
// boundary), measured on a tetrahedral mesh for tests, benchmarks and logging.
#pragma once

#include <string>

#include "core/mesh.h"

namespace arreg::cutting {

struct MeshInvariants {
  int num_nonpositive = 0;           // elements with exact orientation <= 0
  int num_repeated_vertex = 0;       // elements naming a vertex twice
  int num_overshared_faces = 0;      // faces shared by more than two elements
  int num_duplicate_elements = 0;    // two elements on the same four vertices
  int num_nonmanifold_edges = 0;     // boundary edges not in exactly two boundary faces
  int num_nonmanifold_vertices = 0;  // boundary vertices whose boundary faces form != 1 fan cycle
  int num_unreferenced_vertices = 0;
  double total_volume = 0;  // sum of signed element volumes
  double min_quality = 0;   // smallest normalised volume (see TetQuality)
  double min_dihedral_deg = 0;

  bool ok() const {
    return num_nonpositive == 0 && num_repeated_vertex == 0 && num_overshared_faces == 0 &&
           num_duplicate_elements == 0 && num_nonmanifold_edges == 0 &&
           num_nonmanifold_vertices == 0;
  }
  std::string ToString() const;
};

MeshInvariants CheckMeshInvariants(const TetMesh& mesh);

}  // namespace arreg::cutting
