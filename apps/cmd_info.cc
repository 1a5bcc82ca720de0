// `arreg info FILE [--json]`: what a mesh file holds (counts, topology,
// volume or area, bounding box, element quality), as text or JSON.
#include <cstdio>
#include <string>

#include "commands.h"
#include "core/mesh_info.h"
#include "option_parser.h"

namespace arreg::cli {

int RunInfo(int argc, char** argv) {
  std::string path;
  bool json = false;
  OptionParser parser("arreg info FILE [--json]",
                      "Describes a mesh file (.msh, .vtk, .obj, .stl, .off): vertices, elements by "
                      "type, boundary triangles, connected components, volume (tetrahedra) or "
                      "area and enclosed volume (closed surfaces), bounding box, dihedral angles, "
                      "radius ratios and inverted elements. Lengths are in the file's units.");
  parser.AddPositional("FILE", &path, "mesh file; the format follows the extension");
  parser.AddFlag("json", &json, "print JSON instead of text");
  parser.SetEpilog(
      "JSON keys: file, format, vertices, tetrahedra, quadratic, triangles, elements, uvs, "
      "normals, colors, bounding_box {min,max,size}, volume, components, and for tetrahedral "
      "meshes boundary_triangles, inverted_elements, degenerate_elements, min/max_tet_volume, "
      "min/max_dihedral_angle_deg, min/mean_radius_ratio; surface {triangles, components, area, "
      "closed, manifold, consistently_oriented, boundary_edges, nonmanifold_edges, "
      "degenerate_triangles, euler_characteristic, enclosed_volume}.\n\n"
      "example: arreg info liver.msh --json");
  if (!parser.Parse(argc, argv)) return 0;
  const MeshInfo info = DescribeMeshFile(path);
  if (json)
    std::printf("%s\n", MeshInfoToJson(info).dump(2).c_str());
  else
    std::printf("%s", MeshInfoToText(info).c_str());
  return 0;
}

}  // namespace arreg::cli
