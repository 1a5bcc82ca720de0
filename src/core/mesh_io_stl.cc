// STL, ASCII and binary (told apart by the binary size formula, since binary
// headers may also start with "solid"); identical vertices are merged.
#include <Eigen/Geometry>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>
#include <unordered_map>
#include <vector>

#include "core/mesh_io_internal.h"

namespace arreg::mesh_io_internal {

namespace {

struct PointKey {
  uint64_t bits[3];
  bool operator==(const PointKey& o) const {
    return bits[0] == o.bits[0] && bits[1] == o.bits[1] && bits[2] == o.bits[2];
  }
};
struct PointKeyHash {
  size_t operator()(const PointKey& k) const {
    uint64_t h = k.bits[0] * 0x9E3779B97F4A7C15ULL;
    h ^= k.bits[1] + 0x9E3779B97F4A7C15ULL + (h << 6) + (h >> 2);
    h ^= k.bits[2] + 0x9E3779B97F4A7C15ULL + (h << 6) + (h >> 2);
    return static_cast<size_t>(h ^ (h >> 29));
  }
};

// Merges bit-identical positions (+0 and -0 count as the same).
class VertexMerger {
 public:
  explicit VertexMerger(size_t expected) { map_.reserve(expected); }
  int Add(double x, double y, double z) {
    const double p[3] = {x + 0.0, y + 0.0, z + 0.0};
    PointKey key;
    std::memcpy(key.bits, p, sizeof(p));
    const auto [it, inserted] = map_.emplace(key, static_cast<int>(xyz_.size() / 3));
    if (inserted) xyz_.insert(xyz_.end(), p, p + 3);
    return it->second;
  }
  const std::vector<double>& xyz() const { return xyz_; }

