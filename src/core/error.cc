#include "core/error.h"

namespace arreg {

std::string FormatErrorMessage(const std::string& file, const std::string& where,
                               const std::string& what) {
  std::string out;
  if (!file.empty()) out += file;
  if (!where.empty()) {
    if (!out.empty()) out += ": ";
    out += where;
  }
  if (!out.empty()) out += ": ";
  out += what;
  return out;
}

Error::Error(std::string file, std::string where, std::string what)
    : std::runtime_error(FormatErrorMessage(file, where, what)),
      file_(std::move(file)),
      where_(std::move(where)),
      detail_(std::move(what)) {}

}  // namespace arreg
