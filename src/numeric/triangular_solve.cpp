// strata — multifrontal triangular solves with the stored factor (Liu 1992, §6).
//
// Forward substitution visits the fronts children-first (front order is a postorder),
// backward substitution parents-first. For each front the right-hand sides of its rows
// are gathered into a dense m×nrhs block, so every front costs one TRSM and one GEMM
// whatever the number of right-hand sides (TRSV and GEMV for one, which read the panel
// once where TRSM and GEMM first copy it into their blocked layout; a large pivot block's
// TRSV by column blocks when BLAS has several threads, see trsv below). The three passes are
// exposed front by front so that the distributed solve (src/distributed) and the solve by
// subtrees (subtree_solve.cpp) run them over the fronts of their own.
//
//   LLᵀ / LDLᵀ:  forward  y_P = L11⁻¹ x_P,  x_R −= L21 y_P     (P: pivot rows, R: the rest)
//                diagonal y = D⁻¹ y (LDLᵀ; 1×1 and 2×2 blocks)
//                backward x_P = L11⁻ᵀ (y_P − L21ᵀ x_R)
//   LU:          forward  with the permuted pivot rows P′: y = L11⁻¹ x_P′, stored at the
//                column positions P; x_R −= L21 y
//                backward x_P = U11⁻¹ (y − U12 x_R)
#include <algorithm>
#include <vector>

#include "base/blas.hpp"
#include "numeric/cpu/small_dense.hpp"
#include "numeric/factor.hpp"

