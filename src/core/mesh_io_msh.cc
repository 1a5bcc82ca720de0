// Gmsh .msh: reads versions 1, 2.x and 4.1 (ASCII), writes 2.2 and 4.1.
#include <algorithm>
#include <cctype>
#include <string>
#include <unordered_map>
#include <vector>

#include "core/mesh_io_internal.h"
#include "core/mesh_ops.h"

namespace arreg::mesh_io_internal {

namespace {

// Node tags of a file to 0-based indices; tags 1..n in order need no map.
class NodeTags {
 public:
  void Add(int64_t tag, int index, const TextScanner& s) {
    if (sequential_ && tag == index + 1) return;
    if (sequential_) {
      sequential_ = false;
      for (int i = 0; i < index; ++i) map_.emplace(i + 1, i);
    }
    if (!map_.emplace(tag, index).second)
      s.Fail("node number " + std::to_string(tag) + " appears twice");
  }
  int Find(int64_t tag, int count) const {
    if (sequential_) return tag >= 1 && tag <= count ? static_cast<int>(tag - 1) : -1;
    const auto it = map_.find(tag);
    return it == map_.end() ? -1 : it->second;
  }

 private:
  bool sequential_ = true;
  std::unordered_map<int64_t, int> map_;
};

struct GmshType {
  int type;
  int num_nodes;
  const char* name;
};
// The element types a mesh file is likely to hold; others are skipped by line.
constexpr GmshType kGmshTypes[] = {
    {1, 2, "line"},
    {2, 3, "triangle"},
    {3, 4, "quadrangle"},
    {4, 4, "tetrahedron"},
    {5, 8, "hexahedron"},
    {6, 6, "prism"},
    {7, 5, "pyramid"},
    {8, 3, "quadratic line"},
    {9, 6, "quadratic triangle"},
    {10, 9, "quadrangle 9"},
    {11, 10, "quadratic tetrahedron"},
    {15, 1, "point"},
    {16, 8, "quadrangle 8"},
    {17, 20, "hexahedron 20"},
    {12, 27, "hexahedron 27"},
};

const GmshType* FindType(int64_t type) {
  for (const auto& t : kGmshTypes)
    if (t.type == type) return &t;
  return nullptr;
}

// Edge nodes (ab, ac, ad, bc, bd, cd) of Gmsh's 10-node tetrahedron, whose
// nodes 4..9 lie on edges 01, 12, 20, 30, 32, 31.
constexpr int kGmshTet10Edges[6] = {4, 6, 7, 5, 9, 8};

struct Reader {
  Reader(TextScanner& scanner, MeshFileData* data) : s(scanner), out(data) {}
  TextScanner& s;
  MeshFileData* out;
  NodeTags tags;
  int num_nodes = 0;
  bool have_nodes = false;
  std::vector<double> xyz;
  std::vector<int> tets, edges, tris;
  int num_linear_tets = 0, num_quadratic_tets = 0;

  bool IsSectionEnd(std::string_view token) const { return !token.empty() && token[0] == '$'; }

  void BeginNodes(int64_t count) {
    if (have_nodes) s.Fail("second node section");
    have_nodes = true;
    num_nodes = s.CheckCount(count, 6, "number of nodes");
    xyz.reserve(static_cast<size_t>(num_nodes) * 3);
  }

  void AddNode(int64_t tag, const double p[3]) {
    const int index = static_cast<int>(xyz.size() / 3);
    tags.Add(tag, index, s);
    xyz.insert(xyz.end(), p, p + 3);
  }

  int NodeIndex(int64_t tag) {
    const int index = tags.Find(tag, static_cast<int>(xyz.size() / 3));
    if (index < 0)
      s.Fail("element refers to node " + std::to_string(tag) + ", which is not defined");
    return index;
  }

