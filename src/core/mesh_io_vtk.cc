// VTK legacy .vtk: UNSTRUCTURED_GRID and POLYDATA, ASCII and big-endian
// binary; reads the classic and the 5.x (OFFSETS/CONNECTIVITY) cell layout.
#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "core/log.h"
#include "core/mesh_io_internal.h"

namespace arreg::mesh_io_internal {

namespace {

std::string Upper(std::string_view s) {
  std::string u(s);
  for (char& c : u) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  return u;
}

struct VtkType {
  const char* name;
  int bytes;
  bool real;
  bool is_signed;
};
constexpr VtkType kVtkTypes[] = {
    {"unsigned_char", 1, false, false},
    {"char", 1, false, true},
    {"short", 2, false, true},
    {"unsigned_short", 2, false, false},
    {"int", 4, false, true},
    {"unsigned_int", 4, false, false},
    {"long", 8, false, true},
    {"unsigned_long", 8, false, false},
    {"vtktypeint64", 8, false, true},
    {"vtktypeuint64", 8, false, false},
    {"vtkidtype", 4, false, true},
    {"float", 4, true, true},
    {"double", 8, true, true},
};

// Legacy cell type ids and the names used in element_counts.
const char* CellTypeName(int64_t type) {
  switch (type) {
    case 1:
      return "point";
    case 2:
      return "poly vertex";
    case 3:
      return "line";
    case 4:
      return "polyline";
    case 5:
      return "triangle";
    case 6:
      return "triangle strip";
    case 7:
      return "polygon";
    case 8:
      return "pixel";
    case 9:
      return "quadrangle";
    case 10:
      return "tetrahedron";
    case 11:
      return "voxel";
    case 12:
      return "hexahedron";
    case 13:
      return "wedge";
    case 14:
      return "pyramid";
    case 21:
      return "quadratic line";
    case 22:
      return "quadratic triangle";
    case 23:
      return "quadratic quadrangle";
    case 24:
      return "quadratic tetrahedron";
    case 25:
      return "quadratic hexahedron";
    default:
      return nullptr;
  }
}

// VTK's 10-node tetrahedron has nodes 4..9 on edges 01, 12, 02, 03, 13, 23.
constexpr int kVtkTet10Edges[6] = {4, 6, 7, 5, 8, 9};

class VtkReader {
 public:
  VtkReader(const std::string& path, std::string_view text, MeshFileData* out)
      : path_(path), text_(text), s_(path, text), out_(out) {}

