// Case F of docs/validation.md (paper section 7) at test scale: 4 h of CES with 4 PSB pairs at NSIDE 64.
// Matched pairs leak nothing; pointing and beam mismatch leak T into B, as delta^2.
#include <gtest/gtest.h>

#include "validation_report.hpp"

TEST(ClassSurvey, MismatchLeakageOrderingAndDeltaSquared) {
  pisco_test::expect_case_passes(pisco::validation::class_survey(pisco::validation::Scale::test));
}
