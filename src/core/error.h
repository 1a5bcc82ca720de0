// The one exception type for bad input (files, options, video): it carries the
// file, the place in it (line or field) and what was expected.
#pragma once

#include <sstream>
#include <stdexcept>
#include <string>

namespace arreg {

class Error : public std::runtime_error {
 public:
  // `file` may be empty (options, in-memory data); `where` is a line ("line 12"),
  // a field ("camera.fx") or a frame ("frame 31"); `what` says what was wrong or expected.
  Error(std::string file, std::string where, std::string what);

  const std::string& file() const { return file_; }
  const std::string& where() const { return where_; }
  const std::string& detail() const { return detail_; }

 private:
  std::string file_;
  std::string where_;
  std::string detail_;
};

// Formats "file:where: what" with the empty parts left out.
std::string FormatErrorMessage(const std::string& file, const std::string& where,
                               const std::string& what);

namespace internal {
template <typename... Args>
std::string Concat(Args&&... args) {
  std::ostringstream os;
  (os << ... << args);
  return os.str();
}
}  // namespace internal

}  // namespace arreg

// Throws arreg::Error when `cond` is false. The message parts are streamed.
#define ARREG_CHECK_INPUT(cond, file, where, ...)                                               \
  do {                                                                                          \
    if (!(cond)) throw ::arreg::Error((file), (where), ::arreg::internal::Concat(__VA_ARGS__)); \
  } while (0)

// For broken internal invariants (programming errors, not bad input): throws
// std::logic_error naming the source location, never aborts.
#define ARREG_ASSERT(cond, ...)                                                            \
  do {                                                                                     \
    if (!(cond))                                                                           \
      throw std::logic_error(::arreg::internal::Concat(                                    \
          __FILE__, ":", __LINE__, ": internal check failed: " #cond " ", ##__VA_ARGS__)); \
  } while (0)
