// Beam files written for the tests (docs/beams.md): harmonic coefficients in healpy's alm FITS layout,
// through CFITSIO, and GRASP uv grids of an analytic field.
#pragma once

#include <fitsio.h>
#include <gtest/gtest.h>

#include <cmath>
#include <complex>
#include <filesystem>
#include <fstream>
#include <functional>
#include <numbers>
#include <vector>

#include "pisco/beam_files.hpp"

namespace pisco_test {

// healpy.write_alm's layout: one binary table a component, INDEX = l^2 + l + m + 1, REAL, IMAG, with
// MAX-LPOL = lmax and MAX-MPOL = mmax_key (mmax when negative). `parts` in HarmonicBeam's layout.
inline void write_alm_fits(const std::filesystem::path& file, const std::vector<const std::vector<std::complex<double>>*>& parts,
                           int lmax, int mmax, long mmax_key = -1) {
  std::filesystem::remove(file);
  fitsfile* f = nullptr;
  int status = 0;
  fits_create_file(&f, file.c_str(), &status);
  for (const auto* part : parts) {
    const char* names[] = {"INDEX", "REAL", "IMAG"};
    const char* forms[] = {"1J", "1D", "1D"};
    fits_create_tbl(f, BINARY_TBL, 0, 3, const_cast<char**>(names), const_cast<char**>(forms), nullptr, "ALM", &status);
    long lk = lmax, mk = mmax_key >= 0 ? mmax_key : mmax;
    fits_write_key(f, TLONG, "MAX-LPOL", &lk, nullptr, &status);
    fits_write_key(f, TLONG, "MAX-MPOL", &mk, nullptr, &status);
    long row = 1;
    for (int m = 0; m <= mmax; ++m)
      for (int l = m; l <= lmax; ++l, ++row) {
        int index = l * l + l + m + 1;
        const std::complex<double> v = (*part)[pisco::HarmonicBeam::index(lmax, l, m)];
        double re = v.real(), im = v.imag();
        fits_write_col(f, TINT, 1, row, 1, 1, &index, &status);
        fits_write_col(f, TDOUBLE, 2, row, 1, 1, &re, &status);
        fits_write_col(f, TDOUBLE, 3, row, 1, 1, &im, &status);
      }
  }
  fits_close_file(f, &status);
  ASSERT_EQ(status, 0) << file;
}

// A Gaussian of `fwhm` polarized along x as the frameworks write it (mmax 2, -sqrt 2 on E and B,
// B = i E at m = 2, healpy's polarized window exp(2 s^2)).
inline pisco::HarmonicBeam gaussian_blm(double fwhm, int lmax) {
  const double s = fwhm / std::sqrt(8 * std::log(2.0)), pi = std::numbers::pi;
  pisco::HarmonicBeam g;
  g.lmax = lmax;
  g.mmax = 2;
  const std::size_t n = pisco::HarmonicBeam::size(lmax, 2);
  g.t.assign(n, {});
  g.e.assign(n, {});
  g.b.assign(n, {});
  for (int l = 0; l <= lmax; ++l) {
    const double bl = std::exp(-0.5 * l * (l + 1) * s * s);
    g.t[pisco::HarmonicBeam::index(lmax, l, 0)] = std::sqrt((2 * l + 1) / (4 * pi)) * bl;
    if (l >= 2) {
      const double e = -std::sqrt(2.0) * std::sqrt((2 * l + 1) / (32 * pi)) * bl * std::exp(2 * s * s);
      g.e[pisco::HarmonicBeam::index(lmax, l, 2)] = e;
      g.b[pisco::HarmonicBeam::index(lmax, l, 2)] = {0.0, e};
    }
  }
  return g;
}

// A GRASP .grd file (KTYPE 1, ICOMP 3, NCOMP 2, IGRID 1) of `fields(rho, sigma, co, cx)` on an n x n uv
// grid |u|, |v| <= half, `nsets` identical field sets.
inline void write_uv_grd(const std::filesystem::path& file,
                         const std::function<void(double, double, std::complex<double>&, std::complex<double>&)>& fields,
                         double half, int n, int nsets = 1) {
  std::ofstream out(file);
  out << "Analytic beam\nVERSION: TICRA-EM-FIELD-V0.1\nFREQUENCIES [GHz]:\n";
  for (int s = 0; s < nsets; ++s) out << " 100.0";
  out << "\n++++\n1\n" << nsets << " 3 2 1\n";
  for (int s = 0; s < nsets; ++s) out << "0 0\n";
  out.precision(17);
  for (int s = 0; s < nsets; ++s) {
    out << -half << " " << -half << " " << half << " " << half << "\n" << n << " " << n << " 0\n";
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const double u = -half + 2 * half * i / (n - 1), v = -half + 2 * half * j / (n - 1);
        const double r = std::min(1.0, std::sqrt(u * u + v * v));
        std::complex<double> co, cx;
        fields(std::asin(r), std::atan2(v, u), co, cx);
        out << co.real() << " " << co.imag() << " " << cx.real() << " " << cx.imag() << "\n";
      }
  }
}

}  // namespace pisco_test
