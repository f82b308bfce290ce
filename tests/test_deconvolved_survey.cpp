// Case M of docs/validation.md at test scale: the beam-deconvolving map-maker on the CLASS-like survey
// of case F for an hour of two pairs, against the binned maps, with pointing and beam mismatch.
#include <gtest/gtest.h>

#include "validation_report.hpp"

TEST(DeconvolvedSurvey, DeconvolutionRemovesMismatchLeakage) {
  pisco::validation::SurveyOptions o;
  pisco_test::expect_case_passes(pisco::validation::deconvolved_survey(pisco::validation::Scale::test, "simd", o));
}
