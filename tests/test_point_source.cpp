// Case C of docs/validation.md (paper 6.1): a polarized point source observed by a raster scan and binned into maps,
// against the same single-pixel map smoothed by HEALPix C++ (src/validation/validation.cpp).
#include <gtest/gtest.h>

#include "validation_report.hpp"

TEST(PointSource, FluxTemperatureToPolarizationAndPolarization) {
  pisco_test::expect_case_passes(pisco::validation::point_source(pisco::validation::Scale::test));
}