  void Read() {
    const std::string_view header = s_.Line();
    if (header.rfind("# vtk DataFile Version", 0) != 0)
      s_.Fail("not a VTK legacy file: expected '# vtk DataFile Version x.y', found '" +
              Printable(header) + "'");
    const std::string_view version =
        header.substr(std::string_view("# vtk DataFile Version").size());
    const size_t digit = version.find_first_of("0123456789");
    version_major_ = digit == std::string_view::npos ? 0 : version[digit] - '0';
    s_.Line();  // title
    const std::string mode = Upper(s_.Line());
    if (mode == "BINARY")
      binary_ = true;
    else if (mode != "ASCII")
      s_.Fail("expected ASCII or BINARY, found '" + Printable(mode) + "'");
    std::string_view dataset_line = s_.Line();
    while (dataset_line.empty() && !s_.AtEnd()) dataset_line = s_.Line();
    TextScanner line_scanner(path_, dataset_line);
    if (Upper(line_scanner.TokenOnLine()) != "DATASET") s_.Fail("expected 'DATASET <type>'");
    const std::string dataset = Upper(line_scanner.TokenOnLine());
    if (dataset == "UNSTRUCTURED_GRID")
      polydata_ = false;
    else if (dataset == "POLYDATA")
      polydata_ = true;
    else
      s_.Fail("unsupported dataset '" + dataset + "' (expected UNSTRUCTURED_GRID or POLYDATA)");
    out_->format = std::string("vtk ") + (binary_ ? "binary " : "ascii ") +
                   (polydata_ ? "polydata" : "unstructured grid");
    s_.set_report_offsets(binary_);

    for (;;) {
      const std::string_view token = s_.Token();
      if (token.empty()) break;
      const std::string keyword = Upper(token);
      if (keyword == "POINTS")
        ReadPoints();
      else if (keyword == "METADATA")
        SkipMetadata();
      else if (keyword == "FIELD")
        SkipField();
      else if (!polydata_ && keyword == "CELLS")
        ReadCells(&ug_cells_, "cells");
      else if (!polydata_ && keyword == "CELL_TYPES")
        ReadCellTypes();
      else if (polydata_ && (keyword == "VERTICES" || keyword == "LINES" || keyword == "POLYGONS" ||
                             keyword == "TRIANGLE_STRIPS"))
        ReadPolyCells(keyword);
      else if (keyword == "POINT_DATA" || keyword == "CELL_DATA") {
        attribute_on_points_ = keyword == "POINT_DATA";
        attribute_count_ =
            Count(s_.IntOnLine("number of attribute values"), binary_ ? 1 : 2, keyword);
        s_.SkipRestOfLine();
      } else if (keyword == "SCALARS" || keyword == "VECTORS" || keyword == "NORMALS" ||
                 keyword == "TEXTURE_COORDINATES" || keyword == "TENSORS" ||
                 keyword == "COLOR_SCALARS" || keyword == "LOOKUP_TABLE") {
        ReadAttribute(keyword);
      } else {
        s_.Fail("expected a VTK section keyword (POINTS, " +
                std::string(polydata_ ? "POLYGONS" : "CELLS, CELL_TYPES") +
                ", POINT_DATA, ...), found '" + Printable(token) + "'");
      }
    }
    Finish();
  }

 private:
  struct Cells {
    std::vector<int64_t> offsets{0};  // (#cells + 1)
    std::vector<int64_t> connectivity;
    bool read = false;
  };

  int Count(int64_t value, size_t min_bytes_each, std::string_view what) {
    return s_.CheckCount(value, min_bytes_each, what);
  }

  const VtkType& TypeNamed(std::string_view name) {
    const std::string lower = [&] {
      std::string l(name);
      for (char& c : l) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
      return l;
    }();
    for (const auto& t : kVtkTypes)
      if (lower == t.name) return t;
    s_.Fail("unsupported VTK data type '" + Printable(name) + "'");
  }

  // Reads `count` values of `type` (ASCII tokens or big-endian binary). When
  // `integer` the values must be whole numbers.
  template <typename T>
  void ReadValues(const VtkType& type, int64_t count, std::vector<T>* values, const char* what) {
    values->clear();
    if (binary_) {
      s_.SkipRestOfLine();  // the data starts after the header line's newline
      BinaryCursor c(path_, text_, s_.offset());
      if (static_cast<uint64_t>(count) * type.bytes > c.remaining_bytes())
        c.Fail(std::string("file ends early: ") + std::to_string(count) + " " + what + " of type " +
               type.name + " need " + std::to_string(count * type.bytes) + " bytes, " +
               std::to_string(c.remaining_bytes()) + " left");
      values->resize(static_cast<size_t>(count));
      for (int64_t i = 0; i < count; ++i) {
        double v = 0;
        switch (type.bytes) {
          case 1:
            v = type.is_signed ? c.Read<int8_t>(true) : c.Read<uint8_t>(true);
            break;
          case 2:
            v = type.is_signed ? c.Read<int16_t>(true) : c.Read<uint16_t>(true);
            break;
          case 4:
            v = type.real ? c.Read<float>(true)
                          : (type.is_signed ? c.Read<int32_t>(true) : c.Read<uint32_t>(true));
            break;
          default:
            v = type.real ? c.Read<double>(true)
                          : (type.is_signed ? static_cast<double>(c.Read<int64_t>(true))
                                            : static_cast<double>(c.Read<uint64_t>(true)));
            break;
        }
        if constexpr (std::is_floating_point_v<T>) {
          if (!std::isfinite(v)) {
            BinaryCursor at(path_, text_, c.offset() - type.bytes);
            at.Fail(std::string(what) + " value is not finite");
          }
        }
        (*values)[static_cast<size_t>(i)] = static_cast<T>(v);
      }
      s_.Seek(c.offset());
    } else {
      // Each ASCII value takes at least two bytes; never reserve more than that.
      values->reserve(std::min(static_cast<size_t>(count), s_.remaining_bytes() / 2 + 1));
      for (int64_t i = 0; i < count; ++i) {
        const std::string_view t = s_.Token();
        if (t.empty())
          s_.Fail(std::string("file ends after ") + std::to_string(i) + " of " +
                  std::to_string(count) + " " + what);
        if constexpr (std::is_floating_point_v<T>)
          values->push_back(s_.ParseDouble(t, what));
        else
          values->push_back(s_.ParseInt(t, what));
      }
    }
  }

