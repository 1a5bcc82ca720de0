// Checked reading of JSON configuration objects: every error names the file and
// the full key path ("scene.json: scene.camera.fx: ..."), and unknown keys are rejected.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/enum_names.h"

namespace arreg {

// Parses a JSON file. Syntax errors throw arreg::Error naming the file, the line
// and column ("scene.json: line 12, column 5: ..."); duplicate keys in one object
// are errors too (JSON libraries silently keep one of them). `//` and `/* */`
// comments are accepted.
nlohmann::json ParseJsonFile(const std::string& path);
// Same for text already in memory; `file` is only used in messages.
nlohmann::json ParseJsonText(const std::string& text, const std::string& file);

// Converts one JSON value to a C++ value; throws arreg::Error("file", key_path, what)
// when the type or shape does not fit. Overloads exist for the types below; the
// reader's Required/Optional templates accept exactly these.
void ReadJsonValue(const nlohmann::json& value, const std::string& file,
                   const std::string& key_path, double* out);
void ReadJsonValue(const nlohmann::json& value, const std::string& file,
                   const std::string& key_path, float* out);
// Integers must be whole numbers within range (2.0 is accepted, 2.5 is not).
void ReadJsonValue(const nlohmann::json& value, const std::string& file,
                   const std::string& key_path, int* out);
void ReadJsonValue(const nlohmann::json& value, const std::string& file,
                   const std::string& key_path, std::int64_t* out);
void ReadJsonValue(const nlohmann::json& value, const std::string& file,
                   const std::string& key_path, bool* out);
void ReadJsonValue(const nlohmann::json& value, const std::string& file,
                   const std::string& key_path, std::string* out);
void ReadJsonValue(const nlohmann::json& value, const std::string& file,
                   const std::string& key_path, std::vector<double>* out);
void ReadJsonValue(const nlohmann::json& value, const std::string& file,
                   const std::string& key_path, std::vector<int>* out);
void ReadJsonValue(const nlohmann::json& value, const std::string& file,
                   const std::string& key_path, std::vector<std::string>* out);
void ReadJsonValue(const nlohmann::json& value, const std::string& file,
                   const std::string& key_path, Eigen::Vector2d* out);
void ReadJsonValue(const nlohmann::json& value, const std::string& file,
                   const std::string& key_path, Eigen::Vector3d* out);
void ReadJsonValue(const nlohmann::json& value, const std::string& file,
                   const std::string& key_path, Eigen::Vector4d* out);
void ReadJsonValue(const nlohmann::json& value, const std::string& file,
                   const std::string& key_path, Eigen::Vector2i* out);
void ReadJsonValue(const nlohmann::json& value, const std::string& file,
                   const std::string& key_path, Eigen::Vector3i* out);
void ReadJsonValue(const nlohmann::json& value, const std::string& file,
                   const std::string& key_path, Eigen::VectorXd* out);
// 3x3: either nested rows [[a,b,c],[d,e,f],[g,h,i]] or 9 numbers in row-major order.
void ReadJsonValue(const nlohmann::json& value, const std::string& file,
                   const std::string& key_path, Eigen::Matrix3d* out);
// 4x4: nested rows or 16 numbers in row-major order.
void ReadJsonValue(const nlohmann::json& value, const std::string& file,
                   const std::string& key_path, Eigen::Matrix4d* out);
// Any JSON value, kept as is (module sections parsed later by their owners).
void ReadJsonValue(const nlohmann::json& value, const std::string& file,
                   const std::string& key_path, nlohmann::json* out);

// A view of one JSON object that hands out its members with type checks and
// remembers which keys were asked for, so that Finish() can name the unknown
// ones (typos such as "fxx" must not be silently ignored).
//
//   JsonObjectReader r(json, "scene.json", "scene.camera");
//   r.Required("fx", &fx);  r.CheckPositive("fx", fx);
//   r.Optional("k1", &k1);  // keeps k1's value when absent
//   r.Finish();             // throws naming every unknown key
//
// The reader keeps a pointer to `object`, which must outlive it.
class JsonObjectReader {
 public:
  // Throws arreg::Error when `object` is not a JSON object. `path` is the key
  // path of the object itself ("scene.camera"); it may be empty for a file's root.
  JsonObjectReader(const nlohmann::json& object, std::string file, std::string path);