namespace strata::numeric {
namespace {

// TRSV of a large pivot block by columns blocks of kTrsvBlock: OpenBLAS's DTRSV runs on
// one thread whatever the number of BLAS threads, and on a large front (the top
// separators of a 3D problem) it then holds the solve to one core's memory bandwidth. A
// TRSV of each diagonal block and a GEMV for the rest of its block column (the GEMV on
// every BLAS thread) streams the same bytes. Used with more than one BLAS thread only
// (with one it is DTRSV's own blocking, no faster).
constexpr int kTrsvBlock = 256;
constexpr int kBlockedTrsvMin = 1024;  // pivots from which the blocked form is used

// Below this many multiply-adds an LU front's one-right-hand-side products and triangular
// solves run as the plain loops of cpu/small_dense.hpp: a multibody Newton matrix has
// thousands of fronts of a few dozen rows, where a BLAS call costs more than its arithmetic.
constexpr index_t kLoops = 1 << 15;

// x ← op(A)⁻¹ x for the k×k triangle A (leading dimension lda): "L","N" (forward, right-
// looking), "U","N" (backward, right-looking), "L","T" (backward, left-looking); `diag`
// "U" for a unit diagonal.
void trsv(const char* uplo, const char* trans, const char* diag, int k, const double* a, int lda,
          double* x) {
  const int inc = 1;
  if (k < kBlockedTrsvMin || openblas_get_num_threads() <= 1) {
    dtrsv_(uplo, trans, diag, &k, a, &lda, x, &inc);
    return;
  }
  const double one = 1.0, minus_one = -1.0;
  auto at = [&](int i, int j) { return a + static_cast<std::size_t>(j) * lda + i; };
  if (*uplo == 'L' && *trans == 'N') {
    for (int j = 0; j < k; j += kTrsvBlock) {
      const int w = std::min(kTrsvBlock, k - j), rest = k - j - w;
      dtrsv_("L", "N", diag, &w, at(j, j), &lda, x + j, &inc);
      if (rest > 0)
        dgemv_("N", &rest, &w, &minus_one, at(j + w, j), &lda, x + j, &inc, &one, x + j + w, &inc);
    }
    return;
  }
  for (int j = (k - 1) / kTrsvBlock * kTrsvBlock; j >= 0; j -= kTrsvBlock) {
    const int w = std::min(kTrsvBlock, k - j), rest = k - j - w;
    if (*uplo == 'U') {  // "U","N": solve the block, then the rows above it
      dtrsv_("U", "N", diag, &w, at(j, j), &lda, x + j, &inc);
      if (j > 0) dgemv_("N", &j, &w, &minus_one, at(0, j), &lda, x + j, &inc, &one, x, &inc);
    } else {  // "L","T": the rows below the block first, then the block
      if (rest > 0)
        dgemv_("T", &rest, &w, &minus_one, at(j + w, j), &lda, x + j + w, &inc, &one, x + j, &inc);
      dtrsv_("L", "T", diag, &w, at(j, j), &lda, x + j, &inc);
    }
  }
}

}  // namespace

void forward_front(const Analysis& an, const NumericFactor& fac, index_t f, double* x, index_t nrhs,
                   std::vector<double>& w) {
  forward_front(an, fac, f, x, nrhs, w, nullptr, nullptr, 0);
}

void forward_front(const Analysis& an, const NumericFactor& fac, index_t f, double* x, index_t nrhs,
                   std::vector<double>& w, const index_t* slots, double* delta, index_t ld_delta) {
  const auto& t = an.tree;
  const index_t n = an.n;
  const bool lu = fac.type == MatrixType::general;
  const bool ldlt = fac.type == MatrixType::symmetric_indefinite;
  const int nr = static_cast<int>(nrhs);
  const double one = 1.0, minus_one = -1.0;
  const index_t m = t.n_rows(f), k = t.n_pivots(f);
  if (k == 0) return;
  const index_t* prow = fac.rows.data() + t.row_offsets[f];  // pivot rows as factored
  const index_t* crow = t.rows_of(f);                        // column order
  const double* panel = fac.panels.data() + an.factor_layout.panel_offset[f];
  w.resize(static_cast<std::size_t>(m) * nrhs);
  // a row whose slot is set lives in delta (a subtree's updates of rows outside it)
  auto at = [&](index_t i, index_t r) -> double& {
    const index_t s = slots && i >= k ? slots[i] : -1;
    return s >= 0 ? delta[s + r * ld_delta] : x[prow[i] + r * n];
  };
  for (index_t r = 0; r < nrhs; ++r)
    for (index_t i = 0; i < m; ++i) w[i + r * m] = at(i, r);
  const int mi = static_cast<int>(m), ki = static_cast<int>(k), mk = mi - ki, inc = 1;
  const char* diag = (lu || ldlt) ? "U" : "N";
  if (nrhs == 1 && lu && k * k <= kLoops && (m - k) * k <= kLoops) {
    cpu::unit_lower_solve(k, panel, m, w.data());
    if (mk > 0) cpu::gemv_subtract(m - k, k, panel + k, m, w.data(), w.data() + k);
  } else if (nrhs == 1) {  // TRSV/GEMV read the panel once; TRSM/GEMM would copy it first
    trsv("L", "N", diag, ki, panel, mi, w.data());
    if (mk > 0)
      dgemv_("N", &mk, &ki, &minus_one, panel + k, &mi, w.data(), &inc, &one, w.data() + k, &inc);
  } else {
    dtrsm_("L", "L", "N", diag, &ki, &nr, &one, panel, &mi, w.data(), &mi);
    if (mk > 0)
      dgemm_("N", "N", &mk, &nr, &ki, &minus_one, panel + k, &mi, w.data(), &mi, &one, w.data() + k,
             &mi);
  }
  const index_t* out = lu ? crow : prow;
  for (index_t r = 0; r < nrhs; ++r) {
    for (index_t i = 0; i < k; ++i) x[out[i] + r * n] = w[i + r * m];
    for (index_t i = k; i < m; ++i) at(i, r) = w[i + r * m];
  }
}

void diagonal_front(const Analysis& an, const NumericFactor& fac, index_t f, double* x,
                    index_t nrhs) {
  if (fac.type != MatrixType::symmetric_indefinite) return;
  const auto& t = an.tree;
  const index_t n = an.n;
  const index_t k = t.n_pivots(f), p0 = t.first_pivot[f];
  const index_t* prow = fac.rows.data() + t.row_offsets[f];
  for (index_t i = 0; i < k; ++i) {
    const index_t p = p0 + i;
    if (fac.pivot_size[p] == 1) {
      for (index_t r = 0; r < nrhs; ++r) x[prow[i] + r * n] /= fac.d_diag[p];
    } else if (fac.pivot_size[p] == 2) {
      const double a = fac.d_diag[p], b = fac.d_off[p], d = fac.d_diag[p + 1];
      const double det = a * d - b * b;
      for (index_t r = 0; r < nrhs; ++r) {
        double& u = x[prow[i] + r * n];
        double& v = x[prow[i + 1] + r * n];
        const double uu = (d * u - b * v) / det, vv = (a * v - b * u) / det;
        u = uu;
        v = vv;
      }
    }
  }
}

void backward_front(const Analysis& an, const NumericFactor& fac, index_t f, double* x,
                    index_t nrhs, std::vector<double>& w) {
  const auto& t = an.tree;
  const index_t n = an.n;
  const bool lu = fac.type == MatrixType::general;
  const bool ldlt = fac.type == MatrixType::symmetric_indefinite;
  const int nr = static_cast<int>(nrhs);
  const double one = 1.0, minus_one = -1.0;
  const index_t m = t.n_rows(f), k = t.n_pivots(f);
  if (k == 0) return;
  const index_t* prow = fac.rows.data() + t.row_offsets[f];
  const index_t* crow = t.rows_of(f);
  const index_t* col = lu ? crow : prow;
  const double* panel = fac.panels.data() + an.factor_layout.panel_offset[f];
  w.resize(static_cast<std::size_t>(m) * nrhs);
  for (index_t r = 0; r < nrhs; ++r)
    for (index_t i = 0; i < m; ++i) w[i + r * m] = x[col[i] + r * n];
  const int mi = static_cast<int>(m), ki = static_cast<int>(k), mk = mi - ki, inc = 1;
  const bool one_rhs = nrhs == 1;  // TRSV/GEMV read the panel once; TRSM/GEMM copy it first
  // the plain loops where the pivot block has no zero pivot (upper_solve gives 0 there, the
  // BLAS an infinity, which the caller reports)
  bool loops = one_rhs && lu && k * k <= kLoops && (m - k) * k <= kLoops;
  for (index_t j = 0; loops && j < k; ++j) loops = panel[j * m + j] != 0.0;
  if (loops) {
    if (mk > 0) cpu::gemv_subtract(k, m - k, panel + m * k, k, w.data() + k, w.data());
    cpu::upper_solve(k, panel, m, w.data());
  } else if (lu) {
    if (mk > 0) {  // y −= U12 x_R, U12 is k×(m−k) with leading dimension k
      if (one_rhs)
        dgemv_("N", &ki, &mk, &minus_one, panel + m * k, &ki, w.data() + k, &inc, &one, w.data(),
               &inc);
      else
        dgemm_("N", "N", &ki, &nr, &mk, &minus_one, panel + m * k, &ki, w.data() + k, &mi, &one,
               w.data(), &mi);
    }
    if (one_rhs)
      trsv("U", "N", "N", ki, panel, mi, w.data());
    else
      dtrsm_("L", "U", "N", "N", &ki, &nr, &one, panel, &mi, w.data(), &mi);
  } else {
    const char* diag = ldlt ? "U" : "N";
    if (mk > 0) {
      if (one_rhs)
        dgemv_("T", &mk, &ki, &minus_one, panel + k, &mi, w.data() + k, &inc, &one, w.data(), &inc);
      else
        dgemm_("T", "N", &ki, &nr, &mk, &minus_one, panel + k, &mi, w.data() + k, &mi, &one,
               w.data(), &mi);
    }
    if (one_rhs)
      trsv("L", "T", diag, ki, panel, mi, w.data());
    else
      dtrsm_("L", "L", "T", diag, &ki, &nr, &one, panel, &mi, w.data(), &mi);
  }
  for (index_t r = 0; r < nrhs; ++r)
    for (index_t i = 0; i < k; ++i) x[col[i] + r * n] = w[i + r * m];
}

void solve_in_place(const Analysis& an, const NumericFactor& fac, double* x, index_t nrhs) {
  const auto& t = an.tree;
  std::vector<double> w;
  openblas_set_num_threads(1);
  for (index_t f = 0; f < t.n_fronts(); ++f) forward_front(an, fac, f, x, nrhs, w);
  for (index_t f = 0; f < t.n_fronts(); ++f) diagonal_front(an, fac, f, x, nrhs);
  for (index_t f = t.n_fronts() - 1; f >= 0; --f) backward_front(an, fac, f, x, nrhs, w);
}

}  // namespace strata::numeric
