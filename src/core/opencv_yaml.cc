#include "core/opencv_yaml.h"

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <limits>

#include "core/error.h"
#include "core/file_util.h"

namespace arreg {
namespace {

std::string LineWhere(int line) { return "line " + std::to_string(line); }

std::string Trim(const std::string& s) {
  const std::size_t b = s.find_first_not_of(" \t");
  if (b == std::string::npos) return "";
  const std::size_t e = s.find_last_not_of(" \t");
  return s.substr(b, e - b + 1);
}

struct Line {
  int number = 0;       // 1-based
  int indent = 0;       // leading spaces
  std::string content;  // without indentation, comment and trailing spaces
};

// Removes a "#" comment (outside quotes, at the start or after a blank).
std::string StripComment(const std::string& s) {
  char quote = 0;
  for (std::size_t i = 0; i < s.size(); ++i) {
    const char c = s[i];
    if (quote) {
      if (c == '\\' && quote == '"') {
        ++i;
      } else if (c == quote) {
        quote = 0;
      }
    } else if (c == '"' || c == '\'') {
      quote = c;
    } else if (c == '#' && (i == 0 || s[i - 1] == ' ' || s[i - 1] == '\t')) {
      return s.substr(0, i);
    }
  }
  return s;
}

// Position of the ':' that ends a block mapping key ("key: value" or "key:"),
// skipping quoted keys; npos when the content is not a key line.
std::size_t FindKeyColon(const std::string& s) {
  if (s.empty() || s[0] == '[' || s[0] == '{') return std::string::npos;
  std::size_t i = 0;
  if (s[0] == '"' || s[0] == '\'') {
    const char q = s[0];
    for (i = 1; i < s.size(); ++i) {
      if (s[i] == '\\' && q == '"') {
        ++i;
      } else if (s[i] == q) {
        if (q == '\'' && i + 1 < s.size() && s[i + 1] == '\'') {
          ++i;
          continue;
        }
        break;
      }
    }
    ++i;
  }
  for (; i < s.size(); ++i) {
    if (s[i] == ':' && (i + 1 == s.size() || s[i + 1] == ' ' || s[i + 1] == '\t')) return i;
  }
  return std::string::npos;
}

bool IsSequenceItem(const std::string& content) {
  return content == "-" || (content.size() >= 2 && content[0] == '-' && content[1] == ' ');
}

class Parser {
 public:
  Parser(const std::string& text, std::string file) : file_(std::move(file)) { Split(text); }

  YamlNode ParseDocument() {
    if (lines_.empty()) return YamlNode();
    if (lines_[0].indent != 0) Fail(lines_[0].number, "the document must start at column 1");
    YamlNode root = ParseBlock(0);
    if (pos_ < lines_.size()) Fail(lines_[pos_].number, "unexpected indentation");
    return root;
  }

 private:
  [[noreturn]] void Fail(int line, const std::string& what) const {
    throw Error(file_, LineWhere(line), what);
  }

  void Split(const std::string& text) {
    std::size_t start = 0;
    int number = 0;
    while (start <= text.size()) {
      std::size_t end = text.find('\n', start);
      if (end == std::string::npos) end = text.size();
      std::string raw = text.substr(start, end - start);
      start = end + 1;
      ++number;
      if (!raw.empty() && raw.back() == '\r') raw.pop_back();
      std::string s = StripComment(raw);
      const std::string trimmed = Trim(s);
      if (trimmed.empty()) {
        if (end == text.size()) break;
        continue;
      }
      if (s[0] == '%') {
        if (!lines_.empty()) Fail(number, "directive after the document start");
        continue;
      }
      if (trimmed == "---" || trimmed.rfind("--- ", 0) == 0) {
        if (!lines_.empty()) Fail(number, "only one YAML document per file is supported");
        continue;
      }
      if (trimmed == "...") break;
      Line line;
      line.number = number;
      std::size_t i = 0;
      while (i < s.size() && (s[i] == ' ' || s[i] == '\t')) {
        if (s[i] == '\t') Fail(number, "tab in indentation (YAML allows spaces only)");
        ++i;
      }
      line.indent = static_cast<int>(i);
      line.content = Trim(s.substr(i));
      lines_.push_back(std::move(line));
      if (end == text.size()) break;
    }
  }

