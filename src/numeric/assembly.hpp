// strata — the two additions that assemble a front, shared by the CPU executor
// (cpu/cpu_executor.cpp, process_front) and the host assembly of the GPU's tiled fronts
// (cuda/tiled_host.cpp), so that both add the same things in the same order.
//
// A front F is n_rows(f) × n_rows(f), column-major (leading dimension m). Its original
// entries come from the AssemblyMap (analysis/analysis.hpp); a child's contribution block
// (mc × mc, column-major) is added at the front rows and columns rel[0..mc), increasing
// (the child's CB rows' positions in the front): the extend-add of the multifrontal
// method (Duff & Reid, ACM TOMS 9, 1983; Liu, SIAM Review 34, 1992).
#pragma once
#include <cstdint>

#include "base/lower_panels.hpp"
#include "strata/types.hpp"

namespace strata::numeric {

/// F[entry_dst[e] − d0] += values[entry_src[e]] for e in [e0, e1) whose destination lies
/// in [d0, d1) (whole front: 0, m·m): F points at the front's entry d0 (a block of whole
/// columns when d0 is a multiple of m). Destinations are distinct.
inline void add_entries(double* F, const index_t* entry_dst, const index_t* entry_src,
                        const double* values, index_t e0, index_t e1, std::int64_t d0,
                        std::int64_t d1) {
  for (index_t e = e0; e < e1; ++e) {
    const std::int64_t d = entry_dst[e];
    if (d >= d0 && d < d1) F[d - d0] += values[entry_src[e]];
  }
}

/// Columns jj in [j0, j1) of the child block cb (mc × mc) added into F at rows rel[ii] and
/// column rel[jj] − col0 (F: the front's columns from col0 on, leading dimension m);
/// `lower`: rows ii ≥ jj only (LLᵀ, LDLᵀ), else all rows (LU).
inline void extend_add(double* F, std::int64_t m, const double* cb, std::int64_t mc,
                       const index_t* rel, std::int64_t j0, std::int64_t j1, bool lower,
                       std::int64_t col0 = 0) {
  for (std::int64_t jj = j0; jj < j1; ++jj) {
    double* dst = F + (rel[jj] - col0) * m;
    const double* src = cb + jj * mc;
    for (std::int64_t ii = lower ? jj : 0; ii < mc; ++ii) dst[rel[ii]] += src[ii];
  }
}

/// The same addition for a symmetric child block stored by its lower triangle in panels
/// (base/lower_panels.hpp; a plain square is one panel): columns jj in [j0, j1), rows
/// ii ≥ jj, added into F (leading dimension m) at rows and column rel[·].
inline void extend_add_lower(double* F, std::int64_t m, const LowerPanels& cb, const index_t* rel,
                             index_t j0, index_t j1) {
  for (index_t jj = j0; jj < j1; ++jj) {
    const double* col = cb.diag(jj);  // col[ii − jj]: element (ii, jj)
    double* dst = F + static_cast<std::int64_t>(rel[jj]) * m;
    for (index_t ii = jj; ii < cb.n; ++ii) dst[rel[ii]] += col[ii - jj];
  }
}

}  // namespace strata::numeric
