// Names of PISCO's TOD and pointing files (layout: include/pisco/tod_file.hpp, docs/formats.md), shared
// by the writer and the readers.
#pragma once

namespace pisco::detail::tod {

inline constexpr const char* format = "pisco-tod-1";                    // root attribute pisco_format
inline constexpr const char* pointing_names[3] = {"theta", "phi", "psi"};  // datasets of a detector group
inline constexpr const char* quat_name = "quat";  // the detector's rotation (samples, 4), with the angles
inline constexpr const char* flags_name = "flags";  // uint8 per sample, when the writer flags samples
inline constexpr const char* weights_name = "weights";  // (samples, 3), with tod_weights
inline constexpr const char* weights_meaning =
    "the detector's response to the sky's I, Q and U at the sample (its polarization angle, gain, "
    "efficiency and half-wave plate): the binned map-maker's weights, signal = weights . (I, Q, U) of a "
    "sky smooth on the beam's scale";
inline constexpr const char* flags_meaning =
    "1: the sample's disc holds an UNSEEN pixel of the sky (taken as 0; the sample is left out of the maps); 0: not";

}  // namespace pisco::detail::tod
