// The validation cases of docs/validation.md (C, D, E) that compare the engine with references no part of the
// project computes itself (HEALPix C++ harmonic smoothing, exact spectra). Used by the test suite
// (which asserts each figure) and by `pisco-vk validate` (which prints them as a table).
#pragma once

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "pisco/scan.hpp"

namespace pisco::validation {

enum class Scale {
  test,  // minutes on two CPU cores: what the test suite runs
  full,  // the paper's scale
};

struct Figure {
  std::string name;
  double value = 0;
  double bar = 0;  // pass when value <= bar
  std::string unit;
  bool pass() const { return value <= bar; }
};

struct CaseResult {
  std::string id, title;
  std::vector<Figure> figures;
  std::vector<std::string> notes;  // lines worth printing beside the figures
  double seconds = 0;
  bool pass() const;
};

// C (paper 6.1): point source at 45 deg declination, S = (1,0,0,0), (1,1,0,0), (1,0,1,0), against
// HEALPix C++ polarized Gaussian smoothing. Full scale repeats at beam resolutions 2x coarser and finer.
CaseResult point_source(Scale scale, const std::string& backend = "cpu");

// D (paper 6.2): Gaussian r = 0 CMB, pixel-centre pointing at 0, 45, 90 deg, binned maps, spectra
// against the input's and against the harmonic image of the same observation.
CaseResult ideal_cmb(Scale scale, const std::string& backend = "cpu");

// E (paper 6.3): the same with random offsets from the pixel centres (spurious BB), symmetric
// offsets (BB falls by >= 1e3), and an unpolarized sky (no T->P).
CaseResult pointing_offsets(Scale scale, const std::string& backend = "cpu");

// F (paper 7): a CLASS-like survey of constant-elevation scans with PSB pairs: matched pairs on an
// unpolarized sky (no EE, BB), pointing mismatch (delta_p = 0.42% and half of it) and beam mismatch
// (delta_b = 1.73% and half of it) leaking T into B as delta^2, and, at full scale, matched pairs on a
// polarized r = 0 sky (P -> B from uneven intra-pixel coverage). Test scale: 4 h, 4 pairs, NSIDE 64;
// full: a week, 36 pairs, NSIDE 128 (the paper's 871 million samples).
enum class Mismatch { none, pointing, beam };
// The survey's constant-elevation scans (paper 7): the CLASS site in the Atacama, elevation 45 deg,
// 720 deg azimuth sweeps at 1 deg/s around south, 20 Hz from 2019-06-01, the boresight rotated
// daily through -45 ... +45 deg; `samples` of them. `pisco-vk bench --stream` scans the same way.
CesScan class_like_scan(std::size_t samples);
struct SurveyOptions {
  int nside = 0;       // 0: the scale's
  int pairs = 0;       // 0: the scale's
  double hours = 0;    // 0: the scale's
  bool polarized = false;  // run the polarized case at test scale too
  int deconvolve_iterations = 0;  // case M: conjugate-gradient iterations (0: the case's own)
  double deconvolve_regularization = -1;  // case M: DeconvolutionOptions::regularization (< 0: the case's own)
  // Non-empty: maps, hits, spectra and beam window of every case under report_dir/F/<case>/, and
  // report_dir/F/report.md.
  std::filesystem::path report_dir;
  std::filesystem::path assets_dir;  // empty: the source tree's assets/
};
CaseResult class_survey(Scale scale, const std::string& backend = "cpu", const SurveyOptions& options = {});
// Case M: the survey's binned maps against the beam-deconvolving map-maker's, for matched, pointing-
// and beam-mismatched pairs (docs/validation.md, "M").
CaseResult deconvolved_survey(Scale scale, const std::string& backend = "simd", const SurveyOptions& options = {});

// Every case, in order, through the given backend.
std::vector<std::function<CaseResult(Scale)>> all_cases(const std::string& backend = "cpu");

}  // namespace pisco::validation
