// The names of a setting's values, both ways (the engine's enums, the vulkan backend's arithmetic):
// one table a setting, read by name with an error that lists them.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "core/text.hpp"
#include "pisco/error.hpp"

namespace pisco::detail {

template <class E>
struct Named {
  const char* name;
  E value;
};

// "a", "b" or "c", quoted.
template <class E, std::size_t N>
std::string listed(const Named<E> (&names)[N]) {
  std::vector<std::string> quoted;
  for (const Named<E>& n : names) quoted.push_back(std::string("\"") + n.name + "\"");
  return series_text(quoted, "or");
}

// The value named `name`; throws pisco::Error (input, keyed `key`) listing the names for any other.
template <class E, std::size_t N>
E from_name(const Named<E> (&names)[N], const std::string& name, const char* key) {
  for (const Named<E>& n : names)
    if (name == n.name) return n.value;
  throw Error("expected " + listed(names) + ", got \"" + name + "\"", ErrorKind::input, key);
}

template <class E, std::size_t N>
std::string name_of(const Named<E> (&names)[N], E value) {
  for (const Named<E>& n : names)
    if (n.value == value) return n.name;
  return names[0].name;
}

}  // namespace pisco::detail
