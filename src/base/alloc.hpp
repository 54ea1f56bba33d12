// strata — growing a large buffer with a named size.
//
// A std::bad_alloc (or a std::length_error for a size beyond what a vector can hold) from
// resizing one of the solver's large buffers — factor panels, contribution-block arena,
// dense front workspace — becomes strata::OutOfMemory naming the buffer and the bytes
// asked for, so that a user learns what did not fit. Allocations deep inside other code
// are translated at the phase boundary instead (Solver::analyze/factorize/solve), where
// only the phase is known.
#pragma once

#include <cstddef>
#include <new>
#include <stdexcept>
#include <vector>

#include "strata/errors.hpp"

namespace strata {

/// v.resize(n); an allocation failure throws OutOfMemory(n·sizeof(T), what).
template <class T, class A>
void sized_resize(std::vector<T, A>& v, std::size_t n, const char* what) {
  try {
    v.resize(n);
  } catch (const std::bad_alloc&) {
    throw OutOfMemory(n * sizeof(T), what);
  } catch (const std::length_error&) {
    throw OutOfMemory(n * sizeof(T), what);
  }
}

/// v.assign(n, x) with the same translation.
template <class T, class A>
void sized_assign(std::vector<T, A>& v, std::size_t n, const T& x, const char* what) {
  try {
    v.assign(n, x);
  } catch (const std::bad_alloc&) {
    throw OutOfMemory(n * sizeof(T), what);
  } catch (const std::length_error&) {
    throw OutOfMemory(n * sizeof(T), what);
  }
}

}  // namespace strata
