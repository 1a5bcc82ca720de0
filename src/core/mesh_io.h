// Reading and writing tetrahedral and surface meshes: Gmsh .msh (1, 2.2, 4.1
// ASCII), VTK legacy .vtk (ASCII/binary), .obj, .stl (ASCII/binary) and .off.
#pragma once

#include <map>
#include <string>
#include <vector>

#include "core/mesh.h"

namespace arreg {

// Gmsh format version written for .msh files.
enum class MshVersion {
  kV22,  // "2.2 0 8": read by Gmsh, SOFA, meshio, TetGen tools
  kV41,  // "4.1 0 8": current Gmsh default (with an $Entities section)
};

struct MeshWriteOptions {
  // Binary variant where the format has one (.vtk: big-endian legacy binary,
  // .stl: binary STL); ignored for the text-only formats .obj, .off, .msh.
  // Default: false (ASCII).
  bool binary = false;
  // Version of .msh output. Default: 2.2.
  MshVersion msh_version = MshVersion::kV22;
  // Significant digits of coordinates in text formats, 1..17. 17 (default)
  // writes the shortest text that reads back to the identical double.
  int precision = 17;

  // Throws arreg::Error naming the field when a value is out of range.
  void Check() const;
};

// Everything a reader found in a file, before it is narrowed to a TetMesh or
// a SurfaceMesh. Indices are 0-based and checked against `vertices`.
struct MeshFileData {
  std::string format;         // e.g. "msh 1", "msh 2.2", "vtk binary polydata", "stl binary"
  RowMatX3d vertices;         // (#V x 3); quadratic edge nodes come after all corner nodes
  RowMatX4i tetrahedra;       // (#T x 4) linear tets and the corners of quadratic ones
  RowMatXi high_order_nodes;  // (#T x 6) edge nodes (ab, ac, ad, bc, bd, cd) or 0 x 0
  RowMatX3i triangles;        // (#F x 3) triangles; polygons are split into fans
  RowMatX2d uvs;              // (#UV x 2) texture coordinates (obj, vtk)
  RowMatX3i face_uvs;         // (#F x 3) indices into uvs, or empty
  RowMatX3d normals;          // (#V x 3) per-vertex normals, or empty
  RowMatX3d colors;           // (#V x 3) per-vertex RGB in [0,1], or empty
  // Elements as found in the file, by kind ("tetrahedron", "triangle",
  // "quadrangle", "polygon", "line", "point", "hexahedron", ...): counts before
  // polygons are split. Kinds that are not kept (lines, hexahedra...) appear
  // here and nowhere else.
  std::map<std::string, int> element_counts;
};

// Reads any supported file (format from the extension, case-insensitive).
// Throws arreg::Error naming the file and the line (text) or byte offset
// (binary) on malformed content, and for an unknown extension.
MeshFileData ReadMeshFile(const std::string& path);

// A tetrahedral mesh from .msh (1, 2.2, 4.1 ASCII) or .vtk (UNSTRUCTURED_GRID).
// Surface elements of the file go to `triangles`. Throws arreg::Error when
// the file holds no tetrahedra. Orientation is kept as in the file (see
// FixOrientation in mesh_ops.h).
TetMesh ReadTetMesh(const std::string& path);

// A triangle surface from .obj, .stl, .off, .vtk (POLYDATA, or the triangle
// cells of an UNSTRUCTURED_GRID) or .msh (triangle elements). STL vertices
// are merged when their coordinates are bit-identical. Throws arreg::Error
// when the file holds no triangles.
SurfaceMesh ReadSurfaceMesh(const std::string& path);

// Writes a tetrahedral mesh (with its `triangles`) as .msh or .vtk
// (UNSTRUCTURED_GRID); other extensions throw arreg::Error. The file appears
// atomically (complete or not at all).
void WriteTetMesh(const std::string& path, const TetMesh& mesh,
                  const MeshWriteOptions& options = {});

// Writes a surface mesh as .obj (with uvs and normals), .stl, .off, .vtk
// (POLYDATA with NORMALS/TEXTURE_COORDINATES when they are per vertex) or
// .msh (triangle elements). Atomic like WriteTetMesh.
void WriteSurfaceMesh(const std::string& path, const SurfaceMesh& mesh,
                      const MeshWriteOptions& options = {});

// Writes several surfaces into one OBJ file, one `o NAME` group each (vertices
// and faces only, 9 significant digits), after a `# arreg run: WHAT` comment:
// the internal/NNNNNN.obj and thin/NNNNNN.obj records (docs/run-format.md).
// A mesh without a name in `names` is called structureK. Atomic like WriteTetMesh.
void WriteObjGroups(const std::string& path, const std::vector<SurfaceMesh>& meshes,
                    const std::vector<std::string>& names, const std::string& what);

// Lower-case extension with the dot (".msh"), "" when there is none.
std::string MeshFileExtension(const std::string& path);

}  // namespace arreg
