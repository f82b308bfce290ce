// Detectors and focal planes (paper section 3, eq. M_pol and copol_bolo).
#pragma once

#include <cstddef>
#include <optional>
#include <filesystem>
#include <string>
#include <vector>

#include "pisco/hwp.hpp"
#include "pisco/quaternion.hpp"

namespace pisco {

// One node of a beam that changes with time (Detector::beam_sequence): from `time` on, the beam
// `beam` (an index into the engine's beam list), linearly interpolated towards the next node's.
struct BeamNode {
  double time = 0.0;  // seconds, on the clock of the sample times given with the pointing
  std::size_t beam = 0;
};

// A beam that turns with a half-wave plate (Detector::plate_beams): the optics and the plate simulated
// together at N plate angles, each a beam with the plate in it.
struct PlateBeams {
  // The beams (indices into the engine's beam list) at plate angles gamma + k period / N, k = 0 .. N - 1.
  std::vector<std::size_t> beams;
  // radians: pi for a half-wave plate, whose turn by pi is the same plate (harmonics of 2 theta); 2 pi
  // for a plate whose turn by pi is not (a wedge, a tilt: every harmonic of theta).
  double period = 3.14159265358979323846;
  double gamma = 0.0;  // radians: the plate angle (hwp_angle, focal-plane frame) of the first beam
  // sr: the solid angle the beams' TOD is normalized by. 0: their mean Omega~, so that the plate's mean
  // transmission is calibrated away (its modulation with the angle stays); the beam's own Omega~ without
  // the plate keeps the plate's losses in the TOD, as the plate model (HalfWavePlate) does.
  double omega = 0.0;
};

struct Detector {
  std::string name;
  double zeta = 0.0;     // polarization angle from theta' towards phi', radians
  double epsilon = 0.0;  // cross-polar leakage: polarization efficiency is 1 - epsilon
  double gain = 1.0;     // responsivity s
  std::size_t beam = 0;  // index of this detector's beamsor in the engine's beam list
  // Offset from the boresight: the rotation from the boresight's antenna basis to the detector's
  // (pisco::offset_quat), identity on the boresight. Its other spelling is focal-plane coordinates
  // (xi, eta, gamma): set_offset() and offset_xi_eta_gamma() convert through quaternion.hpp. The
  // engine applies it to every pointing it is given, angles or quaternions.
  Quat offset{};
  void set_offset(double xi, double eta, double gamma) noexcept { offset = offset_quat(xi, eta, gamma); }
  void offset_xi_eta_gamma(double& xi, double& eta, double& gamma) const noexcept {
    offset_from_quat(offset, xi, eta, gamma);
  }
  bool has_offset() const noexcept { return offset.x != 0.0 || offset.y != 0.0 || offset.z != 0.0; }
  // A half-wave plate in front of the detector (hwp.hpp): its TOD is then modulated per sample by the
  // plate's angle, which the caller gives with every pointing chunk.
  std::optional<HalfWavePlate> hwp;
  // A beam that changes with time (docs/beams.md, "Beams that change with time"): at least two nodes,
  // their times strictly ascending; at a sample's time t between nodes k and k + 1 the detector's TOD is
  // (1 - w) times node k's beam's plus w times node k + 1's, w = (t - t_k) / (t_k+1 - t_k): the beams,
  // each normalized as the engine normalizes a beam, interpolated linearly. Empty (the default): the
  // fixed beam `beam`, which such a detector does not use. The engine then needs every sample's time.
  std::vector<BeamNode> beam_sequence;
  // A beam that turns with a half-wave plate (docs/changing.md, "Beams that turn with the plate"): at
  // each sample's plate angle theta (hwp_angle), the beams' trigonometric interpolant in
  // 2 pi (theta - gamma) / period through the N beams, exact for beams whose dependence on the plate
  // holds no harmonic of 2 pi theta / period above (N - 1) / 2. The plate is in the beams: such a
  // detector has no `hwp` (which would count it twice), and the engine needs hwp_angle.
  std::optional<PlateBeams> plate_beams;
};

// The gamma a detector's half-wave plate takes when its table gives none (no hwp_gamma_deg, no TOAST
// gamma column): the detector's polarization angle in the focal plane, its offset's gamma plus zeta.
// The one definition used by pisco-vk, the simulation files (simulation_config.hpp) and Python.
inline double default_hwp_gamma(const Detector& d) noexcept {
  double xi = 0, eta = 0, gamma = 0;
  d.offset_xi_eta_gamma(xi, eta, gamma);
  return gamma + d.zeta;
}

class FocalPlane {
 public:
  FocalPlane() = default;
  explicit FocalPlane(std::vector<Detector> detectors) : detectors_(std::move(detectors)) {}