  void ReadPoints() {
    const int64_t raw = s_.IntOnLine("number of points");
    const std::string_view type_name = s_.TokenOnLine();
    if (type_name.empty()) s_.Fail("expected the POINTS data type");
    const VtkType& type = TypeNamed(type_name);
    const int n = Count(raw, binary_ ? 3 * type.bytes : 6, "number of points");
    std::vector<double> xyz;
    ReadValues(type, static_cast<int64_t>(n) * 3, &xyz, "point coordinates");
    out_->vertices = ToMatrix<RowMatX3d>(xyz, 3);
    num_points_ = n;
    have_points_ = true;
  }

  void SkipMetadata() {
    // Lines up to the first empty one.
    s_.SkipRestOfLine();
    while (!s_.AtEnd() && !s_.Line().empty()) {
    }
  }

  void SkipField() {
    s_.TokenOnLine();  // field name
    const int64_t arrays = s_.IntOnLine("number of field arrays");
    if (arrays < 0 || arrays > 10000) s_.Fail("implausible number of field arrays");
    s_.SkipRestOfLine();
    for (int64_t a = 0; a < arrays; ++a) {
      const std::string_view name = s_.Token();
      if (name.empty()) s_.Fail("file ends inside a FIELD");
      if (Upper(name) == "METADATA") {
        SkipMetadata();
        --a;
        continue;
      }
      const int64_t components = s_.IntOnLine("number of components");
      const int64_t tuples = s_.IntOnLine("number of tuples");
      const std::string_view type_name = s_.TokenOnLine();
      const VtkType& type = TypeNamed(type_name);
      if (components < 1 || components > 1000) s_.Fail("implausible number of components");
      const int64_t count =
          Count(tuples, binary_ ? components * type.bytes : 2, "number of tuples");
      std::vector<double> ignored;
      ReadValues(type, count * components, &ignored, "field values");
    }
  }

