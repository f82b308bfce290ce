// Case E of docs/validation.md (paper 6.3) at test scale: random pointing offsets from the pixel centres give a
// spurious BB; symmetric offsets suppress it; an unpolarized sky shows no T->P.
#include <gtest/gtest.h>

#include "validation_report.hpp"

TEST(PointingOffsets, SpuriousBBAndItsSymmetricSuppression) {
  pisco_test::expect_case_passes(pisco::validation::pointing_offsets(pisco::validation::Scale::test));
}