  // Adds one detector; returns its index.
  std::size_t add(Detector detector);
  // Adds a PSB pair: detectors name+"a" at zeta and name+"b" at zeta - 90 deg, each with its own
  // beam. Returns the index of the first.
  std::size_t add_pair(const std::string& name, double zeta, std::size_t beam_a, std::size_t beam_b,
                       double epsilon = 0.0, double gain_a = 1.0, double gain_b = 1.0);

  const std::vector<Detector>& detectors() const noexcept { return detectors_; }
  std::size_t size() const noexcept { return detectors_.size(); }
  const Detector& operator[](std::size_t i) const { return detectors_.at(i); }

 private:
  std::vector<Detector> detectors_;
};

// The checks every engine makes of its focal plane, so that the command line, Python and C++ callers
// get the same errors: throws pisco::Error naming the detector for an empty or repeated name, a gain
// that is not positive and finite, epsilon outside [0, 1], a zeta that is not finite, an offset whose
// norm differs from 1 by more than unit_quat_tolerance, a beam index not below `beams`, or a half-wave
// plate that HalfWavePlate::check refuses (docs/physics.md, "Physical bounds on Mueller matrices").
void check_focal_plane(const FocalPlane& focal_plane, std::size_t beams);

// A TOAST 3 focal plane file, as toast.instrument.Focalplane.save_hdf5 writes it (docs/formats.md,
// "TOAST focal planes"): the compound dataset `focalplane`, one row per detector, with the units of its
// columns in `focalplane.__table_column_meta__`. Each row becomes a Detector: name; epsilon =
// pol_leakage (or (1 - eta)/(1 + eta) from pol_efficiency eta when only that column exists); gain =
// 2 / (1 + epsilon), so that the TOD is TOAST's I + (1 - epsilon)/(1 + epsilon) (Q cos 2a + U sin 2a);
// zeta = psi_pol (0 without the column); offset = quat R_z(-zeta), so that the detector's polarization
// axis (offset R_z(zeta) x^) is TOAST's quat x^; beam = `beam` for every detector. TOAST's xi, eta and
// gamma columns are another spelling of quat and are not read.
struct ToastFocalPlane {
  std::vector<Detector> detectors;  // in the table's row order
  std::vector<double> fwhm;         // per detector, radians (column fwhm); empty without the column
  // Per detector, radians (column gamma): the polarization angle in the focal-plane frame, the
  // HalfWavePlate::gamma of TOAST's plate model; empty without the column.
  std::vector<double> gamma;
  double sample_rate = 0.0;         // Hz, the table's meta sample_rate; 0 when absent
};
// Throws pisco::Error naming the file, the row (from 0) and detector, and the column: for a file that
// is not HDF5, a missing `focalplane` dataset or `name` / `quat` column, an empty table, a quaternion
// that is not finite or not unit to within 1e-6, duplicate names, or an angle column in a unit other
// than rad, deg, arcmin or arcsec.
ToastFocalPlane read_toast_focal_plane(const std::filesystem::path& file, std::size_t beam = 0);

}  // namespace pisco