  // Classic "KEY n size" with size values (count, ids...), or 5.x "KEY
  // n_offsets n_connectivity" followed by OFFSETS and CONNECTIVITY arrays.
  void ReadCells(Cells* cells, const char* what) {
    const int64_t first = s_.IntOnLine("number of cells");
    const int64_t second = s_.IntOnLine("size of the cell list");
    cells->read = true;
    if (version_major_ >= 5) {
      if (first < 1 && second != 0) s_.Fail("a 5.x cell array needs at least one offset");
      s_.SkipRestOfLine();
      std::vector<int64_t> offsets, connectivity;
      for (int part = 0; part < 2; ++part) {
        const std::string keyword = Upper(s_.Token());
        const char* expected = part == 0 ? "OFFSETS" : "CONNECTIVITY";
        if (keyword != expected)
          s_.Fail(std::string("expected ") + expected + ", found '" + Printable(keyword) + "'");
        const VtkType& type = TypeNamed(s_.TokenOnLine());
        const int64_t n = part == 0 ? first : second;
        Count(n, binary_ ? type.bytes : 2, part == 0 ? "number of offsets" : "connectivity size");
        ReadValues(type, n, part == 0 ? &offsets : &connectivity, expected);
      }
      if (offsets.empty()) offsets.push_back(0);
      if (offsets.front() != 0 || offsets.back() != static_cast<int64_t>(connectivity.size()))
        s_.Fail("cell offsets must start at 0 and end at the connectivity size");
      for (size_t i = 1; i < offsets.size(); ++i)
        if (offsets[i] < offsets[i - 1])
          s_.Fail("cell offsets decrease at offset " + std::to_string(i));
      cells->offsets = std::move(offsets);
      cells->connectivity = std::move(connectivity);
      return;
    }
    const int num_cells = Count(first, binary_ ? 4 : 2, "number of cells");
    const int size = Count(second, binary_ ? 4 : 2, "size of the cell list");
    if (static_cast<int64_t>(num_cells) > size)
      s_.Fail("cell list size is smaller than the number of cells");
    std::vector<int64_t> flat;
    ReadValues(kVtkTypes[4], size, &flat, what);
    cells->offsets.assign(1, 0);
    cells->offsets.reserve(static_cast<size_t>(num_cells) + 1);
    cells->connectivity.reserve(static_cast<size_t>(size - num_cells));
    size_t pos = 0;
    for (int c = 0; c < num_cells; ++c) {
      if (pos >= flat.size())
        s_.Fail(std::string("cell list ends before cell ") + std::to_string(c) + " of " +
                std::to_string(num_cells));
      const int64_t n = flat[pos++];
      if (n < 0 || static_cast<uint64_t>(n) > flat.size() - pos)
        s_.Fail("cell " + std::to_string(c) + " has " + std::to_string(n) +
                " points, more than the cell list holds");
      cells->connectivity.insert(cells->connectivity.end(),
                                 flat.begin() + static_cast<std::ptrdiff_t>(pos),
                                 flat.begin() + static_cast<std::ptrdiff_t>(pos + n));
      pos += static_cast<size_t>(n);
      cells->offsets.push_back(static_cast<int64_t>(cells->connectivity.size()));
    }
    if (pos != flat.size())
      s_.Fail("cell list size " + std::to_string(size) + " does not match its " +
              std::to_string(num_cells) + " cells (" + std::to_string(pos) + " values used)");
  }

  void ReadCellTypes() {
    const int n =
        Count(s_.IntOnLine("number of cell types"), binary_ ? 4 : 2, "number of cell types");
    ReadValues(kVtkTypes[4], n, &cell_types_, "cell types");
    have_cell_types_ = true;
  }

  void ReadPolyCells(const std::string& keyword) {
    Cells cells;
    ReadCells(&cells, keyword.c_str());
    const size_t num = cells.offsets.size() - 1;
    if (keyword == "VERTICES" || keyword == "LINES") {
      out_->element_counts[keyword == "VERTICES" ? "point" : "line"] += static_cast<int>(num);
      return;
    }
    for (size_t c = 0; c < num; ++c) {
      const int64_t begin = cells.offsets[c], n = cells.offsets[c + 1] - begin;
      const int64_t* ids = cells.connectivity.data() + begin;
      if (keyword == "POLYGONS") {
        ++out_->element_counts[n == 3 ? "triangle" : n == 4 ? "quadrangle" : "polygon"];
        AddFan(ids, n, c);
      } else {
        ++out_->element_counts["triangle strip"];
        for (int64_t k = 0; k + 2 < n; ++k) {
          // Every other triangle of a strip is reversed to keep one orientation.
          if (k % 2 == 0)
            AddTriangle(ids[k], ids[k + 1], ids[k + 2], c);
          else
            AddTriangle(ids[k + 1], ids[k], ids[k + 2], c);
        }
      }
    }
  }

