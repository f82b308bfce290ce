// The focal-plane readers behind pisco::read_focal_plane_file (pisco/focal_plane_file.hpp), and the parts of
// them the simulation-file reader shares for [focal_plane] (src/pipeline/simulation_config.cpp).
// Internal.
#pragma once

#include <cstddef>
#include <filesystem>
#include <string>
#include <vector>

#include "io/toml_table.hpp"
#include "pisco/focal_plane.hpp"
#include "pisco/focal_plane_file.hpp"

namespace pisco::detail {

// The index in `beams` (the [beams] tables' names) of the beam named by key `key` of t; absent, 0 when
// there is one beam (an error when `required` and there are several).
std::size_t beam_index(Table& t, const std::string& key, const std::vector<std::string>& beams, bool required);

// [[detectors]] and [[pairs]] of the table `root` (`where` names it in errors), appended to `out`,
// their plate keys to `hwp` when given.
void read_detectors(const toml::table& root, const std::string& where, const fs::path& file,
                    const std::vector<std::string>& beams, std::vector<Detector>& out,
                    std::vector<DetectorHwp>* hwp = nullptr);

// Whether a focal plane file is a TOAST table (HDF5): by its extension, else by the HDF5 signature.
bool is_hdf5_focal_plane(const fs::path& file);

}  // namespace pisco::detail
