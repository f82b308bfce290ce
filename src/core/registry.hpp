// Registries of kinds (scans/scan_kind.hpp, beams/beam_kind.hpp): lists of entries, each with its
// `kind` (an enum) and its `name` (the type a simulation file gives), found by either.
#pragma once

#include <span>
#include <string>
#include <vector>

namespace pisco::detail {

template <class Entry, class Kind>
const Entry* registered_kind(std::span<const Entry* const> all, Kind kind) {
  for (const Entry* e : all)
    if (e->kind == kind) return e;
  return nullptr;
}

template <class Entry>
const Entry* registered_name(std::span<const Entry* const> all, const std::string& name) {
  for (const Entry* e : all)
    if (name == e->name) return e;
  return nullptr;
}

template <class Entry>
std::vector<std::string> registered_names(std::span<const Entry* const> all) {
  std::vector<std::string> names;
  for (const Entry* e : all) names.emplace_back(e->name);
  return names;
}

}  // namespace pisco::detail
