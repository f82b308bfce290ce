// Shared by the fuzz targets of tests/fuzz: the input bytes as a file the reader under test opens by
// name, and the rule that tells a clean refusal from a finding.
//
// Each process writes its inputs into a private directory of its own (under $TMPDIR, else /tmp), always
// under the same name, so that a reader that dispatches on the extension (.grd, .cut, .csv, .toml) sees
// the one it is fuzzed for, and relative file names inside an input resolve into that directory, which
// holds nothing else. The directory is removed when the process exits normally.
//
// A reader may refuse an input only by throwing pisco::Error. Any other exception (std::bad_alloc,
// std::out_of_range, a third-party library's own type, ...) is printed and the process aborts, so that
// libFuzzer records the input as a crash; crashes, sanitizer reports, hangs (-timeout) and oversized
// allocations (-malloc_limit_mb, -rss_limit_mb) are caught by libFuzzer itself.
#pragma once

#include <cxxabi.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <iostream>
#include <string>
#include <typeinfo>

#include "pisco/error.hpp"

namespace pisco_fuzz {

// The private directory, made on first use and removed at normal exit.
inline const std::filesystem::path& private_directory() {
  static const std::filesystem::path dir = [] {
    const char* tmp = std::getenv("TMPDIR");
    std::string pattern = std::string(tmp && *tmp ? tmp : "/tmp") + "/pisco-fuzz-XXXXXX";
    if (!mkdtemp(pattern.data())) {
      std::perror("pisco fuzz: cannot make a private directory");
      std::abort();
    }
    std::atexit([] {
      std::error_code ec;
      std::filesystem::remove_all(private_directory(), ec);
    });
    return std::filesystem::path(pattern);
  }();
  return dir;
}

// Writes the input as `name` in the private directory (replacing the previous input) and returns its path.
inline std::filesystem::path write_input(const std::uint8_t* data, std::size_t size, const char* name) {
  const std::filesystem::path file = private_directory() / name;
  std::FILE* f = std::fopen(file.c_str(), "wb");
  if (!f || (size > 0 && std::fwrite(data, 1, size, f) != size) || std::fclose(f) != 0) {
    std::perror(("pisco fuzz: cannot write " + file.string()).c_str());
    std::abort();
  }
  return file;
}

// Runs `read`: returns normally when it succeeds or throws pisco::Error, aborts on anything else.
template <typename Read>
void expect_clean(Read&& read) {
  try {
    read();
  } catch (const pisco::Error& e) {
    // The expected refusal of a bad input; PISCO_FUZZ_VERBOSE=1 prints it (to see why a seed is refused).
    static const bool verbose = std::getenv("PISCO_FUZZ_VERBOSE") != nullptr;
    if (verbose) std::fprintf(stderr, "pisco fuzz: refused: %s\n", e.what());
  } catch (const std::exception& e) {
    int status = 0;
    char* type = abi::__cxa_demangle(typeid(e).name(), nullptr, nullptr, &status);
    std::fprintf(stderr, "pisco fuzz: finding: exception %s escaped the reader (not pisco::Error): %s\n",
                 status == 0 && type ? type : typeid(e).name(), e.what());
    std::free(type);
    std::abort();
  } catch (...) {
    std::fprintf(stderr, "pisco fuzz: finding: an exception of unknown type escaped the reader\n");
    std::abort();
  }
}

// The readers' notes on std::clog (e.g. a sky map's POLCCONV = 'IAU') are dropped: printed for every
// input, they would slow the fuzzer down and bury its own output.
inline void quiet_notes() { std::clog.rdbuf(nullptr); }

}  // namespace pisco_fuzz
