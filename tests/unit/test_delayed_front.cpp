// The front kernels with threshold pivoting and delayed pivots
// (numeric/cpu/delayed_front.hpp), against the front they were given: with its rows and
// columns permuted as reported, F0(P, Q) − L·U must equal [0 0; 0 S] (S the Schur
// complement left in the front) to rounding, every multiplier must respect the threshold,
// the refused candidates must be the columns no fully summed row could pivot, and a root
// (no delays) must solve like LAPACK's dgesv. The symmetric kernel also: its pivots'
// inertia that of the eliminated block's eigenvalues (LAPACK dsyev), its delayed rows and
// columns the same variables, its 2×2 pivots where no 1×1 pivot can be.
#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <cfloat>
#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include "base/blas.hpp"
#include "numeric/cpu/delayed_front.hpp"
#include "support/test_support.hpp"

namespace strata::numeric::cpu {
namespace {

struct Result {
  index_t npiv = 0;
  std::vector<double> f;
  std::vector<index_t> rp, cp;
  PivotStats st;
};

Result run(const std::vector<double>& f0, index_t m, index_t p, const DelayPolicy& pol,
           bool symmetric = false, tbb::task_arena* arena = nullptr) {
  Result r;
  r.f = f0;
  r.rp.resize(p);
  r.cp.resize(p);
  r.npiv = symmetric ? factor_front_sym_delayed(r.f.data(), m, p, m, pol, r.rp.data(), r.cp.data(),
                                                r.st, arena)
                     : factor_front_lu_delayed(r.f.data(), m, p, m, pol, r.rp.data(), r.cp.data(),
                                               r.st, arena);
  return r;
}

// x with F0 x = b for a root's factor (every pivot taken: L U = F0(P, Q)): L U x' = b(P),
// x(Q) = x'.
std::vector<double> solve_root(const Result& r, index_t m, const std::vector<double>& b) {
  std::vector<double> y(m), x(m);
  for (index_t i = 0; i < m; ++i) y[i] = b[r.rp[i]];
  for (index_t j = 0; j < m; ++j)
    for (index_t i = j + 1; i < m; ++i) y[i] -= r.f[i + j * m] * y[j];
  for (index_t j = m - 1; j >= 0; --j) {
    y[j] /= r.f[j + j * m];
    for (index_t i = 0; i < j; ++i) y[i] -= r.f[i + j * m] * y[j];
  }
  for (index_t j = 0; j < m; ++j) x[r.cp[j]] = y[j];
  return x;
}

// Checks F0(P, Q) = L U + [0 0; 0 S] entrywise to c·u·(|L||U| + |F0|).
void expect_reconstructs(const std::vector<double>& f0, index_t m, index_t p, const Result& r) {
  const index_t k = r.npiv;
  auto perm_row = [&](index_t i) { return i < p ? r.rp[i] : i; };
  auto perm_col = [&](index_t j) { return j < p ? r.cp[j] : j; };
  double worst = 0;
  for (index_t j = 0; j < m; ++j)
    for (index_t i = 0; i < m; ++i) {
      double lu = 0, mag = 0;
      for (index_t q = 0; q < std::min({i + 1, j + 1, k}); ++q) {
        const double l = q == i ? 1.0 : r.f[i + q * m];
        const double u = r.f[q + j * m];
        lu += l * u;
        mag += std::abs(l * u);
      }
      if (i >= k && j >= k) {  // the Schur complement
        lu += r.f[i + j * m];
        mag += std::abs(r.f[i + j * m]);
      }
      const double a = f0[perm_row(i) + perm_col(j) * m];
      mag += std::abs(a);
      const double err = std::abs(a - lu) / (16 * (k + 2) * DBL_EPSILON * std::max(mag, 1e-300));
      worst = std::max(worst, err);
    }
  EXPECT_LE(worst, 1.0) << "m=" << m << " p=" << p << " npiv=" << k;
}

TEST(DelayedFront, ReconstructsAndRespectsTheThreshold) {
  auto rng = test::fresh_rng();
  std::uniform_real_distribution<double> u(-1, 1);
  for (index_t m : {1, 2, 3, 5, 17, 60}) {
    for (index_t p : {index_t{0}, index_t{1}, m / 2, m}) {
      if (p > m) continue;
      SCOPED_TRACE("m=" + std::to_string(m) + " p=" + std::to_string(p));
      std::vector<double> f0(static_cast<std::size_t>(m) * m);
      for (double& x : f0) x = u(rng);
      // make some candidate columns unpivotable: tiny in the fully summed rows, large below
      std::vector<char> bad(p, 0);
      for (index_t j = 0; j < p; ++j)
        if (p < m && u(rng) > 0.3) {
          bad[j] = 1;
          for (index_t i = 0; i < p; ++i) f0[i + j * m] *= 1e-6;
        }
      DelayPolicy pol;
      pol.threshold = 0.1;
      const Result r = run(f0, m, p, pol);
      ASSERT_LE(r.npiv, p);
      EXPECT_EQ(r.st.perturbed, 0);
      expect_reconstructs(f0, m, p, r);
      // multipliers: |L| ≤ 1/threshold
      for (index_t j = 0; j < r.npiv; ++j)
        for (index_t i = j + 1; i < m; ++i)
          EXPECT_LE(std::abs(r.f[i + j * m]), 1 / pol.threshold * (1 + 1e-12));
      // row and column permutations of 0..p
      std::vector<index_t> a = r.rp, b = r.cp;
      std::sort(a.begin(), a.end());
      std::sort(b.begin(), b.end());
      for (index_t i = 0; i < p; ++i) {
        EXPECT_EQ(a[i], i);
        EXPECT_EQ(b[i], i);
      }
      // with no contribution rows, nothing needs delaying
      if (p == m) {
        EXPECT_EQ(r.npiv, p);
      }
    }
  }
}

// Fronts wide enough that each panel's update of the columns behind it is split into
// several column blocks: on an arena of three threads the factor is bitwise the one made
// block after block, and it reconstructs the front.
TEST(DelayedFront, PanelUpdatesOnAnArenaGiveTheSameBits) {
  auto rng = test::fresh_rng();
  std::uniform_real_distribution<double> u(-1, 1);
  tbb::task_arena arena(3);
  for (index_t m : {300, 733}) {
    for (index_t p : {m / 2, m}) {
      SCOPED_TRACE("m=" + std::to_string(m) + " p=" + std::to_string(p));
      std::vector<double> f0(static_cast<std::size_t>(m) * m);
      for (double& x : f0) x = u(rng);
      for (index_t j = 0; j < p; ++j)  // some candidates no fully summed row can pivot
        if (p < m && u(rng) > 0.6)
          for (index_t i = 0; i < p; ++i) f0[i + j * m] *= 1e-6;
      DelayPolicy pol;
      pol.threshold = 0.1;
      const Result one = run(f0, m, p, pol);
      Result par;
      par.f = f0;
      par.rp.resize(p);
      par.cp.resize(p);
      par.npiv = factor_front_lu_delayed(par.f.data(), m, p, m, pol, par.rp.data(), par.cp.data(),
                                         par.st, &arena);
      ASSERT_EQ(par.npiv, one.npiv);
      if (p < m) EXPECT_LT(one.npiv, p) << "no candidate was delayed: the case is not covered";
      EXPECT_EQ(par.rp, one.rp);
      EXPECT_EQ(par.cp, one.cp);
      EXPECT_TRUE(std::equal(par.f.begin(), par.f.end(), one.f.begin(), [](double a, double b) {
        return std::memcmp(&a, &b, sizeof a) == 0;
      }));
      expect_reconstructs(f0, m, p, par);
    }
  }
}

// A column that is zero in every fully summed row is always delayed; at a root (no
// delays) a zero pivot is replaced by the static pivot and counted.
TEST(DelayedFront, ZeroColumnsAreDelayedOrPerturbedAtARoot) {
  const index_t m = 4, p = 2;
  // column 0: zero in the fully summed rows 0, 1; column 1 pivots
  std::vector<double> f0 = {0, 0, 1, 2,  //
                            0, 3, 1, 1,  //
                            1, 1, 4, 0,  //
                            2, 0, 1, 5};
  DelayPolicy pol;
  Result r = run(f0, m, p, pol);
  EXPECT_EQ(r.npiv, 1);
  EXPECT_EQ(r.cp[1], 0);  // column 0 refused
  expect_reconstructs(f0, m, p, r);
  // the same fully summed block at a root: p = m = 2, column 0 zero in both rows
  std::vector<double> g0 = {0, 0, 1, 3};
  pol.may_delay = false;
  pol.static_pivot = 1e-10;
  r = run(g0, 2, 2, pol);
  EXPECT_EQ(r.npiv, 2);
  EXPECT_EQ(r.st.perturbed, 1);
}

// p = m, no delays: partial pivoting over the whole matrix, the solution as dgesv's.
TEST(DelayedFront, RootSolvesLikeDgesv) {
  auto rng = test::fresh_rng();
  std::uniform_real_distribution<double> u(-1, 1);
  for (index_t m : {1, 2, 3, 5, 64}) {
    std::vector<double> f0(static_cast<std::size_t>(m) * m), b(m);
    for (double& x : f0) x = u(rng);
    for (double& x : b) x = u(rng);
    DelayPolicy pol;
    pol.may_delay = false;
    const Result r = run(f0, m, m, pol);
    ASSERT_EQ(r.npiv, m);
    const std::vector<double> x = solve_root(r, m, b);
    std::vector<double> ref = b;
    ASSERT_TRUE(test::dense_solve(f0, m, ref, 1));
    // κ-aware: the two solutions agree to about κ·u
    double anorm = 0, xnorm = 0;
    for (index_t i = 0; i < m; ++i) {
      double row = 0;
      for (index_t j = 0; j < m; ++j) row += std::abs(f0[i + j * m]);
      anorm = std::max(anorm, row);
      xnorm = std::max(xnorm, std::abs(ref[i]));
    }
    double bnorm = 0;
    for (double v : b) bnorm = std::max(bnorm, std::abs(v));
    const double kappa_lower = anorm * xnorm / std::max(bnorm, 1e-300);
    EXPECT_LE(test::relative_difference(x, ref),
              std::max(1e-10, 1e3 * m * DBL_EPSILON * kappa_lower))
        << "m=" << m;
  }
}

// Symmetric fronts ---------------------------------------------------------------------

// A random symmetric m×m front: entries in [−1, 1], the diagonal zero in about a third of
// the rows (a KKT-like block, where 1×1 pivots fail and 2×2 pivots are needed), and in
// `tiny_rows` of the fully summed rows every entry within the fully summed block scaled by
// 1e-6 (candidates no fully summed row can pivot, which must be delayed when p < m).
std::vector<double> symmetric_front(index_t m, index_t p, std::mt19937_64& rng,
                                    std::vector<char>* tiny_rows = nullptr) {
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<double> f(static_cast<std::size_t>(m) * m);
  for (index_t j = 0; j < m; ++j)
    for (index_t i = j; i < m; ++i) f[i + j * m] = f[j + i * m] = u(rng);
  for (index_t i = 0; i < m; ++i)
    if (u(rng) < -0.33) f[i + i * m] = 0;
  std::vector<char> tiny(m, 0);
  for (index_t i = 0; i < p; ++i) tiny[i] = p < m && u(rng) > 0.5;
  for (index_t j = 0; j < p; ++j)
    for (index_t i = 0; i < p; ++i)
      if (tiny[i] || tiny[j]) f[i + j * m] *= 1e-6;
  if (tiny_rows) *tiny_rows = tiny;
  return f;
}

// (positive, negative, zero) eigenvalues of the symmetric block f0(v, v) (LAPACK dsyev),
// zero meaning below 1e-12 of the largest magnitude.
std::array<index_t, 3> eigen_inertia(const std::vector<double>& f0, index_t m,
                                     const std::vector<index_t>& v) {
  const int n = static_cast<int>(v.size());
  std::array<index_t, 3> in{0, 0, 0};
  if (n == 0) return in;
  std::vector<double> b(static_cast<std::size_t>(n) * n), w(n);
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) b[i + j * n] = f0[v[i] + v[j] * m];
  int lwork = -1, info = 0;
  double q = 0;
  dsyev_("N", "L", &n, b.data(), &n, w.data(), &q, &lwork, &info);
  lwork = static_cast<int>(q);
  std::vector<double> work(lwork);
  dsyev_("N", "L", &n, b.data(), &n, w.data(), work.data(), &lwork, &info);
  EXPECT_EQ(info, 0);
  double big = 0;
  for (double x : w) big = std::max(big, std::abs(x));
  for (double x : w) ++in[std::abs(x) <= 1e-12 * big ? 2 : x > 0 ? 0 : 1];
  return in;
}

// The symmetric kernel's structural promises: permutations of 0..p, the delayed positions
// the same variables in the row and column lists, the pivots' lists equal but within
// 2×2 pivots (an interchanged pair), inertia and 2×2 counts adding up.
void expect_symmetric_lists(const Result& r, index_t p) {
  std::vector<index_t> a = r.rp, b = r.cp;
  std::sort(a.begin(), a.end());
  std::sort(b.begin(), b.end());
  for (index_t i = 0; i < p; ++i) {
    ASSERT_EQ(a[i], i);
    ASSERT_EQ(b[i], i);
  }
  for (index_t i = r.npiv; i < p; ++i) EXPECT_EQ(r.rp[i], r.cp[i]) << "delayed position " << i;
  index_t swapped = 0;
  for (index_t i = 0; i < r.npiv; ++i)
    if (r.rp[i] != r.cp[i]) {
      ++swapped;
      const bool with_next = i + 1 < r.npiv && r.rp[i] == r.cp[i + 1] && r.rp[i + 1] == r.cp[i];
      const bool with_prev = i > 0 && r.rp[i] == r.cp[i - 1] && r.rp[i - 1] == r.cp[i];
      EXPECT_TRUE(with_next || with_prev) << "pivot position " << i;
    }
  EXPECT_LE(swapped, 2 * r.st.two_by_two);
  EXPECT_EQ(r.st.positive + r.st.negative + r.st.zero, r.npiv);
  EXPECT_LE(2 * r.st.two_by_two, r.npiv);
}

TEST(DelayedFrontSymmetric, ReconstructsWithTheEliminatedBlocksInertia) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  index_t delayed = 0, two_by_two = 0;
  for (index_t m : {1, 2, 3, 5, 17, 60}) {
    for (index_t p : {index_t{0}, index_t{1}, m / 2, m}) {
      if (p > m) continue;
      SCOPED_TRACE("m=" + std::to_string(m) + " p=" + std::to_string(p));
      std::vector<char> tiny;
      const std::vector<double> f0 = symmetric_front(m, p, rng, &tiny);
      DelayPolicy pol;
      pol.threshold = 0.1;
      const Result r = run(f0, m, p, pol, true);
      ASSERT_LE(r.npiv, p);
      EXPECT_EQ(r.st.perturbed, 0);
      expect_reconstructs(f0, m, p, r);
      expect_symmetric_lists(r, p);
      // the pivots' inertia is the eliminated block's (Sylvester)
      const std::vector<index_t> pivots(r.cp.begin(), r.cp.begin() + r.npiv);
      const std::array<index_t, 3> in = eigen_inertia(f0, m, pivots);
      EXPECT_EQ(r.st.positive, in[0]);
      EXPECT_EQ(r.st.negative, in[1]);
      EXPECT_EQ(r.st.zero, in[2]);
      // a candidate tiny in every fully summed entry can pivot nowhere: it is delayed
      for (index_t i = 0; i < r.npiv; ++i) EXPECT_FALSE(tiny[r.cp[i]]) << "took " << r.cp[i];
      delayed += p - r.npiv;
      two_by_two += r.st.two_by_two;
    }
  }
  EXPECT_GT(delayed, 0) << "no candidate was delayed: the case is not covered";
  EXPECT_GT(two_by_two, 0) << "no 2x2 pivot was taken: the case is not covered";
}

