#include "option_parser.h"

#include <cmath>
#include <cstdio>
#include <sstream>

#include "core/error.h"

namespace arreg::cli {
namespace {

int ParseIntValue(const std::string& name, const std::string& text) {
  try {
    size_t used = 0;
    const long v = std::stol(text, &used);
    if (used != text.size() || v < INT32_MIN || v > INT32_MAX) throw std::invalid_argument("");
    return static_cast<int>(v);
  } catch (const std::exception&) {
    throw UsageError("--" + name, "expected an integer, got '" + text + "'");
  }
}

double ParseDoubleValue(const std::string& name, const std::string& text) {
  try {
    size_t used = 0;
    const double v = std::stod(text, &used);
    if (used != text.size() || !std::isfinite(v)) throw std::invalid_argument("");
    return v;
  } catch (const std::exception&) {
    throw UsageError("--" + name, "expected a finite number, got '" + text + "'");
  }
}

std::string FormatDouble(double v) {
  std::ostringstream os;
  os << v;
  return os.str();
}

}  // namespace

OptionParser::OptionParser(std::string usage, std::string summary)
    : usage_(std::move(usage)), summary_(std::move(summary)) {}

void OptionParser::AddFlag(const std::string& name, bool* target, const std::string& help) {
  Option o;
  o.name = name;
  o.help = help;
  o.is_flag = true;
  o.set = [target](const std::string&) { *target = true; };
  options_.push_back(std::move(o));
}

void OptionParser::AddString(const std::string& name, std::string* target,
                             const std::string& metavar, const std::string& help, bool required) {
  Option o{name,
           metavar,
           help,
           target->empty() ? "" : *target,
           false,
           required,
           [target](const std::string& v) { *target = v; }};
  options_.push_back(std::move(o));
}

void OptionParser::AddStringList(const std::string& name, std::vector<std::string>* target,
                                 const std::string& metavar, const std::string& help) {
  Option o{name, metavar, help + " (repeatable)", "", false, false, [target](const std::string& v) {
             target->push_back(v);
           }};
  options_.push_back(std::move(o));
}

void OptionParser::AddInt(const std::string& name, int* target, const std::string& metavar,
                          const std::string& help, bool required) {
  Option o{name,
           metavar,
           help,
           std::to_string(*target),
           false,
           required,
           [target, name](const std::string& v) { *target = ParseIntValue(name, v); }};
  options_.push_back(std::move(o));
}

void OptionParser::AddDouble(const std::string& name, double* target, const std::string& metavar,
                             const std::string& help, bool required) {
  Option o{name,
           metavar,
           help,
           FormatDouble(*target),
           false,
           required,
           [target, name](const std::string& v) { *target = ParseDoubleValue(name, v); }};
  options_.push_back(std::move(o));
}

void OptionParser::AddPositional(const std::string& metavar, std::string* target,
                                 const std::string& help, bool required) {
  positionals_.push_back({metavar, help, target, required});
}

bool OptionParser::Given(const std::string& name) const { return given_.count(name) > 0; }

bool OptionParser::Parse(int argc, char** argv, int first) {
  size_t next_positional = 0;
  for (int i = first; i < argc; ++i) {
    std::string arg = argv[i];
    if (arg == "--help" || arg == "-h") {
      std::fputs(Help().c_str(), stdout);
      return false;
    }
    if (arg.size() > 2 && arg.compare(0, 2, "--") == 0) {
      std::string name = arg.substr(2), value;
      bool has_inline_value = false;
      if (const size_t eq = name.find('='); eq != std::string::npos) {
        value = name.substr(eq + 1);
        name = name.substr(0, eq);
        has_inline_value = true;
      }
      Option* opt = nullptr;
      for (auto& o : options_)
        if (o.name == name) opt = &o;
      if (!opt) throw UsageError("--" + name, "unknown option (see --help)");
      if (opt->is_flag) {
        if (has_inline_value) throw UsageError("--" + name, "is a flag and takes no value");
      } else if (!has_inline_value) {
        if (i + 1 >= argc) throw UsageError("--" + name, "expects a value " + opt->metavar);
        value = argv[++i];
      }
      opt->set(value);
      given_[name] = true;
      continue;
    }
    if (next_positional >= positionals_.size())
      throw UsageError("argument '" + arg + "'", "unexpected (see --help)");
    *positionals_[next_positional++].target = arg;
  }
  for (size_t p = next_positional; p < positionals_.size(); ++p)
    if (positionals_[p].required)
      throw UsageError(positionals_[p].metavar, "missing required argument (see --help)");
  for (const auto& o : options_)
    if (o.required && !Given(o.name))
      throw UsageError("--" + o.name, "missing required option (see --help)");
  return true;
}

std::string OptionParser::Help() const {
  std::ostringstream os;
  os << "usage: " << usage_ << "\n\n" << summary_ << "\n";
  if (!positionals_.empty()) {
    os << "\narguments:\n";
    for (const auto& p : positionals_) os << "  " << p.metavar << "\n      " << p.help << "\n";
  }
  os << "\noptions:\n";
  for (const auto& o : options_) {
    os << "  --" << o.name;
    if (!o.is_flag) os << " " << o.metavar;
    os << "\n      " << o.help;
    if (o.required)
      os << " (required)";
    else if (!o.is_flag && !o.default_text.empty())
      os << " (default: " << o.default_text << ")";
    os << "\n";
  }
  os << "  --help\n      show this help and exit\n";
  if (!epilog_.empty()) os << "\n" << epilog_ << "\n";
  return os.str();
}

}  // namespace arreg::cli
