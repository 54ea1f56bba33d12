// strata — the numerical outcomes of a factorization's pivots (perturbations, 2×2 blocks,
// inertia, log-determinant), accumulated front by front by every executor (CPU, CUDA,
// delayed pivoting) and added up into FactorStats; sent between MPI ranks as bytes.
#pragma once

#include "strata/types.hpp"

namespace strata::numeric {

/// Numerical outcomes of partial factorizations, accumulated over fronts.
struct PivotStats {
  index_t perturbed = 0;   ///< pivots replaced by ±static_pivot
  index_t two_by_two = 0;  ///< 2×2 pivot blocks (LDLᵀ)
  index_t positive = 0;    ///< inertia of D (LLᵀ: every pivot is positive)
  index_t negative = 0;
  index_t zero = 0;
  double log_abs_det = 0;  ///< Σ log|pivot| = log|det| of the eliminated pivot blocks
                           ///< (LLᵀ: Σ log L_jj²; LDLᵀ: log|det D|; LU: of U11's diagonal)
  int det_sign = 1;        ///< sign of det of the eliminated pivot blocks: sign of the
                           ///< product of pivots, times the row-swap parity for LU (0 after
                           ///< an exactly zero pivot)
  /// Adds another set of fronts' outcomes to these.
  void merge(const PivotStats& o) {
    perturbed += o.perturbed;
    two_by_two += o.two_by_two;
    positive += o.positive;
    negative += o.negative;
    zero += o.zero;
    log_abs_det += o.log_abs_det;
    det_sign *= o.det_sign;
  }
};

}  // namespace strata::numeric
