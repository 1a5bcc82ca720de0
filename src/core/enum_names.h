#pragma once
// Names of an enum's values, from one table: the name of a value, the value of a name, and the
// list of names for an error message. An enum that is read from a file or a command line and
// written to a record declares one table beside its Name/Parse functions:
//
//   constexpr EnumName<RobustLoss> kRobustLossNames[] = {
//       {RobustLoss::kHuber, "huber"}, {RobustLoss::kCauchy, "cauchy"}, {RobustLoss::kNone,
//       "none"}};
//   const char* RobustLossName(RobustLoss l) { return NameOf(kRobustLossNames, l); }
//   RobustLoss ParseRobustLoss(const std::string& name, const std::string& field) {
//     return ParseName(kRobustLossNames, name, "", field);   // throws Error naming the field
//   }

#include <cstddef>
#include <optional>
#include <string>
#include <string_view>

#include "core/error.h"

namespace arreg {

template <typename E>
struct EnumName {
  E value;
  const char* name;
};

// The name of `value`, "?" when the table lacks it (a value cast from an out-of-range integer).
template <typename E, std::size_t N>
const char* NameOf(const EnumName<E> (&table)[N], E value) {
  for (const EnumName<E>& e : table)
    if (e.value == value) return e.name;
  return "?";
}

// The value named `name`, or nothing.
template <typename E, std::size_t N>
std::optional<E> FindName(const EnumName<E> (&table)[N], std::string_view name) {
  for (const EnumName<E>& e : table)
    if (name == e.name) return e.value;
  return std::nullopt;
}

// The names in table order as "a, b or c".
template <typename E, std::size_t N>
std::string NameList(const EnumName<E> (&table)[N]) {
  std::string list;
  for (std::size_t i = 0; i < N; ++i) {
    if (i > 0) list += i + 1 == N ? " or " : ", ";
    list += table[i].name;
  }
  return list;
}

// The value named `name`; otherwise throws Error(file, field, "must be a, b or c, got 'x'").
template <typename E, std::size_t N>
E ParseName(const EnumName<E> (&table)[N], const std::string& name, const std::string& file,
            const std::string& field) {
  if (std::optional<E> value = FindName(table, name)) return *value;
  throw Error(file, field, "must be " + NameList(table) + ", got '" + name + "'");
}

}  // namespace arreg
