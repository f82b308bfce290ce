// Writes the generated seeds of the fuzz corpora (tests/fuzz/corpus/<target>/): FITS sky maps, beamsor
// and b_lm files, HDF5 pointing files and TOAST focal planes, GRASP grids and cuts, each small (NSIDE 1 to
// 4, a few detectors and samples, 7 x 7 grids), valid ones and a few broken on purpose. The library's own
// writers make what they can (Sky::write_fits, Beamsor::write_healpix_fits, BoresightFile::write,
// TodWriter); CFITSIO and HDF5's C API make the variants they do not write (other column types and
// orderings, alm tables, per-detector angles, TOAST's compound table). The hand-written text seeds
// (simulation files, CSV and TOML focal planes, C_l tables) are committed as they are.
//
// Usage: pisco_fuzz_seeds CORPUS_DIR   (tests/fuzz/corpus; existing files of the same names are replaced)
#include <fitsio.h>
#include <hdf5.h>

#include <cmath>
#include <complex>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <numbers>
#include <string>
#include <vector>

#include "pisco/beamsor.hpp"
#include "pisco/focal_plane.hpp"
#include "pisco/pointing.hpp"
#include "pisco/pointing_file.hpp"
#include "pisco/quaternion.hpp"
#include "pisco/sky.hpp"
#include "pisco/tod_file.hpp"
#include "pisco/units.hpp"

