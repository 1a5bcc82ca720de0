// Object File Format .off (ASCII): OFF, COFF (vertex colours), NOFF (vertex
// normals) and CNOFF headers; polygons split into fans; '#' comments.
#include <string>
#include <vector>

#include "core/mesh_io_internal.h"

namespace arreg::mesh_io_internal {

namespace {

// Next token, skipping '#' comments up to the end of their line.
std::string_view OffToken(TextScanner& s) {
  for (;;) {
    const std::string_view t = s.Token();
    if (t.empty() || t[0] != '#') return t;
    s.SkipRestOfLine();
  }
}

int64_t OffInt(TextScanner& s, const char* what) {
  const std::string_view t = OffToken(s);
  if (t.empty()) s.Fail(std::string("expected ") + what + ", found end of file");
  return s.ParseInt(t, what);
}

double OffDouble(TextScanner& s, const char* what) {
  const std::string_view t = OffToken(s);
  if (t.empty()) s.Fail(std::string("expected ") + what + ", found end of file");
  return s.ParseDouble(t, what);
}

}  // namespace

void ReadOff(const std::string& path, std::string_view text, MeshFileData* out) {
  TextScanner s(path, text);
  const std::string_view header = OffToken(s);
  if (header.size() < 3 || header.substr(header.size() - 3) != "OFF")
    s.Fail("not an OFF file: expected OFF, COFF, NOFF or CNOFF, found '" + Printable(header) + "'");
  const std::string_view prefix = header.substr(0, header.size() - 3);
  if (prefix != "" && prefix != "C" && prefix != "N" && prefix != "CN")
    s.Fail("unsupported OFF variant '" + Printable(header) + "'");
  if (!s.AtEndOfLine()) {
    const std::string_view next = s.TokenOnLine();
    if (next == "BINARY") s.Fail("binary OFF files are not supported");
    // Counts on the header line: parse them as the first numbers.
    s.Seek(s.offset() - next.size());
  }
  const bool has_normals = prefix.find('N') != std::string_view::npos;
  const bool has_colors = prefix.find('C') != std::string_view::npos;
  out->format = "off";
  const int nv = s.CheckCount(OffInt(s, "number of vertices"), 6, "number of vertices");
  const int nf = s.CheckCount(OffInt(s, "number of faces"), 6, "number of faces");
  OffInt(s, "number of edges");
  s.SkipRestOfLine();
  std::vector<double> xyz, normals, colors;
  xyz.reserve(static_cast<size_t>(nv) * 3);
  for (int v = 0; v < nv; ++v) {
    for (int a = 0; a < 3; ++a) xyz.push_back(OffDouble(s, "vertex coordinate"));
    if (has_normals)
      for (int a = 0; a < 3; ++a) normals.push_back(OffDouble(s, "normal component"));
    if (has_colors) {
      double rgba[4] = {0, 0, 0, 1};
      int n = 0;
      bool integer = true;
      while (n < 4 && !s.AtEndOfLine()) {
        const std::string_view t = s.TokenOnLine();
        if (t[0] == '#') break;
        integer &= t.find_first_of(".eE") == std::string_view::npos;
        rgba[n++] = s.ParseDouble(t, "colour component");
      }
      if (n < 3) s.Fail("expected an RGB colour after the vertex");
      // Integer colours are 0..255, real ones 0..1.
      for (int a = 0; a < 3; ++a) colors.push_back(integer ? rgba[a] / 255.0 : rgba[a]);
    }
    s.SkipRestOfLine();
  }
  std::vector<int> faces;
  faces.reserve(static_cast<size_t>(nf) * 3);
  for (int f = 0; f < nf; ++f) {
    const int64_t n = OffInt(s, "number of face vertices");
    if (n < 3 || n > 100000)
      s.Fail("face " + std::to_string(f) + " has " + std::to_string(n) + " vertices");
    ++out->element_counts[n == 3 ? "triangle" : n == 4 ? "quadrangle" : "polygon"];
    int first = -1, previous = -1;
    for (int64_t k = 0; k < n; ++k) {
      const std::string_view t = s.TokenOnLine();
      if (t.empty())
        s.Fail("face " + std::to_string(f) + " ends after " + std::to_string(k) + " of " +
               std::to_string(n) + " vertices");
      const int64_t index = s.ParseInt(t, "vertex index");
      if (index < 0 || index >= nv)
        s.Fail("face " + std::to_string(f) + " refers to vertex " + std::to_string(index) +
               " but there are " + std::to_string(nv));
      const int i = static_cast<int>(index);
      if (k == 0)
        first = i;
      else if (k >= 2)
        faces.insert(faces.end(), {first, previous, i});
      previous = i;
    }
    s.SkipRestOfLine();  // optional face colour
  }
  out->vertices = ToMatrix<RowMatX3d>(xyz, 3);
  out->triangles = ToMatrix<RowMatX3i>(faces, 3);
  if (has_normals) out->normals = ToMatrix<RowMatX3d>(normals, 3);
  if (has_colors) out->colors = ToMatrix<RowMatX3d>(colors, 3);
}

std::string WriteOff(const MeshFileData& d, const MeshWriteOptions& options) {
  std::string out;
  const Eigen::Index nv = d.vertices.rows(), nf = d.triangles.rows();
  const bool colors = d.colors.rows() == nv && nv > 0;
  const bool normals = d.normals.rows() == nv && nv > 0;
  out.reserve(static_cast<size_t>(nv * (60 + 60 * colors + 60 * normals) + nf * 30 + 64));
  out += colors ? "C" : "";
  out += normals ? "N" : "";
  out += "OFF\n";
  AppendInt(&out, nv);
  out += ' ';
  AppendInt(&out, nf);
  out += " 0\n";
  for (Eigen::Index i = 0; i < nv; ++i) {
    for (int a = 0; a < 3; ++a) {
      if (a) out += ' ';
      AppendDouble(&out, d.vertices(i, a), options.precision);
    }
    if (normals)
      for (int a = 0; a < 3; ++a) {
        out += ' ';
        AppendDouble(&out, d.normals(i, a), options.precision);
      }
    if (colors) {
      for (int a = 0; a < 3; ++a) {
        out += ' ';
        // Always with a decimal point so the reader takes them as 0..1 reals.
        std::string value;
        AppendDouble(&value, d.colors(i, a), options.precision);
        if (value.find_first_of(".eE") == std::string::npos) value += ".0";
        out += value;
      }
      out += " 1.0";
    }
    out += '\n';
  }
  for (Eigen::Index f = 0; f < nf; ++f) {
    out += '3';
    for (int k = 0; k < 3; ++k) {
      out += ' ';
      AppendInt(&out, d.triangles(f, k));
    }
    out += '\n';
  }
  return out;
}

}  // namespace arreg::mesh_io_internal