  // Reads the node tags of one element of `type` from the current line and
  // keeps it when it is a triangle, quadrangle or tetrahedron.
  void ReadElementNodes(int64_t type, int64_t explicit_count) {
    if (!have_nodes) s.Fail("elements before the node section");
    const GmshType* known = FindType(type);
    if (!known) {
      ++out->element_counts["gmsh type " + std::to_string(type)];
      s.SkipRestOfLine();
      return;
    }
    if (explicit_count >= 0 && explicit_count != known->num_nodes)
      s.Fail("element of type " + std::to_string(type) + " (" + known->name + ") must have " +
             std::to_string(known->num_nodes) + " nodes, header says " +
             std::to_string(explicit_count));
    ++out->element_counts[known->name];
    int nodes[27];
    for (int k = 0; k < known->num_nodes; ++k) {
      const std::string_view t = s.TokenOnLine();
      if (t.empty())
        s.Fail(std::string("expected ") + std::to_string(known->num_nodes) +
               " node numbers for a " + known->name + ", found " + std::to_string(k));
      nodes[k] = NodeIndex(s.ParseInt(t, "node number"));
    }
    s.ExpectEndOfLine("the element's nodes");
    switch (type) {
      case 2:
      case 9:
        tris.insert(tris.end(), nodes, nodes + 3);
        break;
      case 3:
      case 10:
      case 16:
        tris.insert(tris.end(), {nodes[0], nodes[1], nodes[2], nodes[0], nodes[2], nodes[3]});
        break;
      case 4:
        tets.insert(tets.end(), nodes, nodes + 4);
        ++num_linear_tets;
        break;
      case 11:
        tets.insert(tets.end(), nodes, nodes + 4);
        for (int e : kGmshTet10Edges) edges.push_back(nodes[e]);
        ++num_quadratic_tets;
        break;
      default:
        break;
    }
  }

  // Skips an unknown section up to its $End line.
  void SkipSection(std::string_view name) {
    std::string end = "$End" + std::string(name.substr(1));
    for (;;) {
      if (s.AtEnd()) s.Fail("missing " + end);
      const std::string_view line = s.Line();
      if (line.size() == end.size() &&
          std::equal(line.begin(), line.end(), end.begin(),
                     [](char a, char b) { return std::tolower(a) == std::tolower(b); }))
        return;
    }
  }

  void ExpectLine(std::string_view expected, const char* context) {
    const int line_number = s.line();
    const std::string_view line = s.Line();
    if (line != expected) {
      s.FailAtLine(line_number, "expected " + std::string(expected) + " " + context + ", found '" +
                                    Printable(line) + "'");
    }
  }

  // Next token, which must be a number of the node/element block; "$End..."
  // means the file holds fewer items than its header said.
  int64_t ItemNumber(const char* what, int done, int total) {
    const std::string_view t = s.TokenOnLine();
    if (t.empty() || IsSectionEnd(t))
      s.Fail(std::string("section ends after ") + std::to_string(done) + " of " +
             std::to_string(total) + " " + what + " announced in its header");
    return s.ParseInt(t, std::string(what) == "nodes" ? "node number" : "element number");
  }

  void ReadPoint(double p[3]) {
    p[0] = s.DoubleOnLine("x coordinate");
    p[1] = s.DoubleOnLine("y coordinate");
    p[2] = s.DoubleOnLine("z coordinate");
  }

  // Version 1 and 2 node sections: "count", then "tag x y z" lines.
  void ReadNodesV12(const char* end_marker) {
    BeginNodes(s.IntOnLine("number of nodes"));
    s.ExpectEndOfLine("the number of nodes");
    for (int i = 0; i < num_nodes; ++i) {
      const int64_t tag = ItemNumber("nodes", i, num_nodes);
      double p[3];
      ReadPoint(p);
      s.ExpectEndOfLine("the node's coordinates");
      AddNode(tag, p);
    }
    ExpectLine(end_marker, "after the last node (more nodes than the header says?)");
  }

  void ReadElementsV1() {
    const int count = s.CheckCount(s.IntOnLine("number of elements"), 6, "number of elements");
    s.ExpectEndOfLine("the number of elements");
    for (int i = 0; i < count; ++i) {
      ItemNumber("elements", i, count);
      const int64_t type = s.IntOnLine("element type");
      s.IntOnLine("physical region");
      s.IntOnLine("elementary region");
      const int64_t n = s.IntOnLine("number of nodes");
      if (n < 1 || n > 1000) s.Fail("implausible number of nodes " + std::to_string(n));
      ReadElementNodes(type, n);
    }
    ExpectLine("$ENDELM", "after the last element (more elements than the header says?)");
  }

