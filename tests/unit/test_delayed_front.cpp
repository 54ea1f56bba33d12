// The front kernel with threshold pivoting and delayed pivots
// (numeric/cpu/delayed_front.hpp), against the front it was given: with its rows and
// columns permuted as reported, F0(P, Q) − L·U must equal [0 0; 0 S] (S the Schur
// complement left in the front) to rounding, every multiplier must respect the threshold,
// the refused candidates must be the columns no fully summed row could pivot, and a root
// (no delays) must solve like LAPACK's dgesv.
#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstring>
#include <random>
#include <vector>

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

Result run(const std::vector<double>& f0, index_t m, index_t p, const DelayPolicy& pol) {
  Result r;
  r.f = f0;
  r.rp.resize(p);
  r.cp.resize(p);
  r.npiv = factor_front_lu_delayed(r.f.data(), m, p, m, pol, r.rp.data(), r.cp.data(), r.st);
  return r;
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
    // solve: L U x' = b(P), x(Q) = x'
    std::vector<double> y(m), x(m);
    for (index_t i = 0; i < m; ++i) y[i] = b[r.rp[i]];
    for (index_t j = 0; j < m; ++j)
      for (index_t i = j + 1; i < m; ++i) y[i] -= r.f[i + j * m] * y[j];
    for (index_t j = m - 1; j >= 0; --j) {
      y[j] /= r.f[j + j * m];
      for (index_t i = 0; i < j; ++i) y[i] -= r.f[i + j * m] * y[j];
    }
    for (index_t j = 0; j < m; ++j) x[r.cp[j]] = y[j];
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

}  // namespace
}  // namespace strata::numeric::cpu
