// Point sources evaluated per sample (pisco/sources.hpp; docs/sources.md): the host's float64
// arithmetic of the reference backend (src/kernel/pixel.glsl through kernel/contribution.hpp) at the source's
// direction instead of a pixel centre, so that a source at a pixel's centre with flux F reads exactly
// as that pixel at F / Omega_pix does in a plain pixel sum.
#pragma once

#include <span>
#include <vector>

#include "core/backend.hpp"
#include "pisco/sources.hpp"

namespace pisco::detail {

// One part of a detector's beam as the backends hold it: its prepared detector, the row detectors of
// a plate before the detector, and the pixel area its weights carry.
struct SourcePart {
  const PreparedDetector* detector = nullptr;
  std::array<const PreparedDetector*, 4> rows{};
  double pixel_area = 0.0;
};

// Adds to tod[i] every source's response at sample i (time[i]) through each part; plate_angle is the
// plate's angle from the detector's axis per sample (empty without a plate). Throws pisco::Error
// naming the source and the sample when a sample's time lies outside a source's track, before
// anything is added.
void add_source_tod(const PointingInput& in, std::span<const double> plate_angle, std::span<const double> time,
                    const std::vector<SourceTrack>& sources, const std::vector<SourcePart>& parts,
                    std::span<double> tod);

}  // namespace pisco::detail