  const std::string& file() const { return file_; }
  const std::string& path() const { return path_; }
  const nlohmann::json& json() const { return *object_; }
  // "path.key" (or "key" at the root).
  std::string KeyPath(const std::string& key) const;

  // True when `key` is present (null counts as absent). Marks the key as known.
  bool Has(const std::string& key);

  // Reads a required member; a missing key or a wrong type throws naming the key path.
  template <typename T>
  void Required(const std::string& key, T* value) {
    const nlohmann::json* member = Find(key, /*required=*/true);
    ReadJsonValue(*member, file_, KeyPath(key), value);
  }
  // Reads an optional member: when absent (or null) `*value` is left unchanged,
  // so initialise it with the default. Returns whether the key was present.
  template <typename T>
  bool Optional(const std::string& key, T* value) {
    const nlohmann::json* member = Find(key, /*required=*/false);
    if (member == nullptr) return false;
    ReadJsonValue(*member, file_, KeyPath(key), value);
    return true;
  }
  // Optional with an explicit default, for std::optional-style use.
  template <typename T>
  T Get(const std::string& key, const T& default_value) {
    T value = default_value;
    Optional(key, &value);
    return value;
  }

  // Reads a string member that must be one of `choices` (error lists them).
  void RequiredChoice(const std::string& key, const std::vector<std::string>& choices,
                      std::string* value);
  bool OptionalChoice(const std::string& key, const std::vector<std::string>& choices,
                      std::string* value);
  // The same for an enum named by a table (core/enum_names.h).
  template <typename E, std::size_t N>
  bool OptionalEnum(const std::string& key, const EnumName<E> (&table)[N], E* value) {
    std::vector<std::string> names;
    names.reserve(N);
    for (const EnumName<E>& e : table) names.emplace_back(e.name);
    std::string name;
    if (!OptionalChoice(key, names, &name)) return false;
    *value = *FindName(table, name);
    return true;
  }
  template <typename E, std::size_t N>
  void RequiredEnum(const std::string& key, const EnumName<E> (&table)[N], E* value) {
    Find(key, /*required=*/true);
    OptionalEnum(key, table, value);
  }

  // Nested objects: the child reader's path is "path.key". Its own Finish() is
  // the caller's job.
  JsonObjectReader Object(const std::string& key);
  std::optional<JsonObjectReader> OptionalObject(const std::string& key);
  // An array of objects; child paths are "path.key[i]". Absent means empty when
  // `required` is false.
  std::vector<JsonObjectReader> ObjectArray(const std::string& key, bool required = false);

  // Declares keys that are accepted but read elsewhere (or deliberately ignored).
  void Ignore(const std::string& key);

  // Range checks, throwing arreg::Error naming the key path and the offending value.
  void CheckPositive(const std::string& key, double value) const;     // value > 0
  void CheckNonNegative(const std::string& key, double value) const;  // value >= 0
  // lo <= value <= hi (or lo < value < hi when `open` is true).
  void CheckInRange(const std::string& key, double value, double lo, double hi,
                    bool open = false) const;
  // Throws arreg::Error(file, KeyPath(key), what): for checks the helpers above do not cover.
  [[noreturn]] void Fail(const std::string& key, const std::string& what) const;

  // Throws when the object has members that no call above asked for, naming
  // all of them and the keys that are expected.
  void Finish() const;

 private:
  const nlohmann::json* Find(const std::string& key, bool required);
  void Remember(const std::string& key);

  const nlohmann::json* object_;
  std::string file_;
  std::string path_;
  std::vector<std::string> known_keys_;  // in the order they were asked for
};

}  // namespace arreg