  YamlNode ParseBlock(int indent) {
    if (IsSequenceItem(lines_[pos_].content)) return ParseSequence(indent);
    return ParseMapping(indent);
  }

  YamlNode ParseMapping(int indent) {
    YamlNode node;
    node.kind = YamlNode::Kind::kMapping;
    node.line = lines_[pos_].number;
    while (pos_ < lines_.size() && lines_[pos_].indent == indent) {
      const Line line = lines_[pos_];
      if (IsSequenceItem(line.content)) Fail(line.number, "sequence item '-' inside a mapping");
      const std::size_t colon = FindKeyColon(line.content);
      if (colon == std::string::npos)
        Fail(line.number, "expected 'key: value', got '" + line.content + "'");
      const std::string key = Unquote(Trim(line.content.substr(0, colon)), line.number);
      if (key.empty()) Fail(line.number, "empty key");
      if (node.Find(key) != nullptr) Fail(line.number, "duplicate key '" + key + "'");
      ++pos_;
      YamlNode value = ParseValue(Trim(line.content.substr(colon + 1)), line.number, indent, true);
      node.entries.emplace_back(key, std::move(value));
    }
    if (pos_ < lines_.size() && lines_[pos_].indent > indent)
      Fail(lines_[pos_].number, "unexpected indentation");
    return node;
  }

  YamlNode ParseSequence(int indent) {
    YamlNode node;
    node.kind = YamlNode::Kind::kSequence;
    node.line = lines_[pos_].number;
    while (pos_ < lines_.size() && lines_[pos_].indent == indent &&
           IsSequenceItem(lines_[pos_].content)) {
      const Line line = lines_[pos_];
      const std::string rest = Trim(line.content.substr(1));
      if (!rest.empty() && FindKeyColon(rest) != std::string::npos) {
        // "- key: value" starts a mapping indented to where "key" begins.
        const int offset = static_cast<int>(line.content.size() - rest.size());
        lines_[pos_].indent = indent + offset;
        lines_[pos_].content = rest;
        node.items.push_back(ParseMapping(indent + offset));
        continue;
      }
      ++pos_;
      node.items.push_back(ParseValue(rest, line.number, indent, false));
    }
    if (pos_ < lines_.size() && lines_[pos_].indent > indent)
      Fail(lines_[pos_].number, "unexpected indentation");
    return node;
  }

  // The value after "key:" or "-" on line `line_number`; `parent_indent` is
  // the indentation of that key or dash.
  YamlNode ParseValue(std::string rest, int line_number, int parent_indent, bool in_mapping) {
    std::string tag;
    if (!rest.empty() && rest[0] == '!') {
      const std::size_t end = rest.find_first_of(" \t");
      tag = rest.substr(0, end);
      tag.erase(0, tag.find_first_not_of('!'));
      rest = end == std::string::npos ? "" : Trim(rest.substr(end));
    }
    YamlNode value;
    if (rest.empty()) {
      if (pos_ < lines_.size() && lines_[pos_].indent > parent_indent) {
        value = ParseBlock(lines_[pos_].indent);
      } else if (in_mapping && pos_ < lines_.size() && lines_[pos_].indent == parent_indent &&
                 IsSequenceItem(lines_[pos_].content)) {
        value = ParseSequence(parent_indent);  // YAML allows "key:\n- a\n- b"
      } else {
        value.line = line_number;
      }
    } else if (rest[0] == '[' || rest[0] == '{') {
      value = ParseFlowText(rest, line_number);
    } else if (rest[0] == '|' || rest[0] == '>') {
      Fail(line_number, "block scalars ('|', '>') are not supported");
    } else if (rest[0] == '&' || rest[0] == '*') {
      Fail(line_number, "anchors and aliases are not supported");
    } else {
      value.kind = YamlNode::Kind::kScalar;
      value.quoted = rest[0] == '"' || rest[0] == '\'';
      value.scalar = Unquote(rest, line_number);
      value.line = line_number;
      if (pos_ < lines_.size() && lines_[pos_].indent > parent_indent)
        Fail(lines_[pos_].number, "unexpected indentation (multi-line scalars are not supported)");
    }
    if (!tag.empty()) value.tag = tag;
    return value;
  }

