#include "core/json_reader.h"

#include <cmath>
#include <limits>
#include <regex>
#include <set>
#include <sstream>

#include "core/error.h"
#include "core/file_util.h"

namespace arreg {
namespace {

using nlohmann::json;

// "line L, column C" of the 1-based byte offset reported by the parser.
std::string LineColumn(const std::string& text, std::size_t byte) {
  std::size_t line = 1, column = 1;
  const std::size_t end = std::min(byte > 0 ? byte - 1 : 0, text.size());
  for (std::size_t i = 0; i < end; ++i) {
    if (text[i] == '\n') {
      ++line;
      column = 1;
    } else {
      ++column;
    }
  }
  return "line " + std::to_string(line) + ", column " + std::to_string(column);
}

// Tracks the key path while parsing so that duplicate keys can be named.
struct ParseFrame {
  bool is_array = false;
  int index = 0;
  std::set<std::string> keys;
  std::string key;   // current key (objects)
  std::string name;  // key path of this container
};

std::string ChildName(const std::vector<ParseFrame>& stack) {
  if (stack.empty()) return "";
  const ParseFrame& f = stack.back();
  if (f.is_array) return f.name + "[" + std::to_string(f.index) + "]";
  return f.name.empty() ? f.key : f.name + "." + f.key;
}

std::string Describe(const json& value) {
  std::string dump = value.dump();
  if (dump.size() > 40) dump = dump.substr(0, 37) + "...";
  return std::string(value.type_name()) + " " + dump;
}

[[noreturn]] void TypeError(const json& value, const std::string& file, const std::string& key_path,
                            const std::string& expected) {
  throw Error(file, key_path, "expected " + expected + ", got " + Describe(value));
}

std::string FormatNumber(double v) {
  std::ostringstream os;
  os.precision(12);
  os << v;
  return os.str();
}

template <typename Int>
void ReadInteger(const json& value, const std::string& file, const std::string& key_path, Int* out,
                 const char* expected) {
  if (value.is_number_integer()) {
    if (value.is_number_unsigned()) {
      const auto v = value.get<std::uint64_t>();
      if (v > static_cast<std::uint64_t>(std::numeric_limits<Int>::max()))
        throw Error(file, key_path,
                    std::string("value ") + value.dump() + " does not fit " + expected);
      *out = static_cast<Int>(v);
      return;
    }
    const auto v = value.get<std::int64_t>();
    if (v < static_cast<std::int64_t>(std::numeric_limits<Int>::min()) ||
        v > static_cast<std::int64_t>(std::numeric_limits<Int>::max()))
      throw Error(file, key_path,
                  std::string("value ") + value.dump() + " does not fit " + expected);
    *out = static_cast<Int>(v);
    return;
  }
  if (value.is_number_float()) {
    const double v = value.get<double>();
    if (std::floor(v) != v) TypeError(value, file, key_path, expected);
    if (v < static_cast<double>(std::numeric_limits<Int>::min()) ||
        v > static_cast<double>(std::numeric_limits<Int>::max()))
      throw Error(file, key_path,
                  std::string("value ") + value.dump() + " does not fit " + expected);
    *out = static_cast<Int>(v);
    return;
  }
  TypeError(value, file, key_path, expected);
}

std::string Element(const std::string& key_path, std::size_t i) {
  return key_path + "[" + std::to_string(i) + "]";
}

template <typename T>
void ReadArray(const json& value, const std::string& file, const std::string& key_path,
               std::vector<T>* out, const char* expected) {
  if (!value.is_array()) TypeError(value, file, key_path, expected);
  std::vector<T> result(value.size());
  for (std::size_t i = 0; i < value.size(); ++i)
    ReadJsonValue(value[i], file, Element(key_path, i), &result[i]);
  *out = std::move(result);
}

template <typename Vec>
void ReadFixedVector(const json& value, const std::string& file, const std::string& key_path,
                     Vec* out, const char* expected) {
  if (!value.is_array() || value.size() != static_cast<std::size_t>(Vec::RowsAtCompileTime))
    TypeError(value, file, key_path, expected);
  for (int i = 0; i < Vec::RowsAtCompileTime; ++i) {
    typename Vec::Scalar element;
    ReadJsonValue(value[i], file, Element(key_path, i), &element);
    (*out)(i) = element;
  }
}

template <int N>
void ReadSquareMatrix(const json& value, const std::string& file, const std::string& key_path,
                      Eigen::Matrix<double, N, N>* out) {
  const std::string expected = std::to_string(N) + "x" + std::to_string(N) +
                               " matrix (nested rows or " + std::to_string(N * N) +
                               " numbers, row-major)";
  if (!value.is_array()) TypeError(value, file, key_path, expected);
  Eigen::Matrix<double, N, N> m;
  if (value.size() == static_cast<std::size_t>(N * N) && !value[0].is_array()) {
    for (int i = 0; i < N * N; ++i)
      ReadJsonValue(value[i], file, Element(key_path, i), &m(i / N, i % N));
  } else if (value.size() == static_cast<std::size_t>(N)) {
    for (int r = 0; r < N; ++r) {
      const json& row = value[r];
      if (!row.is_array() || row.size() != static_cast<std::size_t>(N))
        TypeError(row, file, Element(key_path, r), "a row of " + std::to_string(N) + " numbers");
      for (int c = 0; c < N; ++c)
        ReadJsonValue(row[c], file, Element(Element(key_path, r), c), &m(r, c));
    }
  } else {
    TypeError(value, file, key_path, expected);
  }
  *out = m;
}

}  // namespace

nlohmann::json ParseJsonText(const std::string& text, const std::string& file) {
  std::vector<ParseFrame> stack;
  json::parser_callback_t callback = [&](int /*depth*/, json::parse_event_t event,
                                         json& parsed) -> bool {
    switch (event) {
      case json::parse_event_t::object_start:
      case json::parse_event_t::array_start: {
        ParseFrame frame;
        frame.is_array = event == json::parse_event_t::array_start;
        frame.name = ChildName(stack);
        stack.push_back(std::move(frame));
        break;
      }
      case json::parse_event_t::object_end:
      case json::parse_event_t::array_end:
        if (!stack.empty()) stack.pop_back();
        if (!stack.empty() && stack.back().is_array) ++stack.back().index;
        break;
      case json::parse_event_t::key: {
        ParseFrame& frame = stack.back();
        frame.key = parsed.get<std::string>();
        if (!frame.keys.insert(frame.key).second)
          throw Error(file, ChildName(stack),
                      "duplicate key (each key may appear once per object)");
        break;
      }
      case json::parse_event_t::value:
        if (!stack.empty() && stack.back().is_array) ++stack.back().index;
        break;
    }
    return true;
  };
  try {
    return json::parse(text, callback, /*allow_exceptions=*/true, /*ignore_comments=*/true);
  } catch (const json::parse_error& e) {
    // Drop the library's "[json.exception.parse_error.101] parse error at line 1, column 2: "
    // prefix.
    static const std::regex kPrefix(
        R"(^\[json\.exception\.[a-z_]+\.\d+\]\s*(parse error( at line \d+, column \d+)?:?\s*)?)");
    const std::string detail = std::regex_replace(std::string(e.what()), kPrefix, "");
    throw Error(file, LineColumn(text, e.byte), "JSON syntax error: " + detail);
  } catch (const json::exception& e) {
    // E.g. a number too large for a double (out_of_range.406).
    static const std::regex kPrefix(R"(^\[json\.exception\.[a-z_]+\.\d+\]\s*)");
    throw Error(file, "",
                "invalid JSON: " + std::regex_replace(std::string(e.what()), kPrefix, ""));
  }
}

nlohmann::json ParseJsonFile(const std::string& path) {
  return ParseJsonText(ReadFileToString(path), path);
}

void ReadJsonValue(const json& value, const std::string& file, const std::string& key_path,
                   double* out) {
  if (!value.is_number()) TypeError(value, file, key_path, "a number");
  *out = value.get<double>();
}

void ReadJsonValue(const json& value, const std::string& file, const std::string& key_path,
                   float* out) {
  double v = 0.0;
  ReadJsonValue(value, file, key_path, &v);
  *out = static_cast<float>(v);
}

void ReadJsonValue(const json& value, const std::string& file, const std::string& key_path,
                   int* out) {
  ReadInteger(value, file, key_path, out, "an integer");
}

void ReadJsonValue(const json& value, const std::string& file, const std::string& key_path,
                   std::int64_t* out) {
  ReadInteger(value, file, key_path, out, "an integer");
}

void ReadJsonValue(const json& value, const std::string& file, const std::string& key_path,
                   bool* out) {
  if (!value.is_boolean()) TypeError(value, file, key_path, "true or false");
  *out = value.get<bool>();
}

void ReadJsonValue(const json& value, const std::string& file, const std::string& key_path,
                   std::string* out) {
  if (!value.is_string()) TypeError(value, file, key_path, "a string");
  *out = value.get<std::string>();
}

void ReadJsonValue(const json& value, const std::string& file, const std::string& key_path,
                   std::vector<double>* out) {
  ReadArray(value, file, key_path, out, "an array of numbers");
}

void ReadJsonValue(const json& value, const std::string& file, const std::string& key_path,
                   std::vector<int>* out) {
  ReadArray(value, file, key_path, out, "an array of integers");
}

void ReadJsonValue(const json& value, const std::string& file, const std::string& key_path,
                   std::vector<std::string>* out) {
  ReadArray(value, file, key_path, out, "an array of strings");
}

void ReadJsonValue(const json& value, const std::string& file, const std::string& key_path,
                   Eigen::Vector2d* out) {
  ReadFixedVector(value, file, key_path, out, "an array of 2 numbers");
}

void ReadJsonValue(const json& value, const std::string& file, const std::string& key_path,
                   Eigen::Vector3d* out) {
  ReadFixedVector(value, file, key_path, out, "an array of 3 numbers");
}

void ReadJsonValue(const json& value, const std::string& file, const std::string& key_path,
                   Eigen::Vector4d* out) {
  ReadFixedVector(value, file, key_path, out, "an array of 4 numbers");
}

void ReadJsonValue(const json& value, const std::string& file, const std::string& key_path,
                   Eigen::Vector2i* out) {
  ReadFixedVector(value, file, key_path, out, "an array of 2 integers");
}

void ReadJsonValue(const json& value, const std::string& file, const std::string& key_path,
                   Eigen::Vector3i* out) {
  ReadFixedVector(value, file, key_path, out, "an array of 3 integers");
}

void ReadJsonValue(const json& value, const std::string& file, const std::string& key_path,
                   Eigen::VectorXd* out) {
  std::vector<double> v;
  ReadArray(value, file, key_path, &v, "an array of numbers");
  *out = Eigen::Map<const Eigen::VectorXd>(v.data(), static_cast<Eigen::Index>(v.size()));
}

void ReadJsonValue(const json& value, const std::string& file, const std::string& key_path,
                   Eigen::Matrix3d* out) {
  ReadSquareMatrix<3>(value, file, key_path, out);
}

void ReadJsonValue(const json& value, const std::string& file, const std::string& key_path,
                   Eigen::Matrix4d* out) {
  ReadSquareMatrix<4>(value, file, key_path, out);
}

void ReadJsonValue(const json& value, const std::string& /*file*/, const std::string& /*key_path*/,
                   json* out) {
  *out = value;
}

JsonObjectReader::JsonObjectReader(const nlohmann::json& object, std::string file, std::string path)
    : object_(&object), file_(std::move(file)), path_(std::move(path)) {
  if (!object.is_object())
    throw Error(file_, path_.empty() ? "top level" : path_,
                "expected a JSON object {...}, got " + Describe(object));
}

std::string JsonObjectReader::KeyPath(const std::string& key) const {
  return path_.empty() ? key : path_ + "." + key;
}

void JsonObjectReader::Remember(const std::string& key) {
  for (const std::string& k : known_keys_)
    if (k == key) return;
  known_keys_.push_back(key);
}

const nlohmann::json* JsonObjectReader::Find(const std::string& key, bool required) {
  Remember(key);
  const auto it = object_->find(key);
  if (it == object_->end() || it->is_null()) {
    if (required) throw Error(file_, KeyPath(key), "required key is missing");
    return nullptr;
  }
  return &*it;
}

bool JsonObjectReader::Has(const std::string& key) { return Find(key, false) != nullptr; }

void JsonObjectReader::Ignore(const std::string& key) { Remember(key); }

namespace {
std::string JoinChoices(const std::vector<std::string>& choices) {
  std::string out;
  for (std::size_t i = 0; i < choices.size(); ++i) out += (i ? ", \"" : "\"") + choices[i] + "\"";
  return out;
}
}  // namespace

bool JsonObjectReader::OptionalChoice(const std::string& key,
                                      const std::vector<std::string>& choices, std::string* value) {
  std::string v;
  if (!Optional(key, &v)) return false;
  for (const std::string& c : choices) {
    if (c == v) {
      *value = v;
      return true;
    }
  }
  Fail(key, "\"" + v + "\" is not one of " + JoinChoices(choices));
}

void JsonObjectReader::RequiredChoice(const std::string& key,
                                      const std::vector<std::string>& choices, std::string* value) {
  Find(key, true);
  OptionalChoice(key, choices, value);
}

JsonObjectReader JsonObjectReader::Object(const std::string& key) {
  return JsonObjectReader(*Find(key, true), file_, KeyPath(key));
}

std::optional<JsonObjectReader> JsonObjectReader::OptionalObject(const std::string& key) {
  const nlohmann::json* member = Find(key, false);
  if (member == nullptr) return std::nullopt;
  return JsonObjectReader(*member, file_, KeyPath(key));
}

std::vector<JsonObjectReader> JsonObjectReader::ObjectArray(const std::string& key, bool required) {
  std::vector<JsonObjectReader> out;
  const nlohmann::json* member = Find(key, required);
  if (member == nullptr) return out;
  if (!member->is_array()) TypeError(*member, file_, KeyPath(key), "an array of objects");
  for (std::size_t i = 0; i < member->size(); ++i)
    out.emplace_back((*member)[i], file_, Element(KeyPath(key), i));
  return out;
}

void JsonObjectReader::Fail(const std::string& key, const std::string& what) const {
  throw Error(file_, KeyPath(key), what);
}

void JsonObjectReader::CheckPositive(const std::string& key, double value) const {
  if (!(value > 0.0) || !std::isfinite(value))
    Fail(key, "must be a positive number, got " + FormatNumber(value));
}

void JsonObjectReader::CheckNonNegative(const std::string& key, double value) const {
  if (!(value >= 0.0) || !std::isfinite(value))
    Fail(key, "must be zero or positive, got " + FormatNumber(value));
}

void JsonObjectReader::CheckInRange(const std::string& key, double value, double lo, double hi,
                                    bool open) const {
  const bool ok = open ? (value > lo && value < hi) : (value >= lo && value <= hi);
  if (!ok)
    Fail(key, "must be in " + std::string(open ? "(" : "[") + FormatNumber(lo) + ", " +
                  FormatNumber(hi) + (open ? ")" : "]") + ", got " + FormatNumber(value));
}

void JsonObjectReader::Finish() const {
  std::vector<std::string> unknown;
  for (auto it = object_->begin(); it != object_->end(); ++it) {
    bool known = false;
    for (const std::string& k : known_keys_) known = known || k == it.key();
    if (!known) unknown.push_back(it.key());
  }
  if (unknown.empty()) return;
  std::string expected;
  for (std::size_t i = 0; i < known_keys_.size(); ++i) expected += (i ? ", " : "") + known_keys_[i];
  std::string where;
  for (std::size_t i = 0; i < unknown.size(); ++i) where += (i ? ", " : "") + KeyPath(unknown[i]);
  throw Error(file_, where,
              std::string(unknown.size() == 1 ? "unknown key" : "unknown keys") +
                  " (expected one of: " + (expected.empty() ? "no keys" : expected) + ")");
}

}  // namespace arreg
