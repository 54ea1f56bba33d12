// strata — dense partial factorizations of one front on the CPU (see dense_front.hpp).
//
// A front is an m×m column-major matrix F (leading dimension ld) whose first k
// rows/columns are fully summed. Each routine eliminates those k pivots and leaves the
// Schur complement (contribution block) S in F[k:m, k:m].
//
// Structure common to the three kernels. The pivot block F11 is factored first (with
// pivoting confined to it); the off-diagonal panel is then solved with one large TRSM, and
// the contribution block is formed with one large rank-k update whose inner dimension is k.
// This is the same arithmetic as a right-looking blocked factorization of the whole front
// that carries the trailing update through rows k..m-1 panel by panel, but it passes over
// F22 once instead of k/nb times and gives the GEMMs an inner dimension of k instead of nb,
// which is where almost all the flops of a front go. Small fronts (order ≤ kSmall*) are
// factored by plain right-looking loops instead, because for them the call overhead of
// BLAS dominates.
//
// LLᵀ. dpotrf on F11, dtrsm for L21 = F21 L11⁻ᵀ, dsyrk for S = F22 − L21 L21ᵀ. Returns the
// local index of the first pivot that is not positive (dpotrf's info − 1); PivotStats is
// then left untouched. log_abs_det accumulates log det(F11) = Σ log(L_jj²); every pivot
// counts as positive.
//
// LDLᵀ. Bunch–Kaufman partial pivoting with α = (1 + √17)/8 (Bunch & Kaufman 1977; Golub
// & Van Loan 4th ed. §4.4.4), restricted to the pivot block: the candidate search AND the
// magnitude tests (colmax, rowmax) use only rows/columns 0..k−1. The pivot sequence is
// thus the one Bunch–Kaufman chooses on F11 alone (the tests check it against dsytrf), with
// the same bound on element growth within F11; F21 plays no part, so nothing bounds L21 (a
// large F21 against a small pivot gives a large L21; Bunch–Kaufman does not bound |L11|
// either, only rook pivoting would). Pivots are never delayed — that is what static
// pivoting plus iterative refinement is for (Duff & Pralet 2007). A pivot block of order
// ≤ kBkUnblocked is factored by the unblocked right-looking loop; a larger one with a
// blocked left-looking-in-the-panel / right-looking-between-panels scheme in the manner of
// LAPACK's dsytrf/dlasyf (Anderson et al., LAPACK Users' Guide): a panel of kBkPanel
// columns is factored column by column against a workspace W = L·D of the panel, then the
// rest of F11 is updated by a lower-triangular rank-nb update. The symmetric interchanges
// are applied to whole rows and columns of the front restricted to indices < k; in
// particular the columns of F21 are permuted (F21 Pᵀ), rows ≥ k never move. Then
// W21 = F21 Pᵀ L11⁻ᵀ (one dtrsm, with the 2×2 off-diagonals of D temporarily zeroed),
// S = F22 − W21 D⁻¹ W21ᵀ (lower triangle, by a recursive split into GEMMs with small
// diagonal leaves) and L21 = W21 D⁻¹.
//   Static pivoting: if every entry of the candidate column within the pivot block, the
// diagonal included, is below static_pivot in magnitude, the step is a 1×1 pivot without
// interchange; any 1×1 pivot d with |d| < static_pivot is replaced by sign(d)·static_pivot
// (sign(0) = +) and counted in `perturbed`. A 2×2 pivot [a b; b c] is therefore only
// formed when |b| = colmax ≥ static_pivot, and the Bunch–Kaufman tests guarantee
// |ac| ≤ α²b², i.e. |det| ≥ (1 − α²)·b² ≥ 0.59·static_pivot²; it is never perturbed. A
// defensive check (|ac/b² − 1| < 1/4, or a NaN) falls back to a 1×1 pivot at the current
// column, which can only happen through rounding on pathological input.
//   Statistics: the inertia of D (a 2×2 block with det < 0 counts one positive and one
// negative eigenvalue, with det > 0 two of the sign of its diagonal), two_by_two, and
// log_abs_det/det_sign of det(D) = det(F11) (the symmetric permutation does not change it),
// all of the perturbed D.
//
// LU. Threshold partial pivoting restricted to the fully summed rows 0..k−1 (Golub & Van
// Loan §3.4; the threshold u as in Duff, Erisman & Reid §5.4): column j keeps its diagonal
// pivot when |a_jj| ≥ u·max_{j≤i<k} |a_ij|, else takes the largest of those entries, the
// first on ties (u = 1: partial pivoting). On a matrix whose matching put large entries on
// the diagonal, u < 1 lets most fronts keep the analysis's order with |L| ≤ 1/u in the
// fully summed rows, which the GPU's kernels exploit (they eliminate without interchanges
// and check that bound). Then the same static pivoting rule as 1×1 LDLᵀ pivots. F11 is factored by
// recursive column splitting (left half, TRSM + GEMM update of the right half, right half — the
// recursive formulation of LAPACK's dgetrf2; Toledo, SIAM J. Matrix Anal. Appl. 18, 1997),
// with unblocked dgetf2-like leaves of kLuLeaf
// columns. The row interchanges are then applied to F12 (whole rows 0..k−1 of the front
// move; rows ≥ k never do), U12 = L11⁻¹ P F12 and L21 = F21 U11⁻¹ by dtrsm, and
// S = F22 − L21 U12 by dgemm. log_abs_det = Σ log|u_jj| and det_sign = sign(Π u_jj) times
// the parity of the row interchanges, i.e. the sign of det(F11) (of the perturbed F11);
// the inertia counters are not meaningful for LU and are left alone, except `zero`.
//
// Zero pivots: with static_pivot > 0 no pivot is ever zero and the output is finite for
// finite input. static_pivot ≤ 0 switches static pivoting off; an exactly zero pivot (its
// column in the pivot block is then zero too) is counted in `zero`, sets det_sign to 0 and
// log_abs_det to −∞, and is inverted as 0 (pseudo-inverse): its columns of L11 and L21 are
// zero and it contributes nothing to S, so the output stays finite, but whatever F21/F12
// held in that column/row is dropped — the caller must treat the front as singular.
//
// Sizes are index_t; BLAS/LAPACK take 32-bit ints, so m and ld must fit in an int (checked,
// NotSupported otherwise). The number of OpenBLAS threads is the caller's business.
//
// Sources: J. R. Bunch and L. Kaufman, "Some stable methods for calculating inertia and
// solving symmetric linear systems", Math. Comp. 31 (1977); G. H. Golub and C. F. Van Loan,
// "Matrix Computations", 4th ed., §3.2–3.4 and §4.4; E. Anderson et al., "LAPACK Users'
// Guide", 3rd ed. (dsytrf/dlasyf, dgetrf); I. S. Duff and S. Pralet, "Towards stable mixed
// pivoting strategies for the sequential and parallel solution of sparse symmetric
// indefinite systems", SIAM J. Matrix Anal. Appl. 29 (2007). The code is written from these
// descriptions; none is copied from LAPACK or elsewhere.
#include "numeric/cpu/dense_front.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "numeric/cpu/dense_blas.hpp"
#include "numeric/static_pivot.hpp"
#include "strata/errors.hpp"