  // A quoted scalar must be closed on its line with nothing after it.
  std::string Unquote(const std::string& s, int line_number) const {
    if (s.empty() || (s[0] != '"' && s[0] != '\'')) return s;
    std::size_t pos = 0;
    std::string out = ReadQuoted(s, &pos, line_number);
    if (!Trim(s.substr(pos)).empty())
      Fail(line_number, "unexpected text after the closing quote: '" + s.substr(pos) + "'");
    return out;
  }

  std::string ReadQuoted(const std::string& s, std::size_t* pos, int line_number) const {
    const char q = s[*pos];
    std::string out;
    std::size_t i = *pos + 1;
    for (; i < s.size(); ++i) {
      const char c = s[i];
      if (q == '"' && c == '\\' && i + 1 < s.size()) {
        const char e = s[++i];
        switch (e) {
          case 'n':
            out += '\n';
            break;
          case 't':
            out += '\t';
            break;
          case '"':
            out += '"';
            break;
          case '\\':
            out += '\\';
            break;
          case '/':
            out += '/';
            break;
          default:
            out += '\\';
            out += e;
            break;
        }
      } else if (c == q) {
        if (q == '\'' && i + 1 < s.size() && s[i + 1] == '\'') {
          out += '\'';
          ++i;
        } else {
          *pos = i + 1;
          return out;
        }
      } else {
        if (c == '\n') ++line_number;
        out += c;
      }
    }
    Fail(line_number, "unterminated quoted string");
  }

  // Collects the lines of a flow collection until its brackets balance.
  YamlNode ParseFlowText(std::string text, int line_number) {
    while (!FlowBalanced(text)) {
      if (pos_ >= lines_.size())
        Fail(line_number, "unterminated flow collection (missing ']' or '}')");
      text += "\n" + lines_[pos_].content;
      ++pos_;
    }
    flow_ = &text;
    flow_pos_ = 0;
    flow_line_ = line_number;
    YamlNode node = ParseFlowNode(false);
    SkipFlowSpace();
    if (flow_pos_ < text.size())
      Fail(flow_line_,
           "unexpected text after the flow collection: '" + text.substr(flow_pos_) + "'");
    flow_ = nullptr;
    return node;
  }

  static bool FlowBalanced(const std::string& s) {
    int depth = 0;
    char quote = 0;
    for (std::size_t i = 0; i < s.size(); ++i) {
      const char c = s[i];
      if (quote) {
        if (c == '\\' && quote == '"') {
          ++i;
        } else if (c == quote) {
          quote = 0;
        }
      } else if (c == '"' || c == '\'') {
        quote = c;
      } else if (c == '[' || c == '{') {
        ++depth;
      } else if (c == ']' || c == '}') {
        --depth;
      }
    }
    return depth <= 0 && quote == 0;
  }

  void SkipFlowSpace() {
    const std::string& s = *flow_;
    while (flow_pos_ < s.size() &&
           (s[flow_pos_] == ' ' || s[flow_pos_] == '\t' || s[flow_pos_] == '\n')) {
      if (s[flow_pos_] == '\n') ++flow_line_;
      ++flow_pos_;
    }
  }

