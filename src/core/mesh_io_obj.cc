// Wavefront .obj: positions (optional per-vertex colours), texture
// coordinates, normals; polygons split into fans; negative (relative) indices.
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "core/log.h"
#include "core/mesh_io_internal.h"

namespace arreg::mesh_io_internal {

namespace {

struct Corner {
  int v = -1, vt = -1, vn = -1;
};

// "7", "7/2", "7//3", "7/2/3": 1-based or negative (relative to the end).
Corner ParseCorner(const TextScanner& s, std::string_view token, int nv, int nvt, int nvn) {
  Corner c;
  int* targets[3] = {&c.v, &c.vt, &c.vn};
  const int counts[3] = {nv, nvt, nvn};
  const char* names[3] = {"vertex", "texture coordinate", "normal"};
  size_t start = 0;
  for (int part = 0; part < 3 && start <= token.size(); ++part) {
    const size_t slash = token.find('/', start);
    const std::string_view field = token.substr(
        start, slash == std::string_view::npos ? std::string_view::npos : slash - start);
    if (!field.empty()) {
      const int64_t i = s.ParseInt(field, std::string(names[part]) + " index");
      const int64_t index = i > 0 ? i - 1 : counts[part] + i;
      if (i == 0 || index < 0 || index >= counts[part])
        s.Fail(std::string(names[part]) + " index " + std::to_string(i) +
               " out of range: " + std::to_string(counts[part]) + " defined so far");
      *targets[part] = static_cast<int>(index);
    } else if (part == 0) {
      s.Fail("face corner '" + Printable(token) + "' has no vertex index");
    }
    if (slash == std::string_view::npos) break;
    start = slash + 1;
  }
  return c;
}

}  // namespace

void ReadObj(const std::string& path, std::string_view text, MeshFileData* out) {
  out->format = "obj";
  TextScanner s(path, text);
  std::vector<double> xyz, rgb, uv, normals;
  std::vector<int> faces, face_uvs;
  std::vector<Corner> corners;
  bool all_colored = true, faces_with_uv = false, faces_without_uv = false;
  std::vector<int> vertex_normal;  // per vertex: normal index, -1 none, -2 conflicting
  std::vector<double> normal_sum;
  int64_t nv = 0, nvt = 0, nvn = 0;
  while (!s.AtEnd()) {
    const std::string_view key = s.TokenOnLine();
    if (key.empty() || key[0] == '#') {
      s.SkipRestOfLine();
      continue;
    }
    if (key == "v") {
      double p[3];
      p[0] = s.DoubleOnLine("x coordinate");
      p[1] = s.DoubleOnLine("y coordinate");
      p[2] = s.DoubleOnLine("z coordinate");
      xyz.insert(xyz.end(), p, p + 3);
      double extra[4];
      int num_extra = 0;
      while (num_extra < 4 && !s.AtEndOfLine()) extra[num_extra++] = s.DoubleOnLine("colour");
      if (num_extra == 3)
        rgb.insert(rgb.end(), extra, extra + 3);
      else
        all_colored = false;
      s.ExpectEndOfLine("the vertex");
      ++nv;
      if (nv > std::numeric_limits<int>::max() / 4) s.Fail("too many vertices");
    } else if (key == "vt") {
      uv.push_back(s.DoubleOnLine("u coordinate"));
      uv.push_back(s.AtEndOfLine() ? 0.0 : s.DoubleOnLine("v coordinate"));
      s.SkipRestOfLine();  // optional w
      ++nvt;
      if (nvt > std::numeric_limits<int>::max() / 4) s.Fail("too many texture coordinates");
    } else if (key == "vn") {
      normals.push_back(s.DoubleOnLine("normal x"));
      normals.push_back(s.DoubleOnLine("normal y"));
      normals.push_back(s.DoubleOnLine("normal z"));
      s.ExpectEndOfLine("the normal");
      ++nvn;
      if (nvn > std::numeric_limits<int>::max() / 4) s.Fail("too many normals");
    } else if (key == "f") {
      corners.clear();
      for (std::string_view t = s.TokenOnLine(); !t.empty(); t = s.TokenOnLine())
        corners.push_back(
            ParseCorner(s, t, static_cast<int>(nv), static_cast<int>(nvt), static_cast<int>(nvn)));
      if (corners.size() < 3)
        s.Fail("face with " + std::to_string(corners.size()) + " corners (at least 3 expected)");
      bool has_uv = corners[0].vt >= 0;
      for (const Corner& c : corners)
        if ((c.vt >= 0) != has_uv) s.Fail("face gives texture coordinates for some corners only");
      (has_uv ? faces_with_uv : faces_without_uv) = true;
      ++out->element_counts[corners.size() == 3   ? "triangle"
                            : corners.size() == 4 ? "quadrangle"
                                                  : "polygon"];
      for (size_t k = 1; k + 1 < corners.size(); ++k) {
        for (const Corner* c : {&corners[0], &corners[k], &corners[k + 1]}) {
          faces.push_back(c->v);
          face_uvs.push_back(c->vt);
        }
      }
      if (vertex_normal.size() < static_cast<size_t>(nv)) {
        vertex_normal.resize(static_cast<size_t>(nv), -1);
        normal_sum.resize(static_cast<size_t>(nv) * 3, 0.0);
      }
      for (const Corner& c : corners) {
        if (c.vn < 0) continue;
        int& assigned = vertex_normal[c.v];
        if (assigned == -1)
          assigned = c.vn;
        else if (assigned != c.vn)
          assigned = -2;
        for (int k = 0; k < 3; ++k) normal_sum[c.v * 3 + k] += normals[c.vn * 3 + k];
      }
      s.SkipRestOfLine();
    } else if (key == "l" || key == "p") {
      ++out->element_counts[key == "l" ? "line" : "point"];
      s.SkipRestOfLine();
    } else {
      // Groups, objects, smoothing groups, materials: not part of the geometry.
      s.SkipRestOfLine();
    }
  }
  out->vertices = ToMatrix<RowMatX3d>(xyz, 3);
  out->triangles = ToMatrix<RowMatX3i>(faces, 3);
  if (nv > 0 && all_colored) out->colors = ToMatrix<RowMatX3d>(rgb, 3);
  if (faces_with_uv) {
    if (faces_without_uv) {
      ARREG_LOG_WARNING(path, ": some faces have texture coordinates and some do not; uvs dropped");
    } else {
      out->uvs = ToMatrix<RowMatX2d>(uv, 2);
      out->face_uvs = ToMatrix<RowMatX3i>(face_uvs, 3);
    }
  }
  bool any_normal = false;
  for (int n : vertex_normal) any_normal |= n != -1;
  if (any_normal) {
    out->normals = RowMatX3d::Zero(nv, 3);
    for (size_t v = 0; v < vertex_normal.size(); ++v) {
      const int n = vertex_normal[v];
      if (n >= 0) {
        out->normals.row(static_cast<Eigen::Index>(v)) << normals[n * 3], normals[n * 3 + 1],
            normals[n * 3 + 2];
      } else if (n == -2) {
        // Corners of this vertex disagree (a crease): keep the mean direction.
        Eigen::Vector3d sum(normal_sum[v * 3], normal_sum[v * 3 + 1], normal_sum[v * 3 + 2]);
        if (sum.norm() > 0) sum.normalize();
        out->normals.row(static_cast<Eigen::Index>(v)) = sum.transpose();
      }
    }
  }
}

std::string WriteObj(const MeshFileData& d, const MeshWriteOptions& options) {
  std::string out;
  const Eigen::Index nv = d.vertices.rows(), nf = d.triangles.rows();
  out.reserve(
      static_cast<size_t>(nv * 60 + d.uvs.rows() * 40 + d.normals.rows() * 60 + nf * 40 + 64));
  out += "# written by arreg\n";
  const bool colors = d.colors.rows() == nv && nv > 0;
  for (Eigen::Index i = 0; i < nv; ++i) {
    out += 'v';
    for (int k = 0; k < 3; ++k) {
      out += ' ';
      AppendDouble(&out, d.vertices(i, k), options.precision);
    }
    if (colors)
      for (int k = 0; k < 3; ++k) {
        out += ' ';
        AppendDouble(&out, d.colors(i, k), options.precision);
      }
    out += '\n';
  }
  for (Eigen::Index i = 0; i < d.uvs.rows(); ++i) {
    out += "vt ";
    AppendDouble(&out, d.uvs(i, 0), options.precision);
    out += ' ';
    AppendDouble(&out, d.uvs(i, 1), options.precision);
    out += '\n';
  }
  const bool normals = d.normals.rows() == nv && nv > 0;
  if (normals)
    for (Eigen::Index i = 0; i < nv; ++i) {
      out += "vn";
      for (int k = 0; k < 3; ++k) {
        out += ' ';
        AppendDouble(&out, d.normals(i, k), options.precision);
      }
      out += '\n';
    }
  const bool uvs = d.face_uvs.rows() == nf && nf > 0;
  for (Eigen::Index f = 0; f < nf; ++f) {
    out += 'f';
    for (int k = 0; k < 3; ++k) {
      out += ' ';
      AppendInt(&out, d.triangles(f, k) + 1);
      if (uvs || normals) {
        out += '/';
        if (uvs) AppendInt(&out, d.face_uvs(f, k) + 1);
        if (normals) {
          out += '/';
          AppendInt(&out, d.triangles(f, k) + 1);
        }
      }
    }
    out += '\n';
  }
  return out;
}

}  // namespace arreg::mesh_io_internal
