#include "core/mesh_info.h"

#include <cmath>
#include <cstdio>
#include <sstream>

namespace arreg {

namespace {

constexpr double kRadToDeg = 180.0 / 3.14159265358979323846;

nlohmann::json Vec(const Eigen::Vector3d& v) {
  return nlohmann::json::array({v.x(), v.y(), v.z()});
}

std::string Format(const char* fmt, double value) {
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), fmt, value);
  return buffer;
}

}  // namespace

MeshInfo DescribeMeshFile(const std::string& path) {
  MeshFileData data = ReadMeshFile(path);
  MeshInfo info;
  info.path = path;
  info.format = data.format;
  info.vertices = static_cast<int>(data.vertices.rows());
  info.tetrahedra = static_cast<int>(data.tetrahedra.rows());
  info.quadratic = data.high_order_nodes.size() > 0;
  info.triangles = static_cast<int>(data.triangles.rows());
  info.element_counts = data.element_counts;
  info.has_uvs = data.uvs.rows() > 0;
  info.has_normals = data.normals.rows() > 0;
  info.has_colors = data.colors.rows() > 0;
  info.bounding_box = ComputeBoundingBox(data.vertices);

  SurfaceMesh surface;
  if (info.tetrahedra > 0) {
    TetMesh mesh;
    mesh.vertices = std::move(data.vertices);
    mesh.tetrahedra = std::move(data.tetrahedra);
    info.quality = ComputeTetQuality(mesh);
    info.volume = TetVolumes(mesh).cwiseAbs().sum();
    ConnectedComponents(mesh, Adjacency::kFace, &info.tet_components);
    surface = ExtractBoundary(mesh);
    info.boundary_triangles = surface.num_faces();
  } else {
    surface.vertices = std::move(data.vertices);
    surface.faces = std::move(data.triangles);
  }
  info.surface = AnalyzeSurface(surface);
  ConnectedComponents(surface, Adjacency::kFace, &info.surface_components);
  info.area = SurfaceArea(surface);
  if (info.surface.closed_oriented_manifold()) info.enclosed_volume = EnclosedVolume(surface);
  if (info.tetrahedra == 0 && info.enclosed_volume) info.volume = std::abs(*info.enclosed_volume);
  return info;
}

nlohmann::json MeshInfoToJson(const MeshInfo& info) {
  nlohmann::json j;
  j["file"] = info.path;
  j["format"] = info.format;
  j["vertices"] = info.vertices;
  j["tetrahedra"] = info.tetrahedra;
  j["quadratic"] = info.quadratic;
  j["triangles"] = info.triangles;
  j["elements"] = info.element_counts;
  j["uvs"] = info.has_uvs;
  j["normals"] = info.has_normals;
  j["colors"] = info.has_colors;
  if (!info.bounding_box.empty())
    j["bounding_box"] = {{"min", Vec(info.bounding_box.min)},
                         {"max", Vec(info.bounding_box.max)},
                         {"size", Vec(info.bounding_box.size())}};
  // null when nothing is known (an open surface has no volume).
  j["volume"] = info.tetrahedra > 0 || info.enclosed_volume ? nlohmann::json(info.volume)
                                                            : nlohmann::json(nullptr);
  if (info.tetrahedra > 0) {
    const TetQualitySummary& q = info.quality;
    j["boundary_triangles"] = info.boundary_triangles;
    j["components"] = info.tet_components;
    j["inverted_elements"] = q.num_inverted;
    j["degenerate_elements"] = q.num_degenerate;
    j["min_tet_volume"] = q.min_volume;
    j["max_tet_volume"] = q.max_volume;
    j["min_dihedral_angle_deg"] = q.min_dihedral_angle_rad * kRadToDeg;
    j["max_dihedral_angle_deg"] = q.max_dihedral_angle_rad * kRadToDeg;
    j["min_radius_ratio"] = q.min_radius_ratio;
    j["mean_radius_ratio"] = q.mean_radius_ratio;
  } else {
    j["components"] = info.surface_components;
  }
  const SurfaceTopology& t = info.surface;
  j["surface"] = {{"triangles", t.num_faces},
                  {"components", info.surface_components},
                  {"area", info.area},
                  {"closed", t.closed()},
                  {"manifold", t.num_nonmanifold_edges == 0},
                  {"consistently_oriented", t.num_misoriented_edges == 0},
                  {"boundary_edges", t.num_boundary_edges},
                  {"nonmanifold_edges", t.num_nonmanifold_edges},
                  {"degenerate_triangles", t.num_degenerate_faces},
                  {"euler_characteristic", t.euler_characteristic},
                  {"enclosed_volume", info.enclosed_volume ? nlohmann::json(*info.enclosed_volume)
                                                           : nlohmann::json(nullptr)}};
  return j;
}

