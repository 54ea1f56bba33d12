// strata — the warp-level step of the pivot searches of the LU kernels: the largest value
// and its index over a warp's lanes, the smaller index on ties (LAPACK's IDAMAX takes the
// first largest entry; the CPU kernels do the same).
#pragma once

namespace strata::cuda {

/// Reduces (v, at) over the 32 lanes of the calling warp by shuffles down: lane 0 ends with
/// the largest v and, among equal ones, the smallest `at`. Every lane must call it. A NaN
/// never wins (comparisons with it are false), so callers pass −1 for "no candidate".
__device__ __forceinline__ void warp_argmax_down(double& v, int& at) {
  for (int off = 16; off > 0; off >>= 1) {
    const double ov = __shfl_down_sync(0xffffffffu, v, off);
    const int oi = __shfl_down_sync(0xffffffffu, at, off);
    if (ov > v || (ov == v && oi < at)) {
      v = ov;
      at = oi;
    }
  }
}

}  // namespace strata::cuda
