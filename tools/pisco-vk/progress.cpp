#include "progress.hpp"

#include <cstdio>
#include <unistd.h>

namespace pisco_cli {

std::string human_seconds(double s) {
  char buf[32];
  if (!(s < 1e7)) {  // beyond 115 days (or not a number): no hours and minutes, and no overflowing int
    std::snprintf(buf, sizeof buf, "%.3g s", s);
    return buf;
  }
  if (s < 60) std::snprintf(buf, sizeof buf, "%.1f s", s);
  else if (s < 3600) std::snprintf(buf, sizeof buf, "%dm%02ds", int(s) / 60, int(s) % 60);
  else std::snprintf(buf, sizeof buf, "%dh%02dm", int(s) / 3600, (int(s) % 3600) / 60);
  return buf;
}

Progress::Progress(std::uint64_t total, bool quiet)
    : total_(total), quiet_(quiet), tty_(isatty(STDERR_FILENO) != 0),
      start_(std::chrono::steady_clock::now()), last_(start_) {}

double Progress::elapsed() const {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
}

void Progress::advance(std::uint64_t samples) {
  done_ += samples;
  const auto now = std::chrono::steady_clock::now();
  // A terminal is redrawn five times a second; a log gets one line every ten seconds.
  const double interval = tty_ ? 0.2 : 10.0;
  if (std::chrono::duration<double>(now - last_).count() >= interval) {
    last_ = now;
    draw(false);
  }
}

void Progress::finish() { draw(true); }

void Progress::draw(bool final) {
  if (quiet_ || total_ == 0) return;
  const double t = elapsed();
  const double rate = t > 0 ? done_ / t : 0;
  const double left = rate > 0 ? (total_ - done_) / rate : 0;
  const double frac = double(done_) / double(total_);
  if (tty_) {
    const int width = 30, fill = static_cast<int>(frac * width);
    std::fprintf(stderr, "\r[%.*s%*s] %5.1f%%  %.3g samples/s  %s left   ", fill, "##############################",
                 width - fill, "", 100 * frac, rate, human_seconds(left).c_str());
    if (final) std::fputc('\n', stderr);
  } else if (!final) {
    std::fprintf(stderr, "progress: %llu of %llu samples (%.1f%%), %.3g samples/s, %s left\n",
                 static_cast<unsigned long long>(done_), static_cast<unsigned long long>(total_), 100 * frac, rate,
                 human_seconds(left).c_str());
  }
  std::fflush(stderr);
}

}  // namespace pisco_cli