std::string MeshInfoToText(const MeshInfo& info) {
  std::ostringstream os;
  os << info.path << " (" << info.format << ")\n";
  os << "  vertices            " << info.vertices << "\n";
  std::string elements;
  for (const auto& [kind, count] : info.element_counts)
    elements += (elements.empty() ? "" : ", ") + std::to_string(count) + " " + kind;
  os << "  elements            " << (elements.empty() ? "none" : elements) << "\n";
  if (info.tetrahedra > 0) {
    const TetQualitySummary& q = info.quality;
    os << "  tetrahedra          " << info.tetrahedra << (info.quadratic ? " (quadratic)" : "")
       << ", " << q.num_inverted << " inverted, " << q.num_degenerate << " degenerate\n";
    os << "  components          " << info.tet_components << " (tetrahedra sharing faces)\n";
    os << "  volume              " << info.volume << " (sum of |tet volume|)\n";
    os << "  tet volume          min " << q.min_volume << ", max " << q.max_volume << "\n";
    os << "  dihedral angle      min " << Format("%.2f", q.min_dihedral_angle_rad * kRadToDeg)
       << " deg, max " << Format("%.2f", q.max_dihedral_angle_rad * kRadToDeg) << " deg\n";
    os << "  radius ratio        min " << Format("%.4f", q.min_radius_ratio) << ", mean "
       << Format("%.4f", q.mean_radius_ratio) << "\n";
    os << "  boundary            " << info.boundary_triangles << " triangles";
  } else {
    os << "  triangles           " << info.triangles;
  }
  const SurfaceTopology& t = info.surface;
  os << ", " << info.surface_components << " component(s), area " << info.area << "\n";
  os << "  surface topology    "
     << (t.closed() ? "closed" : std::to_string(t.num_boundary_edges) + " boundary edges") << ", "
     << (t.num_nonmanifold_edges == 0
             ? "manifold"
             : std::to_string(t.num_nonmanifold_edges) + " non-manifold edges")
     << ", "
     << (t.num_misoriented_edges == 0
             ? "consistently oriented"
             : std::to_string(t.num_misoriented_edges) + " misoriented edges")
     << ", Euler characteristic " << t.euler_characteristic << "\n";
  if (info.tetrahedra == 0) {
    os << "  enclosed volume     ";
    if (info.enclosed_volume)
      os << *info.enclosed_volume << "\n";
    else
      os << "n/a (not a closed, consistently oriented manifold)\n";
  }
  if (!info.bounding_box.empty()) {
    const BoundingBox& b = info.bounding_box;
    os << "  bounding box        [" << b.min.x() << ", " << b.max.x() << "] x [" << b.min.y()
       << ", " << b.max.y() << "] x [" << b.min.z() << ", " << b.max.z() << "], size "
       << b.size().x() << " x " << b.size().y() << " x " << b.size().z() << "\n";
  }
  std::string extras;
  if (info.has_uvs) extras += " uvs";
  if (info.has_normals) extras += " normals";
  if (info.has_colors) extras += " colours";
  if (!extras.empty()) os << "  attributes         " << extras << "\n";
  return os.str();
}

}  // namespace arreg
