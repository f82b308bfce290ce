// Case D of docs/validation.md (paper 6.2) at test scale: a Gaussian r = 0 CMB sky at NSIDE 256 observed at every
// NSIDE 128 pixel centre at psi = 0, 45, 90 deg, binned maps, beam-deconvolved spectra against the
// input's and against the harmonic image of the same observation (src/validation/validation.cpp).
#include <gtest/gtest.h>

#include "validation_report.hpp"

TEST(IdealCmb, ResidualSpectraWithinThePapersBars) {
  pisco_test::expect_case_passes(pisco::validation::ideal_cmb(pisco::validation::Scale::test));
}
