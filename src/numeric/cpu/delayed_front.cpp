// strata — front factorization with threshold pivoting and delayed pivots (see
// delayed_front.hpp).
//
// LU. The p candidate columns are eliminated right-looking, one at a time, over all m rows
// (the column maximum of the threshold test must see the contribution-block rows as they
// are after the earlier pivots): a rank-one update of the candidate columns per pivot,
// BLAS-2 work of about m·p² flops. Whole rows are interchanged at once (the fully summed
// rows' entries in the contribution-block columns are still the assembled ones, so the
// interchange commutes with their later update). A refused column is swapped with the
// last untried candidate and is updated with the others from then on, so that at the end
// the delayed columns hold exactly what the pivots taken made of them. After the
// candidates: U12 of the contribution-block columns by one TRSM, their Schur complement by
// one GEMM — BLAS-3, with the delayed rows among the updated ones.
#include "numeric/cpu/delayed_front.hpp"

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>

#include "numeric/cpu/dense_blas.hpp"
#include "strata/errors.hpp"

namespace strata::numeric::cpu {
namespace {

void count(double d, PivotStats& st) {
  if (d < 0) st.det_sign = -st.det_sign;
  if (d == 0) {
    ++st.zero;
    st.det_sign = 0;
  }
  st.log_abs_det += std::log(std::abs(d));
}

}  // namespace

index_t factor_front_lu_delayed(double* f, index_t m, index_t p, index_t ld,
                                const DelayPolicy& policy, index_t* row_perm, index_t* col_perm,
                                PivotStats& st) {
  if (m < 0 || p < 0 || p > m || ld < std::max<index_t>(m, 1))
    throw InvalidInput("delayed front: need 0 <= p <= m <= ld (m=" + std::to_string(m) +
                       ", p=" + std::to_string(p) + ", ld=" + std::to_string(ld) + ")");
  if (!(policy.threshold > 0 && policy.threshold <= 1))
    throw InvalidInput("delayed front: the pivot threshold must be in (0, 1]");
  auto A = [&](index_t i, index_t j) -> double& { return f[i + j * ld]; };
  for (index_t i = 0; i < p; ++i) row_perm[i] = col_perm[i] = i;
  index_t npiv = 0;
  index_t last = p;  // candidates are columns npiv..last-1; last..p-1 were refused
  while (npiv < last) {
    const index_t j = npiv;
    // largest entry among the remaining fully summed rows, and over all remaining rows
    index_t r = j;
    double best = std::abs(A(j, j));
    for (index_t i = j + 1; i < p; ++i)
      if (std::abs(A(i, j)) > best) best = std::abs(A(i, j)), r = i;
    double colmax = best;
    for (index_t i = p; i < m; ++i) colmax = std::max(colmax, std::abs(A(i, j)));
    const bool good = best > policy.tiny && best >= policy.threshold * colmax;
    if (!good && policy.may_delay) {
      // refuse column j: behind the remaining candidates
      --last;
      if (j != last) {
        for (index_t i = 0; i < m; ++i) std::swap(A(i, j), A(i, last));
        std::swap(col_perm[j], col_perm[last]);
      }
      continue;
    }
    if (r != j) {
      for (index_t c = 0; c < m; ++c) std::swap(A(j, c), A(r, c));
      std::swap(row_perm[j], row_perm[r]);
    }
    double d = A(j, j);
    if (std::abs(d) < policy.static_pivot) {  // a root's last resort
      d = d < 0 ? -policy.static_pivot : policy.static_pivot;
      ++st.perturbed;
    }
    A(j, j) = d;
    count(d, st);
    const double inv = d != 0 ? 1.0 / d : 0.0;
    for (index_t i = j + 1; i < m; ++i) A(i, j) *= inv;
    // update the other candidate columns and the refused ones (all rows below j)
    for (index_t c = j + 1; c < p; ++c) {
      const double u = A(j, c);
      if (u == 0.0) continue;
      double* col = &A(0, c);
      const double* l = &A(0, j);
      for (index_t i = j + 1; i < m; ++i) col[i] -= l[i] * u;
    }
    ++npiv;
  }
  const index_t n = m - p;
  if (n > 0 && npiv > 0) {
    // U12 of the contribution-block columns, then their Schur complement (delayed rows too)
    trsm('L', 'L', 'N', 'U', npiv, n, f, ld, &A(0, p), ld);
    gemm('N', 'N', m - npiv, n, npiv, -1.0, &A(npiv, 0), ld, &A(0, p), ld, 1.0, &A(npiv, p), ld);
  }
  return npiv;
}

}  // namespace strata::numeric::cpu
