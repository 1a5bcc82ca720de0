// Shared pieces of the mesh readers and writers (mesh_io_*.cc): a text
// scanner and a binary cursor that report errors by line or byte offset.
#pragma once

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>

#include "core/error.h"
#include "core/mesh_io.h"

namespace arreg::mesh_io_internal {

// Tokenizes a text file held in memory, tracking the line number so that
// every error names "file:line N".
class TextScanner {
 public:
  TextScanner(const std::string& path, std::string_view text)
      : path_(path), begin_(text.data()), p_(text.data()), end_(text.data() + text.size()) {}

  const std::string& path() const { return path_; }
  int line() const { return line_; }
  bool AtEnd() const { return p_ == end_; }
  size_t offset() const { return static_cast<size_t>(p_ - begin_); }
  size_t remaining_bytes() const { return static_cast<size_t>(end_ - p_); }

  // Skips spaces, tabs and carriage returns, staying on the current line.
  void SkipBlanks() {
    while (p_ != end_ && (*p_ == ' ' || *p_ == '\t' || *p_ == '\r' || *p_ == '\f' || *p_ == '\v'))
      ++p_;
  }
  bool AtEndOfLine() {
    SkipBlanks();
    return p_ == end_ || *p_ == '\n';
  }
  // Next token on the current line; empty at the end of the line or file.
  std::string_view TokenOnLine() {
    SkipBlanks();
    const char* start = p_;
    while (p_ != end_ && !IsSpace(*p_)) ++p_;
    return std::string_view(start, static_cast<size_t>(p_ - start));
  }
  // Next token, crossing line ends; empty only at the end of the file.
  std::string_view Token() {
    for (;;) {
      SkipBlanks();
      if (p_ == end_) return {};
      if (*p_ != '\n') return TokenOnLine();
      ++p_;
      ++line_;
    }
  }
  // Rest of the current line (blanks trimmed) and moves to the next line.
  std::string_view Line() {
    SkipBlanks();
    const char* start = p_;
    while (p_ != end_ && *p_ != '\n') ++p_;
    const char* stop = p_;
    while (stop != start && IsSpace(stop[-1])) --stop;
    if (p_ != end_) {
      ++p_;
      ++line_;
    }
    return std::string_view(start, static_cast<size_t>(stop - start));
  }
  void SkipRestOfLine() { Line(); }
  // Moves past the newline that ends the current line, failing if anything
  // but blanks is left on it.
  void ExpectEndOfLine(std::string_view context) {
    if (!AtEndOfLine()) {
      const std::string_view extra = TokenOnLine();
      Fail(std::string("unexpected '") + std::string(extra.substr(0, 40)) + "' after " +
           std::string(context));
    }
    SkipRestOfLine();
  }

  [[noreturn]] void Fail(const std::string& what) const {
    throw Error(
        path_,
        binary_ ? "byte offset " + std::to_string(offset()) : "line " + std::to_string(line_),
        what);
  }
  // For an error about a line that has already been consumed.
  [[noreturn]] void FailAtLine(int line, const std::string& what) const {
    throw Error(path_, "line " + std::to_string(line), what);
  }
  // In files that mix text and binary blocks line numbers stop meaning
  // anything after the first block: errors then name byte offsets.
  void set_report_offsets(bool binary) { binary_ = binary; }
  // Continues scanning at `offset` (after a binary block read elsewhere).
  void Seek(size_t offset) { p_ = begin_ + std::min(offset, static_cast<size_t>(end_ - begin_)); }

  int64_t ParseInt(std::string_view token, std::string_view what) const;
  // Rejects NaN and infinities: a mesh coordinate must be finite.
  double ParseDouble(std::string_view token, std::string_view what) const;

  int64_t IntOnLine(std::string_view what) {
    const std::string_view t = TokenOnLine();
    if (t.empty()) Fail("expected " + std::string(what) + ", found end of line");
    return ParseInt(t, what);
  }
  double DoubleOnLine(std::string_view what) {
    const std::string_view t = TokenOnLine();
    if (t.empty()) Fail("expected " + std::string(what) + ", found end of line");
    return ParseDouble(t, what);
  }
  int64_t Int(std::string_view what) {
    const std::string_view t = Token();
    if (t.empty()) Fail("expected " + std::string(what) + ", found end of file");
    return ParseInt(t, what);
  }
  double Double(std::string_view what) {
    const std::string_view t = Token();
    if (t.empty()) Fail("expected " + std::string(what) + ", found end of file");
    return ParseDouble(t, what);
  }
  // A count read from a header: must be >= 0 and small enough that
  // `min_bytes_each` bytes per item fit in the rest of the file (so a corrupt
  // header cannot make us allocate absurd amounts).
  int CheckCount(int64_t count, size_t min_bytes_each, std::string_view what) const;

