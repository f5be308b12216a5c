#pragma once
// Enum values and their names, both ways, from one table per enum:
//
//   constexpr EnumName<Mode> kModeNames[] = {{Mode::a, "a"}, {Mode::b, "b"}, {Mode::a, "alias"}};
//   const char* mode_name(Mode m) { return name_of(kModeNames, m); }
//   Expected<Mode> parse_mode(const std::string& s) { return parse_name(kModeNames, s, "mode"); }
//
// A value's name is its first row; later rows of the same value are aliases
// that parse too.
#include <cstddef>
#include <optional>
#include <string>
#include <string_view>

#include "veneer/util/expected.hpp"

namespace veneer {

template <class E>
struct EnumName {
  E value;
  const char* name;
};

// The name of `value`, or `otherwise` when the table has no row for it.
template <class E, std::size_t N>
constexpr const char* name_of(const EnumName<E> (&names)[N], E value, const char* otherwise = "unknown") {
  for (const auto& row : names) {
    if (row.value == value) return row.name;
  }
  return otherwise;
}

// The value named `name`, or nothing.
template <class E, std::size_t N>
constexpr std::optional<E> find_value(const EnumName<E> (&names)[N], std::string_view name) {
  for (const auto& row : names) {
    if (name == row.name) return row.value;
  }
  return std::nullopt;
}

// The value named `name`, or the error `<what> "<name>" is not one of a, b, c`
// (every name in the table, in its order; `name` cut to 32 characters).
template <class E, std::size_t N>
Expected<E> parse_name(const EnumName<E> (&names)[N], const std::string& name, const char* what) {
  if (auto value = find_value(names, name)) return *value;
  std::string known;
  for (const auto& row : names) known += (known.empty() ? "" : ", ") + std::string(row.name);
  return make_error(std::string(what) + " \"" + name.substr(0, 32) + "\" is not one of " + known);
}

}  // namespace veneer
