// A small reader for the YAML subset written by OpenCV's FileStorage and ROS
// camera_info files, so that core can read calibrations without linking OpenCV.
#pragma once

#include <Eigen/Core>
#include <string>
#include <utility>
#include <vector>

namespace arreg {

// Supported: "%YAML:1.0" / "%YAML 1.2" directives, "---" and "..." markers,
// block mappings by indentation, block sequences ("- item"), flow sequences
// and flow mappings ("[1, 2,\n 3]", "{rows: 3, cols: 1}") spread over several
// lines, plain/single/double-quoted scalars, "#" comments and tags such as
// "!!opencv-matrix" (kept in `tag`). Not supported (errors naming the line):
// anchors/aliases, multi-line plain or block scalars ("|", ">"), tabs in
// indentation, complex keys.
struct YamlNode {
  enum class Kind { kNull, kScalar, kSequence, kMapping };
  Kind kind = Kind::kNull;
  std::string tag;              // e.g. "opencv-matrix" for "!!opencv-matrix"; "" if none
  std::string scalar;           // kScalar: the text, quotes removed
  bool quoted = false;          // kScalar: it was quoted (so never a number)
  std::vector<YamlNode> items;  // kSequence
  std::vector<std::pair<std::string, YamlNode>> entries;  // kMapping, in file order
  int line = 0;                                           // 1-based line where the node starts

  // Mapping lookup; nullptr when absent or when this is not a mapping.
  const YamlNode* Find(const std::string& key) const;
  bool IsScalar() const { return kind == Kind::kScalar; }
};

// Parses `text`; `file` is used in error messages ("calib.yaml: line 7: ...").
YamlNode ParseOpenCvYaml(const std::string& text, const std::string& file);
YamlNode ParseOpenCvYamlFile(const std::string& path);

// Typed access with errors naming the file, the key and the node's line.
double YamlToDouble(const YamlNode& node, const std::string& file, const std::string& key);
int YamlToInt(const YamlNode& node, const std::string& file, const std::string& key);
std::string YamlToString(const YamlNode& node, const std::string& file, const std::string& key);
// A matrix given as an OpenCV matrix mapping ({rows, cols, dt, data}, with or
// without the !!opencv-matrix tag) or as a plain sequence of numbers (then
// returned as a column vector). Data are row-major as OpenCV writes them.
Eigen::MatrixXd YamlToMatrix(const YamlNode& node, const std::string& file, const std::string& key);

}  // namespace arreg