  YamlNode ParseFlowNode(bool as_key) {
    const std::string& s = *flow_;
    SkipFlowSpace();
    YamlNode node;
    node.line = flow_line_;
    if (flow_pos_ < s.size() && s[flow_pos_] == '!') {
      const std::size_t end = s.find_first_of(" \t\n,]}", flow_pos_);
      node.tag = s.substr(flow_pos_, end - flow_pos_);
      node.tag.erase(0, node.tag.find_first_not_of('!'));
      flow_pos_ = end == std::string::npos ? s.size() : end;
      SkipFlowSpace();
    }
    if (flow_pos_ >= s.size()) Fail(flow_line_, "unexpected end of flow collection");
    const char c = s[flow_pos_];
    if (c == '[' && !as_key) {
      node.kind = YamlNode::Kind::kSequence;
      ++flow_pos_;
      while (true) {
        SkipFlowSpace();
        if (flow_pos_ < s.size() && s[flow_pos_] == ']') {
          ++flow_pos_;
          break;
        }
        node.items.push_back(ParseFlowNode(false));
        SkipFlowSpace();
        if (flow_pos_ < s.size() && s[flow_pos_] == ',') {
          ++flow_pos_;
        } else if (flow_pos_ < s.size() && s[flow_pos_] == ']') {
          ++flow_pos_;
          break;
        } else {
          Fail(flow_line_, "expected ',' or ']' in flow sequence");
        }
      }
    } else if (c == '{' && !as_key) {
      node.kind = YamlNode::Kind::kMapping;
      ++flow_pos_;
      while (true) {
        SkipFlowSpace();
        if (flow_pos_ < s.size() && s[flow_pos_] == '}') {
          ++flow_pos_;
          break;
        }
        const int key_line = flow_line_;
        YamlNode key = ParseFlowNode(true);
        SkipFlowSpace();
        if (flow_pos_ >= s.size() || s[flow_pos_] != ':')
          Fail(flow_line_, "expected ':' after key '" + key.scalar + "' in flow mapping");
        ++flow_pos_;
        if (node.Find(key.scalar) != nullptr) Fail(key_line, "duplicate key '" + key.scalar + "'");
        node.entries.emplace_back(key.scalar, ParseFlowNode(false));
        SkipFlowSpace();
        if (flow_pos_ < s.size() && s[flow_pos_] == ',') {
          ++flow_pos_;
        } else if (flow_pos_ < s.size() && s[flow_pos_] == '}') {
          ++flow_pos_;
          break;
        } else {
          Fail(flow_line_, "expected ',' or '}' in flow mapping");
        }
      }
    } else if (c == '"' || c == '\'') {
      node.kind = YamlNode::Kind::kScalar;
      node.quoted = true;
      const int start_line = flow_line_;
      node.scalar = ReadQuoted(s, &flow_pos_, start_line);
      for (char ch : node.scalar) flow_line_ += ch == '\n';
    } else {
      node.kind = YamlNode::Kind::kScalar;
      const std::size_t start = flow_pos_;
      while (flow_pos_ < s.size()) {
        const char ch = s[flow_pos_];
        if (ch == ',' || ch == ']' || ch == '}' || ch == '\n' || ch == '[' || ch == '{') break;
        if (ch == ':' && (as_key || flow_pos_ + 1 == s.size() || s[flow_pos_ + 1] == ' ')) break;
        ++flow_pos_;
      }
      node.scalar = Trim(s.substr(start, flow_pos_ - start));
      if (node.scalar.empty()) Fail(flow_line_, "empty value in flow collection");
    }
    return node;
  }

