// Progress of a long run: a bar with samples/s and time left on a terminal, plain periodic lines
// in a log (when stderr is not a terminal).
#pragma once

#include <chrono>
#include <cstdint>
#include <string>

namespace pisco_cli {

class Progress {
 public:
  Progress(std::uint64_t total, bool quiet);
  void advance(std::uint64_t samples);
  void finish();
  double elapsed() const;

 private:
  void draw(bool final);
  std::uint64_t total_, done_ = 0;
  bool quiet_, tty_;
  std::chrono::steady_clock::time_point start_, last_;
};

std::string human_seconds(double s);

}  // namespace pisco_cli
