// strata — the quotient x / d of the elimination kernels' multipliers, without CUDA's
// general division routine for a zero dividend.
//
// CUDA's double division (div.rn.f64 on sm_90: a reciprocal by Newton's iteration, then a
// range check) calls a long, fully general subroutine whenever the dividend's exponent is
// tiny, and x = ±0 is such a dividend. Most entries below a pivot in a sparse front's
// column are zero, so the threads of a pivot step that divide their rows' entries would
// mostly run that subroutine, and the step waits for the slowest thread. For x = ±0 and a
// divisor that is neither zero nor NaN the correctly rounded quotient is the signed zero
// x · sign(d), which divide_rn returns without dividing: the same bits as x / d in every
// case.
#pragma once

namespace strata::cuda {

/// x / d correctly rounded (bit for bit the result of `x / d`), computed without a
/// division when x = ±0 and d is neither ±0 nor NaN: the quotient is then ±0 with the
/// sign of x · d.
__device__ __forceinline__ double divide_rn(double x, double d) {
  return (x != 0.0 || !(fabs(d) > 0.0)) ? x / d : x * copysign(1.0, d);
}

}  // namespace strata::cuda
