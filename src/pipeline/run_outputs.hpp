// What a run writes beside its TOD (pisco::Simulation, simulation.cpp): the TOD file opened with its
// attributes, the maps of either map-maker with their spectra, and the lines of the run's account
// about them. Internal.
#pragma once

#include <cstddef>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "pisco/deconvolution.hpp"
#include "pisco/mapmaker.hpp"
#include "pisco/simulation.hpp"
#include "pisco/tod_file.hpp"

namespace pisco::detail {

namespace fs = std::filesystem;

// The spectra files of maps I, Q, U: `note` says what the maps are, `fw` the Gaussian beam window
// [output] deconvolve_beam divides out (none: nullopt).
std::vector<fs::path> spectra_files(const SimulationConfig& c, const Sky& sky, const std::vector<double>& I,
                                    const std::vector<double>& Q, const std::vector<double>& U, int maps_nside,
                                    std::string note, std::optional<double> fw);

// The half-wave plate's figure of a run's binned maps: their polarization against their temperature
// (on an unpolarized sky, the plate's leakage of temperature into polarization as the map-maker's
// model leaves it), as a line of the run's account.
std::string hwp_figure(const BinnedMaps& maps, std::size_t solved, const std::string& units, bool ideal_mapmaker);

// Why binned maps that solve no pixel solve none: no sample reached them, or too few angles.
std::string unsolved_reason(const BinnedMaps& maps, int maps_nside, bool flagging, double rcond_min);

// The TOD file (tod.h5) of a run: its attributes (units, NSIDE, beams, backend, device, version, time
// and the simulation file's text) and, under MPI, one file for all ranks.
std::optional<pisco::TodWriter> open_tod_file(const SimulationConfig& c, const fs::path& tod_path, const Sky& sky,
                                              const SimulationBeams& made, const Engine& engine, const FocalPlane& fp,
                                              std::size_t samples_per_detector, bool flagging, RunContext& cl);

// The maps of a run as written: the files, the pixels solved, and why none was ("" when some were).
struct MapOutputs {
  std::vector<fs::path> written;
  std::size_t solved = 0;
  std::string nothing_solved;
};

// The deconvolving map-maker's maps: maps.fits holds the solution, reconvolved with the target beam
// when one is given (then the solution itself in deconvolved.fits); binned_maps.fits and hits.fits
// from the binned map-maker beside it; the spectra of maps.fits.
MapOutputs write_deconvolved_maps(const SimulationConfig& c, const Sky& sky, int maps_nside, const pisco::DeconvolvedMaps& d,
                                  pisco::BinnedMapmaker& binned_mapmaker,
                                  const std::function<void(const std::string&)>& log);

// The binned map-maker's maps (maps.fits, hits.fits), the plate's figure and the spectra.
MapOutputs write_binned_maps(const SimulationConfig& c, const Sky& sky, int maps_nside, pisco::BinnedMapmaker& mapmaker,
                             bool flagging, const std::function<void(const std::string&)>& log);

// [ground]: the ground's TOD alone, binned as the maps are (ground_maps.fits, I Q U) and its spectra
// (ground_spectra.txt, the same windows divided out as spectra.txt's), and a line of the run's
// account with their RMS beside the maps' own: what the ground leaves in the maps.
std::vector<fs::path> write_ground_maps(const SimulationConfig& c, const Sky& sky, int maps_nside,
                                        pisco::BinnedMapmaker& ground, const std::function<void(const std::string&)>& log);

}  // namespace pisco::detail