namespace {

namespace fs = std::filesystem;
using pisco::deg;
constexpr double pi = std::numbers::pi;
constexpr double unseen = -1.6375e30;

[[noreturn]] void die(const std::string& what) {
  std::cerr << "pisco_fuzz_seeds: " << what << "\n";
  std::exit(1);
}

// ---- FITS ---------------------------------------------------------------------------------------

struct Column {
  std::string name, form;  // TTYPE, TFORM ("1D", "12E", "1J", ...)
  std::vector<double> values;
};

struct Keys {
  std::vector<std::pair<std::string, std::string>> text;
  std::vector<std::pair<std::string, long>> integer;
};

// One binary table after an empty primary HDU (the HEALPix layout), `rows` rows; further tables are
// appended with `append`.
void fits_table(const fs::path& file, const std::vector<Column>& columns, long rows, const Keys& keys,
                bool append = false) {
  int status = 0;
  fitsfile* f = nullptr;
  if (append) {
    fits_open_diskfile(&f, file.c_str(), READWRITE, &status);
  } else {
    fs::remove(file);
    fits_create_diskfile(&f, file.c_str(), &status);
  }
  std::vector<char*> names, forms;
  for (const Column& c : columns) {
    names.push_back(const_cast<char*>(c.name.c_str()));
    forms.push_back(const_cast<char*>(c.form.c_str()));
  }
  fits_create_tbl(f, BINARY_TBL, rows, static_cast<int>(columns.size()), names.data(), forms.data(), nullptr,
                  nullptr, &status);
  for (const auto& [key, value] : keys.text)
    fits_write_key(f, TSTRING, key.c_str(), const_cast<char*>(value.c_str()), nullptr, &status);
  for (const auto& [key, value] : keys.integer) {
    long v = value;
    fits_write_key(f, TLONG, key.c_str(), &v, nullptr, &status);
  }
  for (std::size_t c = 0; c < columns.size(); ++c) {
    std::vector<double> v = columns[c].values;
    if (!v.empty())
      fits_write_col(f, TDOUBLE, static_cast<int>(c + 1), 1, 1, static_cast<long long>(v.size()), v.data(), &status);
  }
  fits_close_file(f, &status);
  if (status) {
    char text[FLEN_STATUS];
    fits_get_errstatus(status, text);
    die(file.string() + ": CFITSIO: " + text);
  }
}

// The first `bytes` bytes of `from` as `to`: a file cut short.
void truncated_copy(const fs::path& from, const fs::path& to, std::size_t bytes) {
  std::ifstream in(from, std::ios::binary);
  std::string data((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  data.resize(std::min(bytes, data.size()));
  std::ofstream(to, std::ios::binary) << data;
}

// A smooth test map over 12 NSIDE^2 pixels.
std::vector<double> map_values(int nside, double scale, double offset) {
  std::vector<double> v(static_cast<std::size_t>(12) * nside * nside);
  for (std::size_t p = 0; p < v.size(); ++p) v[p] = offset + scale * std::sin(0.7 * static_cast<double>(p) + scale);
  return v;
}

void sky_seeds(const fs::path& dir) {
  fs::create_directories(dir);
  // The library's writer: RING, COSMO, I Q U V as float64.
  pisco::Sky sky(1, "uK_CMB");
  for (int k = 0; k < 4; ++k) {
    const auto v = map_values(1, 1.0 + k, k == 0 ? 10.0 : 0.0);
    auto map = sky.stokes(static_cast<pisco::StokesIndex>(k));
    std::copy(v.begin(), v.end(), map.begin());
  }
  sky.write_fits(dir / "iquv_nside1_library.fits");
  // NESTED, IAU, I Q U as float32 vector columns of 12 values a row.
  const Keys nested{{{"PIXTYPE", "HEALPIX"}, {"ORDERING", "NESTED"}, {"POLCCONV", "IAU"}, {"INDXSCHM", "IMPLICIT"},
                     {"OBJECT", "FULLSKY"}, {"TUNIT1", "K_CMB"}},
                    {{"NSIDE", 2}, {"FIRSTPIX", 0}, {"LASTPIX", 47}}};
  fits_table(dir / "iqu_nside2_nested_iau_float32.fits",
             {{"I_STOKES", "12E", map_values(2, 1, 5)}, {"Q_STOKES", "12E", map_values(2, 0.1, 0)},
              {"U_STOKES", "12E", map_values(2, 0.2, 0)}},
             4, nested);
  // I alone, integers, one value a row.
  fits_table(dir / "i_nside1_int32.fits", {{"TEMPERATURE", "1J", map_values(1, 100, 1000)}}, 12,
             {{{"ORDERING", "RING"}}, {{"NSIDE", 1}}});
  // A masked map: UNSEEN pixels (refused, or taken as zero).
  std::vector<double> masked = map_values(1, 1, 3);
  masked[3] = masked[7] = unseen;
  fits_table(dir / "iqu_nside1_unseen.fits",
             {{"I_STOKES", "1D", masked}, {"Q_STOKES", "1D", map_values(1, 1, 0)}, {"U_STOKES", "1D", map_values(1, 1, 0)}},
             12, {{{"ORDERING", "RING"}, {"POLCCONV", "COSMO"}}, {{"NSIDE", 1}}});
  // Broken: a NaN pixel, NSIDE not a power of two, a cut-sky map, no NSIDE, two columns, cut short.
  std::vector<double> nan = map_values(1, 1, 3);
  nan[5] = std::nan("");
  fits_table(dir / "bad_nan_pixel.fits", {{"I_STOKES", "1D", nan}}, 12, {{{"ORDERING", "RING"}}, {{"NSIDE", 1}}});
  fits_table(dir / "bad_nside3.fits", {{"I_STOKES", "1D", map_values(1, 1, 3)}}, 12,
             {{{"ORDERING", "RING"}}, {{"NSIDE", 3}}});
  fits_table(dir / "bad_partial.fits", {{"PIXEL", "1J", map_values(1, 0, 1)}, {"SIGNAL", "1D", map_values(1, 1, 3)}}, 12,
             {{{"ORDERING", "RING"}, {"INDXSCHM", "EXPLICIT"}, {"OBJECT", "PARTIAL"}}, {{"NSIDE", 1}}});
  fits_table(dir / "bad_no_nside.fits", {{"I_STOKES", "1D", map_values(1, 1, 3)}}, 12, {{{"ORDERING", "RING"}}, {}});
  truncated_copy(dir / "iqu_nside2_nested_iau_float32.fits", dir / "bad_truncated.fits", 2880 * 2 + 100);
}

void beamsor_seeds(const fs::path& dir) {
  fs::create_directories(dir);
  // The library's writer: a polarized Gaussian beam, 20 deg wide, out to 40 deg, at NSIDE 4.
  pisco::BeamOptions options;
  options.rho_max = 40 * deg;
  options.cross_polar = 0.05;
  pisco::Beamsor::gaussian(20 * deg, options).write_healpix_fits(dir / "gaussian_nside4_library.fits", 4);
  // The same kind of beam written by hand: NESTED, float32, four elements.
  std::vector<double> tt(192), qq(192), qt(192), uu(192);
  for (int p = 0; p < 192; ++p) {
    // Distance from the north pole of NESTED pixel p, roughly: enough for a falling profile.
    const double t = 0.05 * ((p * 37) % 192);
    tt[p] = std::exp(-t * t);
    qq[p] = 0.99 * tt[p];
    uu[p] = 0.98 * tt[p];
    qt[p] = 0.01 * tt[p];
  }
  const Keys keys{{{"PIXTYPE", "HEALPIX"}, {"ORDERING", "NESTED"}, {"INDXSCHM", "IMPLICIT"}},
                  {{"NSIDE", 4}}};
  fits_table(dir / "four_elements_nside4_nested.fits",
             {{"B_TT", "1E", tt}, {"B_QQ", "1E", qq}, {"B_UU", "1E", uu}, {"B_QT", "1E", qt}}, 192, keys);
  // Every one of the 16 elements at NSIDE 2, RING, 12 values a row.
  std::vector<Column> all;
  const char* letters = "TQUV";
  for (int e = 0; e < 16; ++e) {
    std::vector<double> v(48);
    for (int p = 0; p < 48; ++p) v[p] = (e % 5 == 0 ? 1.0 : 0.01) * std::exp(-0.1 * p);
    all.push_back({std::string("B_") + letters[e % 4] + letters[e / 4], "12D", v});
  }
  fits_table(dir / "sixteen_elements_nside2.fits", all, 4, {{{"ORDERING", "RING"}}, {{"NSIDE", 2}}});
  // Broken: no B_TT, B_TT twice, UNSEEN inside the cap, a column of the wrong length, cut short.
  fits_table(dir / "bad_no_btt.fits", {{"B_QQ", "1D", map_values(1, 1, 2)}}, 12, {{{"ORDERING", "RING"}}, {{"NSIDE", 1}}});
  fits_table(dir / "bad_two_btt.fits", {{"B_TT", "1D", map_values(1, 1, 2)}, {"b_tt", "1D", map_values(1, 1, 2)}}, 12,
             {{{"ORDERING", "RING"}}, {{"NSIDE", 1}}});
  std::vector<double> hole = map_values(2, 0.1, 1);
  hole[0] = unseen;
  fits_table(dir / "bad_unseen_in_cap.fits", {{"B_TT", "1D", hole}}, 48, {{{"ORDERING", "RING"}}, {{"NSIDE", 2}}});
  fits_table(dir / "bad_length.fits", {{"B_TT", "1D", map_values(1, 1, 2)}}, 12, {{{"ORDERING", "RING"}}, {{"NSIDE", 2}}});
  truncated_copy(dir / "four_elements_nside4_nested.fits", dir / "bad_truncated.fits", 2880 * 2 + 700);
}

// healpy.write_alm's layout: INDEX = l^2 + l + m + 1, REAL, IMAG; one table a component.
Column alm_index(int lmax, int mmax) {
  Column c{"INDEX", "1J", {}};
  for (int m = 0; m <= mmax; ++m)
    for (int l = m; l <= lmax; ++l) c.values.push_back(l * l + l + m + 1);
  return c;
}

std::vector<Column> alm_table(int lmax, int mmax, double scale, const char* form) {
  Column index = alm_index(lmax, mmax), re{"REAL", form, {}}, im{"IMAG", form, {}};
  for (int m = 0; m <= mmax; ++m)
    for (int l = m; l <= lmax; ++l) {
      const double b = scale * std::sqrt((2 * l + 1) / (4 * pi)) * std::exp(-0.5 * l * (l + 1) * 0.01);
      re.values.push_back(m == 0 ? b : 0.1 * b / (m + 1));
      im.values.push_back(m == 0 ? 0.0 : 0.05 * b);
    }
  return {index, re, im};
}

void blm_seeds(const fs::path& dir) {
  fs::create_directories(dir);
  const int lmax = 8, mmax = 2;
  const Keys keys{{}, {{"MAX-LPOL", lmax}, {"MAX-MPOL", mmax}}};
  const long rows = static_cast<long>(alm_index(lmax, mmax).values.size());
  fits_table(dir / "t_lmax8_mmax2.fits", alm_table(lmax, mmax, 1.0, "1D"), rows, keys);
  fits_table(dir / "teb_lmax8_mmax2.fits", alm_table(lmax, mmax, 1.0, "1D"), rows, keys);
  fits_table(dir / "teb_lmax8_mmax2.fits", alm_table(lmax, mmax, -0.2, "1D"), rows, keys, true);
  fits_table(dir / "teb_lmax8_mmax2.fits", alm_table(lmax, mmax, 0.1, "1D"), rows, keys, true);
  // Without MAX-LPOL and MAX-MPOL (taken from the rows), float32 values, a radial beam (m = 0 only).
  fits_table(dir / "t_lmax6_radial_float32_nokeys.fits", alm_table(6, 0, 1.0, "1E"), 7, {});
  // Broken: mmax above lmax, an INDEX of no (l, m), a NaN coefficient, two tables, b_00 <= 0, cut short.
  fits_table(dir / "bad_mmax_above_lmax.fits", alm_table(4, 2, 1.0, "1D"), static_cast<long>(alm_index(4, 2).values.size()),
             {{}, {{"MAX-LPOL", 2}, {"MAX-MPOL", 4}}});
  auto zero_index = alm_table(4, 0, 1.0, "1D");
  zero_index[0].values[2] = 0;
  fits_table(dir / "bad_index_zero.fits", zero_index, 5, {});
  auto nan = alm_table(4, 1, 1.0, "1D");
  nan[1].values[3] = std::nan("");
  fits_table(dir / "bad_nan.fits", nan, static_cast<long>(nan[0].values.size()), {});
  fits_table(dir / "bad_two_tables.fits", alm_table(4, 0, 1.0, "1D"), 5, {});
  fits_table(dir / "bad_two_tables.fits", alm_table(4, 0, 1.0, "1D"), 5, {}, true);
  fits_table(dir / "bad_negative_b00.fits", alm_table(4, 0, -1.0, "1D"), 5, {});
  truncated_copy(dir / "teb_lmax8_mmax2.fits", dir / "bad_truncated.fits", 2880 * 3 + 500);
}

// ---- HDF5 ---------------------------------------------------------------------------------------

void h5_check(herr_t status, const std::string& what) {
  if (status < 0) die("HDF5: " + what);
}

// A 1-D dataset of n elements of `type` (file), written from memory of `memory_type`.
void h5_dataset(hid_t loc, const char* name, hid_t type, hid_t memory_type, std::size_t count, const void* data) {
  const hsize_t n = count;
  const hid_t space = H5Screate_simple(1, &n, nullptr);
  const hid_t ds = H5Dcreate2(loc, name, type, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  h5_check(H5Dwrite(ds, memory_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, data), name);
  H5Dclose(ds);
  H5Sclose(space);
}

// A 1-D dataset of `type` (file) written from doubles.
void h5_vector(hid_t loc, const char* name, hid_t type, const std::vector<double>& v) {
  h5_dataset(loc, name, type, H5T_NATIVE_DOUBLE, v.size(), v.data());
}

std::vector<pisco::Quat> boresight(std::size_t n) {
  std::vector<pisco::Quat> q(n);
  for (std::size_t i = 0; i < n; ++i) {
    const double a = 0.1 * static_cast<double>(i), b = 0.5 * a;
    q[i] = {std::sin(a) * std::cos(b), std::sin(a) * std::sin(b), 0.0, std::cos(a)};
  }
  return q;
}

void pointing_seeds(const fs::path& dir) {
  fs::create_directories(dir);
  // Boresight quaternions, with and without times and plate angles (the library's writer).
  std::vector<double> times, hwp;
  for (int i = 0; i < 16; ++i) {
    times.push_back(1.7e9 + i / 19.0);
    hwp.push_back(std::fmod(0.3 * i, 2 * pi));
  }
  pisco::BoresightFile::write(dir / "boresight_16_times_hwp.h5", boresight(16), times, hwp);
  pisco::BoresightFile::write(dir / "boresight_8.h5", boresight(8));
  // Per-detector angles: two groups, float64 and float32.
  {
    const fs::path file = dir / "angles_two_detectors.h5";
    fs::remove(file);
    const hid_t f = H5Fcreate(file.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
    for (const char* det : {"det0", "det1"}) {
      const hid_t g = H5Gcreate2(f, det, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
      const hid_t type = std::strcmp(det, "det0") == 0 ? H5T_IEEE_F64LE : H5T_IEEE_F32LE;
      h5_vector(g, "theta", type, {0.1, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.1});
      h5_vector(g, "phi", type, {0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 6.2});
      h5_vector(g, "psi", type, {0.0, 0.3, -0.3, 1.0, -1.0, 2.0, -2.0, 3.0});
      H5Gclose(g);
    }
    H5Fclose(f);
  }
  // A TOD file written with its pointing (the library's writer): also a pointing file.
  {
    pisco::FocalPlane fp;
    fp.add_pair("q1", 0.0, 0, 0);
    const std::size_t n = 6;
    pisco::TodWriter tod(dir / "tod_with_pointing.h5", fp, n, pisco::TodPrecision::float32, true,
                         {{"units", "K_CMB"}, {"backend", "cpu"}});
    for (std::size_t d = 0; d < fp.size(); ++d) {
      pisco::Pointing p;
      std::vector<double> signal;
      for (std::size_t i = 0; i < n; ++i) {
        p.push_back(0.3 + 0.1 * static_cast<double>(i), 0.2 * static_cast<double>(i + d), 0.5);
        signal.push_back(1e-3 * static_cast<double>(i));
      }
      const pisco::PointingView view = p.view();
      tod.write(d, 0, signal, &view);
    }
    tod.commit();
  }
  // Broken: quaternions of 3 components, a non-unit quaternion, angles of different lengths, cut short.
  {
    const fs::path file = dir / "bad_boresight_shape.h5";
    fs::remove(file);
    const hid_t f = H5Fcreate(file.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
    const hsize_t dims[2] = {4, 3};
    const hid_t space = H5Screate_simple(2, dims, nullptr);
    const hid_t ds = H5Dcreate2(f, "boresight", H5T_IEEE_F64LE, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    const double v[12] = {0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 0, 1};
    h5_check(H5Dwrite(ds, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, v), "boresight");
    H5Dclose(ds);
    H5Sclose(space);
    H5Fclose(f);
  }
  {
    std::vector<pisco::Quat> q = boresight(4);
    const fs::path file = dir / "bad_boresight_not_unit.h5";
    const fs::path good = dir / "boresight_4.tmp.h5";
    pisco::BoresightFile::write(good, q);
    // Scale one quaternion in place through HDF5.
    const hid_t f = H5Fopen(good.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
    const hid_t ds = H5Dopen2(f, "boresight", H5P_DEFAULT);
    q[2] = {2 * q[2].x, 2 * q[2].y, 2 * q[2].z, 2 * q[2].w};
    h5_check(H5Dwrite(ds, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, q.data()), "boresight");
    H5Dclose(ds);
    H5Fclose(f);
    fs::rename(good, file);
  }
  {
    const fs::path file = dir / "bad_angles_lengths.h5";
    fs::remove(file);
    const hid_t f = H5Fcreate(file.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
    const hid_t g = H5Gcreate2(f, "det0", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    h5_vector(g, "theta", H5T_IEEE_F64LE, {0.1, 0.5, 1.0});
    h5_vector(g, "phi", H5T_IEEE_F64LE, {0.0, 1.0});
    h5_vector(g, "psi", H5T_IEEE_F64LE, {0.0, 0.3, -0.3});
    H5Gclose(g);
    H5Fclose(f);
  }
  truncated_copy(dir / "boresight_16_times_hwp.h5", dir / "bad_truncated.h5", 1500);
}

// TOAST's table: a compound row per detector with a fixed-length name, quat as float64[4] and angles.
struct ToastRow {
  char name[8];
  double quat[4];
  double psi_pol, pol_leakage, fwhm, gamma;
};

void write_toast(const fs::path& file, const std::vector<ToastRow>& rows, const std::vector<std::string>& meta,
                 bool with_quat = true) {
  fs::remove(file);
  const hid_t f = H5Fcreate(file.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
  const hid_t name = H5Tcopy(H5T_C_S1);
  H5Tset_size(name, 8);
  const hsize_t four = 4;
  const hid_t quat = H5Tarray_create2(H5T_NATIVE_DOUBLE, 1, &four);
  const hid_t row = H5Tcreate(H5T_COMPOUND, sizeof(ToastRow));
  H5Tinsert(row, "name", HOFFSET(ToastRow, name), name);
  if (with_quat) H5Tinsert(row, "quat", HOFFSET(ToastRow, quat), quat);
  H5Tinsert(row, "psi_pol", HOFFSET(ToastRow, psi_pol), H5T_NATIVE_DOUBLE);
  H5Tinsert(row, "pol_leakage", HOFFSET(ToastRow, pol_leakage), H5T_NATIVE_DOUBLE);
  H5Tinsert(row, "fwhm", HOFFSET(ToastRow, fwhm), H5T_NATIVE_DOUBLE);
  H5Tinsert(row, "gamma", HOFFSET(ToastRow, gamma), H5T_NATIVE_DOUBLE);
  h5_dataset(f, "focalplane", row, row, rows.size(), rows.data());
  if (!meta.empty()) {
    // astropy's header: one variable-length string a line.
    const hid_t text = H5Tcopy(H5T_C_S1);
    H5Tset_size(text, H5T_VARIABLE);
    std::vector<const char*> lines;
    for (const auto& l : meta) lines.push_back(l.c_str());
    h5_dataset(f, "focalplane.__table_column_meta__", text, text, lines.size(), lines.data());
    H5Tclose(text);
  }
  H5Tclose(row);
  H5Tclose(quat);
  H5Tclose(name);
  H5Fclose(f);
}

void toast_seeds(const fs::path& dir) {
  fs::create_directories(dir);
  // A pair at the boresight and one off it; the B detectors turned by 90 deg.
  const double h = std::sqrt(0.5);
  const double s = std::sin(0.01), c = std::cos(0.01);
  std::vector<ToastRow> rows = {
      {"d0A", {0, 0, 0, 1}, 0.0, 0.01, 30.0, 0.0},
      {"d0B", {0, 0, h, h}, 90.0, 0.01, 30.0, 90.0},
      {"d1A", {s, 0, 0, c}, 0.0, 0.0, 31.0, 0.0},
      {"d1B", {s * h, s * h, c * h, c * h}, 90.0, 0.02, 31.0, 90.0},
  };
  const std::vector<std::string> meta = {
      "# %ECSV 1.0",
      "# ---",
      "datatype:",
      "- {name: name, datatype: string}",
      "- {name: quat, datatype: string, subtype: 'float64[4]'}",
      "- {name: psi_pol, unit: deg, datatype: float64}",
      "- {name: pol_leakage, datatype: float64}",
      "- {name: fwhm, unit: arcmin, datatype: float64}",
      "- {name: gamma, unit: deg, datatype: float64}",
      "meta: !!omap",
      "- sample_rate: !astropy.units.Quantity",
      "    unit: &id001 !astropy.units.Unit {unit: Hz}",
      "    value: 20.0",
      "schema: astropy-2.0",
  };
  write_toast(dir / "two_pairs_deg_arcmin.h5", rows, meta);
  // No header: every angle column in radians.
  std::vector<ToastRow> rad = rows;
  for (auto& r : rad) {
    r.psi_pol *= deg;
    r.gamma *= deg;
    r.fwhm *= deg / 60;
  }
  write_toast(dir / "two_pairs_rad_no_meta.h5", rad, {});
  // Broken: no quat column, a non-unit quaternion, a repeated name, a unit no angle has.
  write_toast(dir / "bad_no_quat.h5", rows, meta, false);
  std::vector<ToastRow> bad = rows;
  bad[2].quat[3] = 2.0;
  write_toast(dir / "bad_quat_not_unit.h5", bad, meta);
  bad = rows;
  std::strcpy(bad[3].name, "d1A");
  write_toast(dir / "bad_repeated_name.h5", bad, meta);
  std::vector<std::string> furlong = meta;
  furlong[5] = "- {name: psi_pol, unit: furlong, datatype: float64}";
  write_toast(dir / "bad_unit.h5", rows, furlong);
#ifdef PISCO_SOURCE_DIR
  // A table TOAST wrote itself (14 detectors, astropy's full header).
  fs::copy_file(fs::path(PISCO_SOURCE_DIR) / "assets" / "focalplanes" / "toast_hex7.h5", dir / "toast_hex7.h5",
                fs::copy_options::overwrite_existing);
#endif
}

// ---- GRASP --------------------------------------------------------------------------------------

// A Gaussian co-polar field with a weak cross-polar lobe at angle `t` (radians) from the axis and
// azimuth `p`.
void field(double t, double p, std::complex<double>& co, std::complex<double>& cx) {
  const double g = std::exp(-t * t / (2 * std::pow(1.0 * deg, 2)));
  co = {g, 0.01 * g};
  cx = {0.02 * g * std::sin(2 * p), 0.0};
}

void point(std::ostream& out, double t, double p, int ncomp) {
  std::complex<double> co, cx;
  field(t, p, co, cx);
  char line[160];
  std::snprintf(line, sizeof line, " %.8E %.8E %.8E %.8E", co.real(), co.imag(), cx.real(), cx.imag());
  out << line;
  if (ncomp == 3) out << "  0.00000000E+00  0.00000000E+00";
  out << "\n";
}

// A .grd of `igrid` on n x n points over [-half, half] (uv units for IGRID 1, degrees otherwise).
void grd(const fs::path& file, int igrid, int n, double half, int nsets, int ncomp, bool klimit) {
  std::ofstream out(file);
  out << "Fuzz seed: Gaussian beam with a cross-polar lobe\nVERSION: TICRA-EM-FIELD-V0.1\n"
         "FIELD_NAME: po_freq_1\nFREQUENCY_NAME: freq\nFREQUENCIES [GHz]:\n";
  for (int s = 0; s < nsets; ++s) out << "  " << 100 + 40 * s << ".0";
  out << "\n++++\n           1\n           " << nsets << "           3           " << ncomp << "           " << igrid
      << "\n";
  for (int s = 0; s < nsets; ++s) out << "           0           0\n";
  for (int s = 0; s < nsets; ++s) {
    char line[160];
    std::snprintf(line, sizeof line, " %.10E %.10E %.10E %.10E\n", -half, -half, half, half);
    out << line << "           " << n << "           " << n << "           " << (klimit ? 1 : 0) << "\n";
    for (int j = 0; j < n; ++j) {
      if (klimit) out << "           1           " << n << "\n";
      for (int i = 0; i < n; ++i) {
        const double x = -half + 2 * half * i / (n - 1), y = -half + 2 * half * j / (n - 1);
        double t, p;
        if (igrid == 1) {
          t = std::asin(std::min(1.0, std::hypot(x, y)));
          p = std::atan2(y, x);
        } else if (igrid == 7) {
          p = x * deg;
          t = y * deg;
        } else {
          t = std::hypot(x, y) * deg;
          p = std::atan2(y, -x);
        }
        point(out, t, p, ncomp);
      }
    }
  }
}

void grasp_seeds(const fs::path& grd_dir, const fs::path& cut_dir) {
  fs::create_directories(grd_dir);
  fs::create_directories(cut_dir);
  grd(grd_dir / "uv_igrid1.grd", 1, 7, 0.06, 1, 2, false);
  grd(grd_dir / "elevation_over_azimuth_igrid4_klimit.grd", 4, 7, 3.0, 1, 2, true);
  grd(grd_dir / "elevation_and_azimuth_igrid5_two_sets_ncomp3.grd", 5, 7, 3.0, 2, 3, false);
  grd(grd_dir / "azimuth_over_elevation_igrid6.grd", 6, 7, 3.0, 1, 2, false);
  {
    // IGRID 7: x = phi from 0 to 360 deg (the last column repeats the first), y = theta from 0 to 3 deg.
    std::ofstream out(grd_dir / "theta_phi_igrid7.grd");
    out << "Fuzz seed: theta-phi grid\n++++\n1\n1 3 2 7\n0 0\n0.0 0.0 360.0 3.0\n5 7 0\n";
    for (int j = 0; j < 7; ++j)
      for (int i = 0; i < 5; ++i) point(out, 0.5 * j * deg, 90.0 * i * deg, 2);
  }
  // Broken: no "++++", ICOMP 1, IGRID 2, a row short of its points.
  {
    std::ofstream(grd_dir / "bad_no_header_end.grd") << "Fuzz seed\nFREQUENCIES [GHz]:\n 100.0\n1\n1 3 2 1\n0 0\n";
    std::ofstream(grd_dir / "bad_icomp1.grd") << "x\n++++\n1\n1 1 2 1\n0 0\n-0.1 -0.1 0.1 0.1\n2 2 0\n"
                                                 "1 0 0 0\n1 0 0 0\n1 0 0 0\n1 0 0 0\n";
    std::ofstream(grd_dir / "bad_igrid2.grd") << "x\n++++\n1\n1 3 2 2\n0 0\n-0.1 -0.1 0.1 0.1\n2 2 0\n"
                                                 "1 0 0 0\n1 0 0 0\n1 0 0 0\n1 0 0 0\n";
    std::ofstream(grd_dir / "bad_short_row.grd") << "x\n++++\n1\n1 3 2 1\n0 0\n-0.1 -0.1 0.1 0.1\n2 2 1\n"
                                                    "1 2\n1 0 0 0\n1 0 0 0\n1 3\n1 0 0 0\n";
  }
  // .cut: four polar cuts through the axis (phi 0, 45, 90, 135 deg), theta from -3 to 3 deg, at two
  // frequencies (the second block starts again at phi = 0).
  {
    std::ofstream out(cut_dir / "four_cuts_two_frequencies.cut");
    for (int f = 0; f < 2; ++f)
      for (int c = 0; c < 4; ++c) {
        out << "Field data in cuts, frequency " << f + 1 << "\n";
        out << "  -3.0000000000E+00   5.0000000000E-01   13   " << 45.0 * c << "   3   1   2\n";
        for (int k = 0; k < 13; ++k) {
          const double theta = (-3.0 + 0.5 * k) * deg;
          point(out, std::abs(theta), 45.0 * c * deg + (theta < 0 ? pi : 0.0), 2);
        }
      }
  }
  {
    // Half-lines from the axis (theta from 0), six of them, NCOMP 3, Fortran D exponents.
    std::ofstream out(cut_dir / "six_half_cuts_ncomp3.cut");
    for (int c = 0; c < 6; ++c) {
      out << "cut " << c << "\n  0.0D+00  0.5D+00  7  " << 60.0 * c << "  3  1  3\n";
      for (int k = 0; k < 7; ++k) point(out, 0.5 * k * deg, 60.0 * c * deg, 3);
    }
  }
  // Broken: a conical cut (ICUT 2), V_INC 0, cuts sampling theta differently, a NaN field.
  std::ofstream(cut_dir / "bad_conical.cut") << "cut\n 0.0 1.0 2 0.0 3 2 2\n1 0 0 0\n1 0 0 0\n";
  std::ofstream(cut_dir / "bad_vinc_zero.cut") << "cut\n 0.0 0.0 2 0.0 3 1 2\n1 0 0 0\n1 0 0 0\n";
  std::ofstream(cut_dir / "bad_mixed_theta.cut") << "a\n 0.0 1.0 2 0.0 3 1 2\n1 0 0 0\n1 0 0 0\n"
                                                    "b\n 0.0 2.0 2 90.0 3 1 2\n1 0 0 0\n1 0 0 0\n";
  std::ofstream(cut_dir / "bad_nan.cut") << "a\n 0.0 1.0 2 0.0 3 1 2\n1 0 0 0\nNaN 0 0 0\n";
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) die("usage: pisco_fuzz_seeds CORPUS_DIR");
  const fs::path root = argv[1];
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  sky_seeds(root / "fuzz_sky_fits");
  beamsor_seeds(root / "fuzz_beamsor_fits");
  blm_seeds(root / "fuzz_blm_fits");
  pointing_seeds(root / "fuzz_pointing_hdf5");
  toast_seeds(root / "fuzz_focal_plane_hdf5");
  grasp_seeds(root / "fuzz_grasp_grd", root / "fuzz_grasp_cut");
  std::cout << "pisco_fuzz_seeds: seeds written under " << root.string() << "\n";
  return 0;
}