  int PointIndex(int64_t id, size_t cell) {
    if (id < 0 || (have_points_ && id >= num_points_))
      s_.Fail("cell " + std::to_string(cell) + " refers to point " + std::to_string(id) +
              " but there are " + std::to_string(num_points_) + " points");
    if (id > std::numeric_limits<int>::max()) s_.Fail("point index out of range");
    return static_cast<int>(id);
  }
  void AddTriangle(int64_t a, int64_t b, int64_t c, size_t cell) {
    triangles_.insert(triangles_.end(),
                      {PointIndex(a, cell), PointIndex(b, cell), PointIndex(c, cell)});
  }
  void AddFan(const int64_t* ids, int64_t n, size_t cell) {
    if (n < 3) s_.Fail("polygon " + std::to_string(cell) + " has fewer than 3 points");
    for (int64_t k = 1; k + 1 < n; ++k) AddTriangle(ids[0], ids[k], ids[k + 1], cell);
  }

  void ReadAttribute(const std::string& keyword) {
    if (keyword == "LOOKUP_TABLE") {
      s_.TokenOnLine();
      const int64_t size = s_.IntOnLine("lookup table size");
      const int n = Count(size, 4, "lookup table size");
      std::vector<double> ignored;
      ReadValues(binary_ ? kVtkTypes[0] : kVtkTypes[12], static_cast<int64_t>(n) * 4, &ignored,
                 "lookup table entries");
      return;
    }
    if (attribute_count_ < 0) s_.Fail(keyword + " outside POINT_DATA or CELL_DATA");
    const std::string_view name = s_.TokenOnLine();
    if (name.empty()) s_.Fail("expected the name of the " + keyword + " array");
    int64_t components = 3;
    const VtkType* type = nullptr;
    if (keyword == "SCALARS") {
      type = &TypeNamed(s_.TokenOnLine());
      components = s_.AtEndOfLine() ? 1 : s_.IntOnLine("number of components");
      s_.SkipRestOfLine();
      if (Upper(s_.Token()) != "LOOKUP_TABLE") s_.Fail("expected LOOKUP_TABLE after SCALARS");
      s_.TokenOnLine();
    } else if (keyword == "TEXTURE_COORDINATES") {
      components = s_.IntOnLine("texture coordinate dimension");
      type = &TypeNamed(s_.TokenOnLine());
    } else if (keyword == "TENSORS") {
      components = 9;
      type = &TypeNamed(s_.TokenOnLine());
    } else if (keyword == "COLOR_SCALARS") {
      components = s_.IntOnLine("number of colour values");
      type = binary_ ? &kVtkTypes[0] : &kVtkTypes[11];
    } else {
      type = &TypeNamed(s_.TokenOnLine());
    }
    if (components < 1 || components > 16)
      s_.Fail("implausible number of components " + std::to_string(components));
    std::vector<double> values;
    ReadValues(*type, components * attribute_count_, &values, "attribute values");
    if (!attribute_on_points_) return;
    auto take = [&](int cols, double scale) {
      RowMatX3d m = RowMatX3d::Zero(attribute_count_, 3);
      for (int i = 0; i < attribute_count_; ++i)
        for (int k = 0; k < cols; ++k)
          m(i, k) = values[static_cast<size_t>(i * components + k)] * scale;
      return m;
    };
    if (keyword == "NORMALS")
      point_normals_ = take(3, 1.0);
    else if (keyword == "COLOR_SCALARS" && components >= 3)
      point_colors_ = take(3, binary_ ? 1.0 / 255 : 1.0);
    else if (keyword == "TEXTURE_COORDINATES" && components >= 2) {
      point_uvs_.resize(attribute_count_, 2);
      for (int i = 0; i < attribute_count_; ++i)
        for (int k = 0; k < 2; ++k)
          point_uvs_(i, k) = values[static_cast<size_t>(i * components + k)];
    }
  }

