// HEALPix maps written for the tests as another tool would write them: through CFITSIO, without the
// library's checks, so that the readers' tests get the maps the library's own writers refuse (a NaN
// pixel: write_healpix_map names it and writes nothing).
#pragma once

#include <fitsio.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <string>
#include <vector>

#include "pisco/sky.hpp"

namespace pisco_test {

// A full-sky RING table of I, Q, U, V (one value a row), with the keys the readers look for.
inline void write_unchecked_sky(const pisco::Sky& sky, const std::filesystem::path& file) {
  std::filesystem::remove(file);
  fitsfile* f = nullptr;
  int status = 0;
  fits_create_diskfile(&f, file.c_str(), &status);
  fits_create_img(f, BYTE_IMG, 0, nullptr, &status);
  const char* names[4] = {"I_STOKES", "Q_STOKES", "U_STOKES", "V_STOKES"};
  std::string form = "1D", unit = sky.units();
  char* ttype[4];
  char* tform[4];
  char* tunit[4];
  for (int c = 0; c < 4; ++c) {
    ttype[c] = const_cast<char*>(names[c]);
    tform[c] = form.data();
    tunit[c] = unit.data();
  }
  fits_create_tbl(f, BINARY_TBL, static_cast<LONGLONG>(sky.npix()), 4, ttype, tform, tunit, "xtension", &status);
  long long nside = sky.nside();
  fits_update_key(f, TSTRING, "PIXTYPE", const_cast<char*>("HEALPIX"), nullptr, &status);
  fits_update_key(f, TSTRING, "ORDERING", const_cast<char*>("RING"), nullptr, &status);
  fits_update_key(f, TLONGLONG, "NSIDE", &nside, nullptr, &status);
  fits_update_key(f, TSTRING, "POLCCONV", const_cast<char*>("COSMO"), nullptr, &status);
  for (int c = 0; c < 4; ++c) {
    std::vector<double> values(sky.stokes(static_cast<pisco::StokesIndex>(c)).begin(),
                               sky.stokes(static_cast<pisco::StokesIndex>(c)).end());
    fits_write_col(f, TDOUBLE, c + 1, 1, 1, static_cast<LONGLONG>(values.size()), values.data(), &status);
  }
  fits_close_file(f, &status);
  ASSERT_EQ(status, 0) << "test setup: CFITSIO status " << status << " writing " << file;
}

}  // namespace pisco_test
