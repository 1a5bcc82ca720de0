// A small declarative command-line parser shared by every `arreg` subcommand:
// options are declared with their help text and default, parsing rejects
// unknown options and malformed values with a one-line reason, and the help
// text is generated from the declarations so it cannot drift from the code.
#pragma once

#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "core/error.h"

namespace arreg::cli {

// Wrong command-line usage (unknown option, missing or malformed value): main()
// exits with code 2 for these and 1 for bad input files.
class UsageError : public Error {
 public:
  UsageError(const std::string& where, const std::string& what) : Error("", where, what) {}
};

class OptionParser {
 public:
  // `usage` is the synopsis line ("arreg info FILE [--json]"), `summary` one
  // or two sentences on what the command does.
  OptionParser(std::string usage, std::string summary);

  // Declarations. `name` without dashes ("out" for --out). The target keeps its
  // current value as the default unless the option is given.
  void AddFlag(const std::string& name, bool* target, const std::string& help);
  void AddString(const std::string& name, std::string* target, const std::string& metavar,
                 const std::string& help, bool required = false);
  void AddInt(const std::string& name, int* target, const std::string& metavar,
              const std::string& help, bool required = false);
  void AddDouble(const std::string& name, double* target, const std::string& metavar,
                 const std::string& help, bool required = false);
  // A repeatable option: each occurrence appends its value to `target`.
  void AddStringList(const std::string& name, std::vector<std::string>* target,
                     const std::string& metavar, const std::string& help);
  // Positional arguments, in order.
  void AddPositional(const std::string& metavar, std::string* target, const std::string& help,
                     bool required = true);
  // Free-form trailing text for the help page (examples, output files).
  void SetEpilog(std::string epilog) { epilog_ = std::move(epilog); }

  // Parses argv[first..argc). Returns false when --help was asked for (the
  // help was printed to stdout). Throws UsageError on bad usage.
  bool Parse(int argc, char** argv, int first = 1);

  std::string Help() const;
  // True when the named option was given on the command line.
  bool Given(const std::string& name) const;

 private:
  struct Option {
    std::string name, metavar, help, default_text;
    bool is_flag = false, required = false;
    std::function<void(const std::string&)> set;
  };
  struct Positional {
    std::string metavar, help;
    std::string* target;
    bool required;
  };
  std::string usage_, summary_, epilog_;
  std::vector<Option> options_;
  std::vector<Positional> positionals_;
  std::map<std::string, bool> given_;
};

}  // namespace arreg::cli