// [[0, 1], [1, 0]]: no 1×1 pivot passes, one 2×2 pivot takes both, inertia (1, 1, 0).
TEST(DelayedFrontSymmetric, ZeroDiagonalTakesATwoByTwoPivot) {
  const std::vector<double> f0 = {0, 1, 1, 0};
  DelayPolicy pol;
  const Result r = run(f0, 2, 2, pol, true);
  EXPECT_EQ(r.npiv, 2);
  EXPECT_EQ(r.st.two_by_two, 1);
  EXPECT_EQ(r.st.positive, 1);
  EXPECT_EQ(r.st.negative, 1);
  EXPECT_EQ(r.st.det_sign * (r.rp[0] == r.cp[0] ? 1 : -1), -1);  // det = −1
  EXPECT_NEAR(r.st.log_abs_det, 0.0, 1e-15);
  expect_reconstructs(f0, 2, 2, r);
  // with a contribution row coupled 1e6 times more strongly, the same pair must wait
  const std::vector<double> g0 = {0, 1, 1e6, 1, 0, 1e6, 1e6, 1e6, 1};
  const Result d = run(g0, 3, 2, pol, true);
  EXPECT_EQ(d.npiv, 0);
  expect_symmetric_lists(d, 2);
  // at a root every row is eliminated; a zero matrix gets static pivots, counted
  pol.may_delay = false;
  pol.static_pivot = 1e-10;
  const Result z = run(std::vector<double>(4, 0.0), 2, 2, pol, true);
  EXPECT_EQ(z.npiv, 2);
  EXPECT_EQ(z.st.perturbed, 2);
}

