// strata — typed exceptions. Every error strata throws derives from strata::Error.
//
// Errors are for conditions that stop a phase (bad input, unsupported request, out of
// memory, device failure, a Cholesky pivot that is not positive). Numerical outcomes that
// do not stop a phase (perturbed pivots, inertia, refinement that stalls) are reported in
// strata::Stats instead.
#pragma once

#include <cstddef>
#include <stdexcept>
#include <string>

#include "strata/types.hpp"

namespace strata {

/// Base of every exception strata throws.
class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// The input is malformed: a matrix that is not square, an index out of range, a NaN,
/// a right-hand side of the wrong length, an inconsistent option.
class InvalidInput : public Error {
 public:
  using Error::Error;
};

/// A file could not be parsed. what() reads "FILE:LINE: message"; file() and line()
/// give the parts (line is 1-based; 0 when the problem is not tied to one line, e.g. a
/// file that cannot be opened).
class ParseError : public InvalidInput {
 public:
  ParseError(std::string file, index_t line, const std::string& message);
  const std::string& file() const noexcept { return file_; }
  index_t line() const noexcept { return line_; }

 private:
  std::string file_;
  index_t line_;
};

/// The request is valid but this build or this backend cannot do it (e.g. a GPU asked
/// of a build without CUDA).
class NotSupported : public Error {
 public:
  using Error::Error;
};

/// An allocation failed. what() names where (the phase, and the buffer when it is one of
/// the solver's large ones) and the size; bytes_requested() is the size in bytes of the
/// allocation that failed, or 0 when it is not known (an allocation deep inside other code,
/// e.g. a std::bad_alloc translated at a phase boundary).
class OutOfMemory : public Error {
 public:
  OutOfMemory(std::size_t bytes_requested, const std::string& where);
  std::size_t bytes_requested() const noexcept { return bytes_; }

 private:
  std::size_t bytes_;
};

/// A CUDA, cuBLAS or cuSOLVER call failed; what() names the call and its error string.
class DeviceError : public Error {
 public:
  using Error::Error;
};

/// Cholesky (MatrixType::spd) met a pivot that is not positive. column() is the column
/// of the ORIGINAL matrix (0-based) at which the factorization broke down.
class NotPositiveDefinite : public Error {
 public:
  NotPositiveDefinite(index_t column, double pivot);
  index_t column() const noexcept { return column_; }
  double pivot() const noexcept { return pivot_; }

 private:
  index_t column_;
  double pivot_;
};

/// A phase was called out of order (e.g. solve before factorize).
class InvalidState : public Error {
 public:
  using Error::Error;
};

/// An internal invariant of strata was broken: a bug in strata, not a problem of the
/// input (please report it with the input that caused it). what() reads
/// "internal error: " followed by what was found; detail() is the part after the prefix.
class InternalError : public Error {
 public:
  explicit InternalError(const std::string& detail);
  const std::string& detail() const noexcept { return detail_; }

 private:
  std::string detail_;
};

}  // namespace strata