 private:
  static bool IsSpace(char c) {
    return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\f' || c == '\v';
  }
  std::string path_;
  const char* begin_;
  const char* p_;
  const char* end_;
  int line_ = 1;
  bool binary_ = false;
};

// At most `max_chars` of `text` for an error message, with bytes that are not
// printable ASCII shown as \xNN (binary garbage must not mangle a terminal).
inline std::string Printable(std::string_view text, size_t max_chars = 40) {
  std::string out;
  for (size_t i = 0; i < text.size() && i < max_chars; ++i) {
    const unsigned char c = static_cast<unsigned char>(text[i]);
    if (c >= 32 && c < 127) {
      out += static_cast<char>(c);
    } else {
      static const char* kHex = "0123456789abcdef";
      out += "\\x";
      out += kHex[c >> 4];
      out += kHex[c & 15];
    }
  }
  if (text.size() > max_chars) out += "...";
  return out;
}

// Reads fixed-size values from a binary block, naming the byte offset on errors.
class BinaryCursor {
 public:
  BinaryCursor(const std::string& path, std::string_view data, size_t offset = 0)
      : path_(path), data_(data), pos_(offset) {}
  size_t offset() const { return pos_; }
  size_t remaining_bytes() const { return data_.size() - pos_; }
  [[noreturn]] void Fail(const std::string& what) const {
    throw Error(path_, "byte offset " + std::to_string(pos_), what);
  }
  void Require(size_t bytes, std::string_view what) const {
    if (bytes > remaining_bytes())
      Fail("file ends early: expected " + std::to_string(bytes) + " bytes of " + std::string(what) +
           ", " + std::to_string(remaining_bytes()) + " left");
  }
  template <typename T>
  T Read(bool big_endian) {
    static_assert(std::is_trivially_copyable_v<T>);
    Require(sizeof(T), "data");
    unsigned char bytes[sizeof(T)];
    std::memcpy(bytes, data_.data() + pos_, sizeof(T));
    if (big_endian) {
      for (size_t i = 0; i < sizeof(T) / 2; ++i) std::swap(bytes[i], bytes[sizeof(T) - 1 - i]);
    }
    pos_ += sizeof(T);
    T value;
    std::memcpy(&value, bytes, sizeof(T));
    return value;
  }
  void Skip(size_t bytes) {
    Require(bytes, "data");
    pos_ += bytes;
  }

 private:
  std::string path_;
  std::string_view data_;
  size_t pos_;
};

// Appends `value` as text: shortest exact form for precision >= 17, else
// `precision` significant digits.
void AppendDouble(std::string* out, double value, int precision);
void AppendInt(std::string* out, int64_t value);

// Big-endian (VTK) and little-endian (STL) appends.
template <typename T>
void AppendBinary(std::string* out, T value, bool big_endian) {
  unsigned char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  if (big_endian)
    for (size_t i = 0; i < sizeof(T) / 2; ++i) std::swap(bytes[i], bytes[sizeof(T) - 1 - i]);
  out->append(reinterpret_cast<const char*>(bytes), sizeof(T));
}

// Per-format readers: fill `out` from the file contents `text`.
void ReadMsh(const std::string& path, std::string_view text, MeshFileData* out);
void ReadVtk(const std::string& path, std::string_view text, MeshFileData* out);
void ReadObj(const std::string& path, std::string_view text, MeshFileData* out);
void ReadStl(const std::string& path, std::string_view text, MeshFileData* out);
void ReadOff(const std::string& path, std::string_view text, MeshFileData* out);

// Per-format writers: return the file contents. `data` has been validated.
std::string WriteMsh(const MeshFileData& data, const MeshWriteOptions& options);
std::string WriteVtk(const MeshFileData& data, bool volume, const MeshWriteOptions& options);
std::string WriteObj(const MeshFileData& data, const MeshWriteOptions& options);
std::string WriteStl(const MeshFileData& data, const MeshWriteOptions& options);
std::string WriteOff(const MeshFileData& data, const MeshWriteOptions& options);

// Moves quadratic edge nodes behind all other nodes (the TetMesh convention)
// and renumbers every index; no-op without high-order nodes.
void MoveEdgeNodesLast(MeshFileData* data);

// Builds a (#rows x cols) row-major int matrix from a flat vector.
template <typename Matrix, typename Vector>
Matrix ToMatrix(const Vector& flat, int cols) {
  Matrix m(static_cast<Eigen::Index>(flat.size() / cols), cols);
  if (!flat.empty()) std::copy(flat.begin(), flat.end(), m.data());
  return m;
}

}  // namespace arreg::mesh_io_internal
