#include "pisco/error.hpp"

namespace pisco {

const char* error_kind_name(ErrorKind kind) noexcept {
  switch (kind) {
    case ErrorKind::input: return "input";
    case ErrorKind::unavailable: return "unavailable";
    case ErrorKind::device: return "device";
    case ErrorKind::io: return "io";
    case ErrorKind::internal: return "internal";
  }
  return "internal";
}

}  // namespace pisco