  std::string file_;
  std::vector<Line> lines_;
  std::size_t pos_ = 0;
  // Flow-collection state.
  const std::string* flow_ = nullptr;
  std::size_t flow_pos_ = 0;
  int flow_line_ = 0;
};

[[noreturn]] void NodeError(const YamlNode& node, const std::string& file, const std::string& key,
                            const std::string& what) {
  throw Error(file, LineWhere(node.line), key + ": " + what);
}

}  // namespace

const YamlNode* YamlNode::Find(const std::string& key) const {
  if (kind != Kind::kMapping) return nullptr;
  for (const auto& entry : entries)
    if (entry.first == key) return &entry.second;
  return nullptr;
}

YamlNode ParseOpenCvYaml(const std::string& text, const std::string& file) {
  // Editors on Windows may prepend a UTF-8 byte-order mark.
  if (text.rfind("\xEF\xBB\xBF", 0) == 0) return ParseOpenCvYaml(text.substr(3), file);
  Parser parser(text, file);
  return parser.ParseDocument();
}

YamlNode ParseOpenCvYamlFile(const std::string& path) {
  return ParseOpenCvYaml(ReadFileToString(path), path);
}

double YamlToDouble(const YamlNode& node, const std::string& file, const std::string& key) {
  if (node.kind != YamlNode::Kind::kScalar || node.quoted)
    NodeError(node, file, key, "expected a number");
  const std::string& s = node.scalar;
  if (s == ".nan" || s == ".NaN" || s == ".NAN" || s == ".Nan")
    return std::numeric_limits<double>::quiet_NaN();
  if (s == ".inf" || s == ".Inf" || s == ".INF" || s == "+.inf" || s == "+.Inf")
    return std::numeric_limits<double>::infinity();
  if (s == "-.inf" || s == "-.Inf" || s == "-.INF") return -std::numeric_limits<double>::infinity();
  errno = 0;
  char* end = nullptr;
  const double v = std::strtod(s.c_str(), &end);
  if (s.empty() || end != s.c_str() + s.size() || errno == ERANGE)
    NodeError(node, file, key, "expected a number, got '" + s + "'");
  return v;
}

int YamlToInt(const YamlNode& node, const std::string& file, const std::string& key) {
  const double v = YamlToDouble(node, file, key);
  if (!(std::floor(v) == v) || std::fabs(v) > 2147483647.0)
    NodeError(node, file, key, "expected an integer, got '" + node.scalar + "'");
  return static_cast<int>(v);
}

std::string YamlToString(const YamlNode& node, const std::string& file, const std::string& key) {
  if (node.kind != YamlNode::Kind::kScalar) NodeError(node, file, key, "expected a string");
  return node.scalar;
}

Eigen::MatrixXd YamlToMatrix(const YamlNode& node, const std::string& file,
                             const std::string& key) {
  if (node.kind == YamlNode::Kind::kSequence) {
    const auto n = static_cast<Eigen::Index>(node.items.size());
    if (n > 0 && node.items[0].kind == YamlNode::Kind::kSequence) {
      const auto cols = static_cast<Eigen::Index>(node.items[0].items.size());
      Eigen::MatrixXd m(n, cols);
      for (Eigen::Index r = 0; r < n; ++r) {
        const YamlNode& row = node.items[r];
        if (row.kind != YamlNode::Kind::kSequence ||
            static_cast<Eigen::Index>(row.items.size()) != cols)
          NodeError(row, file, key,
                    "rows of a nested matrix must all have " + std::to_string(cols) + " numbers");
        for (Eigen::Index c = 0; c < cols; ++c)
          m(r, c) = YamlToDouble(row.items[c], file,
                                 key + "[" + std::to_string(r) + "][" + std::to_string(c) + "]");
      }
      return m;
    }
    Eigen::MatrixXd m(n, 1);
    for (Eigen::Index i = 0; i < n; ++i)
      m(i, 0) = YamlToDouble(node.items[i], file, key + "[" + std::to_string(i) + "]");
    return m;
  }
  if (node.kind != YamlNode::Kind::kMapping)
    NodeError(
        node, file, key,
        "expected a matrix (!!opencv-matrix {rows, cols, dt, data}) or a sequence of numbers");
  const YamlNode* rows_node = node.Find("rows");
  const YamlNode* cols_node = node.Find("cols");
  const YamlNode* data_node = node.Find("data");
  if (rows_node == nullptr) NodeError(node, file, key + ".rows", "required key is missing");
  if (cols_node == nullptr) NodeError(node, file, key + ".cols", "required key is missing");
  if (data_node == nullptr) NodeError(node, file, key + ".data", "required key is missing");
  const int rows = YamlToInt(*rows_node, file, key + ".rows");
  const int cols = YamlToInt(*cols_node, file, key + ".cols");
  if (rows < 0 || cols < 0) NodeError(node, file, key, "negative matrix size");
  if (const YamlNode* dt = node.Find("dt")) {
    const std::string t = YamlToString(*dt, file, key + ".dt");
    if (t != "d" && t != "f" && t != "i" && t != "u" && t != "s" && t != "w" && t != "c")
      NodeError(*dt, file, key + ".dt",
                "single-channel element type expected (d, f, i, ...), got '" + t + "'");
  }
  if (data_node->kind != YamlNode::Kind::kSequence)
    NodeError(*data_node, file, key + ".data", "expected a sequence of numbers");
  if (data_node->items.size() != static_cast<std::size_t>(rows) * static_cast<std::size_t>(cols))
    NodeError(*data_node, file, key + ".data",
              "has " + std::to_string(data_node->items.size()) +
                  " numbers, rows x cols = " + std::to_string(rows) + " x " + std::to_string(cols) +
                  " needs " + std::to_string(rows * cols));
  Eigen::MatrixXd m(rows, cols);
  for (int i = 0; i < rows * cols; ++i)
    m(i / cols, i % cols) =
        YamlToDouble(data_node->items[i], file, key + ".data[" + std::to_string(i) + "]");
  return m;
}

}  // namespace arreg
