// Tests of the dense partial factorizations of one front (numeric/cpu/dense_front).
//
// Every factorization is checked against the original front by reconstruction (products
// computed here with dgemm from the factors the kernel left in the front), and the
// contribution block against an independent dense Schur complement
// S_ref = F22 − F21 F11⁻¹ F12 computed with LAPACK's dgesv. Inertia and determinants are
// checked against dsyev eigenvalues (symmetric) or dgetrf (LU). Inputs are fresh random
// fronts; the seed is printed on failure.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <tuple>
#include <vector>

#include "base/blas.hpp"
#include "numeric/cpu/dense_blas.hpp"
#include "numeric/cpu/dense_front.hpp"
#include "strata/errors.hpp"
#include "support/test_support.hpp"

namespace strata::numeric::cpu {
namespace {

constexpr double kSentinel = 12345.25;  // upper triangle / padding, must stay untouched

// A dense column-major matrix.
struct Mat {
  index_t rows = 0, cols = 0;
  std::vector<double> v;
  Mat() = default;
  Mat(index_t r, index_t c) : rows(r), cols(c), v(static_cast<std::size_t>(r * c), 0.0) {}
  double& operator()(index_t i, index_t j) { return v[i + j * rows]; }
  double operator()(index_t i, index_t j) const { return v[i + j * rows]; }
};

// op(a)·op(b) with dgemm.
Mat mul(const Mat& a, const Mat& b, char ta = 'N', char tb = 'N') {
  const index_t m = ta == 'N' ? a.rows : a.cols;
  const index_t kk = ta == 'N' ? a.cols : a.rows;
  const index_t n = tb == 'N' ? b.cols : b.rows;
  Mat c(m, n);
  if (m == 0 || n == 0 || kk == 0) return c;
  const int im = static_cast<int>(m), in = static_cast<int>(n), ik = static_cast<int>(kk);
  const int lda = static_cast<int>(std::max<index_t>(a.rows, 1));
  const int ldb = static_cast<int>(std::max<index_t>(b.rows, 1));
  const double one = 1.0, zero = 0.0;
  dgemm_(&ta, &tb, &im, &in, &ik, &one, a.v.data(), &lda, b.v.data(), &ldb, &zero, c.v.data(), &im);
  return c;
}

Mat abs_of(Mat a) {
  for (double& x : a.v) x = std::abs(x);
  return a;
}

Mat block(const Mat& a, index_t r0, index_t r1, index_t c0, index_t c1) {
  Mat b(r1 - r0, c1 - c0);
  for (index_t j = c0; j < c1; ++j)
    for (index_t i = r0; i < r1; ++i) b(i - r0, j - c0) = a(i, j);
  return b;
}

double fro(const Mat& a) {
  double s = 0;
  for (double x : a.v) s += x * x;
  return std::sqrt(s);
}

// ‖x − y‖_F over all entries, or over the lower triangle only.
double diff(const Mat& x, const Mat& y, bool lower_only = false) {
  double s = 0;
  for (index_t j = 0; j < x.cols; ++j)
    for (index_t i = lower_only ? j : 0; i < x.rows; ++i) {
      const double d = x(i, j) - y(i, j);
      s += d * d;
    }
  return std::sqrt(s);
}

bool all_finite(const Mat& a) {
  return std::all_of(a.v.begin(), a.v.end(), [](double x) { return std::isfinite(x); });
}

// --- random fronts -------------------------------------------------------------------------

enum class Kind { spd, indefinite, general };

Mat random_front(index_t m, Kind kind, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Mat f(m, m);
  if (kind == Kind::general) {
    for (double& x : f.v) x = u(rng);
    return f;
  }
  if (kind == Kind::spd) {  // B Bᵀ/m + I/4: well conditioned, dense
    Mat b(m, m);
    for (double& x : b.v) x = u(rng);
    f = mul(b, b, 'N', 'T');
    for (double& x : f.v) x /= static_cast<double>(m);
    for (index_t i = 0; i < m; ++i) f(i, i) += 0.25;
    return f;
  }
  // Symmetric indefinite, with some zero diagonal entries.
  std::uniform_int_distribution<int> coin(0, 4);
  for (index_t j = 0; j < m; ++j)
    for (index_t i = j; i < m; ++i) f(i, j) = f(j, i) = u(rng);
  for (index_t j = 0; j < m; ++j)
    if (coin(rng) == 0) f(j, j) = 0.0;
  return f;
}

// KKT-like pivot block [[0, B], [Bᵀ, H]] (zero block first, H small) inside a random
// symmetric front: Bunch–Kaufman needs 2×2 pivots on it.
Mat kkt_front(index_t m, index_t n_con, index_t n_var, std::mt19937_64& rng) {
  Mat f = random_front(m, Kind::indefinite, rng);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const index_t k = n_con + n_var;
  for (index_t j = 0; j < k; ++j)
    for (index_t i = j; i < k; ++i) {
      double v = 0;
      if (i >= n_con && j < n_con) v = u(rng);          // B (rows con, cols var)
      if (i >= n_con && j >= n_con) v = 0.01 * u(rng);  // H
      f(i, j) = f(j, i) = v;
    }
  return f;
}

// The front as the kernel sees it: ld = m + pad; symmetric kinds get only the lower
// triangle, the strict upper triangle and the padding hold kSentinel.
std::vector<double> pack(const Mat& f, index_t ld, bool lower) {
  const index_t m = f.rows;
  std::vector<double> buf(static_cast<std::size_t>(ld * std::max<index_t>(m, 1)), kSentinel);
  for (index_t j = 0; j < m; ++j)
    for (index_t i = lower ? j : 0; i < m; ++i) buf[i + j * ld] = f(i, j);
  return buf;
}

Mat unpack(const std::vector<double>& buf, index_t m, index_t ld) {
  Mat f(m, m);
  for (index_t j = 0; j < m; ++j)
    for (index_t i = 0; i < m; ++i) f(i, j) = buf[i + j * ld];
  return f;
}

void expect_untouched(const std::vector<double>& buf, index_t m, index_t ld, bool lower) {
  index_t bad = 0;
  for (index_t j = 0; j < m; ++j) {
    for (index_t i = m; i < ld; ++i) bad += buf[i + j * ld] != kSentinel;
    if (lower)
      for (index_t i = 0; i < j; ++i) bad += buf[i + j * ld] != kSentinel;
  }
  EXPECT_EQ(bad, 0) << "entries outside the referenced part of the front were written";
}

constexpr double kRecTol = 1e-13;   // reconstruction, normwise relative (scaled by k below)
constexpr double kSchurTol = 1e-9;  // S against the dgesv reference

double norm1(const Mat& a) {
  double n = 0;
  for (index_t j = 0; j < a.cols; ++j) {
    double c = 0;
    for (index_t i = 0; i < a.rows; ++i) c += std::abs(a(i, j));
    n = std::max(n, c);
  }
  return n;
}

// S_ref = F22 − F21 F11⁻¹ F12 with dgesv; the scale ‖F22‖ + ‖F21‖‖F11⁻¹F12‖; and the
// tolerance relative to that scale. F11⁻¹F12 is known to about u·κ(F11) relative to its
// norm on either side (Higham, Accuracy and Stability, §7.1), so a fixed tolerance fails
// on the odd random F11 of large κ: the tolerance is kSchurTol or 10·k·u·κ₁(F11), the
// larger (κ₁ from the explicit inverse; k ≤ a few hundred here).
Mat schur_reference(const Mat& f, index_t k, double* scale, double* tol) {
  const index_t m = f.rows, n = m - k;
  Mat f11 = block(f, 0, k, 0, k), f12 = block(f, 0, k, k, m);
  Mat f21 = block(f, k, m, 0, k), f22 = block(f, k, m, k, m);
  *tol = kSchurTol;
  if (k == 0) {
    *scale = fro(f22);
    return f22;
  }
  // one solve for [F12 I]: F11⁻¹F12 and F11⁻¹
  std::vector<double> x = f12.v;
  x.resize(static_cast<std::size_t>(k * (n + k)), 0.0);
  for (index_t i = 0; i < k; ++i) x[static_cast<std::size_t>(k * (n + i) + i)] = 1.0;
  EXPECT_TRUE(test::dense_solve(f11.v, k, x, n + k)) << "reference F11 is singular";
  Mat inv(k, k);
  inv.v.assign(x.begin() + k * n, x.end());
  const double kappa = norm1(f11) * norm1(inv);
  *tol = std::max(kSchurTol,
                  10.0 * static_cast<double>(k) * std::numeric_limits<double>::epsilon() * kappa);
  Mat xm(k, n);
  xm.v.assign(x.begin(), x.begin() + k * n);
  Mat p = mul(f21, xm);
  Mat s = f22;
  for (std::size_t i = 0; i < s.v.size(); ++i) s.v[i] -= p.v[i];
  *scale = fro(f22) + fro(f21) * fro(xm);
  return s;
}

std::vector<double> eigenvalues(const Mat& a) {
  const int n = static_cast<int>(a.rows);
  std::vector<double> w(a.rows), tmp = a.v;
  if (n == 0) return w;
  const char jobz = 'N', uplo = 'L';
  int lwork = -1, info = 0;
  double q = 0;
  dsyev_(&jobz, &uplo, &n, tmp.data(), &n, w.data(), &q, &lwork, &info);
  lwork = static_cast<int>(q);
  std::vector<double> work(static_cast<std::size_t>(lwork));
  dsyev_(&jobz, &uplo, &n, tmp.data(), &n, w.data(), work.data(), &lwork, &info);
  EXPECT_EQ(info, 0);
  return w;
}

double rec_tol(index_t k) { return kRecTol * std::max<double>(1.0, std::sqrt(double(k))); }

bool is_permutation_of_k(const std::vector<index_t>& p, index_t k) {
  std::vector<char> seen(static_cast<std::size_t>(k), 0);
  for (index_t x : p) {
    if (x < 0 || x >= k || seen[x]) return false;
    seen[x] = 1;
  }
  return true;
}

// --- LLᵀ ---------------------------------------------------------------------------------

void run_llt(index_t m, index_t k, std::mt19937_64& rng) {
  SCOPED_TRACE(testing::Message() << "LLt m=" << m << " k=" << k);
  const Mat f = random_front(m, Kind::spd, rng);
  const index_t ld = m + 3;
  std::vector<double> buf = pack(f, ld, true);
  PivotStats st;
  ASSERT_EQ(factor_front_llt(buf.data(), m, k, ld, st), -1);
  expect_untouched(buf, m, ld, true);
  const Mat out = unpack(buf, m, ld);
  Mat l11 = block(out, 0, k, 0, k), l21 = block(out, k, m, 0, k), s = block(out, k, m, k, m);
  for (index_t j = 0; j < k; ++j)
    for (index_t i = 0; i < j; ++i) l11(i, j) = 0;
  const Mat f11 = block(f, 0, k, 0, k), f21 = block(f, k, m, 0, k), f22 = block(f, k, m, k, m);
  const double tol = rec_tol(k);
  EXPECT_LE(diff(mul(l11, l11, 'N', 'T'), f11, true), tol * fro(f11));
  EXPECT_LE(diff(mul(l21, l11, 'N', 'T'), f21), tol * (fro(f21) + fro(l21) * fro(l11)));
  Mat s_plus = mul(l21, l21, 'N', 'T');
  for (std::size_t i = 0; i < s_plus.v.size(); ++i) s_plus.v[i] += s.v[i];
  EXPECT_LE(diff(s_plus, f22, true), tol * (fro(f22) + fro(l21) * fro(l21)));
  if (m > k) {
    double scale = 0, schur_tol = 0;
    const Mat s_ref = schur_reference(f, k, &scale, &schur_tol);
    EXPECT_LE(diff(s, s_ref, true), schur_tol * scale);
  }
  EXPECT_EQ(st.positive, k);
  EXPECT_EQ(st.negative + st.zero + st.perturbed, 0);
  double logdet = 0;
  for (double w : eigenvalues(f11)) logdet += std::log(w);
  EXPECT_NEAR(st.log_abs_det, logdet, 1e-10 * std::max(1.0, std::abs(logdet)));
  EXPECT_EQ(st.det_sign, 1);
}

// The split LLᵀ (panel in one buffer, the contribution block in lower panels of `width`
// columns): L against the whole-front kernel, S against the dense Schur complement, and
// the storage's positions that hold no element left alone.
void run_llt_split(index_t m, index_t k, index_t width, std::mt19937_64& rng) {
  SCOPED_TRACE(testing::Message() << "split LLt m=" << m << " k=" << k << " width=" << width);
  const Mat f = random_front(m, Kind::spd, rng);
  const index_t n = m - k, ld = m + 2;
  std::vector<double> panel(static_cast<std::size_t>(ld) * std::max<index_t>(k, 1), kSentinel);
  for (index_t j = 0; j < k; ++j)
    for (index_t i = 0; i < m; ++i) panel[i + j * ld] = i >= j ? f(i, j) : 0.0;
  std::vector<double> store(LowerPanels::size(n, width) + 1, kSentinel);
  const LowerPanels cb{store.data(), n, width, n};
  std::vector<char> is_element(store.size(), 0);
  for (index_t j = 0; j < n; ++j)
    for (index_t i = j; i < n; ++i) {
      double* e = cb.diag(j) + (i - j);
      ASSERT_GE(e, store.data());
      ASSERT_LT(e, store.data() + store.size() - 1) << "element (" << i << ", " << j << ")";
      ASSERT_FALSE(is_element[e - store.data()]) << "two elements share a place";
      is_element[e - store.data()] = 1;
      *e = f(k + i, k + j);
    }
  PivotStats st;
  ASSERT_EQ(factor_front_llt(panel.data(), m, k, ld, cb, st), -1);
  for (std::size_t p = 0; p < store.size(); ++p)
    if (!is_element[p]) ASSERT_EQ(store[p], kSentinel) << "place " << p << " written";

  std::vector<double> whole = pack(f, m, true);
  PivotStats st_whole;
  ASSERT_EQ(factor_front_llt(whole.data(), m, k, m, st_whole), -1);
  double lmax = 0, ldiff = 0;
  for (index_t j = 0; j < k; ++j)
    for (index_t i = j; i < m; ++i) {
      lmax = std::max(lmax, std::abs(whole[i + j * m]));
      ldiff = std::max(ldiff, std::abs(panel[i + j * ld] - whole[i + j * m]));
    }
  EXPECT_LE(ldiff, 64 * std::numeric_limits<double>::epsilon() * std::max(lmax, 1.0));
  EXPECT_EQ(st.positive, st_whole.positive);
  EXPECT_NEAR(st.log_abs_det, st_whole.log_abs_det,
              1e-12 * std::max(1.0, std::abs(st.log_abs_det)));
  if (n > 0) {
    double scale = 0, schur_tol = 0;
    const Mat s_ref = schur_reference(f, k, &scale, &schur_tol);
    double worst = 0;
    for (index_t j = 0; j < n; ++j)
      for (index_t i = j; i < n; ++i)
        worst = std::max(worst, std::abs(cb.diag(j)[i - j] - s_ref(i, j)));
    EXPECT_LE(worst, schur_tol * scale);
  }
}

// --- LDLᵀ ----------------------------------------------------------------------------------

struct LdltResult {
  PivotStats st;
  std::vector<index_t> perm;
  std::vector<int> psize;
  Mat out;  // the front after factorization (full square; upper triangle = sentinel)
};

LdltResult factor_ldlt(const Mat& f, index_t k, double sp) {
  const index_t m = f.rows, ld = m + 2;
  std::vector<double> buf = pack(f, ld, true);
  LdltResult r;
  r.perm.assign(static_cast<std::size_t>(k), -7);
  r.psize.assign(static_cast<std::size_t>(k), 0);
  factor_front_ldlt(buf.data(), m, k, ld, sp, r.perm.data(), r.psize.data(), r.st);
  expect_untouched(buf, m, ld, true);
  r.out = unpack(buf, m, ld);
  return r;
}

// Checks the LDLᵀ identities; `perturb_tol` allows the (known) static perturbations.
void check_ldlt(const Mat& f, index_t k, const LdltResult& r, bool check_schur,
                double perturb_tol = 0) {
  const index_t m = f.rows;
  ASSERT_TRUE(is_permutation_of_k(r.perm, k)) << "local_perm is not a permutation of 0..k-1";
  // pivot_size: 1, or 2 in consecutive pairs
  index_t twos = 0;
  for (index_t j = 0; j < k;) {
    if (r.psize[j] == 1) {
      ++j;
    } else {
      ASSERT_EQ(r.psize[j], 2);
      ASSERT_LT(j + 1, k);
      ASSERT_EQ(r.psize[j + 1], 2);
      ++twos;
      j += 2;
    }
  }
  EXPECT_EQ(twos, r.st.two_by_two);
  Mat l11(k, k), d(k, k);
  for (index_t j = 0; j < k; ++j) {
    l11(j, j) = 1;
    for (index_t i = j + 1; i < k; ++i) l11(i, j) = r.out(i, j);
  }
  for (index_t j = 0; j < k;) {
    d(j, j) = r.out(j, j);
    if (r.psize[j] == 2) {
      d(j + 1, j) = d(j, j + 1) = r.out(j + 1, j);
      d(j + 1, j + 1) = r.out(j + 1, j + 1);
      l11(j + 1, j) = 0;
      j += 2;
    } else {
      ++j;
    }
  }
  Mat pf11(k, k), f21p(m - k, k);
  for (index_t j = 0; j < k; ++j) {
    for (index_t i = 0; i < k; ++i) pf11(i, j) = f(r.perm[i], r.perm[j]);
    for (index_t i = k; i < m; ++i) f21p(i - k, j) = f(i, r.perm[j]);  // rows ≥ k unmoved
  }
  const Mat l21 = block(r.out, k, m, 0, k), s = block(r.out, k, m, k, m);
  const Mat f22 = block(f, k, m, k, m);
  EXPECT_TRUE(all_finite(l11) && all_finite(d) && all_finite(l21));

  const double tol = rec_tol(k);
  const Mat ld11 = mul(l11, d);
  const Mat ald = mul(abs_of(l11), abs_of(d));
  EXPECT_LE(diff(mul(ld11, l11, 'N', 'T'), pf11, true),
            tol * (fro(pf11) + fro(mul(ald, abs_of(l11), 'N', 'T'))) + perturb_tol);
  const Mat l21d = mul(l21, d);
  if (m > k) {
    EXPECT_LE(diff(mul(l21d, l11, 'N', 'T'), f21p),
              tol * (fro(f21p) + fro(mul(mul(abs_of(l21), abs_of(d)), abs_of(l11), 'N', 'T'))) +
                  perturb_tol * fro(l21));
    Mat s_plus = mul(l21d, l21, 'N', 'T');
    for (std::size_t i = 0; i < s_plus.v.size(); ++i) s_plus.v[i] += s.v[i];
    EXPECT_LE(diff(s_plus, f22, true),
              tol * (fro(f22) + fro(mul(mul(abs_of(l21), abs_of(d)), abs_of(l21), 'N', 'T'))));
  }
  if (check_schur && m > k) {
    double scale = 0, schur_tol = 0;
    const Mat s_ref = schur_reference(f, k, &scale, &schur_tol);
    EXPECT_LE(diff(s, s_ref, true), schur_tol * scale);
  }
}

void check_inertia(const Mat& f, index_t k, const PivotStats& st) {
  index_t pos = 0, neg = 0;
  double logdet = 0;
  int sign = 1;
  for (double w : eigenvalues(block(f, 0, k, 0, k))) {
    (w > 0 ? pos : neg) += 1;
    if (w < 0) sign = -sign;
    logdet += std::log(std::abs(w));
  }
  EXPECT_EQ(st.positive, pos);
  EXPECT_EQ(st.negative, neg);
  EXPECT_EQ(st.zero, 0);
  EXPECT_EQ(st.det_sign, sign);
  EXPECT_NEAR(st.log_abs_det, logdet, 1e-9 * std::max(1.0, std::abs(logdet)));
}

// Restricted pivoting only looks at F11, so the pivot sequence must be the one LAPACK's
// dsytrf (Bunch–Kaufman, lower) chooses on F11 alone. (Decisions could differ only for
// values within rounding of a threshold — negligible for random input.)
void check_same_pivots_as_dsytrf(const Mat& f, index_t k, const LdltResult& r) {
  if (k == 0) return;
  Mat a = block(f, 0, k, 0, k);
  const int n = static_cast<int>(k);
  const char uplo = 'L';
  std::vector<int> ipiv(static_cast<std::size_t>(k));
  int lwork = -1, info = 0;
  double q = 0;
  dsytrf_(&uplo, &n, a.v.data(), &n, ipiv.data(), &q, &lwork, &info);
  lwork = std::max(1, static_cast<int>(q));
  std::vector<double> work(static_cast<std::size_t>(lwork));
  dsytrf_(&uplo, &n, a.v.data(), &n, ipiv.data(), work.data(), &lwork, &info);
  ASSERT_GE(info, 0);
  std::vector<index_t> perm(static_cast<std::size_t>(k));
  std::vector<int> psize(static_cast<std::size_t>(k));
  for (index_t i = 0; i < k; ++i) perm[i] = i;
  for (index_t j = 0; j < k;) {
    if (ipiv[j] > 0) {
      std::swap(perm[j], perm[ipiv[j] - 1]);
      psize[j] = 1;
      j += 1;
    } else {
      std::swap(perm[j + 1], perm[-ipiv[j] - 1]);
      psize[j] = psize[j + 1] = 2;
      j += 2;
    }
  }
  EXPECT_EQ(r.psize, psize) << "pivot sizes differ from dsytrf on F11";
  EXPECT_EQ(r.perm, perm) << "pivot order differs from dsytrf on F11";
}

void run_ldlt(index_t m, index_t k, std::mt19937_64& rng) {
  SCOPED_TRACE(testing::Message() << "LDLt m=" << m << " k=" << k);
  Mat f = random_front(m, Kind::indefinite, rng);
  if (k == 1 && f(0, 0) == 0.0) f(0, 0) = -0.5;  // a 1×1 pivot block must not be singular
  const LdltResult r = factor_ldlt(f, k, 0.0);
  check_ldlt(f, k, r, true);
  EXPECT_EQ(r.st.perturbed, 0);
  check_inertia(f, k, r.st);
  check_same_pivots_as_dsytrf(f, k, r);
}

// --- LU ------------------------------------------------------------------------------------

struct LuResult {
  PivotStats st;
  std::vector<index_t> perm;
  Mat out;
};

LuResult factor_lu(const Mat& f, index_t k, double sp, double u = 1.0) {
  const index_t m = f.rows, ld = m + 1;
  std::vector<double> buf = pack(f, ld, false);
  LuResult r;
  r.perm.assign(static_cast<std::size_t>(k), -7);
  factor_front_lu(buf.data(), m, k, ld, sp, u, r.perm.data(), r.st);
  expect_untouched(buf, m, ld, false);
  r.out = unpack(buf, m, ld);
  return r;
}

void check_lu(const Mat& f, index_t k, const LuResult& r, bool check_schur, double perturb_tol = 0,
              double u = 1.0) {
  const index_t m = f.rows;
  ASSERT_TRUE(is_permutation_of_k(r.perm, k)) << "local_perm is not a permutation of 0..k-1";
  Mat l11(k, k), u11(k, k);
  for (index_t j = 0; j < k; ++j) {
    l11(j, j) = 1;
    for (index_t i = j + 1; i < k; ++i) l11(i, j) = r.out(i, j);
    for (index_t i = 0; i <= j; ++i) u11(i, j) = r.out(i, j);
  }
  Mat pf1(k, m);  // rows 0..k-1 of the front, permuted
  for (index_t j = 0; j < m; ++j)
    for (index_t i = 0; i < k; ++i) pf1(i, j) = f(r.perm[i], j);
  const Mat pf11 = block(pf1, 0, k, 0, k), pf12 = block(pf1, 0, k, k, m);
  const Mat u12 = block(r.out, 0, k, k, m), l21 = block(r.out, k, m, 0, k);
  const Mat s = block(r.out, k, m, k, m);
  const Mat f21 = block(f, k, m, 0, k), f22 = block(f, k, m, k, m);
  EXPECT_TRUE(all_finite(r.out));
  double lmax = 0;
  for (double x : l11.v) lmax = std::max(lmax, std::abs(x));
  EXPECT_LE(lmax, (1.0 + 1e-12) / u) << "threshold pivoting bounds |L11| by 1/u";
  const double tol = rec_tol(k);
  const Mat al = abs_of(l11), au = abs_of(u11);
  EXPECT_LE(diff(mul(l11, u11), pf11), tol * (fro(pf11) + fro(mul(al, au))) + perturb_tol);
  if (m > k) {
    EXPECT_LE(diff(mul(l11, u12), pf12), tol * (fro(pf12) + fro(mul(al, abs_of(u12)))));
    EXPECT_LE(diff(mul(l21, u11), f21),
              tol * (fro(f21) + fro(mul(abs_of(l21), au))) + perturb_tol * fro(l21));
    Mat s_plus = mul(l21, u12);
    for (std::size_t i = 0; i < s_plus.v.size(); ++i) s_plus.v[i] += s.v[i];
    EXPECT_LE(diff(s_plus, f22), tol * (fro(f22) + fro(mul(abs_of(l21), abs_of(u12)))));
  }
  if (check_schur && m > k) {
    double scale = 0, schur_tol = 0;
    const Mat s_ref = schur_reference(f, k, &scale, &schur_tol);
    EXPECT_LE(diff(s, s_ref), schur_tol * scale);
  }
}

// log|det F11| and sign(det F11) from dgetrf, row interchanges included.
void check_lu_det(const Mat& f, index_t k, const PivotStats& st) {
  if (k == 0) return;
  Mat a = block(f, 0, k, 0, k);
  const int n = static_cast<int>(k);
  std::vector<int> ipiv(static_cast<std::size_t>(k));
  int info = 0;
  dgetrf_(&n, &n, a.v.data(), &n, ipiv.data(), &info);
  ASSERT_EQ(info, 0);
  double logdet = 0;
  int sign = 1;
  for (index_t j = 0; j < k; ++j) {
    logdet += std::log(std::abs(a(j, j)));
    if (a(j, j) < 0) sign = -sign;
    if (ipiv[j] != j + 1) sign = -sign;
  }
  EXPECT_EQ(st.det_sign, sign);
  EXPECT_NEAR(st.log_abs_det, logdet, 1e-9 * std::max(1.0, std::abs(logdet)));
}

void run_lu(index_t m, index_t k, std::mt19937_64& rng) {
  SCOPED_TRACE(testing::Message() << "LU m=" << m << " k=" << k);
  const Mat f = random_front(m, Kind::general, rng);
  const LuResult r = factor_lu(f, k, 0.0);
  check_lu(f, k, r, true);
  EXPECT_EQ(r.st.perturbed, 0);
  EXPECT_EQ(r.st.zero, 0);
  check_lu_det(f, k, r.st);
}

// The pivot order of threshold partial pivoting on F11 by the textbook unblocked
// elimination (Duff, Erisman & Reid §5.4), written apart from the kernel: at column j
// the diagonal when |a_jj| ≥ u·max_{i≥j} |a_ij|, else the first largest entry. Returns
// local_perm's convention: position i holds original row perm[i].
std::vector<index_t> threshold_pivot_order(const Mat& f, index_t k, double u) {
  Mat a = block(f, 0, k, 0, k);
  std::vector<index_t> perm(static_cast<std::size_t>(k));
  for (index_t i = 0; i < k; ++i) perm[i] = i;
  for (index_t j = 0; j < k; ++j) {
    index_t p = j;
    double best = -1;
    for (index_t i = j; i < k; ++i)
      if (std::abs(a(i, j)) > best) best = std::abs(a(i, j)), p = i;
    if (std::abs(a(j, j)) >= u * best) p = j;
    for (index_t c = 0; c < k; ++c) std::swap(a(j, c), a(p, c));
    std::swap(perm[j], perm[p]);
    for (index_t i = j + 1; i < k; ++i) {
      const double l = a(i, j) / a(j, j);
      for (index_t c = j + 1; c < k; ++c) a(i, c) -= l * a(j, c);
    }
  }
  return perm;
}

void run_lu_threshold(index_t m, index_t k, double u, std::mt19937_64& rng) {
  SCOPED_TRACE(testing::Message() << "LU m=" << m << " k=" << k << " u=" << u);
  Mat f = random_front(m, Kind::general, rng);
  // a diagonal of the size of the off-diagonal entries: partial pivoting interchanges
  // rows in most columns, threshold pivoting in few
  const LuResult r = factor_lu(f, k, 0.0, u);
  check_lu(f, k, r, true, 0, u);
  EXPECT_EQ(r.st.perturbed, 0);
  EXPECT_EQ(r.perm, threshold_pivot_order(f, k, u)) << "pivot order differs from the reference";
  check_lu_det(f, k, r.st);
}

// (m, k) grid: tiny, around the small-front threshold, around panel widths, large.
// Paths: unblocked whole front (LLᵀ/LU m ≤ 24, LDLᵀ m ≤ 40), BLAS with an unblocked LDLᵀ
// pivot block (k ≤ 64), panels of 32 (k > 64), recursive LU.
const std::vector<std::pair<index_t, index_t>> kGrid = {
    {1, 1},    {2, 1},    {2, 2},     {3, 2},    {5, 3},     {17, 17}, {24, 24},   {25, 25},
    {25, 7},   {30, 0},   {40, 25},   {41, 41},  {48, 48},   {49, 20}, {64, 10},   {100, 1},
    {100, 64}, {120, 65}, {150, 130}, {200, 97}, {260, 200}, {300, 3}, {733, 300}, {733, 733}};

struct Seeded {
  unsigned long long seed = 0;
  std::mt19937_64 rng;
  Seeded() : rng(test::fresh_rng(&seed)) {}
};

#define TRACE_SEED(s) SCOPED_TRACE(testing::Message() << "seed " << (s).seed)

TEST(DenseFront, LltGrid) {
  Seeded s;
  TRACE_SEED(s);
  for (auto [m, k] : kGrid) run_llt(m, k, s.rng);
}

TEST(DenseFront, LltSplitIntoLowerPanels) {
  Seeded s;
  TRACE_SEED(s);
  for (auto [m, k] : kGrid)
    for (index_t width : {index_t{1}, index_t{3}, index_t{5}, index_t{128}, m - k + 1})
      run_llt_split(m, k, std::max<index_t>(width, 1), s.rng);
}

TEST(DenseFront, LdltGrid) {
  Seeded s;
  TRACE_SEED(s);
  for (auto [m, k] : kGrid) run_ldlt(m, k, s.rng);
}

TEST(DenseFront, LuGrid) {
  Seeded s;
  TRACE_SEED(s);
  for (auto [m, k] : kGrid) run_lu(m, k, s.rng);
}

TEST(DenseFront, LuThresholdGrid) {
  Seeded s;
  TRACE_SEED(s);
  for (double u : {1.0, 0.5, 0.1, 0.01})
    for (auto [m, k] : kGrid) run_lu_threshold(m, k, u, s.rng);
}

TEST(DenseFront, LuThresholdKeepsTheDiagonalWithinTheBound) {
  // column 0: |a00| = 1 against |a10| = 3: partial pivoting (u = 1) and u = 0.5 take row 1,
  // u = 0.1 keeps the diagonal (1 ≥ 0.3) and makes L(1, 0) = 3
  for (double u : {1.0, 0.5, 0.1}) {
    SCOPED_TRACE(testing::Message() << "u=" << u);
    Mat f(3, 3);
    f(0, 0) = 1, f(1, 0) = 3, f(2, 0) = 7;  // row 2 is not fully summed (k = 2)
    f(0, 1) = 2, f(1, 1) = 1, f(2, 1) = 1;
    f(0, 2) = 1, f(1, 2) = 1, f(2, 2) = 1;
    const LuResult r = factor_lu(f, 2, 0.0, u);
    const bool keeps = u < 1.0 / 3;
    EXPECT_EQ(r.perm, (keeps ? std::vector<index_t>{0, 1} : std::vector<index_t>{1, 0}));
    EXPECT_EQ(r.out(1, 0), keeps ? 3.0 : 1.0 / 3);
    check_lu(f, 2, r, true, 0, u);
  }
}

TEST(DenseFront, LuThresholdOutsideItsRangeIsRejected) {
  std::vector<double> f = {1, 2, 3, 4};
  std::vector<index_t> perm(2);
  PivotStats st;
  for (double u : {0.0, -0.5, 1.5, std::nan("")})
    EXPECT_THROW(factor_front_lu(f.data(), 2, 2, 2, 0.0, u, perm.data(), st), InvalidInput)
        << "u=" << u;
}

TEST(DenseFront, MergeStats) {
  PivotStats a, b;
  a.perturbed = 1, a.two_by_two = 2, a.positive = 3, a.negative = 4, a.zero = 0;
  a.log_abs_det = 1.5, a.det_sign = -1;
  b.perturbed = 10, b.two_by_two = 20, b.positive = 30, b.negative = 41, b.zero = 2;
  b.log_abs_det = -0.5, b.det_sign = -1;
  a.merge(b);
  EXPECT_EQ(a.perturbed, 11);
  EXPECT_EQ(a.two_by_two, 22);
  EXPECT_EQ(a.positive, 33);
  EXPECT_EQ(a.negative, 45);
  EXPECT_EQ(a.zero, 2);
  EXPECT_DOUBLE_EQ(a.log_abs_det, 1.0);
  EXPECT_EQ(a.det_sign, 1);
}

// KKT pivot blocks with a zero block: 2×2 pivots are needed, inertia must match dsyev.
TEST(DenseFront, LdltKktInertia) {
  Seeded s;
  TRACE_SEED(s);
  const struct {
    index_t m, n_con, n_var;
  } cases[] = {{4, 1, 1}, {12, 4, 6}, {40, 10, 30}, {90, 20, 50}, {400, 100, 200}, {300, 150, 150}};
  for (auto c : cases) {
    SCOPED_TRACE(testing::Message() << "KKT m=" << c.m << " con=" << c.n_con << " var=" << c.n_var);
    const index_t k = c.n_con + c.n_var;
    const Mat f = kkt_front(c.m, c.n_con, c.n_var, s.rng);
    const LdltResult r = factor_ldlt(f, k, 0.0);
    check_ldlt(f, k, r, true);
    check_inertia(f, k, r.st);
    check_same_pivots_as_dsytrf(f, k, r);
    // With one constraint, [[h, b], [b, 0]] legitimately takes a 1×1 pivot on h whenever
    // |h| ≥ α|b| (Bunch–Kaufman; the pivots equal dsytrf's, checked above); with several
    // zero diagonals, 2×2 pivots are needed.
    if (c.n_con >= 4) EXPECT_GT(r.st.two_by_two, 0);
    EXPECT_EQ(r.st.perturbed, 0);
  }
}

// ldlt_stats_from_d (used by the CUDA backend, whose kernels return D only) gives the
// statistics factor_front_ldlt accumulates while factoring, bitwise, on fronts with 2×2,
// static and zero pivots.
TEST(DenseFront, LdltStatsFromD) {
  Seeded s;
  TRACE_SEED(s);
  struct Case {
    Mat f;
    index_t k;
    double sp;
  };
  std::vector<Case> cases;
  for (auto [m, k] : std::vector<std::pair<index_t, index_t>>{{1, 1}, {5, 3}, {70, 70}, {300, 200}})
    cases.push_back({random_front(m, Kind::indefinite, s.rng), k, 0.0});
  cases.push_back({kkt_front(90, 20, 50, s.rng), 70, 0.0});
  cases.push_back({kkt_front(300, 150, 100, s.rng), 250, 1e-8});
  Mat z = random_front(40, Kind::indefinite, s.rng);
  for (index_t i = 0; i < 40; ++i) z(i, 7) = z(7, i) = z(i, 20) = z(20, i) = 0.0;
  cases.push_back({z, 30, 1e-8});  // two perturbed pivots
  cases.push_back({z, 30, 0.0});   // two exactly zero pivots
  EXPECT_EQ(factor_ldlt(z, 30, 1e-8).st.perturbed, 2);
  EXPECT_EQ(factor_ldlt(z, 30, 0.0).st.zero, 2);
  for (const Case& c : cases) {
    SCOPED_TRACE(testing::Message() << "m=" << c.f.rows << " k=" << c.k << " sp=" << c.sp);
    const LdltResult r = factor_ldlt(c.f, c.k, c.sp);
    std::vector<double> dd(c.k), doff(c.k, 0.0);
    std::vector<int> ps(c.k);
    for (index_t j = 0; j < c.k; ++j) {
      dd[j] = r.out(j, j);
      ps[j] = r.psize[j] == 2 ? (j > 0 && ps[j - 1] == 2 ? 0 : 2) : 1;
      if (ps[j] == 2) doff[j] = r.out(j + 1, j);
    }
    PivotStats st;
    ldlt_stats_from_d(c.k, dd.data(), doff.data(), ps.data(), st);
    EXPECT_EQ(st.two_by_two, r.st.two_by_two);
    EXPECT_EQ(st.positive, r.st.positive);
    EXPECT_EQ(st.negative, r.st.negative);
    EXPECT_EQ(st.zero, r.st.zero);
    EXPECT_EQ(st.det_sign, r.st.det_sign);
    EXPECT_EQ(st.log_abs_det, r.st.log_abs_det);  // −∞ == −∞ after a zero pivot
    EXPECT_EQ(st.perturbed, 0);
  }
}

// Rows ≥ k never take part in pivoting, even when they hold by far the largest entries.
TEST(DenseFront, PivotsStayInPivotBlock) {
  Seeded s;
  TRACE_SEED(s);
  for (auto [m, k] : std::vector<std::pair<index_t, index_t>>{{20, 8}, {300, 120}}) {
    SCOPED_TRACE(testing::Message() << "m=" << m << " k=" << k);
    {
      Mat f = random_front(m, Kind::general, s.rng);
      for (index_t j = 0; j < k; ++j)
        for (index_t i = k; i < m; ++i) f(i, j) *= 1e6;
      const LuResult r = factor_lu(f, k, 0.0);
      check_lu(f, k, r, true);  // checks perm ⊂ 0..k-1, |L11| ≤ 1, F21 = L21 U11 unpermuted
    }
    {
      Mat f = random_front(m, Kind::indefinite, s.rng);
      for (index_t j = 0; j < k; ++j)
        for (index_t i = k; i < m; ++i) f(i, j) = f(j, i) = f(i, j) * 1e6;
      const LdltResult r = factor_ldlt(f, k, 0.0);
      check_ldlt(f, k, r, true);
      check_inertia(f, k, r.st);
      check_same_pivots_as_dsytrf(f, k, r);  // F21 played no part in the choice
    }
  }
}

// A pivot block with a zero row/column (the whole column of the front zero): the pivot is
// perturbed to ±static_pivot, the output is finite and reconstructs F + static_pivot·e eᵀ.
TEST(DenseFront, StaticPivotZeroColumn) {
  Seeded s;
  TRACE_SEED(s);
  const double sp = 1e-8;
  for (auto [m, k] : std::vector<std::pair<index_t, index_t>>{{6, 4}, {30, 30}, {200, 150}}) {
    SCOPED_TRACE(testing::Message() << "m=" << m << " k=" << k);
    const index_t z = k / 2;
    {
      Mat f = random_front(m, Kind::indefinite, s.rng);
      for (index_t i = 0; i < m; ++i) f(i, z) = f(z, i) = 0.0;
      const LdltResult r = factor_ldlt(f, k, sp);
      EXPECT_EQ(r.st.perturbed, 1);
      check_ldlt(f, k, r, false, 1.01 * sp);
    }
    {
      Mat f = random_front(m, Kind::general, s.rng);
      for (index_t i = 0; i < m; ++i) f(i, z) = 0.0;
      const LuResult r = factor_lu(f, k, sp);
      EXPECT_EQ(r.st.perturbed, 1);
      check_lu(f, k, r, false, 1.01 * sp);
    }
  }
}

// Rank-deficient and all-zero pivot blocks: perturbed pivots, finite output.
TEST(DenseFront, StaticPivotRankDeficient) {
  Seeded s;
  TRACE_SEED(s);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const double sp = 1e-8;
  for (auto [m, k] : std::vector<std::pair<index_t, index_t>>{{10, 8}, {40, 40}, {250, 200}}) {
    SCOPED_TRACE(testing::Message() << "m=" << m << " k=" << k);
    const index_t rank = k / 2;
    Mat x(k, rank), y(k, rank);
    for (double& v : x.v) v = u(s.rng);
    for (double& v : y.v) v = u(s.rng);
    {  // symmetric indefinite, rank k/2: X diag(±1) Xᵀ
      Mat f = random_front(m, Kind::indefinite, s.rng);
      Mat xs = x;
      for (index_t j = 0; j < rank; ++j)
        if (j % 2)
          for (index_t i = 0; i < k; ++i) xs(i, j) = -xs(i, j);
      const Mat f11 = mul(xs, x, 'N', 'T');
      for (index_t j = 0; j < k; ++j)
        for (index_t i = 0; i < k; ++i) f(i, j) = f11(i, j);
      const LdltResult r = factor_ldlt(f, k, sp);
      EXPECT_GE(r.st.perturbed, 1);
      EXPECT_TRUE(all_finite(r.out));
      EXPECT_EQ(r.st.zero, 0);
      EXPECT_EQ(r.st.positive + r.st.negative, k);
    }
    {  // general, rank k/2: X Yᵀ
      Mat f = random_front(m, Kind::general, s.rng);
      const Mat f11 = mul(x, y, 'N', 'T');
      for (index_t j = 0; j < k; ++j)
        for (index_t i = 0; i < k; ++i) f(i, j) = f11(i, j);
      const LuResult r = factor_lu(f, k, sp);
      EXPECT_GE(r.st.perturbed, 1);
      EXPECT_TRUE(all_finite(r.out));
    }
    {  // all-zero pivot block: every pivot perturbed
      Mat f = random_front(m, Kind::indefinite, s.rng);
      for (index_t j = 0; j < k; ++j)
        for (index_t i = 0; i < k; ++i) f(i, j) = 0;
      const LdltResult r = factor_ldlt(f, k, sp);
      EXPECT_EQ(r.st.perturbed, k);
      EXPECT_EQ(r.st.positive, k);
      EXPECT_EQ(r.st.two_by_two, 0);
      EXPECT_TRUE(all_finite(r.out));
      Mat g = random_front(m, Kind::general, s.rng);
      for (index_t j = 0; j < k; ++j)
        for (index_t i = 0; i < k; ++i) g(i, j) = 0;
      const LuResult q = factor_lu(g, k, sp);
      EXPECT_EQ(q.st.perturbed, k);
      EXPECT_TRUE(all_finite(q.out));
    }
  }
}

// LLᵀ on a pivot block that is not positive definite returns the first failing pivot.
TEST(DenseFront, LltNotPositiveDefinite) {
  Seeded s;
  TRACE_SEED(s);
  for (auto [m, k, bad] : std::vector<std::tuple<index_t, index_t, index_t>>{
           {1, 1, 0}, {20, 12, 0}, {20, 12, 7}, {48, 48, 47}, {300, 200, 0}, {300, 200, 150}}) {
    SCOPED_TRACE(testing::Message() << "m=" << m << " k=" << k << " bad=" << bad);
    Mat f = random_front(m, Kind::spd, s.rng);
    f(bad, bad) = -1.0;  // leading bad×bad block stays SPD, (bad+1)×(bad+1) is not
    const index_t ld = m;
    std::vector<double> buf = pack(f, ld, true);
    PivotStats st;
    EXPECT_EQ(factor_front_llt(buf.data(), m, k, ld, st), bad);
    EXPECT_EQ(st.positive, 0);
  }
}

// Without static pivoting an exactly zero pivot is counted, not hidden; it is inverted as
// 0, so its columns of L are zero and the output stays finite.
TEST(DenseFront, ZeroPivotCountedWithoutStaticPivoting) {
  Mat f(3, 3);
  f(0, 0) = 1;  // F = diag(1, 0, 2): the second pivot is exactly zero
  f(2, 2) = 2;
  const LuResult r = factor_lu(f, 3, 0.0);
  EXPECT_EQ(r.st.zero, 1);
  EXPECT_EQ(r.st.det_sign, 0);
  const LdltResult q = factor_ldlt(f, 3, 0.0);
  EXPECT_EQ(q.st.zero, 1);
  EXPECT_EQ(q.st.positive, 2);
  EXPECT_EQ(q.st.det_sign, 0);

  Seeded s;
  TRACE_SEED(s);
  for (auto [m, k] : std::vector<std::pair<index_t, index_t>>{{20, 10}, {160, 100}}) {
    SCOPED_TRACE(testing::Message() << "m=" << m << " k=" << k);
    const index_t z = 3;  // zero row and column inside the pivot block only
    Mat g = random_front(m, Kind::general, s.rng);
    for (index_t i = 0; i < k; ++i) g(i, z) = g(z, i) = 0.0;
    const LuResult lu = factor_lu(g, k, 0.0);
    EXPECT_EQ(lu.st.zero, 1);
    EXPECT_EQ(lu.st.det_sign, 0);
    EXPECT_TRUE(all_finite(lu.out));
    index_t zcol = -1;  // the zero pivot's position
    for (index_t j = 0; j < k; ++j)
      if (lu.out(j, j) == 0.0) zcol = j;
    ASSERT_GE(zcol, 0);
    for (index_t i = k; i < m; ++i) EXPECT_EQ(lu.out(i, zcol), 0.0);

    Mat h = random_front(m, Kind::indefinite, s.rng);
    for (index_t i = 0; i < k; ++i) h(i, z) = h(z, i) = 0.0;
    const LdltResult ldl = factor_ldlt(h, k, 0.0);
    EXPECT_EQ(ldl.st.zero, 1);
    EXPECT_EQ(ldl.st.positive + ldl.st.negative, k - 1);
    EXPECT_TRUE(all_finite(block(ldl.out, 0, m, 0, m)));
  }
}

// The trsm wrapper (dense_blas.hpp), recursive above kTrsmLeaf for the combinations the
// front kernels use and DTRSM otherwise, against the definition: op(A)·X = B or
// X·op(A) = B checked entry by entry with sums over A's referenced triangle only, within
// the componentwise backward-error bound of a triangular solve (Higham, "Accuracy and
// Stability of Numerical Algorithms", 2nd ed., Thm. 8.5). The triangle that must not be
// read is NaN, a unit diagonal is kSentinel, and the padding rows of A and B must stay.
TEST(DenseBlas, TrsmSolvesEveryCombinationTheFrontsUse) {
  Seeded s;
  TRACE_SEED(s);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  struct Combo {
    char side, uplo, ta, diag;
  };
  for (const Combo c :
       {Combo{'R', 'L', 'T', 'N'}, Combo{'R', 'L', 'T', 'U'}, Combo{'R', 'U', 'N', 'N'},
        Combo{'L', 'L', 'N', 'U'}, Combo{'L', 'L', 'N', 'N'}, Combo{'L', 'U', 'N', 'N'}})
    for (const index_t order : {1, 2, 3, 5, 64, 65, 97, 200, 733})
      for (const index_t other : {1, 3, 130}) {
        SCOPED_TRACE(testing::Message() << c.side << c.uplo << c.ta << c.diag << " order=" << order
                                        << " other=" << other);
        const bool right = c.side == 'R', lower = c.uplo == 'L', unit = c.diag == 'U';
        const index_t lda = order + 3, rows = right ? other : order, cols = right ? order : other;
        const index_t ldb = rows + 2;
        std::vector<double> a(static_cast<std::size_t>(lda * order), kSentinel);
        auto A = [&](index_t i, index_t j) -> double& { return a[i + j * lda]; };
        for (index_t j = 0; j < order; ++j)
          for (index_t i = 0; i < order; ++i) {
            if (i == j)
              A(i, j) = unit ? kSentinel : 1.0 + 0.5 * (u(s.rng) + 1.0);
            else if ((i > j) == lower)
              A(i, j) = u(s.rng) / static_cast<double>(order);
            else
              A(i, j) = nan;
          }
        // op(A)(i, j) over the referenced triangle, 1 on a unit diagonal
        auto opA = [&](index_t i, index_t j) {
          const index_t r = c.ta == 'T' ? j : i, q = c.ta == 'T' ? i : j;
          if (r == q) return unit ? 1.0 : A(r, r);
          return (r > q) == lower ? A(r, q) : 0.0;
        };
        std::vector<double> b(static_cast<std::size_t>(ldb * cols), kSentinel);
        for (index_t j = 0; j < cols; ++j)
          for (index_t i = 0; i < rows; ++i) b[i + j * ldb] = u(s.rng);
        std::vector<double> x = b;
        trsm(c.side, c.uplo, c.ta, c.diag, rows, cols, a.data(), lda, x.data(), ldb);
        const double eps = std::numeric_limits<double>::epsilon();
        index_t outside = 0;  // entries beyond the bound (or NaN)
        for (index_t j = 0; j < cols; ++j)
          for (index_t i = 0; i < rows; ++i) {
            double sum = 0.0, mag = 0.0;
            for (index_t l = 0; l < order; ++l) {
              const double t = right ? x[i + l * ldb] * opA(l, j) : opA(i, l) * x[l + j * ldb];
              sum += t;
              mag += std::abs(t);
            }
            const double bound = 4.0 * static_cast<double>(order + 1) * eps * mag;
            if (!(std::abs(sum - b[i + j * ldb]) <= bound)) ++outside;
          }
        EXPECT_EQ(outside, 0);
        for (index_t j = 0; j < cols; ++j)
          for (index_t i = rows; i < ldb; ++i) ASSERT_EQ(x[i + j * ldb], kSentinel);
        for (index_t j = 0; j < order; ++j)
          for (index_t i = order; i < lda; ++i) ASSERT_EQ(A(i, j), kSentinel);
      }
}

}  // namespace
}  // namespace strata::numeric::cpu
