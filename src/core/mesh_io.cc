#include "core/mesh_io.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <ostream>
#include <vector>

#include "core/error.h"
#include "core/file_util.h"
#include "core/mesh_io_internal.h"

namespace arreg {

namespace mi = mesh_io_internal;

namespace mesh_io_internal {

int64_t TextScanner::ParseInt(std::string_view token, std::string_view what) const {
  std::string_view t = token;
  if (!t.empty() && t[0] == '+') t.remove_prefix(1);
  int64_t value = 0;
  const auto [ptr, ec] = std::from_chars(t.data(), t.data() + t.size(), value);
  if (ec == std::errc::result_out_of_range)
    Fail("integer '" + Printable(token) + "' out of range for " + std::string(what));
  if (ec != std::errc() || ptr != t.data() + t.size() || t.empty())
    Fail("expected an integer " + std::string(what) + ", found '" + Printable(token) + "'");
  return value;
}

double TextScanner::ParseDouble(std::string_view token, std::string_view what) const {
  std::string_view t = token;
  if (!t.empty() && t[0] == '+') t.remove_prefix(1);
  double value = 0;
  const auto [ptr, ec] = std::from_chars(t.data(), t.data() + t.size(), value);
  bool ok = ec == std::errc() && ptr == t.data() + t.size() && !t.empty();
  if (ec == std::errc::result_out_of_range && ptr == t.data() + t.size()) {
    // from_chars reports subnormal results as out of range; strtod gives them.
    const std::string copy(t);
    value = std::strtod(copy.c_str(), nullptr);
    ok = true;
  }
  if (!ok) Fail("expected a number " + std::string(what) + ", found '" + Printable(token) + "'");
  if (!std::isfinite(value))
    Fail(std::string(what) + " is not finite ('" + Printable(token) + "')");
  return value;
}

int TextScanner::CheckCount(int64_t count, size_t min_bytes_each, std::string_view what) const {
  if (count < 0) Fail("negative " + std::string(what) + " (" + std::to_string(count) + ")");
  if (count > std::numeric_limits<int>::max() / 16)
    Fail("absurd " + std::string(what) + " (" + std::to_string(count) + ")");
  if (static_cast<uint64_t>(count) * min_bytes_each > remaining_bytes())
    Fail(std::string(what) + " " + std::to_string(count) + " cannot fit in the rest of the file (" +
         std::to_string(remaining_bytes()) + " bytes left): truncated file or wrong count");
  return static_cast<int>(count);
}

void AppendDouble(std::string* out, double value, int precision) {
  char buffer[64];
  const auto result = precision >= 17 ? std::to_chars(buffer, buffer + sizeof(buffer), value)
                                      : std::to_chars(buffer, buffer + sizeof(buffer), value,
                                                      std::chars_format::general, precision);
  out->append(buffer, result.ptr);
}

void AppendInt(std::string* out, int64_t value) {
  char buffer[24];
  const auto result = std::to_chars(buffer, buffer + sizeof(buffer), value);
  out->append(buffer, result.ptr);
}

void MoveEdgeNodesLast(MeshFileData* data) {
  if (data->high_order_nodes.size() == 0) return;
  const int n = static_cast<int>(data->vertices.rows());
  std::vector<char> is_corner(n, 0), is_edge(n, 0);
  for (Eigen::Index i = 0; i < data->tetrahedra.size(); ++i)
    is_corner[data->tetrahedra.data()[i]] = 1;
  for (Eigen::Index i = 0; i < data->triangles.size(); ++i)
    is_corner[data->triangles.data()[i]] = 1;
  for (Eigen::Index i = 0; i < data->high_order_nodes.size(); ++i)
    is_edge[data->high_order_nodes.data()[i]] = 1;
  std::vector<int> order;
  order.reserve(n);
  for (int v = 0; v < n; ++v)
    if (is_corner[v] || !is_edge[v]) order.push_back(v);
  for (int v = 0; v < n; ++v)
    if (!is_corner[v] && is_edge[v]) order.push_back(v);
  std::vector<int> old_to_new(n);
  for (int i = 0; i < n; ++i) old_to_new[order[i]] = i;
  auto permute_rows = [&](RowMatX3d* m) {
    if (m->rows() != n) return;
    RowMatX3d p(n, 3);
    for (int i = 0; i < n; ++i) p.row(i) = m->row(order[i]);
    *m = std::move(p);
  };
  permute_rows(&data->vertices);
  permute_rows(&data->normals);
  permute_rows(&data->colors);
  for (Eigen::Index i = 0; i < data->tetrahedra.size(); ++i)
    data->tetrahedra.data()[i] = old_to_new[data->tetrahedra.data()[i]];
  for (Eigen::Index i = 0; i < data->triangles.size(); ++i)
    data->triangles.data()[i] = old_to_new[data->triangles.data()[i]];
  for (Eigen::Index i = 0; i < data->high_order_nodes.size(); ++i)
    data->high_order_nodes.data()[i] = old_to_new[data->high_order_nodes.data()[i]];
}

}  // namespace mesh_io_internal

namespace {

enum class Format { kMsh, kVtk, kObj, kStl, kOff };

Format FormatFromPath(const std::string& path) {
  const std::string ext = MeshFileExtension(path);
  if (ext == ".msh") return Format::kMsh;
  if (ext == ".vtk") return Format::kVtk;
  if (ext == ".obj") return Format::kObj;
  if (ext == ".stl") return Format::kStl;
  if (ext == ".off") return Format::kOff;
  throw Error(
      path, "",
      "unknown mesh file extension '" + ext + "' (expected .msh, .vtk, .obj, .stl or .off)");
}

// Index checks shared by every reader (a last line of defence: the parsers
// already report bad indices with their line) and by the writers.
template <typename Matrix>
void CheckIndices(const std::string& path, const Matrix& m, int limit, const char* what,
                  const char* target) {
  for (Eigen::Index r = 0; r < m.rows(); ++r)
    for (Eigen::Index c = 0; c < m.cols(); ++c) {
      const int v = m(r, c);
      if (v < 0 || v >= limit)
        throw Error(path, std::string(what) + " " + std::to_string(r),
                    "index " + std::to_string(v) + " out of range: there are " +
                        std::to_string(limit) + " " + target);
    }
}

void Validate(const std::string& path, const MeshFileData& d) {
  const int n = static_cast<int>(d.vertices.rows());
  for (Eigen::Index r = 0; r < d.vertices.rows(); ++r)
    if (!d.vertices.row(r).allFinite())
      throw Error(path, "vertex " + std::to_string(r), "coordinate is not finite");
  CheckIndices(path, d.tetrahedra, n, "tetrahedron", "vertices");
  CheckIndices(path, d.triangles, n, "triangle", "vertices");
  if (d.high_order_nodes.size() > 0) {
    if (d.high_order_nodes.rows() != d.tetrahedra.rows() || d.high_order_nodes.cols() != 6)
      throw Error(path, "high_order_nodes", "expected one row of 6 edge nodes per tetrahedron");
    CheckIndices(path, d.high_order_nodes, n, "tetrahedron", "vertices");
  }
  if (d.face_uvs.size() > 0) {
    if (d.face_uvs.rows() != d.triangles.rows())
      throw Error(path, "face_uvs", "expected one row of uv indices per triangle");
    CheckIndices(path, d.face_uvs, static_cast<int>(d.uvs.rows()), "face", "texture coordinates");
  }
  if (d.normals.rows() != 0 && d.normals.rows() != n)
    throw Error(path, "normals", "expected one normal per vertex");
  if (d.colors.rows() != 0 && d.colors.rows() != n)
    throw Error(path, "colors", "expected one colour per vertex");
}

MeshFileData ReadAny(const std::string& path, Format format) {
  const std::string text = ReadFileToString(path);
  if (text.empty()) throw Error(path, "", "file is empty");
  MeshFileData data;
  switch (format) {
    case Format::kMsh:
      mi::ReadMsh(path, text, &data);
      break;
    case Format::kVtk:
      mi::ReadVtk(path, text, &data);
      break;
    case Format::kObj:
      mi::ReadObj(path, text, &data);
      break;
    case Format::kStl:
      mi::ReadStl(path, text, &data);
      break;
    case Format::kOff:
      mi::ReadOff(path, text, &data);
      break;
  }
  Validate(path, data);
  return data;
}

void WriteAny(const std::string& path, const MeshFileData& data, bool volume,
              const MeshWriteOptions& options) {
  options.Check();
  const Format format = FormatFromPath(path);
  Validate(path, data);
  std::string contents;
  switch (format) {
    case Format::kMsh:
      contents = mi::WriteMsh(data, options);
      break;
    case Format::kVtk:
      contents = mi::WriteVtk(data, volume, options);
      break;
    case Format::kObj:
      contents = mi::WriteObj(data, options);
      break;
    case Format::kStl:
      contents = mi::WriteStl(data, options);
      break;
    case Format::kOff:
      contents = mi::WriteOff(data, options);
      break;
  }
  WriteFileAtomic(
      path,
      [&](std::ostream& os) {
        os.write(contents.data(), static_cast<std::streamsize>(contents.size()));
      },
      /*binary=*/true);
}

}  // namespace

void MeshWriteOptions::Check() const {
  if (precision < 1 || precision > 17)
    throw Error("", "MeshWriteOptions.precision",
                "must be in [1, 17], got " + std::to_string(precision));
  if (msh_version != MshVersion::kV22 && msh_version != MshVersion::kV41)
    throw Error("", "MeshWriteOptions.msh_version", "must be kV22 or kV41");
}

std::string MeshFileExtension(const std::string& path) {
  const size_t slash = path.find_last_of("/\\");
  const size_t dot = path.find_last_of('.');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
  std::string ext = path.substr(dot);
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

MeshFileData ReadMeshFile(const std::string& path) { return ReadAny(path, FormatFromPath(path)); }

TetMesh ReadTetMesh(const std::string& path) {
  const Format format = FormatFromPath(path);
  if (format != Format::kMsh && format != Format::kVtk)
    throw Error(path, "", "a tetrahedral mesh must be a .msh or .vtk file");
  MeshFileData data = ReadAny(path, format);
  if (data.tetrahedra.rows() == 0)
    throw Error(path, "", "the file contains no tetrahedra (" + data.format + ")");
  TetMesh mesh;
  mesh.vertices = std::move(data.vertices);
  mesh.tetrahedra = std::move(data.tetrahedra);
  mesh.high_order_nodes = std::move(data.high_order_nodes);
  mesh.triangles = std::move(data.triangles);
  return mesh;
}

SurfaceMesh ReadSurfaceMesh(const std::string& path) {
  MeshFileData data = ReadMeshFile(path);
  if (data.triangles.rows() == 0)
    throw Error(path, "",
                data.tetrahedra.rows() > 0
                    ? "the file contains tetrahedra but no triangles (read it with ReadTetMesh and "
                      "take its boundary)"
                    : "the file contains no triangles");
  SurfaceMesh mesh;
  mesh.vertices = std::move(data.vertices);
  mesh.faces = std::move(data.triangles);
  mesh.uvs = std::move(data.uvs);
  mesh.face_uvs = std::move(data.face_uvs);
  mesh.normals = std::move(data.normals);
  mesh.colors = std::move(data.colors);
  return mesh;
}

void WriteTetMesh(const std::string& path, const TetMesh& mesh, const MeshWriteOptions& options) {
  const Format format = FormatFromPath(path);
  if (format != Format::kMsh && format != Format::kVtk)
    throw Error(path, "",
                "tetrahedral meshes are written as .msh or .vtk; for a surface format write "
                "ExtractBoundary(mesh) with WriteSurfaceMesh");
  MeshFileData data;
  data.vertices = mesh.vertices;
  data.tetrahedra = mesh.tetrahedra;
  data.high_order_nodes = mesh.high_order_nodes;
  data.triangles = mesh.triangles;
  WriteAny(path, data, /*volume=*/true, options);
}

void WriteObjGroups(const std::string& path, const std::vector<SurfaceMesh>& meshes,
                    const std::vector<std::string>& names, const std::string& what) {
  WriteFileAtomic(path, [&](std::ostream& out) {
    out << "# arreg run: " << what << "\n";
    char line[128];
    int base = 1;
    for (size_t k = 0; k < meshes.size(); ++k) {
      out << "o " << (k < names.size() ? names[k] : "structure" + std::to_string(k)) << "\n";
      const SurfaceMesh& m = meshes[k];
      for (int i = 0; i < m.vertices.rows(); ++i) {
        std::snprintf(line, sizeof(line), "v %.9g %.9g %.9g\n", m.vertices(i, 0), m.vertices(i, 1),
                      m.vertices(i, 2));
        out << line;
      }
      for (int i = 0; i < m.faces.rows(); ++i)
        out << "f " << m.faces(i, 0) + base << " " << m.faces(i, 1) + base << " "
            << m.faces(i, 2) + base << "\n";
      base += static_cast<int>(m.vertices.rows());
    }
  });
}

void WriteSurfaceMesh(const std::string& path, const SurfaceMesh& mesh,
                      const MeshWriteOptions& options) {
  MeshFileData data;
  data.vertices = mesh.vertices;
  data.triangles = mesh.faces;
  data.uvs = mesh.uvs;
  data.face_uvs = mesh.face_uvs;
  data.normals = mesh.normals;
  data.colors = mesh.colors;
  WriteAny(path, data, /*volume=*/false, options);
}

}  // namespace arreg
