// strata — elementwise logarithms over arrays (see vector_math.hpp).
//
// What: log|a| of every entry of an array; the maximum product matching
// (ordering/matching.cpp) takes one logarithm per entry of the matrix.
//
// How: a loop the compiler turns into calls of glibc's vector logarithm (libmvec,
// _ZGV*_log: eight doubles per call at the AVX-512 level, four at AVX2, two at the base
// level), reached through libm's link script. GCC emits those calls only where math.h
// declares the vector variants, which it does under -ffast-math; this file alone is compiled
// so (CMakeLists.txt), and holds nothing else, so that no other code is reassociated or
// loses its infinities and NaNs. The inputs are finite (the analysis validates the values
// first) and a zero is replaced by 1 before the call, so that nothing outside the domain
// is passed to the logarithm.
#include "base/vector_math.hpp"

#include <cmath>

namespace strata::detail {

index_t log_magnitudes(const double* a, double* out, index_t n) {
  index_t zeros = 0;
  for (index_t k = 0; k < n; ++k) {
    const double x = std::abs(a[k]);
    const double zero = x == 0.0;
    zeros += static_cast<index_t>(zero);
    // x + 1 for a zero, x itself otherwise: arithmetic, not a branch or a select, which
    // GCC turns into a masked call that runs lane by lane
    out[k] = std::log(x + zero);
  }
  return zeros;
}

}  // namespace strata::detail