 private:
  std::unordered_map<PointKey, int, PointKeyHash> map_;
  std::vector<double> xyz_;
};

bool StartsWithSolid(std::string_view text) {
  size_t i = 0;
  while (i < text.size() && std::isspace(static_cast<unsigned char>(text[i]))) ++i;
  return text.compare(i, 5, "solid") == 0;
}

void ReadBinaryStl(const std::string& path, std::string_view text, MeshFileData* out) {
  out->format = "stl binary";
  BinaryCursor c(path, text, 80);
  const uint32_t count = c.Read<uint32_t>(false);
  VertexMerger merger(static_cast<size_t>(count) * 3 / 2);
  std::vector<int> faces;
  faces.reserve(static_cast<size_t>(count) * 3);
  for (uint32_t t = 0; t < count; ++t) {
    c.Skip(12);  // facet normal: recomputed from the vertices when needed
    for (int k = 0; k < 3; ++k) {
      float p[3];
      for (int a = 0; a < 3; ++a) {
        p[a] = c.Read<float>(false);
        if (!std::isfinite(p[a])) {
          BinaryCursor at(path, text, c.offset() - 4);
          at.Fail("triangle " + std::to_string(t) + " has a coordinate that is not finite");
        }
      }
      faces.push_back(merger.Add(p[0], p[1], p[2]));
    }
    c.Skip(2);  // attribute byte count
  }
  out->vertices = ToMatrix<RowMatX3d>(merger.xyz(), 3);
  out->triangles = ToMatrix<RowMatX3i>(faces, 3);
  out->element_counts["triangle"] = static_cast<int>(count);
}

void Expect(TextScanner& s, std::string_view expected) {
  const std::string_view t = s.Token();
  if (t != expected)
    s.Fail("expected '" + std::string(expected) + "', found " +
           (t.empty() ? std::string("end of file") : "'" + Printable(t) + "'"));
}

void ReadAsciiStl(const std::string& path, std::string_view text, MeshFileData* out) {
  out->format = "stl ascii";
  TextScanner s(path, text);
  VertexMerger merger(text.size() / 100);
  std::vector<int> faces;
  int solids = 0;
  for (;;) {
    const std::string_view t = s.Token();
    if (t.empty()) break;
    if (t != "solid") s.Fail("expected 'solid', found '" + Printable(t) + "'");
    s.SkipRestOfLine();  // solid name
    ++solids;
    for (;;) {
      const std::string_view key = s.Token();
      if (key == "endsolid") {
        s.SkipRestOfLine();
        break;
      }
      if (key != "facet")
        s.Fail("expected 'facet' or 'endsolid', found " +
               (key.empty() ? std::string("end of file") : "'" + Printable(key) + "'"));
      Expect(s, "normal");
      for (int a = 0; a < 3; ++a) s.Double("facet normal component");
      Expect(s, "outer");
      Expect(s, "loop");
      for (int k = 0; k < 3; ++k) {
        Expect(s, "vertex");
        const double x = s.Double("x coordinate");
        const double y = s.Double("y coordinate");
        const double z = s.Double("z coordinate");
        faces.push_back(merger.Add(x, y, z));
      }
      Expect(s, "endloop");
      Expect(s, "endfacet");
    }
  }
  if (solids == 0) s.Fail("no 'solid' in the file");
  out->vertices = ToMatrix<RowMatX3d>(merger.xyz(), 3);
  out->triangles = ToMatrix<RowMatX3i>(faces, 3);
  out->element_counts["triangle"] = static_cast<int>(faces.size() / 3);
}

}  // namespace

void ReadStl(const std::string& path, std::string_view text, MeshFileData* out) {
  if (text.size() >= 84) {
    uint32_t count = 0;
    std::memcpy(&count, text.data() + 80, 4);  // little-endian hosts only, as STL
    if (84 + 50 * static_cast<uint64_t>(count) == text.size()) {
      ReadBinaryStl(path, text, out);
      return;
    }
    if (!StartsWithSolid(text))
      throw Error(path, "byte offset 80",
                  "binary STL header says " + std::to_string(count) + " triangles (" +
                      std::to_string(84 + 50 * static_cast<uint64_t>(count)) +
                      " bytes) but the file has " + std::to_string(text.size()) +
                      " bytes: truncated or not an STL file");
  }
  if (!StartsWithSolid(text))
    throw Error(path, "byte offset 0", "not an STL file: too short for binary and no 'solid'");
  ReadAsciiStl(path, text, out);
}

std::string WriteStl(const MeshFileData& d, const MeshWriteOptions& options) {
  const Eigen::Index nf = d.triangles.rows();
  std::string out;
  auto normal = [&](Eigen::Index f) {
    const Eigen::Vector3d a = d.vertices.row(d.triangles(f, 0)).transpose();
    const Eigen::Vector3d b = d.vertices.row(d.triangles(f, 1)).transpose();
    const Eigen::Vector3d c = d.vertices.row(d.triangles(f, 2)).transpose();
    const Eigen::Vector3d n = (b - a).cross(c - a);
    const double length = n.norm();
    return length > 0 ? Eigen::Vector3d(n / length) : Eigen::Vector3d::Zero();
  };
  if (options.binary) {
    out.reserve(static_cast<size_t>(84 + 50 * nf));
    std::string header = "binary STL written by arreg";
    header.resize(80, ' ');
    out += header;
    AppendBinary<uint32_t>(&out, static_cast<uint32_t>(nf), false);
    for (Eigen::Index f = 0; f < nf; ++f) {
      const Eigen::Vector3d n = normal(f);
      for (int a = 0; a < 3; ++a) AppendBinary<float>(&out, static_cast<float>(n[a]), false);
      for (int k = 0; k < 3; ++k)
        for (int a = 0; a < 3; ++a)
          AppendBinary<float>(&out, static_cast<float>(d.vertices(d.triangles(f, k), a)), false);
      AppendBinary<uint16_t>(&out, 0, false);
    }
    return out;
  }
  out.reserve(static_cast<size_t>(nf * 250 + 64));
  out += "solid arreg\n";
  for (Eigen::Index f = 0; f < nf; ++f) {
    const Eigen::Vector3d n = normal(f);
    out += "facet normal";
    for (int a = 0; a < 3; ++a) {
      out += ' ';
      AppendDouble(&out, n[a], options.precision);
    }
    out += "\n outer loop\n";
    for (int k = 0; k < 3; ++k) {
      out += "  vertex";
      for (int a = 0; a < 3; ++a) {
        out += ' ';
        AppendDouble(&out, d.vertices(d.triangles(f, k), a), options.precision);
      }
      out += '\n';
    }
    out += " endloop\nendfacet\n";
  }
  out += "endsolid arreg\n";
  return out;
}

}  // namespace arreg::mesh_io_internal
