// Errors: every bad input is reported by throwing pisco::Error with a message that names the file,
// key, value or sample and what was expected (docs/formats.md, "Errors and partial files").
#pragma once

#include <stdexcept>
#include <string>

namespace pisco {

class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

}  // namespace pisco
