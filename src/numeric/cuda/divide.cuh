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
//
// Where one pivot divides many entries along an elimination's chain of dependent steps,
// PivotReciprocal gives the multipliers as x · (1/d) instead: one correctly rounded
// reciprocal per step (__drcp_rn) and a product per entry, at most one rounding from x / d.
// A division of nonzero operands is a long link of a step's chain (about 170 cycles on an
// H200, bench/history.md); the host's dense kernels (OpenBLAS's TRSM and GETRF) scale by
// reciprocals of the pivots as well.
#pragma once

namespace strata::cuda {

/// x / d correctly rounded (bit for bit the result of `x / d`), computed without a
/// division when x = ±0 and d is neither ±0 nor NaN: the quotient is then ±0 with the
/// sign of x · d.
__device__ __forceinline__ double divide_rn(double x, double d) {
  return (x != 0.0 || !(fabs(d) > 0.0)) ? x / d : x * copysign(1.0, d);
}

/// The multipliers x / d of one pivot d: x · (1/d) with 1/d correctly rounded, or divide_rn
/// where 1/d could overflow or d is not finite (|d| < 2^−1020, ±∞, NaN), so that a zero,
/// infinite or NaN pivot gives what the division gives.
struct PivotReciprocal {
  double d, r;
  bool scale;
  __device__ __forceinline__ explicit PivotReciprocal(double pivot)
      : d(pivot), scale(fabs(pivot) >= 0x1p-1020 && fabs(pivot) <= 0x1.fffffffffffffp+1023) {
    r = scale ? __drcp_rn(pivot) : 0.0;
  }
  __device__ __forceinline__ double operator()(double x) const {
    return scale ? x * r : divide_rn(x, d);
  }
};

}  // namespace strata::cuda