  void Finish() {
    if (!have_points_) s_.Fail("no POINTS section in the file");
    if (!polydata_) {
      if (ug_cells_.read != have_cell_types_) s_.Fail("CELLS and CELL_TYPES must both be present");
      const size_t num = ug_cells_.offsets.size() - 1;
      if (cell_types_.size() != num)
        s_.Fail(std::to_string(cell_types_.size()) + " CELL_TYPES for " + std::to_string(num) +
                " cells");
      std::vector<int> tets, edges;
      int linear = 0, quadratic = 0;
      for (size_t c = 0; c < num; ++c) {
        const int64_t begin = ug_cells_.offsets[c], n = ug_cells_.offsets[c + 1] - begin;
        const int64_t* ids = ug_cells_.connectivity.data() + begin;
        const int64_t type = cell_types_[c];
        const char* name = CellTypeName(type);
        ++out_->element_counts[name ? name : "vtk type " + std::to_string(type)];
        auto need = [&](int64_t expected) {
          if (n != expected)
            s_.Fail(std::string("cell ") + std::to_string(c) + " of type " + std::to_string(type) +
                    " has " + std::to_string(n) + " points, expected " + std::to_string(expected));
        };
        switch (type) {
          case 5:
            need(3);
            AddTriangle(ids[0], ids[1], ids[2], c);
            break;
          case 22:
            need(6);
            AddTriangle(ids[0], ids[1], ids[2], c);
            break;
          case 9:
            need(4);
            AddFan(ids, 4, c);
            break;
          case 7:
            AddFan(ids, n, c);
            break;
          case 10:
            need(4);
            for (int k = 0; k < 4; ++k) tets.push_back(PointIndex(ids[k], c));
            ++linear;
            break;
          case 24:
            need(10);
            for (int k = 0; k < 4; ++k) tets.push_back(PointIndex(ids[k], c));
            for (int e : kVtkTet10Edges) edges.push_back(PointIndex(ids[e], c));
            ++quadratic;
            break;
          default:
            break;
        }
      }
      if (linear > 0 && quadratic > 0)
        s_.Fail("the file mixes linear and quadratic tetrahedra, which is not supported");
      out_->tetrahedra = ToMatrix<RowMatX4i>(tets, 4);
      if (quadratic > 0) out_->high_order_nodes = ToMatrix<RowMatXi>(edges, 6);
    }
    out_->triangles = ToMatrix<RowMatX3i>(triangles_, 3);
    if (point_normals_.rows() == num_points_) out_->normals = point_normals_;
    if (point_colors_.rows() == num_points_) out_->colors = point_colors_;
    if (point_uvs_.rows() == num_points_ && out_->triangles.rows() > 0) {
      out_->uvs = point_uvs_;
      out_->face_uvs = out_->triangles;
    }
    MoveEdgeNodesLast(out_);
  }

  std::string path_;
  std::string_view text_;
  TextScanner s_;
  MeshFileData* out_;
  int version_major_ = 0;
  bool binary_ = false;
  bool polydata_ = false;
  bool have_points_ = false;
  int num_points_ = 0;
  Cells ug_cells_;
  std::vector<int64_t> cell_types_;
  bool have_cell_types_ = false;
  std::vector<int> triangles_;
  int attribute_count_ = -1;
  bool attribute_on_points_ = false;
  RowMatX3d point_normals_, point_colors_;
  RowMatX2d point_uvs_;
};

}  // namespace

void ReadVtk(const std::string& path, std::string_view text, MeshFileData* out) {
  VtkReader(path, text, out).Read();
}

namespace {

class VtkWriter {
 public:
  VtkWriter(bool binary, int precision) : binary_(binary), precision_(precision) {}
  std::string& out() { return out_; }

