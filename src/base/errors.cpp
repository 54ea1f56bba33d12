// strata — typed exceptions (see include/strata/errors.hpp).
#include "strata/errors.hpp"

#include <cstdio>
#include <string>

namespace strata {

ParseError::ParseError(std::string file, index_t line, const std::string& message)
    : InvalidInput(file + ":" + std::to_string(line) + ": " + message),
      file_(std::move(file)),
      line_(line) {}

// bytes_requested == 0: the size is not known (an allocation deep inside other code,
// translated at a phase boundary).
OutOfMemory::OutOfMemory(std::size_t bytes_requested, const std::string& where)
    : Error(bytes_requested > 0
                ? "out of memory: " + where + " asked for " + std::to_string(bytes_requested) +
                      " bytes"
                : "out of memory: " + where + " (the size of the failed allocation is not known)"),
      bytes_(bytes_requested) {}

namespace {
// A number for a message: %.3e keeps 4 significant digits whatever the magnitude
// (std::to_string prints a pivot of -1e-9 as "-0.000000").
std::string sci(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3e", v);
  return buf;
}
}  // namespace

InternalError::InternalError(const std::string& detail)
    : Error("internal error: " + detail), detail_(detail) {}

NotPositiveDefinite::NotPositiveDefinite(index_t column, double pivot)
    : Error("matrix is not positive definite: pivot " + sci(pivot) + " at column " +
            std::to_string(column) + " (0-based, original numbering)"),
      column_(column),
      pivot_(pivot) {}

}  // namespace strata
