// TOAST 3 focal plane files (pisco::read_toast_focal_plane, docs/formats.md "TOAST focal planes"):
// the bundled table written by TOAST itself (assets/focalplanes/toast_hex7.h5), its mapping onto
// pisco::Detector, the units of its columns, and the errors for bad files.
#include <gtest/gtest.h>
#include <hdf5.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "pisco/error.hpp"
#include "pisco/focal_plane.hpp"
#include "pisco/pointing.hpp"
#include "pisco/quaternion.hpp"
#include "support.hpp"

namespace {

namespace fs = std::filesystem;
using pisco::Quat;
using pisco_test::expect_error;
using Vec = std::array<double, 3>;
constexpr double pi = std::numbers::pi;

const fs::path asset = fs::path(PISCO_TEST_ASSETS_DIR) / "focalplanes" / "toast_hex7.h5";

// Reference values of the asset, as TOAST 3.0.6 reads them back (Focalplane.load_hdf5): the quat
// column (x, y, z, w), psi_pol (rad), gamma (deg, not read by PISCO-VK: only a cross-check of what
// quat holds), and qarray.rotate(quat, x^) and qarray.rotate(quat, z^).
struct Reference {
  const char* name;
  Quat quat;
  double psi_pol;
  double gamma_deg;
  Vec pol;  // the polarization-sensitive direction in the focal-plane frame
  Vec los;  // the line of sight in the focal-plane frame
};
const Reference reference[] = {
    {"D0A-150", {0.0, 0.0, 0.3826834323650898, 0.9238795325112867}, 0.0, 45.0, {0.7071067811865475, 0.7071067811865476, 0.0}, {0.0, 0.0, 1.0}},
    {"D0B-150", {0.0, 0.0, 0.9238795325112867, 0.38268343236508984}, 1.5707963267948966, 135.0, {-0.7071067811865475, 0.7071067811865477, 0.0}, {0.0, 0.0, 1.0}},
    {"D1A-150", {0.021814885034561124, 3.469446951953615e-18, 0.0, 0.9997620270799092}, 0.0, 0.0, {1.0, 1.5137117278075323e-19, -6.937242635062717e-18}, {6.937242635062717e-18, -0.043619387365336014, 0.9990482215818578}},
    {"D1B-150", {0.015425453138743103, -0.015425453138743097, 0.7069385089210125, 0.7069385089210124}, 1.5707963267948966, 90.0, {0.0, 0.9990482215818577, 0.04361938736533599}, {1.0408340855860843e-17, -0.04361938736533599, 0.9990482215818578}},
    {"D2A-150", {0.0028474138772794618, -0.02162825566897606, 0.38259236407121944, 0.9236596742011229}, 0.0, 45.0, {0.7063106030222257, 0.7066471075090536, 0.042133092783085135}, {-0.037775497555894946, -0.021809693682668017, 0.9990482215818578}},
    {"D2B-150", {-0.013280060587300377, -0.01730691191023835, 0.9236596742011228, 0.38259236407121944}, 1.5707963267948966, 135.0, {-0.7068934458903862, 0.7072299503772139, -0.011289528185853203}, {-0.037775497555894946, -0.021809693682668017, 0.9990482215818578}},
    {"D3A-150", {-0.01090744251728055, -0.018892244620566906, 2.775557561562892e-17, 0.9997620270799091}, 0.0, 0.0, {0.9992861661863933, 0.00041213214444252793, 0.03777549755589496}, {-0.03777549755589496, 0.02180969368266798, 0.9990482215818578}},
    {"D3B-150", {-0.021071560852409476, -0.00564610771366639, 0.7069385089210124, 0.7069385089210126}, 1.5707963267948966, 90.0, {0.00041213214444268953, 0.9997620553954645, -0.021809693682667976}, {-0.03777549755589495, 0.021809693682667986, 0.9990482215818578}},
    {"D4A-150", {-0.021814885034561124, -3.469446951953615e-18, 0.0, 0.9997620270799092}, 0.0, 0.0, {1.0, 1.5137117278075323e-19, 6.937242635062717e-18}, {-6.937242635062717e-18, 0.043619387365336014, 0.9990482215818578}},
    {"D4B-150", {-0.015425453138743106, 0.0154254531387431, 0.7069385089210125, 0.7069385089210126}, 1.5707963267948966, 90.0, {0.0, 0.999048221581858, -0.04361938736533601}, {-3.469446951953614e-18, 0.04361938736533601, 0.9990482215818578}},
    {"D5A-150", {-0.01090744251728057, 0.018892244620566895, 0.0, 0.9997620270799091}, 0.0, 0.0, {0.9992861661863933, -0.000412132144442473, -0.03777549755589494}, {0.03777549755589494, 0.02180969368266802, 0.9990482215818578}},
    {"D5B-150", {0.005646107713666368, 0.021071560852409483, 0.7069385089210125, 0.7069385089210124}, 1.5707963267948966, 90.0, {-0.0004121321444425785, 0.9997620553954644, -0.021809693682668017}, {0.03777549755589493, 0.02180969368266802, 0.9990482215818578}},
    {"D6A-150", {0.017306911910238334, 0.013280060587300397, 0.38259236407121955, 0.9236596742011228}, 0.0, 45.0, {0.706893445890386, 0.7072299503772141, -0.011289528185853255}, {0.037775497555894974, -0.02180969368266797, 0.9990482215818578}},
    {"D6B-150", {0.021628255668976068, -0.002847413877279436, 0.9236596742011229, 0.38259236407121944}, 1.5707963267948966, 135.0, {-0.7063106030222261, 0.7066471075090536, 0.04213309278308512}, {0.037775497555894974, -0.021809693682667976, 0.9990482215818578}},
};
constexpr std::size_t n_reference = sizeof reference / sizeof reference[0];

Quat rz(double angle) { return {0.0, 0.0, std::sin(angle / 2), std::cos(angle / 2)}; }

double distance(const Vec& a, const Vec& b) {
  return std::sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) + (a[2] - b[2]) * (a[2] - b[2]));
}

