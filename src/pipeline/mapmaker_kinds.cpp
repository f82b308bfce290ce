// The registry of map-maker kinds (mapmaker_kind.hpp; docs/library.md, "How to add a map-maker"): a new
// kind is a file in mapmakers/ and one line here.
#include "pipeline/mapmaker_kind.hpp"

#include "core/registry.hpp"

namespace pisco::detail {
namespace {

const MapmakerKindEntry* const kinds[] = {
    &binned_mapmaker_kind,
    &deconvolve_mapmaker_kind,
};

}  // namespace

std::span<const MapmakerKindEntry* const> mapmaker_kinds() { return kinds; }

const MapmakerKindEntry& mapmaker_kind(MapmakerKind kind) {
  if (const MapmakerKindEntry* k = registered_kind(mapmaker_kinds(), kind)) return *k;
  throw Error("map-maker kind " + std::to_string(static_cast<int>(kind)) + " is not registered", ErrorKind::internal);
}

const MapmakerKindEntry* mapmaker_kind_named(const std::string& name) { return registered_name(mapmaker_kinds(), name); }

}  // namespace pisco::detail
