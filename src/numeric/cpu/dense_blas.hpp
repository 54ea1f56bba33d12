// strata — thin BLAS wrappers for the dense front kernels: index_t in, the 32-bit BLAS
// interface checked, nothing called for empty shapes. Shared by dense_front.cpp and
// delayed_front.cpp.
#pragma once

#include <cstddef>
#include <limits>
#include <string>

#include "base/blas.hpp"
#include "strata/errors.hpp"
#include "strata/types.hpp"

namespace strata::numeric::cpu {

/// v as the BLAS's int; throws NotSupported when it does not fit.
inline int blas_int(index_t v) {
  if (v < 0 || v > std::numeric_limits<int>::max())
    throw NotSupported("dense front: dimension " + std::to_string(v) +
                       " does not fit the 32-bit BLAS interface");
  return static_cast<int>(v);
}

/// C = alpha·op(A)·op(B) + beta·C (m×n, inner dimension k); nothing for an empty shape
/// (callers never rely on beta with k = 0).
inline void gemm(char ta, char tb, index_t m, index_t n, index_t k, double alpha, const double* a,
                 index_t lda, const double* b, index_t ldb, double beta, double* c, index_t ldc) {
  if (m <= 0 || n <= 0 || k <= 0) return;
  const int im = blas_int(m), in = blas_int(n), ik = blas_int(k);
  const int ila = blas_int(lda), ilb = blas_int(ldb), ilc = blas_int(ldc);
  dgemm_(&ta, &tb, &im, &in, &ik, &alpha, a, &ila, b, &ilb, &beta, c, &ilc);
}

/// Triangular order up to which trsm calls DTRSM directly.
constexpr index_t kTrsmLeaf = 64;

/// B = op(A)⁻¹·B or B·op(A)⁻¹ (alpha 1; B m × n, A triangular of order m for side 'L', n
/// for 'R'); nothing for an empty shape. A triangular order above kTrsmLeaf is split in
/// two halves: solve with the first diagonal block, subtract its product with the
/// off-diagonal block from the other half of B (one DGEMM), solve with the second — the
/// recursive blocked TRSM of Elmroth, Gustavson, Jonsson & Kågström ("Recursive blocked
/// algorithms and hybrid data structures for dense matrix library software", SIAM Review
/// 46, 2004), which puts most of the flops in DGEMM, faster than OpenBLAS's own DTRSM on the
/// fronts' shapes (bench/history.md). Recursive for the combinations the front kernels use
/// — ('R','L','T'), ('R','U','N'), ('L','L','N') — and plain DTRSM for the others; diag
/// ('N' or 'U') passes to the leaves.
inline void trsm(char side, char uplo, char ta, char diag, index_t m, index_t n, const double* a,
                 index_t lda, double* b, index_t ldb) {
  if (m <= 0 || n <= 0) return;
  const bool right = side == 'R', lower = uplo == 'L', trans = ta == 'T';
  const index_t order = right ? n : m;
  const bool recursive =
      order > kTrsmLeaf &&
      ((right && lower && trans) || (right && !lower && !trans) || (!right && lower && !trans));
  if (!recursive) {
    const double one = 1.0;
    const int im = blas_int(m), in = blas_int(n), ila = blas_int(lda), ilb = blas_int(ldb);
    dtrsm_(&side, &uplo, &ta, &diag, &im, &in, &one, a, &ila, b, &ilb);
    return;
  }
  const index_t h1 = (order / 2 + 7) / 8 * 8, h2 = order - h1;  // h1 < order
  const auto at = [&](index_t i, index_t j) { return a + i + static_cast<std::size_t>(j) * lda; };
  const auto col = [&](index_t j) { return b + static_cast<std::size_t>(j) * ldb; };
  if (right) {
    // X·op(A) = B by column halves: X1 first, then B2 −= X1·(the block coupling them)
    trsm(side, uplo, ta, diag, m, h1, a, lda, b, ldb);
    if (lower)  // op(A) = Lᵀ: the coupling block is L21ᵀ, L21 = A[h1:, :h1]
      gemm('N', 'T', m, h2, h1, -1.0, b, ldb, at(h1, 0), lda, 1.0, col(h1), ldb);
    else  // op(A) = U: the coupling block is U12 = A[:h1, h1:]
      gemm('N', 'N', m, h2, h1, -1.0, b, ldb, at(0, h1), lda, 1.0, col(h1), ldb);
    trsm(side, uplo, ta, diag, m, h2, at(h1, h1), lda, col(h1), ldb);
  } else {
    // L·X = B by row halves: X1, then B2 −= L21·X1, then X2
    trsm(side, uplo, ta, diag, h1, n, a, lda, b, ldb);
    gemm('N', 'N', h2, n, h1, -1.0, at(h1, 0), lda, b, ldb, 1.0, b + h1, ldb);
    trsm(side, uplo, ta, diag, h2, n, at(h1, h1), lda, b + h1, ldb);
  }
}

}  // namespace strata::numeric::cpu
