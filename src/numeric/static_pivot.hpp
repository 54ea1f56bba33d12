// strata — static pivoting's test and replacement, one definition for every kernel (the CPU
// fronts and the CUDA ones), so that both replace the same pivots by the same values.
//
// A pivot p of B (the scaled matrix, entries at most about 1) with |p| below the threshold
// τ = |sp| (sp: PivotPolicy::static_pivot, ε·‖B‖₁) cannot be taken without growth of about
// 1/|p| in the rest of the factor. With sp > 0 (Pivoting::fixed, automatic, delayed before
// its own factorization) it becomes sign(p)·sp: the factor is of a matrix within 2τ of B
// at that entry, the change itself unknown to the solve (refinement recovers the
// accuracy). With sp < 0 (Pivoting::corrected) it becomes p + sign(p)·c for the constant
// c = kCorrectedPivotShift below: a regular pivot (no growth), and the factored matrix
// differs from B by exactly sign(p)·c at that entry, to one rounding, which the solve then
// corrects (core/pivot_correction.hpp). sign(0) is +; sp = 0 replaces nothing.
#pragma once

#include <cmath>

#if defined(__CUDACC__)
#define STRATA_HOST_DEVICE __host__ __device__
#else
#define STRATA_HOST_DEVICE
#endif

namespace strata::numeric {

/// The shift Pivoting::corrected gives a tiny pivot: of the order of B's largest entries,
/// and (1 + π/512) far from the short binary fractions (1, 1.5, 1 + 2⁻¹⁰, …) that pivots of
/// a matrix scaled by powers of two often are, so that no other pivot is likely to be
/// within τ of it, which is_static_pivot relies on (the caller checks the count).
inline constexpr double kCorrectedPivotShift = 1.0061359231515425;

/// Whether pivot p needs static pivoting under `sp` (|p| < |sp|; NaN never).
STRATA_HOST_DEVICE inline bool needs_static_pivot(double p, double sp) {
  return fabs(p) < fabs(sp);
}

/// The pivot static pivoting puts in p's place under `sp` (see above).
STRATA_HOST_DEVICE inline double static_pivot_value(double p, double sp) {
  if (sp >= 0) return p < 0 ? -sp : sp;
  return p < 0 ? p - kCorrectedPivotShift : p + kCorrectedPivotShift;
}

/// Whether a pivot d of a finished factor is one static pivoting under `sp` put there.
STRATA_HOST_DEVICE inline bool is_static_pivot(double d, double sp) {
  if (sp >= 0) return fabs(d) == sp;
  return fabs(fabs(d) - kCorrectedPivotShift) <= fabs(sp);
}

}  // namespace strata::numeric