  void Reals(const double* values, size_t count, int per_line) {
    if (binary_) {
      for (size_t i = 0; i < count; ++i) AppendBinary(&out_, values[i], true);
      out_ += '\n';
      return;
    }
    for (size_t i = 0; i < count; ++i) {
      AppendDouble(&out_, values[i], precision_);
      out_ += (i + 1) % per_line == 0 || i + 1 == count ? '\n' : ' ';
    }
  }
  // One cell: count followed by its point ids.
  void Cell(const int* ids, int n) {
    if (binary_) {
      AppendBinary<int32_t>(&out_, n, true);
      for (int k = 0; k < n; ++k) AppendBinary<int32_t>(&out_, ids[k], true);
      return;
    }
    AppendInt(&out_, n);
    for (int k = 0; k < n; ++k) {
      out_ += ' ';
      AppendInt(&out_, ids[k]);
    }
    out_ += '\n';
  }
  void Int(int value) {
    if (binary_)
      AppendBinary<int32_t>(&out_, value, true);
    else {
      AppendInt(&out_, value);
      out_ += '\n';
    }
  }
  void EndBinaryBlock() {
    if (binary_) out_ += '\n';
  }

 private:
  bool binary_;
  int precision_;
  std::string out_;
};

}  // namespace

std::string WriteVtk(const MeshFileData& d, bool volume, const MeshWriteOptions& options) {
  VtkWriter w(options.binary, options.precision);
  std::string& out = w.out();
  const Eigen::Index nv = d.vertices.rows(), nt = d.tetrahedra.rows(), nf = d.triangles.rows();
  out.reserve(static_cast<size_t>(nv * 60 + nt * 30 + nf * 25 + 256));
  out += "# vtk DataFile Version 3.0\narreg mesh\n";
  out += options.binary ? "BINARY\n" : "ASCII\n";
  out += volume ? "DATASET UNSTRUCTURED_GRID\n" : "DATASET POLYDATA\n";
  out += "POINTS " + std::to_string(nv) + " double\n";
  w.Reals(d.vertices.data(), static_cast<size_t>(nv * 3), 3);
  if (volume) {
    const bool quadratic = d.high_order_nodes.size() > 0;
    const int tet_nodes = quadratic ? 10 : 4;
    out += "CELLS " + std::to_string(nf + nt) + " " +
           std::to_string(nf * 4 + nt * (tet_nodes + 1)) + "\n";
    for (Eigen::Index f = 0; f < nf; ++f) w.Cell(d.triangles.row(f).data(), 3);
    for (Eigen::Index t = 0; t < nt; ++t) {
      int ids[10];
      for (int k = 0; k < 4; ++k) ids[k] = d.tetrahedra(t, k);
      if (quadratic)
        for (int e = 0; e < 6; ++e) ids[kVtkTet10Edges[e]] = d.high_order_nodes(t, e);
      w.Cell(ids, tet_nodes);
    }
    w.EndBinaryBlock();
    out += "CELL_TYPES " + std::to_string(nf + nt) + "\n";
    for (Eigen::Index f = 0; f < nf; ++f) w.Int(5);
    for (Eigen::Index t = 0; t < nt; ++t) w.Int(quadratic ? 24 : 10);
    w.EndBinaryBlock();
    return out;
  }
  out += "POLYGONS " + std::to_string(nf) + " " + std::to_string(nf * 4) + "\n";
  for (Eigen::Index f = 0; f < nf; ++f) w.Cell(d.triangles.row(f).data(), 3);
  w.EndBinaryBlock();
  const bool per_vertex_uvs =
      d.uvs.rows() == nv && d.face_uvs.rows() == nf && nf > 0 && d.face_uvs == d.triangles;
  if (d.uvs.rows() > 0 && !per_vertex_uvs)
    ARREG_LOG_WARNING(
        "VTK stores one texture coordinate per point; these per-corner uvs are not written");
  if (d.normals.rows() == 0 && !per_vertex_uvs) return out;
  out += "POINT_DATA " + std::to_string(nv) + "\n";
  if (d.normals.rows() == nv) {
    out += "NORMALS normals double\n";
    w.Reals(d.normals.data(), static_cast<size_t>(nv * 3), 3);
  }
  if (per_vertex_uvs) {
    out += "TEXTURE_COORDINATES tcoords 2 double\n";
    w.Reals(d.uvs.data(), static_cast<size_t>(nv * 2), 2);
  }
  return out;
}

}  // namespace arreg::mesh_io_internal
