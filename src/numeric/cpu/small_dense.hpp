// strata — dense matrix–vector kernels for the small blocks of a front's solve.
//
// The triangular solves of a multibody Newton matrix's factor go through hundreds of fronts
// of a few dozen rows each, once per Newton iteration. There the BLAS's fixed cost per call
// is larger than the arithmetic, and a column-at-a-time loop (one AXPY per column) reads
// and writes the result vector once per column. These kernels take the columns four at a
// time (register blocking as in the reference GEMV's unrolled variants, Golub & Van Loan,
// Matrix Computations, 4th ed., §1.5), so the result is read and written once per four
// columns. All matrices are column-major with a leading dimension; indices are 0-based.
//
// Each kernel adds the same products in the same order on every call, so a solve with the
// same factor and right-hand side gives bitwise the same result.
#pragma once

#include <algorithm>
#include <cmath>

#include "strata/types.hpp"

namespace strata::numeric::cpu {

/// The largest |x_i| over n entries (0 for n ≤ 0). Eight partial maxima, so that the loop
/// is not one chain of dependent maxima (a pivot test's column scan); a maximum is exact in
/// any order and each partial takes std::max(m, |x_i|), which passes over a NaN, so the
/// result is the plain loop's.
inline double max_abs(const double* x, index_t n) {
  double m[8] = {0, 0, 0, 0, 0, 0, 0, 0};
  index_t i = 0;
  for (; i + 8 <= n; i += 8)
    for (int q = 0; q < 8; ++q) m[q] = std::max(m[q], std::abs(x[i + q]));
  for (; i < n; ++i) m[0] = std::max(m[0], std::abs(x[i]));
  double r = m[0];
  for (int q = 1; q < 8; ++q) r = std::max(r, m[q]);
  return r;
}

/// y −= A·x for A rows×cols (leading dimension lda ≥ rows), x of length cols, y of length
/// rows. Four columns at a time; a group of four zero entries of x is skipped (sparse
/// right-hand sides leave many).
inline void gemv_subtract(index_t rows, index_t cols, const double* a, index_t lda, const double* x,
                          double* y) {
  index_t j = 0;
  for (; j + 4 <= cols; j += 4) {
    const double x0 = x[j], x1 = x[j + 1], x2 = x[j + 2], x3 = x[j + 3];
    if (x0 == 0.0 && x1 == 0.0 && x2 == 0.0 && x3 == 0.0) continue;
    const double* a0 = a + j * lda;
    const double* a1 = a0 + lda;
    const double* a2 = a1 + lda;
    const double* a3 = a2 + lda;
    for (index_t i = 0; i < rows; ++i)
      y[i] -= (a0[i] * x0 + a1[i] * x1) + (a2[i] * x2 + a3[i] * x3);
  }
  for (; j < cols; ++j) {
    const double xj = x[j];
    if (xj == 0.0) continue;
    const double* aj = a + j * lda;
    for (index_t i = 0; i < rows; ++i) y[i] -= aj[i] * xj;
  }
}

/// w = L⁻¹w for L the k×k unit lower triangle of `l` (leading dimension ldl; the diagonal
/// and the upper part are not read). Four columns at a time: the 4×4 diagonal block by
/// substitution, then the rows below by gemv_subtract.
inline void unit_lower_solve(index_t k, const double* l, index_t ldl, double* w) {
  for (index_t j0 = 0; j0 < k; j0 += 4) {
    const index_t j1 = j0 + 4 < k ? j0 + 4 : k;
    for (index_t j = j0; j < j1; ++j) {
      const double wj = w[j];
      const double* col = l + j * ldl;
      for (index_t i = j + 1; i < j1; ++i) w[i] -= col[i] * wj;
    }
    if (j1 < k) gemv_subtract(k - j1, j1 - j0, l + j0 * ldl + j1, ldl, w + j0, w + j1);
  }
}

/// w = U⁻¹w for U the k×k upper triangle of `u` (leading dimension ldu; the part below the
/// diagonal is not read). A zero diagonal entry (a zero pivot left by a factorization without
/// static pivoting) gives 0 for its unknown instead of ∞. Four columns at a time, bottom up.
inline void upper_solve(index_t k, const double* u, index_t ldu, double* w) {
  for (index_t j1 = k; j1 > 0;) {
    const index_t j0 = j1 >= 4 ? j1 - 4 : 0;
    for (index_t j = j1 - 1; j >= j0; --j) {
      const double* col = u + j * ldu;
      const double d = col[j];
      const double wj = d != 0.0 ? w[j] / d : 0.0;
      w[j] = wj;
      for (index_t i = j0; i < j; ++i) w[i] -= col[i] * wj;
    }
    if (j0 > 0) gemv_subtract(j0, j1 - j0, u + j0 * ldu, ldu, w + j0, w);
    j1 = j0;
  }
}

}  // namespace strata::numeric::cpu
