// Point sources, fixed or moving, evaluated exactly per sample (docs/sources.md): the beam at the
// source's offset from each sample's line of sight, with no pixelization of the source.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

namespace pisco {

// One source's track: its direction and flux at a sequence of times. Between two times its direction
// follows the great circle between them at a constant rate and its flux is linear in time; a track of
// one point is a source fixed for all time. Times are on the TOD's own clock (seconds, as the samples'
// times given to Engine::add_sources), strictly increasing. The flux is the integral of the source's
// Stokes brightness over the sky, in the sky's units times steradians (K_CMB sr for a K_CMB sky), Q
// and U in the COSMO convention at the source's position, as a sky map's: a source of flux F in one
// pixel of area Omega is that pixel at F / Omega.
struct SourceTrack {
  std::string name;
  std::vector<double> time;
  std::vector<double> theta, phi;  // colatitude and longitude (radians) at each time
  std::vector<double> I, Q, U, V;  // flux at each time; Q, U, V may be left empty (zero)

  // A source fixed at (theta, phi) with flux (I, Q, U, V).
  static SourceTrack fixed(std::string name, double theta, double phi, double I, double Q = 0.0, double U = 0.0,
                           double V = 0.0);
  // Throws pisco::Error naming the source (`origin`: where it came from) and the first point that is
  // wrong: sizes that differ, no point, a time or flux not finite, times not strictly increasing, a
  // colatitude outside [0, pi].
  void check(const std::string& origin) const;

  // Track files (docs/formats.md, "Source tracks"): CSV with a header naming the columns time_s,
  // theta_deg, phi_deg and I (required) and Q, U, V (optional, zero when absent), one row per time;
  // blank lines and lines starting with '#' are skipped. read_csv returns the track `name`, checked;
  // a bad file is a pisco::Error naming the file, its line and the column. write_csv writes every
  // column, all digits, whole or not at all (pisco::write_file_atomically).
  static SourceTrack read_csv(const std::filesystem::path& file, std::string name);
  void write_csv(const std::filesystem::path& file) const;
};

}  // namespace pisco
