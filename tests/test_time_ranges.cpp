// What float64 carries over a run (docs/formats.md, "Times, rates and angles"): the limits of
// include/pisco/time_ranges.hpp against values computed by hand, and the scans and plates that use
// them refusing what they cannot compute (no float-to-integer conversion out of range).
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <numbers>
#include <string>
#include <vector>

#include "pisco/error.hpp"
#include "pisco/hwp.hpp"
#include "pisco/scan.hpp"
#include "pisco/time_ranges.hpp"
#include "support.hpp"

namespace {

// f throws a pisco::Error whose key() is `key` and whose message mentions `needle`.
void expect_keyed(const std::function<void()>& f, const std::string& key, const std::string& needle) {
  try {
    f();
    ADD_FAILURE() << "expected a pisco::Error with key " << key;
  } catch (const pisco::Error& e) {
    EXPECT_EQ(e.key(), key) << e.what();
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << "expected '" << needle << "', got: " << e.what();
  }
}

constexpr double pi = std::numbers::pi;
bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

TEST(TimeRanges, SampleTimes) {
  // Unix times at 20 Hz: rounded to 2.4e-7 s, 4.8e-6 of a sample.
  EXPECT_EQ(pisco::sample_time_problem(1.7e9, 20 * 86400 * 365.0, 20.0), "");
  // From 2^40 s: spacing 2^-12 s = 0.244 ms; at 4 Hz that is 9.8e-4 of a sample (passes), at 5 Hz 1.2e-3.
  EXPECT_EQ(pisco::sample_time_problem(std::ldexp(1.0, 40), 10, 4.0), "");
  EXPECT_TRUE(contains(pisco::sample_time_problem(std::ldexp(1.0, 40), 10, 5.0), "at most 0.001"));
  EXPECT_TRUE(contains(pisco::sample_time_problem(1e20, 1, 19), "times up to 1e+20 s"));
  EXPECT_TRUE(contains(pisco::sample_time_problem(1e308, 1e15, 1e-300), "overflow"));
  EXPECT_TRUE(contains(pisco::sample_time_problem(0, 10, 0), "positive"));
}

TEST(TimeRanges, Rotations) {
  // Half a turn between samples is the limit, either sense.
  EXPECT_EQ(pisco::turning_problem(pi * 20, 1, 20.0), "");
  EXPECT_TRUE(contains(pisco::turning_problem(-pi * 20 * 1.001, 1, 20.0), "at most 180 deg"));
  // The angle's rounding at t_max: turns = w t / 2 pi, rounded to ulp(turns) turns. A 2 Hz plate from
  // Unix time 1.7e9 s: 3.4e9 turns, ulp 4.8e-7 turns = 3.0e-6 rad (passes); from 1e10 s: 1.9e-5 rad.
  EXPECT_EQ(pisco::turning_problem(4 * pi, 1.7e9, 20.0), "");
  EXPECT_TRUE(contains(pisco::turning_problem(4 * pi, 1e10, 20.0), "at most 1e-05 rad"));
  EXPECT_EQ(pisco::turning_problem(0.0, 1e300, 1.0), "");  // no rotation: nothing to lose
  EXPECT_TRUE(contains(pisco::turning_problem(INFINITY, 1, 1), "not finite"));
}

TEST(TimeRanges, Steps) {
  EXPECT_EQ(pisco::stepping_problem(60, 3.15e7, 20.0), "");
  EXPECT_TRUE(contains(pisco::stepping_problem(0.01, 100, 20.0), "less than one sample"));
  EXPECT_TRUE(contains(pisco::stepping_problem(1.0, 1e16, 20.0), "2^52"));
  EXPECT_TRUE(contains(pisco::stepping_problem(0, 1, 1), "positive"));
}

// A stepped plate at times whose step count float64 cannot hold: an error naming the field, before
// any step index is formed (with -fsanitize=float-cast-overflow this used to be undefined behaviour).
TEST(TimeRanges, PlatesRefuseWhatTheyCannotCompute) {
  pisco::HwpAngleStream s;
  s.kind = pisco::HwpAngleStream::Kind::stepped;
  s.steps = {0.0, 0.5, 1.0};
  s.step_seconds = 1e-300;
  s.sample_rate = 2;
  std::vector<double> out;
  expect_keyed([&] { s.generate(0, 10, out); }, "step_seconds", "each angle is held");
  s.step_seconds = 10;
  s.start_time = 1e283;
  expect_keyed([&] { s.generate(0, 10, out); }, "start_time", "times up to");
  // (A step count beyond 2^52 needs times rounded to more than a sample: the check above comes first.)
  s.start_time = 0;
  s.sample_rate = 0.1;
  s.generate(0, 11, out);  // well within: one step a sample
  EXPECT_EQ(out[9], 0.0) << "sample 9 at 90 s is step 9, 9 mod 3 = 0";
  EXPECT_EQ(out[10], 0.5) << "sample 10 at 100 s is step 10, 10 mod 3 = 1";
  s.kind = pisco::HwpAngleStream::Kind::continuous;
  s.frequency_hz = 1e300;
  expect_keyed([&] { s.generate(0, 10, out); }, "frequency", "turns");
}

TEST(TimeRanges, ScansRefuseWhatTheyCannotCompute) {
  pisco::SatelliteScan sat;
  sat.samples = 100;
  sat.check();
  sat.spin_period = 1e-9;
  expect_keyed([&] { sat.check(); }, "spin_period", "turns");
  sat.spin_period = 60;
  sat.start_time = 1e20;
  expect_keyed([&] { sat.check(); }, "start_time", "times up to");

  pisco::CesScan ces;
  ces.samples = 1000;
  ces.check();
  ces.boresight_angles = {0.0, 1.0};
  ces.boresight_period = 1e-9;
  expect_keyed([&] { ces.check(); }, "boresight_period", "each angle is held");
  ces.boresight_period = 3600;
  ces.az_speed = 1e300;
  expect_keyed([&] { ces.check(); }, "az_speed", "turns");
  ces.az_speed = 1e-9;
  ces.sample_rate = 1e-6;  // the Earth turns 73 rad between samples: keyed by the start, whence its angle
  expect_keyed([&] { ces.check(); }, "start_unix", "the Earth's rotation: turns");
}

}  // namespace
