// Prints a validation case's figures and notes and asserts every figure within its bar.
#pragma once

#include <gtest/gtest.h>

#include <cstdio>

#include "validation/validation.hpp"

namespace pisco_test {

inline void expect_case_passes(const pisco::validation::CaseResult& r) {
  std::printf("%s %s (%.1f s)\n", r.id.c_str(), r.title.c_str(), r.seconds);
  for (const auto& n : r.notes) std::printf("  %s\n", n.c_str());
  for (const auto& f : r.figures) {
    std::printf("  %-58s %11.3g %-9s bar %-9.3g %s\n", f.name.c_str(), f.value, f.unit.c_str(), f.bar,
                f.pass() ? "pass" : "FAIL");
    EXPECT_LE(f.value, f.bar) << r.id << ": " << f.name;
  }
}

}  // namespace pisco_test
