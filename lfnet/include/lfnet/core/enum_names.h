// Closed sets of names as enums, each with one table of its names (docs/architecture.md,
// "Options"). An enum's header declares
//
//   enum class Branches { kNet, kAe, kCnn };
//   std::string to_string(Branches value);
//   Branches from_string(const std::string& name, Branches);  // the second argument picks it
//
// and its source file defines both from one table:
//
//   constexpr EnumName<Branches> kBranches[] = {{Branches::kNet, "net"}, ...};
//   std::string to_string(Branches v) { return name_of(v, kBranches); }
//   Branches from_string(const std::string& s, Branches) { return value_of(s, kBranches); }
//
// Options structs then read and write the field by its name (core/fields.h).
#pragma once

#include <cstddef>
#include <string>

#include "lfnet/core/error.h"

namespace lfnet {

template <typename E>
struct EnumName {
  E value;
  const char* name;
};

// "a, b, c": the known names, for messages.
template <typename E, std::size_t N>
std::string known_names(const EnumName<E> (&table)[N]) {
  std::string out;
  for (std::size_t i = 0; i < N; ++i) out += (i ? ", " : "") + std::string(table[i].name);
  return out;
}

template <typename E, std::size_t N>
std::string name_of(E value, const EnumName<E> (&table)[N]) {
  for (const auto& entry : table) {
    if (entry.value == value) return entry.name;
  }
  throw Error("enum value " + std::to_string(static_cast<int>(value)) + " has no name");
}

// The value named `name`; anything else is a ConfigError "'x' is unknown (known: a, b)".
template <typename E, std::size_t N>
E value_of(const std::string& name, const EnumName<E> (&table)[N]) {
  for (const auto& entry : table) {
    if (name == entry.name) return entry.value;
  }
  throw ConfigError("'" + name + "' is unknown (known: " + known_names(table) + ")");
}

}  // namespace lfnet
