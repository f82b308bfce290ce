// The registry of beam kinds (beam_kind.hpp; docs/library.md, "How to add a beam format"): a new kind
// is a file in kinds/ and one line here.
#include <string>

#include "beams/beam_kind.hpp"
#include "core/registry.hpp"

namespace pisco::detail {
namespace {

const BeamKindEntry* const kinds[] = {
    &gaussian_beam_kind,
    &elliptical_beam_kind,
    &beamsor_file_beam_kind,
    &grasp_beam_kind,
    &blm_beam_kind,
    &sequence_beam_kind,
    &plate_beam_kind,
};

}  // namespace

std::span<const BeamKindEntry* const> beam_kinds() { return kinds; }

const BeamKindEntry& beam_kind(BeamKind kind) {
  if (const BeamKindEntry* k = registered_kind(beam_kinds(), kind)) return *k;
  throw Error("beam kind " + std::to_string(static_cast<int>(kind)) + " is not registered", ErrorKind::internal);
}

const BeamKindEntry* beam_kind_named(const std::string& name) { return registered_name(beam_kinds(), name); }

}  // namespace pisco::detail
