// strata — elementwise logarithms over arrays, vectorized (base/vector_math.cpp).
#pragma once

#include "strata/types.hpp"

namespace strata::detail {

/// out[k] = log|a[k]| for the nonzero a[k] and 0 for a[k] == 0, k in [0, n); returns how
/// many a[k] are zero. `a` and `out` may be the same array. The values must be finite
/// (validated input). The logarithm is glibc's vector one (libmvec: several a[k] per
/// call, within a unit or two in the last place of std::log), which is why this has a
/// file of its own (see the file comment of vector_math.cpp).
index_t log_magnitudes(const double* a, double* out, index_t n);

}  // namespace strata::detail