namespace strata::numeric::cpu {

namespace {

// Bunch–Kaufman's α = (1 + √17)/8, which minimises the element growth bound.
constexpr double kBkAlpha = 0.6403882032022076;
// Tuning constants below were chosen on one OpenBLAS thread (its generic and its SkylakeX
// kernels gave nearly the same crossovers): reasonable, not optimal.
// Fronts of at most this order are factored by plain right-looking loops (no BLAS calls).
constexpr index_t kSmallLlt = 24;
constexpr index_t kSmallLu = 24;
constexpr index_t kSmallLdlt = 40;
// Pivot blocks of LDLᵀ of at most this order are factored by the unblocked right-looking
// Bunch–Kaufman loop (then TRSM/GEMM for the rest of the front); larger ones by panels of
// kBkPanel columns.
constexpr index_t kBkUnblocked = 64;
constexpr index_t kBkPanel = 32;
// Diagonal blocks of at most this order end the recursive lower-triangular updates.
constexpr index_t kUpdateLeaf = 128;
// Column width of the unblocked leaves of the recursive LU.
constexpr index_t kLuLeaf = 8;
// Below this many multiply-adds a GEMM/GEMV-shaped update is done by loops.
constexpr index_t kLoopWork = 1024;

void check_front(index_t m, index_t k, index_t ld) {
  if (m < 0 || k < 0 || k > m || ld < m)
    throw InvalidInput("dense front: need 0 <= k <= m <= ld (m=" + std::to_string(m) +
                       ", k=" + std::to_string(k) + ", ld=" + std::to_string(ld) + ")");
  blas_int(m);
  blas_int(ld);
}

// y[0..m) −= A x, A m×n (lda), x with stride incx.
void gemv_sub(index_t m, index_t n, const double* a, index_t lda, const double* x, index_t incx,
              double* y) {
  if (m <= 0 || n <= 0) return;
  if (m * n <= kLoopWork) {
    for (index_t p = 0; p < n; ++p) {
      const double xp = x[p * incx];
      if (xp == 0.0) continue;
      const double* ap = a + p * lda;
      for (index_t i = 0; i < m; ++i) y[i] -= ap[i] * xp;
    }
    return;
  }
  const char tn = 'N';
  const double minus_one = -1.0, one = 1.0;
  const int im = blas_int(m), in = blas_int(n), ila = blas_int(lda), iinc = blas_int(incx);
  const int ione = 1;
  dgemv_(&tn, &im, &in, &minus_one, a, &ila, x, &iinc, &one, y, &ione);
}

// Lower triangle of C (n×n) −= A Bᵀ with A, B n×r: a diagonal leaf. The upper triangle of
// C is never written (the fronts' upper triangles are not ours to touch).
void lower_leaf(index_t n, index_t r, const double* a, index_t lda, const double* b, index_t ldb,
                double* c, index_t ldc, std::vector<double>& tmp) {
  if (n <= 0 || r <= 0) return;
  if (n * n * r <= 2 * kLoopWork) {
    for (index_t j = 0; j < n; ++j) {
      double* cj = c + j * ldc;
      for (index_t p = 0; p < r; ++p) {
        const double bjp = b[j + p * ldb];
        if (bjp == 0.0) continue;
        const double* ap = a + p * lda;
        for (index_t i = j; i < n; ++i) cj[i] -= ap[i] * bjp;
      }
    }
    return;
  }
  tmp.resize(static_cast<std::size_t>(n * n));
  gemm('N', 'T', n, n, r, 1.0, a, lda, b, ldb, 0.0, tmp.data(), n);
  for (index_t j = 0; j < n; ++j) {
    double* cj = c + j * ldc;
    const double* tj = tmp.data() + j * n;
    for (index_t i = j; i < n; ++i) cj[i] -= tj[i];
  }
}

// Recursive split of a lower-triangular update over the index range [lo, hi): the two
// diagonal halves recursively, and between them the off-diagonal block (rows [mid, hi),
// columns [lo, mid)) as one GEMM. leaf(lo, hi) handles a diagonal block; off(lo, mid, hi)
// the off-diagonal block. The order (first half, off-diagonal, second half) is part of
// the contract: the LDLᵀ contribution update relies on it.
template <class Leaf, class Off>
void split_lower(index_t lo, index_t hi, const Leaf& leaf, const Off& off) {
  if (hi - lo <= kUpdateLeaf) {
    leaf(lo, hi);
    return;
  }
  index_t mid = lo + ((hi - lo) / 2 + 7) / 8 * 8;  // keep blocks a multiple of 8 wide
  if (mid >= hi) mid = lo + (hi - lo) / 2;
  split_lower(lo, mid, leaf, off);
  off(lo, mid, hi);
  split_lower(mid, hi, leaf, off);
}

// Lower triangle of C (n×n) −= A Bᵀ, A and B n×r.
void lower_update(index_t n, index_t r, const double* a, index_t lda, const double* b, index_t ldb,
                  double* c, index_t ldc) {
  if (n <= 0 || r <= 0) return;
  std::vector<double> tmp;
  split_lower(
      0, n,
      [&](index_t lo, index_t hi) {
        lower_leaf(hi - lo, r, a + lo, lda, b + lo, ldb, c + lo + lo * ldc, ldc, tmp);
      },
      [&](index_t lo, index_t mid, index_t hi) {
        gemm('N', 'T', hi - mid, mid - lo, r, -1.0, a + mid, lda, b + lo, ldb, 1.0,
             c + mid + lo * ldc, ldc);
      });
}

// --- pivots and statistics ------------------------------------------------------------

// Static pivoting of one pivot (numeric/static_pivot.hpp).
double perturb(double d, double sp, PivotStats& st) {
  if (needs_static_pivot(d, sp)) {
    ++st.perturbed;
    return static_pivot_value(d, sp);
  }
  return d;
}

void count_pivot(double d, PivotStats& st, bool inertia) {
  if (d > 0) {
    if (inertia) ++st.positive;
  } else if (d < 0) {
    if (inertia) ++st.negative;
    st.det_sign = -st.det_sign;
  } else {
    ++st.zero;
    st.det_sign = 0;
  }
  st.log_abs_det += std::log(std::abs(d));
}

// Inverse of a symmetric 2×2 pivot [a b; b c], computed relative to the off-diagonal b
// (which Bunch–Kaufman makes the largest entry): with p = a/b, q = c/b, g = pq − 1,
// det = b² g and D⁻¹ = [q −1; −1 p] / (b g).
struct Pivot2 {
  double i11 = 0, i21 = 0, i22 = 0;
  double g = 0, b = 0, a = 0;
  bool ok = false;
};

Pivot2 pivot_2x2(double a, double b, double c) {
  Pivot2 v;
  v.a = a;
  v.b = b;
  const double p = a / b, q = c / b;
  v.g = p * q - 1.0;
  v.ok = std::abs(v.g) >= 0.25 && std::isfinite(v.g);  // BK guarantees |g| ≥ 1 − α² ≈ 0.59
  const double e = 1.0 / (b * v.g);
  v.i11 = e * q;
  v.i21 = -e;
  v.i22 = e * p;
  return v;
}

void count_2x2(const Pivot2& v, PivotStats& st) {
  ++st.two_by_two;
  if (v.g < 0) {  // det < 0: eigenvalues of opposite signs
    ++st.positive;
    ++st.negative;
    st.det_sign = -st.det_sign;
  } else if (v.a > 0) {  // det > 0 forces a·c > b² > 0: both eigenvalues have a's sign
    st.positive += 2;
  } else {
    st.negative += 2;
  }
  st.log_abs_det += 2.0 * std::log(std::abs(v.b)) + std::log(std::abs(v.g));
}

// The LDLᵀ pivot sequence: interchanges in the order they were applied, and D⁻¹ per
// pivot (inv[3j..3j+2] = {1/d, 0, 0} for a 1×1 pivot at j, {i11, i21, i22} for a 2×2 pivot
// starting at j).
struct LdltPivots {
  std::vector<std::pair<index_t, index_t>> swaps;
  std::vector<double> inv;
};

// dst (nr×k, ldd) = src (nr×k, lds) · D⁻¹.
void apply_dinv(index_t nr, index_t k, const double* src, index_t lds, double* dst, index_t ldd,
                const int* pivot_size, const std::vector<double>& inv) {
  for (index_t j = 0; j < k;) {
    const double* s1 = src + j * lds;
    double* d1 = dst + j * ldd;
    if (pivot_size[j] == 1) {
      const double v = inv[3 * j];
      for (index_t i = 0; i < nr; ++i) d1[i] = s1[i] * v;
      j += 1;
    } else {
      const double i11 = inv[3 * j], i21 = inv[3 * j + 1], i22 = inv[3 * j + 2];
      const double* s2 = s1 + lds;
      double* d2 = d1 + ldd;
      for (index_t i = 0; i < nr; ++i) {
        const double w1 = s1[i], w2 = s2[i];
        d1[i] = i11 * w1 + i21 * w2;
        d2[i] = i21 * w1 + i22 * w2;
      }
      j += 2;
    }
  }
}

// --- LDLᵀ: small fronts, right-looking on the whole front ------------------------------
// (Also used on the pivot block alone, with m = k, for moderate k.)

void ldlt_small(double* f, index_t m, index_t k, index_t ld, double sp, int* pivot_size,
                LdltPivots& piv, PivotStats& st) {
  auto A = [&](index_t i, index_t j) -> double& { return f[i + j * ld]; };
  index_t kk = 0;
  while (kk < k) {
    const double absakk = std::abs(A(kk, kk));
    double colmax = 0;
    index_t imax = -1;
    for (index_t i = kk + 1; i < k; ++i) {
      const double v = std::abs(A(i, kk));
      if (v > colmax) colmax = v, imax = i;
    }
    int kstep = 1;
    index_t kp = kk;
    Pivot2 p2;
    if (colmax > 0 && !(std::max(absakk, colmax) < sp) && !(absakk >= kBkAlpha * colmax)) {
      double rowmax = 0;
      for (index_t j = kk; j < imax; ++j) rowmax = std::max(rowmax, std::abs(A(imax, j)));
      for (index_t i = imax + 1; i < k; ++i) rowmax = std::max(rowmax, std::abs(A(i, imax)));
      if (absakk >= kBkAlpha * colmax * (colmax / rowmax)) {
        // 1×1 at kk
      } else if (std::abs(A(imax, imax)) >= kBkAlpha * rowmax) {
        kp = imax;
      } else {
        p2 = pivot_2x2(A(kk, kk), A(imax, kk), A(imax, imax));
        if (p2.ok) kstep = 2, kp = imax;
      }
    }
    const index_t ks = kk + kstep - 1;
    if (kp != ks) {  // symmetric interchange of ks and kp over the whole (lower) front
      for (index_t j = 0; j < ks; ++j) std::swap(A(ks, j), A(kp, j));
      std::swap(A(ks, ks), A(kp, kp));
      for (index_t i = ks + 1; i < kp; ++i) std::swap(A(i, ks), A(kp, i));
      for (index_t i = kp + 1; i < m; ++i) std::swap(A(i, ks), A(i, kp));
      piv.swaps.emplace_back(ks, kp);
    }
    if (kstep == 1) {
      const double d = perturb(A(kk, kk), sp, st);
      count_pivot(d, st, true);
      A(kk, kk) = d;
      const double inv = d != 0 ? 1.0 / d : 0.0;  // zero pivot: pseudo-inverse
      piv.inv[3 * kk] = inv;
      pivot_size[kk] = 1;
      double* w = &A(0, kk);
      for (index_t j = kk + 1; j < m; ++j) {
        const double lj = w[j] * inv;
        if (lj == 0.0) continue;
        double* cj = &A(0, j);
        for (index_t i = j; i < m; ++i) cj[i] -= w[i] * lj;
      }
      for (index_t i = kk + 1; i < m; ++i) w[i] *= inv;
    } else {
      count_2x2(p2, st);
      piv.inv[3 * kk] = p2.i11;
      piv.inv[3 * kk + 1] = p2.i21;
      piv.inv[3 * kk + 2] = p2.i22;
      pivot_size[kk] = pivot_size[kk + 1] = 2;
      double* w1 = &A(0, kk);
      double* w2 = &A(0, kk + 1);
      for (index_t j = kk + 2; j < m; ++j) {
        const double l1 = p2.i11 * w1[j] + p2.i21 * w2[j];
        const double l2 = p2.i21 * w1[j] + p2.i22 * w2[j];
        double* cj = &A(0, j);
        for (index_t i = j; i < m; ++i) cj[i] -= w1[i] * l1 + w2[i] * l2;
      }
      for (index_t i = kk + 2; i < m; ++i) {
        const double a1 = w1[i], a2 = w2[i];
        w1[i] = p2.i11 * a1 + p2.i21 * a2;
        w2[i] = p2.i21 * a1 + p2.i22 * a2;
      }
    }
    kk += kstep;
  }
}

// --- LDLᵀ: blocked Bunch–Kaufman on the pivot block F11 (k×k, lower) --------------------

void ldlt_pivot_block(double* a, index_t k, index_t ld, double sp, int* pivot_size, LdltPivots& piv,
                      PivotStats& st) {
  const index_t nb = kBkPanel;
  const index_t ldw = k;
  // W holds, for the current panel, the updated columns before division by D (W = L·D);
  // row r of W is row j0 + r of F11. One spare column receives the candidate column imax.
  std::vector<double> wbuf(static_cast<std::size_t>(ldw * (std::min(k, nb) + 1)));
  auto A = [&](index_t i, index_t j) -> double& { return a[i + j * ld]; };
  index_t j0 = 0;
  while (j0 < k) {
    const bool last = k - j0 <= nb;
    double* w = wbuf.data();
    auto W = [&](index_t r, index_t c) -> double& { return w[r + c * ldw]; };
    index_t kk = j0;
    while (kk < k && (last || kk - j0 < nb)) {
      const index_t c = kk - j0;  // panel column of kk, and W row of kk
      double* wc = &W(0, c);
      for (index_t i = kk; i < k; ++i) wc[i - j0] = A(i, kk);
      gemv_sub(k - kk, c, &A(kk, j0), ld, &W(c, 0), ldw, wc + c);

      const double absakk = std::abs(wc[c]);
      double colmax = 0;
      index_t imax = -1;
      for (index_t i = kk + 1; i < k; ++i) {
        const double v = std::abs(wc[i - j0]);
        if (v > colmax) colmax = v, imax = i;
      }
      int kstep = 1;
      index_t kp = kk;
      Pivot2 p2;
      if (colmax > 0 && !(std::max(absakk, colmax) < sp) && !(absakk >= kBkAlpha * colmax)) {
        // Updated column imax (= row imax of the symmetric trailing matrix) into W(:, c+1).
        double* wn = &W(0, c + 1);
        for (index_t i = kk; i < imax; ++i) wn[i - j0] = A(imax, i);
        for (index_t i = imax; i < k; ++i) wn[i - j0] = A(i, imax);
        gemv_sub(k - kk, c, &A(kk, j0), ld, &W(imax - j0, 0), ldw, wn + c);
        double rowmax = 0;
        for (index_t i = kk; i < k; ++i)
          if (i != imax) rowmax = std::max(rowmax, std::abs(wn[i - j0]));
        if (absakk >= kBkAlpha * colmax * (colmax / rowmax)) {
          // 1×1 at kk
        } else if (std::abs(wn[imax - j0]) >= kBkAlpha * rowmax) {
          kp = imax;
          for (index_t i = kk; i < k; ++i) wc[i - j0] = wn[i - j0];
        } else {
          p2 = pivot_2x2(wc[c], wc[imax - j0], wn[imax - j0]);
          if (p2.ok) kstep = 2, kp = imax;
        }
      }
      const index_t ks = kk + kstep - 1;
      if (kp != ks) {
        // The not yet updated trailing part (columns > kk; column kk is rewritten below).
        std::swap(A(ks, ks), A(kp, kp));
        for (index_t i = ks + 1; i < kp; ++i) std::swap(A(i, ks), A(kp, i));
        for (index_t i = kp + 1; i < k; ++i) std::swap(A(i, ks), A(i, kp));
        // Rows ks and kp of the finished columns of L (earlier panels and this one) and of W.
        for (index_t j = 0; j < kk; ++j) std::swap(A(ks, j), A(kp, j));
        for (index_t cc = 0; cc < c + kstep; ++cc) std::swap(W(ks - j0, cc), W(kp - j0, cc));
        piv.swaps.emplace_back(ks, kp);
      }
      if (kstep == 1) {
        const double d = perturb(wc[c], sp, st);
        count_pivot(d, st, true);
        wc[c] = d;
        A(kk, kk) = d;
        const double inv = d != 0 ? 1.0 / d : 0.0;  // zero pivot: pseudo-inverse
        piv.inv[3 * kk] = inv;
        pivot_size[kk] = 1;
        for (index_t i = kk + 1; i < k; ++i) A(i, kk) = wc[i - j0] * inv;
      } else {
        const double* wn = &W(0, c + 1);
        count_2x2(p2, st);
        piv.inv[3 * kk] = p2.i11;
        piv.inv[3 * kk + 1] = p2.i21;
        piv.inv[3 * kk + 2] = p2.i22;
        pivot_size[kk] = pivot_size[kk + 1] = 2;
        A(kk, kk) = wc[c];
        A(kk + 1, kk) = wc[c + 1];
        A(kk + 1, kk + 1) = wn[c + 1];
        for (index_t i = kk + 2; i < k; ++i) {
          const double w1 = wc[i - j0], w2 = wn[i - j0];
          A(i, kk) = p2.i11 * w1 + p2.i21 * w2;
          A(i, kk + 1) = p2.i21 * w1 + p2.i22 * w2;
        }
      }
      kk += kstep;
    }
    // Right-looking update of the rest of F11 by this panel: A22 −= L_panel W_panelᵀ.
    if (kk < k) lower_update(k - kk, kk - j0, &A(kk, j0), ld, &W(kk - j0, 0), ldw, &A(kk, kk), ld);
    j0 = kk;
  }
}

// --- LDLᵀ: off-diagonal panel and contribution block ------------------------------------

void ldlt_contribution(double* f, index_t m, index_t k, index_t ld, const int* pivot_size,
                       const LdltPivots& piv) {
  const index_t n = m - k;
  double* f21 = f + k;
  double* s = f + k + k * ld;
  // F21 Pᵀ: the symmetric interchanges move whole columns of F21.
  for (const auto& [p, q] : piv.swaps)
    std::swap_ranges(f21 + p * ld, f21 + p * ld + n, f21 + q * ld);
  // W21 = F21 Pᵀ L11⁻ᵀ. L11 is unit lower but F(j+1, j) of a 2×2 pivot holds D's
  // off-diagonal: zero it for the solve.
  std::vector<std::pair<index_t, double>> saved;
  for (index_t j = 0; j + 1 < k; ++j)
    if (pivot_size[j] == 2) {
      saved.emplace_back(j, f[j + 1 + j * ld]);
      f[j + 1 + j * ld] = 0.0;
      ++j;
    }
  trsm('R', 'L', 'T', 'U', n, k, f, ld, f21, ld);
  for (const auto& [j, v] : saved) f[j + 1 + j * ld] = v;
  // S −= W21 D⁻¹ W21ᵀ (lower). Leaves turn their rows of W21 into L21 = W21 D⁻¹ once
  // done; split_lower visits the first half, then the off-diagonal block (which reads L21
  // rows of the first half and W21 rows of the second), then the second half.
  std::vector<double> t(static_cast<std::size_t>(std::min(n, kUpdateLeaf) * k)), tmp;
  split_lower(
      0, n,
      [&](index_t lo, index_t hi) {
        const index_t nr = hi - lo;
        apply_dinv(nr, k, f21 + lo, ld, t.data(), nr, pivot_size, piv.inv);
        lower_leaf(nr, k, f21 + lo, ld, t.data(), nr, s + lo + lo * ld, ld, tmp);
        for (index_t j = 0; j < k; ++j)
          std::copy(t.data() + j * nr, t.data() + (j + 1) * nr, f21 + lo + j * ld);
      },
      [&](index_t lo, index_t mid, index_t hi) {
        gemm('N', 'T', hi - mid, mid - lo, k, -1.0, f21 + mid, ld, f21 + lo, ld, 1.0,
             s + mid + lo * ld, ld);
      });
}

// --- LU -------------------------------------------------------------------------------

// Applies the row interchanges ipiv[j0..j1) (row j ↔ row ipiv[j], in order) to columns
// [c0, c1) of a.
void row_swaps(double* a, index_t ld, const index_t* ipiv, index_t j0, index_t j1, index_t c0,
               index_t c1) {
  for (index_t c = c0; c < c1; ++c) {
    double* col = a + c * ld;
    for (index_t j = j0; j < j1; ++j)
      if (ipiv[j] != j) std::swap(col[j], col[ipiv[j]]);
  }
}

// Unblocked right-looking LU (dgetf2-like) of columns [c0, c1): the pivot of column j is
// its diagonal entry when that is at least u times the largest entry among the fully summed
// rows j..k−1, else the largest of them (threshold partial pivoting restricted to the fully
// summed rows; u = 1: partial pivoting), replaced by ±sp when tiny; row interchanges move
// columns [c0, c1); the multipliers are formed in rows j+1..row_end−1. Both the recursive
// leaves (row_end = k, columns of the pivot block) and whole small fronts (row_end = m,
// columns 0..m) use it, so the pivoting policy is written once.
void lu_unblocked(double* a, index_t k, index_t ld, index_t c0, index_t c1, index_t row_end,
                  double sp, double u, index_t* ipiv, int& parity, PivotStats& st) {
  auto A = [&](index_t i, index_t j) -> double& { return a[i + j * ld]; };
  for (index_t j = c0; j < std::min(c1, k); ++j) {
    index_t p = j;
    const double diag = std::abs(A(j, j));
    double vmax = diag;
    for (index_t i = j + 1; i < k; ++i) {
      const double v = std::abs(A(i, j));
      if (v > vmax) vmax = v, p = i;
    }
    if (diag >= u * vmax) p = j;
    ipiv[j] = p;
    if (p != j) {
      for (index_t c = c0; c < c1; ++c) std::swap(A(j, c), A(p, c));
      parity = -parity;
    }
    const double d = perturb(A(j, j), sp, st);
    count_pivot(d, st, false);
    A(j, j) = d;
    const double inv = d != 0 ? 1.0 / d : 0.0;  // zero pivot: pseudo-inverse
    double* lj = &A(0, j);
    for (index_t i = j + 1; i < row_end; ++i) lj[i] *= inv;
    for (index_t c = j + 1; c < c1; ++c) {
      const double u = A(j, c);
      if (u == 0.0) continue;
      double* col = &A(0, c);
      for (index_t i = j + 1; i < row_end; ++i) col[i] -= lj[i] * u;
    }
  }
}

// Recursive LU with partial pivoting of columns [c0, c1) of the k×k pivot block (rows
// c0..k−1), those columns being already updated by the columns before c0. Interchanges
// are applied to columns [c0, c1) only; the caller applies them elsewhere.
void lu_recursive(double* a, index_t k, index_t ld, index_t c0, index_t c1, double sp, double u,
                  index_t* ipiv, int& parity, PivotStats& st) {
  auto A = [&](index_t i, index_t j) -> double& { return a[i + j * ld]; };
  if (c1 - c0 <= kLuLeaf) {
    lu_unblocked(a, k, ld, c0, c1, k, sp, u, ipiv, parity, st);
    return;
  }
  index_t mid = c0 + ((c1 - c0) / 2 + kLuLeaf - 1) / kLuLeaf * kLuLeaf;
  if (mid >= c1) mid = c0 + (c1 - c0) / 2;
  lu_recursive(a, k, ld, c0, mid, sp, u, ipiv, parity, st);
  row_swaps(a, ld, ipiv, c0, mid, mid, c1);
  trsm('L', 'L', 'N', 'U', mid - c0, c1 - mid, &A(c0, c0), ld, &A(c0, mid), ld);
  gemm('N', 'N', k - mid, c1 - mid, mid - c0, -1.0, &A(mid, c0), ld, &A(c0, mid), ld, 1.0,
       &A(mid, mid), ld);
  lu_recursive(a, k, ld, mid, c1, sp, u, ipiv, parity, st);
  row_swaps(a, ld, ipiv, mid, c1, c0, mid);
}

// Small fronts: the unblocked elimination over the whole front (all m columns, all m rows).
void lu_small(double* f, index_t m, index_t k, index_t ld, double sp, double u, index_t* ipiv,
              int& parity, PivotStats& st) {
  lu_unblocked(f, k, ld, 0, m, m, sp, u, ipiv, parity, st);
}

}  // namespace

// --- public entry points ------------------------------------------------------------------

index_t factor_front_llt(double* f, index_t m, index_t k, index_t ld, PivotStats& stats) {
  check_front(m, k, ld);
  LowerPanels cb;
  cb.data = f + k + static_cast<std::size_t>(k) * ld;
  cb.n = m - k;
  cb.width = std::max<index_t>(m - k, 1);
  cb.ld = ld;
  return factor_front_llt(f, m, k, ld, cb, stats);
}

index_t factor_front_llt(double* panel, index_t m, index_t k, index_t ld, const LowerPanels& cb,
                         PivotStats& stats) {
  check_front(m, k, ld);
  const index_t n = m - k;
  if (cb.n != n || cb.width < 1 || (cb.width >= n && n > 0 && cb.ld < n))
    throw InternalError("factor_front_llt: contribution block storage does not match the front");
  if (k == 0) return -1;
  auto A = [&](index_t i, index_t j) -> double& { return panel[i + j * ld]; };
  double log_det = 0;
  if (m <= kSmallLlt) {
    for (index_t j = 0; j < k; ++j) {
      const double d = A(j, j);
      if (!(d > 0)) return j;
      log_det += std::log(d);
      const double l = std::sqrt(d);
      A(j, j) = l;
      const double inv = 1.0 / l;
      double* lj = &A(0, j);
      for (index_t i = j + 1; i < m; ++i) lj[i] *= inv;
      for (index_t c = j + 1; c < k; ++c) {  // the pivot columns still to come
        const double t = lj[c];
        if (t == 0.0) continue;
        double* col = &A(0, c);
        for (index_t i = c; i < m; ++i) col[i] -= lj[i] * t;
      }
      const double* l2 = lj + k;
      for (index_t c = 0; c < n; ++c) {  // the contribution block (its lower triangle)
        const double t = l2[c];
        if (t == 0.0) continue;
        double* d = cb.diag(c);  // d[i − c]: element (i, c), i ≥ c
        for (index_t i = c; i < n; ++i) d[i - c] -= l2[i] * t;
      }
    }
  } else {
    const char lo = 'L';
    const int ik = blas_int(k), ild = blas_int(ld);
    int info = 0;
    dpotrf_(&lo, &ik, panel, &ild, &info);
    if (info > 0) return info - 1;
    for (index_t j = 0; j < k; ++j) log_det += 2.0 * std::log(A(j, j));
    if (n > 0) {
      double* l21 = panel + k;
      trsm('R', 'L', 'T', 'N', n, k, panel, ld, l21, ld);
      const char tn = 'N', tt = 'T';
      const double minus_one = -1.0, one = 1.0;
      for (index_t p = 0; p < cb.panels(); ++p) {  // S = F22 − L21 L21ᵀ, panel by panel
        const index_t j0 = cb.panel_first(p), w = cb.panel_columns(p), below = n - j0 - w;
        double* c = cb.panel(p);
        const int iw = blas_int(w), ildc = blas_int(cb.panel_ld(p));
        dsyrk_(&lo, &tn, &iw, &ik, &minus_one, l21 + j0, &ild, &one, c, &ildc);
        if (below > 0) {
          const int ib = blas_int(below);
          dgemm_(&tn, &tt, &ib, &iw, &ik, &minus_one, l21 + j0 + w, &ild, l21 + j0, &ild, &one,
                 c + w, &ildc);
        }
      }
    }
  }
  stats.positive += k;
  stats.log_abs_det += log_det;
  return -1;
}

void factor_front_ldlt(double* f, index_t m, index_t k, index_t ld, double static_pivot,
                       index_t* local_perm, int* pivot_size, PivotStats& stats) {
  check_front(m, k, ld);
  if (k == 0) return;
  LdltPivots piv;
  piv.inv.assign(static_cast<std::size_t>(3 * k), 0.0);
  if (m <= kSmallLdlt) {
    ldlt_small(f, m, k, ld, static_pivot, pivot_size, piv, stats);
  } else {
    if (k <= kBkUnblocked)
      ldlt_small(f, k, k, ld, static_pivot, pivot_size, piv, stats);  // F11 only
    else
      ldlt_pivot_block(f, k, ld, static_pivot, pivot_size, piv, stats);
    if (m > k) ldlt_contribution(f, m, k, ld, pivot_size, piv);
  }
  for (index_t i = 0; i < k; ++i) local_perm[i] = i;
  for (const auto& [p, q] : piv.swaps) std::swap(local_perm[p], local_perm[q]);
}

void ldlt_stats_from_d(index_t k, const double* d_diag, const double* d_off, const int* pivot_size,
                       PivotStats& stats) {
  for (index_t j = 0; j < k; ++j) {
    if (pivot_size[j] == 2 && j + 1 < k) {
      count_2x2(pivot_2x2(d_diag[j], d_off[j], d_diag[j + 1]), stats);
      ++j;
    } else {
      count_pivot(d_diag[j], stats, true);
    }
  }
}

void factor_front_lu(double* f, index_t m, index_t k, index_t ld, double static_pivot,
                     double threshold, index_t* local_perm, PivotStats& stats) {
  check_front(m, k, ld);
  if (!(threshold > 0 && threshold <= 1))
    throw InvalidInput("factor_front_lu: the pivot threshold must be in (0, 1], not " +
                       std::to_string(threshold));
  if (k == 0) return;
  std::vector<index_t> ipiv(static_cast<std::size_t>(k));
  int parity = 1;
  if (m <= kSmallLu) {
    lu_small(f, m, k, ld, static_pivot, threshold, ipiv.data(), parity, stats);
  } else {
    const index_t zeros_before = stats.zero;
    lu_recursive(f, k, ld, 0, k, static_pivot, threshold, ipiv.data(), parity, stats);
    const index_t n = m - k;
    if (n > 0) {
      row_swaps(f, ld, ipiv.data(), 0, k, k, m);              // P F12
      trsm('L', 'L', 'N', 'U', k, n, f, ld, f + k * ld, ld);  // U12 = L11⁻¹ P F12
      // L21 = F21 U11⁻¹. A zero pivot (static_pivot ≤ 0 only) is inverted as 0: an
      // infinite diagonal makes the solve divide by it giving 0, a zero column of L21.
      std::vector<index_t> zero_diag;
      if (stats.zero != zeros_before)
        for (index_t j = 0; j < k; ++j)
          if (f[j + j * ld] == 0.0) {
            zero_diag.push_back(j);
            f[j + j * ld] = std::numeric_limits<double>::infinity();
          }
      trsm('R', 'U', 'N', 'N', n, k, f, ld, f + k, ld);
      for (index_t j : zero_diag) f[j + j * ld] = 0.0;
      gemm('N', 'N', n, n, k, -1.0, f + k, ld, f + k * ld, ld, 1.0,  // S = F22 − L21 U12
           f + k + k * ld, ld);
    }
  }
  stats.det_sign *= parity;
  for (index_t i = 0; i < k; ++i) local_perm[i] = i;
  for (index_t j = 0; j < k; ++j) std::swap(local_perm[j], local_perm[ipiv[j]]);
}

}  // namespace strata::numeric::cpu