// p = m at a root (Bunch–Kaufman): every pivot taken, none perturbed on a nonsingular
// front, the solution as dgesv's and the inertia that of the front's eigenvalues.
TEST(DelayedFrontSymmetric, RootSolvesLikeDgesvWithTheFrontsInertia) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  std::uniform_real_distribution<double> u(-1, 1);
  for (index_t m : {1, 2, 3, 5, 64}) {
    SCOPED_TRACE("m=" + std::to_string(m));
    const std::vector<double> f0 = symmetric_front(m, m, rng);
    std::vector<double> b(m);
    for (double& x : b) x = u(rng);
    std::vector<double> ref = b;
    if (!test::dense_solve(f0, m, ref, 1)) continue;  // a singular draw (m = 1, zero diagonal)
    DelayPolicy pol;
    pol.may_delay = false;
    const Result r = run(f0, m, m, pol, true);
    ASSERT_EQ(r.npiv, m);
    EXPECT_EQ(r.st.perturbed, 0);
    expect_reconstructs(f0, m, m, r);
    std::vector<index_t> all(m);
    for (index_t i = 0; i < m; ++i) all[i] = i;
    const std::array<index_t, 3> in = eigen_inertia(f0, m, all);
    EXPECT_EQ(r.st.positive, in[0]);
    EXPECT_EQ(r.st.negative, in[1]);
    const std::vector<double> x = solve_root(r, m, b);
    double anorm = 0, xnorm = 0, bnorm = 0;
    for (index_t i = 0; i < m; ++i) {
      double row = 0;
      for (index_t j = 0; j < m; ++j) row += std::abs(f0[i + j * m]);
      anorm = std::max(anorm, row);
      xnorm = std::max(xnorm, std::abs(ref[i]));
      bnorm = std::max(bnorm, std::abs(b[i]));
    }
    EXPECT_LE(test::relative_difference(x, ref),
              std::max(1e-10, 1e3 * m * DBL_EPSILON * anorm * xnorm / std::max(bnorm, 1e-300)));
  }
}

// Wide fronts, whose final update of the columns behind the candidates is split into
// column blocks: on an arena of three threads the same bits as block after block.
TEST(DelayedFrontSymmetric, UpdatesOnAnArenaGiveTheSameBits) {
  auto rng = test::fresh_rng();
  tbb::task_arena arena(3);
  for (index_t m : {300, 733}) {
    const index_t p = m / 2;
    SCOPED_TRACE("m=" + std::to_string(m));
    const std::vector<double> f0 = symmetric_front(m, p, rng);
    DelayPolicy pol;
    pol.threshold = 0.1;
    const Result one = run(f0, m, p, pol, true);
    const Result par = run(f0, m, p, pol, true, &arena);
    ASSERT_EQ(par.npiv, one.npiv);
    EXPECT_LT(one.npiv, p) << "no candidate was delayed: the case is not covered";
    EXPECT_EQ(par.rp, one.rp);
    EXPECT_EQ(par.cp, one.cp);
    EXPECT_TRUE(std::equal(par.f.begin(), par.f.end(), one.f.begin(),
                           [](double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }));
    expect_reconstructs(f0, m, p, par);
    expect_symmetric_lists(par, p);
  }
}

}  // namespace
}  // namespace strata::numeric::cpu