  void ReadElementsV2() {
    const int count = s.CheckCount(s.IntOnLine("number of elements"), 6, "number of elements");
    s.ExpectEndOfLine("the number of elements");
    for (int i = 0; i < count; ++i) {
      ItemNumber("elements", i, count);
      const int64_t type = s.IntOnLine("element type");
      const int64_t num_tags = s.IntOnLine("number of tags");
      if (num_tags < 0 || num_tags > 100)
        s.Fail("implausible number of tags " + std::to_string(num_tags));
      for (int64_t k = 0; k < num_tags; ++k) s.IntOnLine("element tag");
      ReadElementNodes(type, -1);
    }
    ExpectLine("$EndElements", "after the last element (more elements than the header says?)");
  }

  void ReadNodesV41() {
    const int64_t num_blocks = s.IntOnLine("number of entity blocks");
    BeginNodes(s.IntOnLine("number of nodes"));
    s.SkipRestOfLine();  // min and max tag
    s.CheckCount(num_blocks, 8, "number of node blocks");
    int read = 0;
    std::vector<int64_t> block_tags;
    for (int64_t b = 0; b < num_blocks; ++b) {
      const int64_t dim = s.IntOnLine("entity dimension");
      s.IntOnLine("entity tag");
      const int64_t parametric = s.IntOnLine("parametric flag");
      const int64_t n = s.IntOnLine("number of nodes in block");
      s.ExpectEndOfLine("the node block header");
      if (dim < 0 || dim > 3 || parametric < 0 || parametric > 1)
        s.Fail("malformed node block header");
      if (n < 0 || n > num_nodes - read)
        s.Fail("node block of " + std::to_string(n) + " nodes exceeds the " +
               std::to_string(num_nodes) + " announced");
      block_tags.assign(static_cast<size_t>(n), 0);
      for (int64_t i = 0; i < n; ++i) {
        block_tags[i] = ItemNumber("nodes", read, num_nodes);
        s.ExpectEndOfLine("the node number");
      }
      for (int64_t i = 0; i < n; ++i) {
        double p[3];
        ReadPoint(p);
        s.SkipRestOfLine();  // parametric coordinates
        AddNode(block_tags[i], p);
        ++read;
      }
    }
    if (read != num_nodes)
      s.Fail("node blocks hold " + std::to_string(read) + " nodes, header says " +
             std::to_string(num_nodes));
    ExpectLine("$EndNodes", "after the last node block");
  }

  void ReadElementsV41() {
    const int64_t num_blocks = s.IntOnLine("number of entity blocks");
    const int count = s.CheckCount(s.IntOnLine("number of elements"), 4, "number of elements");
    s.SkipRestOfLine();
    s.CheckCount(num_blocks, 8, "number of element blocks");
    int read = 0;
    for (int64_t b = 0; b < num_blocks; ++b) {
      s.IntOnLine("entity dimension");
      s.IntOnLine("entity tag");
      const int64_t type = s.IntOnLine("element type");
      const int64_t n = s.IntOnLine("number of elements in block");
      s.ExpectEndOfLine("the element block header");
      if (n < 0 || n > count - read)
        s.Fail("element block of " + std::to_string(n) + " elements exceeds the " +
               std::to_string(count) + " announced");
      for (int64_t i = 0; i < n; ++i, ++read) {
        ItemNumber("elements", read, count);
        ReadElementNodes(type, -1);
      }
    }
    if (read != count)
      s.Fail("element blocks hold " + std::to_string(read) + " elements, header says " +
             std::to_string(count));
    ExpectLine("$EndElements", "after the last element block");
  }

