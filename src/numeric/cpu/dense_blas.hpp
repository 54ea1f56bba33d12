// strata — thin BLAS wrappers for the dense front kernels: index_t in, the 32-bit BLAS
// interface checked, nothing called for empty shapes. Shared by dense_front.cpp and
// delayed_front.cpp.
#pragma once

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

/// B = op(A)⁻¹·B or B·op(A)⁻¹ (dtrsm with alpha 1); nothing for an empty shape.
inline void trsm(char side, char uplo, char ta, char diag, index_t m, index_t n, const double* a,
                 index_t lda, double* b, index_t ldb) {
  if (m <= 0 || n <= 0) return;
  const double one = 1.0;
  const int im = blas_int(m), in = blas_int(n), ila = blas_int(lda), ilb = blas_int(ldb);
  dtrsm_(&side, &uplo, &ta, &diag, &im, &in, &one, a, &ila, b, &ilb);
}

}  // namespace strata::numeric::cpu
