// Cases C and D of docs/validation.md through a device backend (PISCO_TEST_BACKEND): the same bars as the float64
// reference meets (tests/test_point_source.cpp, tests/test_ideal_cmb.cpp), with the float32 kernels.
// Skipped, with the reason printed, where the backend has no device.
#include <gtest/gtest.h>

#include "pisco/engine.hpp"
#include "backend_fixtures.hpp"
#include "validation_report.hpp"

namespace {

const std::string backend = PISCO_TEST_BACKEND;

std::string unavailable() { return pisco_test::backend_unavailable(backend); }

TEST(BackendValidation, PointSource) {
  if (const std::string why = unavailable(); !why.empty()) GTEST_SKIP() << backend << " backend unavailable: " << why;
  pisco_test::expect_case_passes(pisco::validation::point_source(pisco::validation::Scale::test, backend));
}

TEST(BackendValidation, IdealCmb) {
  if (const std::string why = unavailable(); !why.empty()) GTEST_SKIP() << backend << " backend unavailable: " << why;
  pisco_test::expect_case_passes(pisco::validation::ideal_cmb(pisco::validation::Scale::test, backend));
}

}  // namespace