  void Finish() {
    if (!have_nodes) s.Fail("no node section ($Nodes or $NOD) in the file");
    if (num_linear_tets > 0 && num_quadratic_tets > 0)
      s.Fail("the file mixes linear and quadratic tetrahedra, which is not supported");
    out->vertices = ToMatrix<RowMatX3d>(xyz, 3);
    out->tetrahedra = ToMatrix<RowMatX4i>(tets, 4);
    out->triangles = ToMatrix<RowMatX3i>(tris, 3);
    if (num_quadratic_tets > 0) {
      out->high_order_nodes = ToMatrix<RowMatXi>(edges, 6);
      MoveEdgeNodesLast(out);
    }
  }
};

}  // namespace

void ReadMsh(const std::string& path, std::string_view text, MeshFileData* out) {
  TextScanner s(path, text);
  Reader r(s, out);
  std::string_view first = s.Line();
  while (first.empty() && !s.AtEnd()) first = s.Line();
  if (first == "$NOD") {
    out->format = "msh 1";
    r.ReadNodesV12("$ENDNOD");
    for (;;) {
      std::string_view line = s.Line();
      while (line.empty() && !s.AtEnd()) line = s.Line();
      if (line.empty()) break;
      if (line == "$ELM")
        r.ReadElementsV1();
      else if (line[0] == '$')
        r.SkipSection(line);
      else
        s.Fail("expected a section ($ELM), found '" + Printable(line) + "'");
    }
    r.Finish();
    return;
  }
  if (first != "$MeshFormat")
    s.Fail("not a Gmsh file: expected $MeshFormat or $NOD, found '" + Printable(first) + "'");
  const std::string_view version = s.TokenOnLine();
  const int64_t file_type = s.IntOnLine("file type (0 = ASCII)");
  s.SkipRestOfLine();
  int major = 0;
  if (version == "2" || version == "2.0" || version == "2.1" || version == "2.2")
    major = 2;
  else if (version == "4.1")
    major = 4;
  else
    s.Fail("unsupported Gmsh version '" + std::string(version.substr(0, 20)) +
           "' (supported: 1, 2.x and 4.1)");
  if (file_type != 0) s.Fail("binary Gmsh files are not supported; save as ASCII");
  out->format = major == 2 ? "msh 2.2" : "msh 4.1";
  r.ExpectLine("$EndMeshFormat", "after the format line");
  for (;;) {
    std::string_view line = s.Line();
    while (line.empty() && !s.AtEnd()) line = s.Line();
    if (line.empty()) break;
    if (line[0] != '$') s.Fail("expected a section name, found '" + Printable(line) + "'");
    if (line == "$Nodes") {
      if (major == 2)
        r.ReadNodesV12("$EndNodes");
      else
        r.ReadNodesV41();
    } else if (line == "$Elements") {
      if (major == 2)
        r.ReadElementsV2();
      else
        r.ReadElementsV41();
    } else {
      r.SkipSection(line);
    }
  }
  r.Finish();
}

namespace {

void AppendPoint(std::string* out, const RowMatX3d& v, Eigen::Index i, int precision) {
  AppendDouble(out, v(i, 0), precision);
  out->push_back(' ');
  AppendDouble(out, v(i, 1), precision);
  out->push_back(' ');
  AppendDouble(out, v(i, 2), precision);
}

// One element's node numbers (1-based) in Gmsh order.
void AppendTetNodes(std::string* out, const MeshFileData& d, Eigen::Index t) {
  const bool quadratic = d.high_order_nodes.size() > 0;
  int nodes[10];
  for (int k = 0; k < 4; ++k) nodes[k] = d.tetrahedra(t, k);
  if (quadratic)
    for (int e = 0; e < 6; ++e) nodes[kGmshTet10Edges[e]] = d.high_order_nodes(t, e);
  for (int k = 0; k < (quadratic ? 10 : 4); ++k) {
    out->push_back(' ');
    AppendInt(out, nodes[k] + 1);
  }
}

}  // namespace

std::string WriteMsh(const MeshFileData& d, const MeshWriteOptions& options) {
  std::string out;
  const Eigen::Index nv = d.vertices.rows(), nt = d.tetrahedra.rows(), nf = d.triangles.rows();
  out.reserve(static_cast<size_t>(nv * 60 + nt * 40 + nf * 30 + 512));
  const bool quadratic = d.high_order_nodes.size() > 0;
  const int tet_type = quadratic ? 11 : 4;
  if (options.msh_version == MshVersion::kV22) {
    out += "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n";
    AppendInt(&out, nv);
    out += '\n';
    for (Eigen::Index i = 0; i < nv; ++i) {
      AppendInt(&out, i + 1);
      out += ' ';
      AppendPoint(&out, d.vertices, i, options.precision);
      out += '\n';
    }
    out += "$EndNodes\n$Elements\n";
    AppendInt(&out, nf + nt);
    out += '\n';
    int64_t id = 1;
    // Tags: physical group 0 (none), elementary entity 1 (volume) / 2 (surface).
    for (Eigen::Index f = 0; f < nf; ++f, ++id) {
      AppendInt(&out, id);
      out += " 2 2 0 2";
      for (int k = 0; k < 3; ++k) {
        out += ' ';
        AppendInt(&out, d.triangles(f, k) + 1);
      }
      out += '\n';
    }
    for (Eigen::Index t = 0; t < nt; ++t, ++id) {
      AppendInt(&out, id);
      out += ' ';
      AppendInt(&out, tet_type);
      out += " 2 0 1";
      AppendTetNodes(&out, d, t);
      out += '\n';
    }
    out += "$EndElements\n";
    return out;
  }

  // 4.1: one surface entity (tag 1) for the triangles, one volume entity
  // (tag 1) for the tetrahedra; all nodes in one block of the highest one.
  const bool has_volume = nt > 0;
  const bool has_surface = nf > 0 || !has_volume;
  const BoundingBox box = ComputeBoundingBox(d.vertices);
  auto append_box = [&] {
    for (int k = 0; k < 3; ++k) {
      out += ' ';
      AppendDouble(&out, box.empty() ? 0.0 : box.min[k], options.precision);
    }
    for (int k = 0; k < 3; ++k) {
      out += ' ';
      AppendDouble(&out, box.empty() ? 0.0 : box.max[k], options.precision);
    }
  };
  out += "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Entities\n0 0 ";
  out += has_surface ? "1 " : "0 ";
  out += has_volume ? "1\n" : "0\n";
  if (has_surface) {
    out += '1';
    append_box();
    out += " 0 0\n";
  }
  if (has_volume) {
    out += '1';
    append_box();
    out += has_surface ? " 0 1 1\n" : " 0 0\n";
  }
  out += "$EndEntities\n$Nodes\n";
  out += nv > 0 ? "1 " : "0 ";
  AppendInt(&out, nv);
  out += nv > 0 ? " 1 " : " 0 ";
  AppendInt(&out, nv);
  out += '\n';
  if (nv > 0) {
    out += has_volume ? "3 1 0 " : "2 1 0 ";
    AppendInt(&out, nv);
    out += '\n';
    for (Eigen::Index i = 0; i < nv; ++i) {
      AppendInt(&out, i + 1);
      out += '\n';
    }
    for (Eigen::Index i = 0; i < nv; ++i) {
      AppendPoint(&out, d.vertices, i, options.precision);
      out += '\n';
    }
  }
  out += "$EndNodes\n$Elements\n";
  AppendInt(&out, (nf > 0) + (nt > 0));
  out += ' ';
  AppendInt(&out, nf + nt);
  out += nf + nt > 0 ? " 1 " : " 0 ";
  AppendInt(&out, nf + nt);
  out += '\n';
  int64_t id = 1;
  if (nf > 0) {
    out += "2 1 2 ";
    AppendInt(&out, nf);
    out += '\n';
    for (Eigen::Index f = 0; f < nf; ++f, ++id) {
      AppendInt(&out, id);
      for (int k = 0; k < 3; ++k) {
        out += ' ';
        AppendInt(&out, d.triangles(f, k) + 1);
      }
      out += '\n';
    }
  }
  if (nt > 0) {
    out += "3 1 ";
    AppendInt(&out, tet_type);
    out += ' ';
    AppendInt(&out, nt);
    out += '\n';
    for (Eigen::Index t = 0; t < nt; ++t, ++id) {
      AppendInt(&out, id);
      AppendTetNodes(&out, d, t);
      out += '\n';
    }
  }
  out += "$EndElements\n";
  return out;
}

}  // namespace arreg::mesh_io_internal
