// Facts about a mesh file for `arreg info`: element counts, topology of the
// boundary, volume/area, bounding box and element quality, as text or JSON.
#pragma once

#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "core/mesh_io.h"
#include "core/mesh_ops.h"

namespace arreg {

struct MeshInfo {
  std::string path;
  std::string format;  // MeshFileData::format
  int vertices = 0;    // all nodes, edge nodes included
  int tetrahedra = 0;
  bool quadratic = false;                     // 10-node tetrahedra
  int triangles = 0;                          // triangles in the file (polygons split)
  std::map<std::string, int> element_counts;  // as found in the file
  bool has_uvs = false, has_normals = false, has_colors = false;
  BoundingBox bounding_box;

  // Tetrahedral meshes (tetrahedra > 0).
  int boundary_triangles = 0;  // faces of exactly one tetrahedron
  int tet_components = 0;      // tetrahedra connected through faces
  TetQualitySummary quality;   // signed volumes and shape measures
  double volume = 0;           // sum of |tet volume| (length^3); enclosed volume for surfaces

  // The surface examined: the file's triangles, or the tets' boundary.
  SurfaceTopology surface;
  int surface_components = 0;  // triangles connected through edges
  double area = 0;             // length^2
  // Enclosed volume of the surface when it is a closed oriented manifold
  // (signed: negative when the triangles face inward).
  std::optional<double> enclosed_volume;
};

// Reads `path` (any supported format) and measures it. Throws arreg::Error on
// unreadable files.
MeshInfo DescribeMeshFile(const std::string& path);

// JSON with at least the keys "vertices", "tetrahedra", "triangles", "volume".
nlohmann::json MeshInfoToJson(const MeshInfo& info);

// Human-readable multi-line description.
std::string MeshInfoToText(const MeshInfo& info);

}  // namespace arreg
