// Helpers shared by the test suites.
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "pisco/error.hpp"

namespace pisco_test {

// The message of the pisco::Error that f throws, its key named before it where it has one
// (Error::named); "no error" if none; other exceptions are named.
inline std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const pisco::Error& e) {
    return e.named();
  } catch (const std::exception& e) {
    return std::string("not a pisco::Error: ") + e.what();
  }
  return "no error";
}

// The kind of the pisco::Error that f throws; fails the test if it throws none.
inline pisco::ErrorKind kind_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const pisco::Error& e) {
    return e.kind();
  }
  ADD_FAILURE() << "expected a pisco::Error";
  return pisco::ErrorKind::internal;
}

inline bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

// A new, empty directory for the running test, <temp>/pisco-<what>-<pid>-<test name>: a test's
// fixture makes it in SetUp and removes it in TearDown.
inline std::filesystem::path fresh_test_dir(const std::string& what) {
  namespace fs = std::filesystem;
  const fs::path dir = fs::temp_directory_path() / ("pisco-" + what + "-" + std::to_string(::getpid()) + "-" +
                                                    ::testing::UnitTest::GetInstance()->current_test_info()->name());
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

// Runs f, expecting a pisco::Error whose message contains `needle`.
inline void expect_error(const std::function<void()>& f, const std::string& needle) {
  const std::string message = error_of(f);
  EXPECT_TRUE(contains(message, needle)) << "expected a pisco::Error mentioning '" << needle << "', got: " << message;
}

// A TOD's RMS about its mean: the scale the validation tests give their errors in.
inline double rms_about_mean(const std::vector<double>& v) {
  double m = 0.0, s = 0.0;
  for (double x : v) m += x;
  m /= double(v.size());
  for (double x : v) s += (x - m) * (x - m);
  return std::sqrt(s / double(v.size()));
}

}  // namespace pisco_test