// q and -q are the same rotation.
double quat_distance(const Quat& a, const Quat& b) {
  const double plus = std::abs(a.x - b.x) + std::abs(a.y - b.y) + std::abs(a.z - b.z) + std::abs(a.w - b.w);
  const double minus = std::abs(a.x + b.x) + std::abs(a.y + b.y) + std::abs(a.z + b.z) + std::abs(a.w + b.w);
  return std::min(plus, minus);
}

// An angle folded into (-pi/2, pi/2]: polarization orientations are defined modulo pi.
double mod_pi(double a) {
  a = std::remainder(a, pi);
  return a <= -pi / 2 ? a + pi : a;
}

// ---------------------------------------------------------------- writing test files

struct Row {
  std::string name;
  std::array<double, 4> quat{0, 0, 0, 1};
  double psi_pol = 0.0, pol_leakage = 0.0, pol_efficiency = 1.0, fwhm = 30.0;
};

struct Spec {
  bool quat = true;
  hsize_t quat_length = 4;
  bool pol_leakage = true;
  bool pol_efficiency = false;
  bool psi_pol = true;
  bool fwhm = true;
  bool variable_names = false;
  bool meta = true;
  std::string psi_pol_unit = "rad";
  std::string fwhm_unit = "arcmin";
};

// Writes a table laid out as astropy writes TOAST's: compound `focalplane`, plus the YAML header in
// `focalplane.__table_column_meta__` (fixed-length strings).
void write_table(const fs::path& file, const std::vector<Row>& rows, const Spec& spec) {
  const std::size_t name_size = spec.variable_names ? sizeof(char*) : 16;
  std::size_t size = 0;
  const std::size_t name_at = size;
  size += name_size;
  const std::size_t quat_at = size;
  if (spec.quat) size += spec.quat_length * sizeof(double);
  const std::size_t leakage_at = size;
  if (spec.pol_leakage) size += sizeof(double);
  const std::size_t efficiency_at = size;
  if (spec.pol_efficiency) size += sizeof(double);
  const std::size_t psi_at = size;
  if (spec.psi_pol) size += sizeof(double);
  const std::size_t fwhm_at = size;
  if (spec.fwhm) size += sizeof(double);

  const hid_t string_type = H5Tcopy(H5T_C_S1);
  H5Tset_size(string_type, spec.variable_names ? H5T_VARIABLE : name_size);
  const hid_t quat_type = H5Tarray_create2(H5T_NATIVE_DOUBLE, 1, &spec.quat_length);
  const hid_t type = H5Tcreate(H5T_COMPOUND, size);
  H5Tinsert(type, "name", name_at, string_type);
  if (spec.quat) H5Tinsert(type, "quat", quat_at, quat_type);
  if (spec.pol_leakage) H5Tinsert(type, "pol_leakage", leakage_at, H5T_NATIVE_DOUBLE);
  if (spec.pol_efficiency) H5Tinsert(type, "pol_efficiency", efficiency_at, H5T_NATIVE_DOUBLE);
  if (spec.psi_pol) H5Tinsert(type, "psi_pol", psi_at, H5T_NATIVE_DOUBLE);
  if (spec.fwhm) H5Tinsert(type, "fwhm", fwhm_at, H5T_NATIVE_DOUBLE);

  std::vector<char> buffer(rows.size() * size, 0);
  for (std::size_t i = 0; i < rows.size(); ++i) {
    char* row = buffer.data() + i * size;
    if (spec.variable_names) {
      const char* p = rows[i].name.c_str();
      std::memcpy(row + name_at, &p, sizeof p);
    } else {
      std::memcpy(row + name_at, rows[i].name.data(), std::min(rows[i].name.size(), name_size));
    }
    for (hsize_t k = 0; spec.quat && k < spec.quat_length; ++k)
      std::memcpy(row + quat_at + k * sizeof(double), &rows[i].quat[k % 4], sizeof(double));
    if (spec.pol_leakage) std::memcpy(row + leakage_at, &rows[i].pol_leakage, sizeof(double));
    if (spec.pol_efficiency) std::memcpy(row + efficiency_at, &rows[i].pol_efficiency, sizeof(double));
    if (spec.psi_pol) std::memcpy(row + psi_at, &rows[i].psi_pol, sizeof(double));
    if (spec.fwhm) std::memcpy(row + fwhm_at, &rows[i].fwhm, sizeof(double));
  }

  const hid_t f = H5Fcreate(file.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
  const hsize_t n = rows.size();
  const hid_t space = H5Screate_simple(1, &n, nullptr);
  const hid_t ds = H5Dcreate2(f, "focalplane", type, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  if (n > 0) H5Dwrite(ds, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, buffer.data());
  H5Dclose(ds);
  H5Sclose(space);
  if (spec.meta) {
    std::vector<std::string> lines = {
        "datatype:",
        "- {name: name, datatype: string}",
        "- {name: quat, datatype: string, subtype: 'float64[4]'}",
        "- {name: pol_leakage, datatype: float64}",
        "- {name: psi_pol, unit: " + spec.psi_pol_unit + ", datatype: float64}",
        "- {name: fwhm, unit: " + spec.fwhm_unit + ", datatype: float64}",
        "meta: !!omap",
        "- sample_rate: !astropy.units.Quantity",
        "    unit: &id003 !astropy.units.Unit {unit: Hz}",
        "    value: 37.5",
    };
    std::size_t width = 0;
    for (const auto& l : lines) width = std::max(width, l.size());
    std::vector<char> text(lines.size() * width, 0);
    for (std::size_t i = 0; i < lines.size(); ++i) std::memcpy(text.data() + i * width, lines[i].data(), lines[i].size());
    const hid_t st = H5Tcopy(H5T_C_S1);
    H5Tset_size(st, width);
    const hsize_t m = lines.size();
    const hid_t ms = H5Screate_simple(1, &m, nullptr);
    const hid_t md = H5Dcreate2(f, "focalplane.__table_column_meta__", st, ms, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    H5Dwrite(md, st, H5S_ALL, H5S_ALL, H5P_DEFAULT, text.data());
    H5Dclose(md);
    H5Sclose(ms);
    H5Tclose(st);
  }
  H5Fclose(f);
  H5Tclose(type);
  H5Tclose(quat_type);
  H5Tclose(string_type);
}

std::vector<Row> two_rows() {
  Row a{"det-a", {0, 0, std::sin(pi / 8), std::cos(pi / 8)}, 0.0, 0.1, 0.0, 30.0};
  Row b{"det-b", {0.01, 0, std::sin(3 * pi / 8), std::cos(3 * pi / 8)}, pi / 2, 0.1, 0.0, 30.0};
  const double nb = std::sqrt(0.01 * 0.01 + 1.0);
  for (double& v : b.quat) v /= nb;
  return {a, b};
}

class ToastFocalPlane : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = pisco_test::fresh_test_dir("toastfp");
  }
  void TearDown() override {
    EXPECT_EQ(H5Fget_obj_count(H5F_OBJ_ALL, H5F_OBJ_ALL), 0) << "HDF5 objects left open";
    fs::remove_all(dir_);
  }
  // A copy of the asset whose quat column is changed by `edit` (the file's own layout otherwise).
  fs::path corrupt_quat(const std::function<void(std::vector<std::array<double, 4>>&)>& edit) {
    const fs::path copy = dir_ / "corrupt.h5";
    fs::copy_file(asset, copy, fs::copy_options::overwrite_existing);
    const hid_t f = H5Fopen(copy.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
    const hid_t ds = H5Dopen2(f, "focalplane", H5P_DEFAULT);
    const hsize_t four = 4;
    const hid_t arr = H5Tarray_create2(H5T_NATIVE_DOUBLE, 1, &four);
    const hid_t mem = H5Tcreate(H5T_COMPOUND, 4 * sizeof(double));
    H5Tinsert(mem, "quat", 0, arr);
    std::vector<std::array<double, 4>> q(n_reference);
    H5Dread(ds, mem, H5S_ALL, H5S_ALL, H5P_DEFAULT, q.data());
    edit(q);
    H5Dwrite(ds, mem, H5S_ALL, H5S_ALL, H5P_DEFAULT, q.data());
    H5Tclose(mem);
    H5Tclose(arr);
    H5Dclose(ds);
    H5Fclose(f);
    return copy;
  }
  fs::path dir_;
};

// ---------------------------------------------------------------- the asset

TEST_F(ToastFocalPlane, ReadsEveryRowOfTheToastAsset) {
  const pisco::ToastFocalPlane fp = pisco::read_toast_focal_plane(asset, 3);
  ASSERT_EQ(fp.detectors.size(), n_reference);
  EXPECT_DOUBLE_EQ(fp.sample_rate, 10.0);  // table meta: 10 Hz
  ASSERT_EQ(fp.fwhm.size(), n_reference);
  for (std::size_t i = 0; i < n_reference; ++i) {
    const pisco::Detector& d = fp.detectors[i];
    const Reference& r = reference[i];
    SCOPED_TRACE(r.name);
    EXPECT_EQ(d.name, r.name);
    EXPECT_EQ(d.beam, 3u);
    EXPECT_EQ(d.epsilon, 0.0);           // pol_leakage
    EXPECT_EQ(d.gain, 2.0);              // 2 / (1 + epsilon): TOAST's weight 1 on I
    EXPECT_EQ(d.zeta, r.psi_pol);        // psi_pol, in rad
    EXPECT_NEAR(fp.fwhm[i], 10.0 * pi / (180 * 60), 1e-18);  // 10 arcmin
    // offset R_z(zeta) is the quat column.
    EXPECT_LT(quat_distance(d.offset * rz(d.zeta), r.quat), 1e-15);
    // TOAST's gamma is the orientation quat holds: for these detectors on the x-y plane of the
    // focal plane's frame, quat is R(n, r) R_z(gamma) (pisco::offset_quat's form).
    double xi = 0, eta = 0, gamma = 0;
    pisco::offset_from_quat(r.quat, xi, eta, gamma);
    EXPECT_NEAR(std::remainder(gamma - r.gamma_deg * pi / 180, 2 * pi), 0.0, 1e-14);
  }
  // D0A: on the boresight, gamma 45 deg, quat (0, 0, sin 22.5 deg, cos 22.5 deg).
  EXPECT_NEAR(fp.detectors[0].offset.z, 0.382683, 1e-6);
  EXPECT_NEAR(fp.detectors[0].offset.w, 0.92388, 1e-5);
}

TEST_F(ToastFocalPlane, PolarizationAxisIsToastsRotatedXAxis) {
  const pisco::ToastFocalPlane fp = pisco::read_toast_focal_plane(asset);
  ASSERT_EQ(fp.detectors.size(), n_reference);
  for (std::size_t i = 0; i < n_reference; ++i) {
    const pisco::Detector& d = fp.detectors[i];
    SCOPED_TRACE(d.name);
    // In the focal-plane frame: the polarization axis, at zeta from the antenna basis' theta', and the
    // line of sight, against TOAST's qarray.rotate.
    EXPECT_LT(distance(pisco::rotate(d.offset * rz(d.zeta), {1, 0, 0}), reference[i].pol), 1e-15);
    EXPECT_LT(distance(pisco::rotate(d.offset, {0, 0, 1}), reference[i].los), 1e-15);
  }
  // The A and B detectors of a pixel share one beam frame (the antenna basis): B's quat carries
  // gamma + 90 deg and its psi_pol is 90 deg.
  for (std::size_t i = 0; i + 1 < n_reference; i += 2)
    EXPECT_LT(quat_distance(fp.detectors[i].offset, fp.detectors[i + 1].offset), 1e-15) << fp.detectors[i].name;
}

// On the sky: PISCO-VK's pointing of each detector (boresight composed with its offset, as the engine
// and the TOD files give it) has psi + zeta = TOAST's polarization angle alpha, the angle of
// (q_boresight quat) x^ from theta^ towards phi^, and the same line of sight.
TEST_F(ToastFocalPlane, PointingOnTheSkyMatchesToastsConvention) {
  const pisco::ToastFocalPlane fp = pisco::read_toast_focal_plane(asset);
  std::mt19937_64 rng(7);
  std::normal_distribution<double> g;
  std::vector<Quat> bore(200);
  for (Quat& q : bore) q = pisco::normalized({g(rng), g(rng), g(rng), g(rng)});
  double worst_los = 0, worst_angle = 0;
  for (std::size_t i = 0; i < n_reference; ++i) {
    const pisco::Detector& d = fp.detectors[i];
    pisco::Pointing out;
    pisco::detector_pointing(pisco::QuatPointingView{bore}, d.offset, out);
    ASSERT_EQ(out.size(), bore.size());
    for (std::size_t s = 0; s < bore.size(); ++s) {
      const Quat q = bore[s] * reference[i].quat;  // TOAST: qa.mult(boresight, fp_quat)
      const Vec dir = pisco::rotate(q, {0, 0, 1}), pol = pisco::rotate(q, {1, 0, 0});
      const double theta = std::acos(std::clamp(dir[2], -1.0, 1.0)), phi = std::atan2(dir[1], dir[0]);
      const Vec th{std::cos(theta) * std::cos(phi), std::cos(theta) * std::sin(phi), -std::sin(theta)};
      const Vec ph{-std::sin(phi), std::cos(phi), 0.0};
      const double alpha = std::atan2(pol[0] * ph[0] + pol[1] * ph[1] + pol[2] * ph[2],
                                      pol[0] * th[0] + pol[1] * th[1] + pol[2] * th[2]);
      const Vec mine{std::sin(out.theta[s]) * std::cos(out.phi[s]), std::sin(out.theta[s]) * std::sin(out.phi[s]),
                     std::cos(out.theta[s])};
      worst_los = std::max(worst_los, distance(mine, dir));
      worst_angle = std::max(worst_angle, std::abs(mod_pi(out.psi[s] + d.zeta - alpha)));
    }
  }
  EXPECT_LT(worst_los, 1e-14);
  EXPECT_LT(worst_angle, 1e-12);
}

// ---------------------------------------------------------------- columns and units

TEST_F(ToastFocalPlane, LeakageGivesEpsilonAndGain) {
  std::vector<Row> rows = two_rows();
  const fs::path file = dir_ / "leak.h5";
  write_table(file, rows, {});
  const auto fp = pisco::read_toast_focal_plane(file);
  ASSERT_EQ(fp.detectors.size(), 2u);
  for (const auto& d : fp.detectors) {
    EXPECT_DOUBLE_EQ(d.epsilon, 0.1);
    EXPECT_DOUBLE_EQ(d.gain, 2.0 / 1.1);
    // The measurement's weights: gain/2 (1 + eps) = 1 on I, gain/2 (1 - eps) = TOAST's eta on Q, U.
    EXPECT_DOUBLE_EQ(d.gain / 2 * (1 + d.epsilon), 1.0);
    EXPECT_DOUBLE_EQ(d.gain / 2 * (1 - d.epsilon), 0.9 / 1.1);
  }
  EXPECT_DOUBLE_EQ(fp.sample_rate, 37.5);
  EXPECT_NEAR(fp.fwhm[0], 30.0 * pi / (180 * 60), 1e-18);
}

TEST_F(ToastFocalPlane, EfficiencyAloneGivesEpsilon) {
  std::vector<Row> rows = two_rows();
  for (Row& r : rows) r.pol_efficiency = 0.8;
  Spec spec;
  spec.pol_leakage = false;
  spec.pol_efficiency = true;
  const fs::path file = dir_ / "eff.h5";
  write_table(file, rows, spec);
  const auto fp = pisco::read_toast_focal_plane(file);
  for (const auto& d : fp.detectors) {
    EXPECT_NEAR(d.epsilon, 0.2 / 1.8, 1e-16);
    EXPECT_NEAR(d.gain / 2 * (1 - d.epsilon), 0.8, 1e-15);  // TOAST's eta on Q, U
    EXPECT_NEAR(d.gain / 2 * (1 + d.epsilon), 1.0, 1e-15);
  }
}

TEST_F(ToastFocalPlane, AngleUnitsComeFromTheHeader) {
  std::vector<Row> rows = two_rows();
  rows[1].psi_pol = 90.0;  // in degrees
  rows[0].fwhm = rows[1].fwhm = 0.5;
  Spec spec;
  spec.psi_pol_unit = "deg";
  spec.fwhm_unit = "deg";
  const fs::path file = dir_ / "deg.h5";
  write_table(file, rows, spec);
  const auto fp = pisco::read_toast_focal_plane(file);
  EXPECT_NEAR(fp.detectors[1].zeta, pi / 2, 1e-15);
  EXPECT_NEAR(fp.fwhm[1], 0.5 * pi / 180, 1e-18);
  // Variable-length names, no psi_pol (zeta 0), no fwhm, no header.
  spec = Spec{};
  spec.variable_names = true;
  spec.psi_pol = false;
  spec.fwhm = false;
  spec.meta = false;
  write_table(file, rows, spec);
  const auto plain = pisco::read_toast_focal_plane(file);
  ASSERT_EQ(plain.detectors.size(), 2u);
  EXPECT_EQ(plain.detectors[1].name, "det-b");
  EXPECT_EQ(plain.detectors[1].zeta, 0.0);
  EXPECT_LT(quat_distance(plain.detectors[1].offset, Quat{rows[1].quat[0], rows[1].quat[1], rows[1].quat[2], rows[1].quat[3]}), 1e-16);
  EXPECT_TRUE(plain.fwhm.empty());
  EXPECT_EQ(plain.sample_rate, 0.0);
}

// ---------------------------------------------------------------- errors

TEST_F(ToastFocalPlane, MissingFileAndNotHdf5) {
  expect_error([&] { pisco::read_toast_focal_plane(dir_ / "absent.h5"); }, "absent.h5: no such file");
  const fs::path text = dir_ / "fp.h5";
  std::ofstream(text) << "name,zeta_deg\nq1a,0\n";
  expect_error([&] { pisco::read_toast_focal_plane(text); }, "fp.h5: not an HDF5 file");
}

TEST_F(ToastFocalPlane, NoTable) {
  const fs::path file = dir_ / "empty.h5";
  H5Fclose(H5Fcreate(file.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT));
  expect_error([&] { pisco::read_toast_focal_plane(file); }, "empty.h5: no dataset '/focalplane' (expected a TOAST focal plane");
  // A plain float dataset is not a table.
  const hid_t f = H5Fcreate(file.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
  const hsize_t dims[2] = {2, 4};
  const hid_t space = H5Screate_simple(2, dims, nullptr);
  H5Dclose(H5Dcreate2(f, "focalplane", H5T_IEEE_F64LE, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT));
  H5Sclose(space);
  H5Fclose(f);
  expect_error([&] { pisco::read_toast_focal_plane(file); }, "dataset '/focalplane' is not a table of named columns");
}

TEST_F(ToastFocalPlane, MissingColumnsAndEmptyTable) {
  const fs::path file = dir_ / "cols.h5";
  Spec spec;
  spec.quat = false;
  write_table(file, two_rows(), spec);
  expect_error([&] { pisco::read_toast_focal_plane(file); }, "cols.h5: dataset '/focalplane' has no column 'quat'");
  write_table(file, {}, {});
  expect_error([&] { pisco::read_toast_focal_plane(file); }, "cols.h5: dataset '/focalplane' has no rows");
  spec = Spec{};
  spec.quat_length = 3;
  write_table(file, two_rows(), spec);
  expect_error([&] { pisco::read_toast_focal_plane(file); }, "column 'quat' of '/focalplane' has shape (3) per row");
}

TEST_F(ToastFocalPlane, BadQuaternionsNameTheRowDetectorAndColumn) {
  const fs::path scaled = corrupt_quat([](auto& q) {
    for (double& v : q[3]) v *= 1.001;
  });
  expect_error([&] { pisco::read_toast_focal_plane(scaled); },
               "corrupt.h5: dataset '/focalplane' row 3 (detector 'D1B-150'), column 'quat' has norm 1.00");
  const fs::path nan = corrupt_quat([](auto& q) { q[5][2] = std::nan(""); });
  expect_error([&] { pisco::read_toast_focal_plane(nan); },
               "row 5 (detector 'D2B-150'), column 'quat' has a non-finite component");
  // Within 1e-6 of unit: accepted.
  const fs::path close = corrupt_quat([](auto& q) {
    for (double& v : q[3]) v *= 1 + 4e-7;
  });
  EXPECT_EQ(pisco::read_toast_focal_plane(close).detectors.size(), n_reference);
}

TEST_F(ToastFocalPlane, DuplicateNamesAndUnknownUnits) {
  const fs::path file = dir_ / "dup.h5";
  std::vector<Row> rows = two_rows();
  rows.push_back(rows[0]);
  write_table(file, rows, {});
  expect_error([&] { pisco::read_toast_focal_plane(file); },
               "dup.h5: dataset '/focalplane' rows 0 and 2, column 'name': both are detector 'det-a'");
  Spec spec;
  spec.psi_pol_unit = "furlong";
  write_table(file, two_rows(), spec);
  expect_error([&] { pisco::read_toast_focal_plane(file); },
               "dup.h5: column 'psi_pol' of dataset '/focalplane' has unit 'furlong' (expected an angle");
  rows = two_rows();
  rows[1].pol_leakage = -0.5;
  write_table(file, rows, {});
  expect_error([&] { pisco::read_toast_focal_plane(file); },
               "row 1 (detector 'det-b'), column 'pol_leakage': -0.5");
}

}  // namespace
