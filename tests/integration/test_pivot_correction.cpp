// Static pivots corrected in the solve (Options::pivoting = Pivoting::corrected;
// core/pivot_correction.hpp) through the Solver: an analysis made for values whose
// matching is wrong for the values refactorized (the Newton loop of a simulation whose
// contacts and rotations changed) factors in the fixed order, shifts the pivots it cannot
// take and corrects every solve by the Sherman–Morrison–Woodbury formula. The solutions
// must be dense LAPACK's (dgesv) to the conditioning without refinement, log|det| and its
// sign dgetrf's, the statistics must say which mechanism ran, and a numerically singular
// matrix must still be reported as such (the correction gives way to delayed pivoting).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "base/blas.hpp"
#include "sparse/generators.hpp"
#include "strata/strata.hpp"
#include "support/test_support.hpp"

namespace strata {
namespace {

// LU on the CPU with fundamental supernodes only (no amalgamation): leaf fronts of one
// pivot, which a zero diagonal leaves without a pivot in the analysis's order; the
// solution checked (its backward error computed) but not refined, so that what is
// measured is the corrected factor's own solution.
Options corrected_solves_only(index_t max_corrected) {
  Options o;
  o.type = MatrixType::general;
  o.backend = Backend::cpu;
  o.relax_small = 0;
  o.relax_zeros_1 = o.relax_zeros_2 = o.relax_zeros_3 = 0;
  o.pivoting = Pivoting::corrected;
  o.max_corrected_pivots = max_corrected;
  o.refinement_max_steps = 0;
  o.gmres_max_iterations = 0;
  return o;
}

// The analysis is made for a dominant diagonal (the matching takes it); the values
// refactorized have some zero diagonal entries, so that the analysis's order meets zero
// pivots: corrected (a few of them, as in the engine's Newton matrices), or, where the
// k×k matrix is too ill-conditioned or the correction misses its probe, delayed; draws
// of n = 733 go on until two were corrected (at most 16 draws).
TEST(PivotCorrection, StaleMatchingSolvedThroughTheCorrection) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  std::uniform_real_distribution<double> u(-1, 1);
  int corrected_draws = 0;
  std::vector<index_t> sizes{2, 3, 5};
  sizes.insert(sizes.end(), 16, 733);
  for (index_t n : sizes) {
    if (corrected_draws == 2) break;
    SCOPED_TRACE("n=" + std::to_string(n));
    const SparseMatrix pattern = test::random_pattern_with_diagonal(n, 3, rng);
    const SparseMatrix a1 = test::with_values(pattern, 20.0, rng);
    // values of another draw, and one diagonal entry in 150 zero (all of them for n < 10)
    SparseMatrix a2 = test::with_values(pattern, 8.0, rng);
    test::zero_some_diagonal(a2, n < 10 ? 1 : 150, rng);
    const int nrhs = 3;
    std::vector<double> b(static_cast<std::size_t>(n) * nrhs);
    for (double& v : b) v = u(rng);
    std::vector<double> ref = b;
    if (!test::dense_solve(test::to_dense(a2), n, ref, nrhs)) continue;  // singular draw
    if (!test::structurally_nonsingular(a2)) continue;
    const double kappa = test::condition_inf(a2);
    if (!(kappa < 1e10)) continue;  // too close to singular to test a solution's digits

    Solver s(corrected_solves_only(n));
    s.factorize(a1);
    EXPECT_EQ(s.stats().factor.corrected_pivots, 0);
    s.refactorize(a2);
    const FactorStats& f = s.stats().factor;
    EXPECT_EQ(f.perturbed_pivots, 0);
    if (f.delayed_pivoting)
      EXPECT_EQ(f.corrected_pivots, 0);
    else
      EXPECT_EQ(f.corrected_pivots, f.fixed_order_perturbed_pivots);
    if (n == 733 && f.corrected_pivots > 0) ++corrected_draws;
    EXPECT_TRUE(f.inertia_valid);
    double logdet = 0;
    int sign = 0;
    test::dense_logdet(a2, &logdet, &sign);
    EXPECT_NEAR(f.log_abs_determinant, logdet, 1e-9 * std::max(1.0, std::abs(logdet)));
    EXPECT_EQ(f.determinant_sign, sign);

    // the correction's (or delayed pivoting's) solution without refinement: backward
    // stable to the conditioning (the formula is not backward stable in general, Yip 1986:
    // its error grows with the conditioning of A + E and of the k×k matrix, which the rcond
    // test and the probe bound). A draw whose fixed order needed no static pivot is not
    // this test's: its pivots, small but not static, may grow the factor unchecked.
    if (f.fixed_order_perturbed_pivots == 0) continue;
    std::vector<double> x(b.size());
    s.solve(b.data(), x.data(), nrhs);
    const SolveStats& ss = s.stats().solve;
    EXPECT_EQ(ss.refinement_steps, 0);
    EXPECT_LE(ss.backward_error, std::max(1e-13, 1e-14 * kappa))
        << "kappa " << kappa << ", static pivots " << f.fixed_order_perturbed_pivots
        << ", corrected " << f.corrected_pivots << ", delayed " << f.delayed_pivoting;
    const double tol = std::max(1e-12, 1e-14 * n * kappa);
    EXPECT_LE(test::relative_difference(x, ref), tol);
    // one column at a time: the solution of each
    for (int c = 0; c < nrhs; ++c) {
      const std::vector<double> bc(b.begin() + c * n, b.begin() + (c + 1) * n);
      const std::vector<double> rc(ref.begin() + c * n, ref.begin() + (c + 1) * n);
      EXPECT_LE(test::relative_difference(s.solve(bc), rc), tol);
    }
  }
  EXPECT_EQ(corrected_draws, 2);
}

// Values moving by six decades between refactorizations (contact-like: rows scaled by
// 1e6 or 1e-6) with the analysis of the first: no perturbed pivot in any factor, whether
// corrected or delayed, and the solve (checked and refined, Options' default) at the
// tolerance.
TEST(PivotCorrection, ValuesChangingBySixDecadesBetweenRefactorizations) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  std::uniform_real_distribution<double> u(-1, 1);
  std::uniform_int_distribution<int> coin(0, 9);
  const index_t n = 733;
  const SparseMatrix pattern = test::random_pattern_with_diagonal(n, 4, rng);
  Options o = corrected_solves_only(n);  // leaf fronts: static pivots in every step
  o.refinement_max_steps = Options{}.refinement_max_steps;
  o.gmres_max_iterations = Options{}.gmres_max_iterations;
  Solver s(o);
  s.factorize(test::with_values(pattern, 10.0, rng));
  for (int step = 0; step < 6; ++step) {
    SCOPED_TRACE("step " + std::to_string(step));
    SparseMatrix a = test::with_values(pattern, u(rng), rng);
    std::vector<double> rs(n);
    for (double& r : rs) r = coin(rng) == 0 ? 1e6 : coin(rng) == 0 ? 1e-6 : 1.0;
    // and one diagonal entry in ten zero: pivots the analysis's order cannot take
    for (index_t j = 0; j < n; ++j) {
      const bool zero = coin(rng) == 0;
      for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p) {
        if (zero && a.indices[p] == j) a.values[p] = 0.0;
        a.values[p] *= rs[a.indices[p]];
      }
    }
    std::vector<double> rhs(n), ref;
    for (double& v : rhs) v = u(rng);
    ref = rhs;
    if (!test::dense_solve(test::to_dense(a), n, ref, 1)) continue;
    s.refactorize(a);
    const FactorStats& f = s.stats().factor;
    EXPECT_EQ(f.perturbed_pivots, 0);
    EXPECT_GT(f.fixed_order_perturbed_pivots, 0);
    // corrected, or (κ(A) here reaches 1e15: its k×k matrix too ill-conditioned to keep
    // half of the digits) delayed
    if (f.delayed_pivoting)
      EXPECT_EQ(f.corrected_pivots, 0);
    else
      EXPECT_EQ(f.corrected_pivots, f.fixed_order_perturbed_pivots);
    s.solve(rhs);
    EXPECT_LE(s.stats().solve.backward_error, 1e-14);
    EXPECT_TRUE(s.stats().solve.refinement_converged);
  }
}

// The same on a 9×9×9 grid's pattern with the default amalgamation: large fronts (the
// recursive LU of the pivot block) meet the zero pivots.
TEST(PivotCorrection, StaleMatchingInLargeFronts) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  std::uniform_real_distribution<double> u(-1, 1);
  const SparseMatrix pattern = expand_symmetric(generators::laplacian_3d(9, 9, 9));
  const index_t n = pattern.n_rows;
  SparseMatrix a2 = test::with_values(pattern, 8.0, rng);
  test::zero_some_diagonal(a2, 10, rng);
  std::vector<double> b(n);
  for (double& v : b) v = u(rng);
  std::vector<double> ref = b;
  if (!test::dense_solve(test::to_dense(a2), n, ref, 1)) GTEST_SKIP() << "a singular draw";
  const double kappa = test::condition_inf(a2);
  Options o = corrected_solves_only(n);
  o.relax_small = Options{}.relax_small;
  o.relax_zeros_1 = Options{}.relax_zeros_1;
  o.relax_zeros_2 = Options{}.relax_zeros_2;
  o.relax_zeros_3 = Options{}.relax_zeros_3;
  Solver s(o);
  s.factorize(test::with_values(pattern, 20.0, rng));
  s.refactorize(a2);
  const FactorStats& f = s.stats().factor;
  EXPECT_GT(f.fixed_order_perturbed_pivots, 0);
  EXPECT_EQ(f.perturbed_pivots, 0);
  if (!f.delayed_pivoting) EXPECT_EQ(f.corrected_pivots, f.fixed_order_perturbed_pivots);
  double logdet = 0;
  int sign = 0;
  test::dense_logdet(a2, &logdet, &sign);
  EXPECT_NEAR(f.log_abs_determinant, logdet, 1e-9 * std::max(1.0, std::abs(logdet)));
  EXPECT_EQ(f.determinant_sign, sign);
  EXPECT_LE(test::relative_difference(s.solve(b), ref), std::max(1e-12, 1e-14 * n * kappa));
  RecordProperty("corrected pivots", std::to_string(f.corrected_pivots));
}

// The engine's Options::solve_check = after_perturbed_pivots: a factorization without
// static pivots leaves its solves unchecked (backward error NaN), a corrected one has
// every solve checked and refined (the correction is not backward stable), to dgesv's
// solution.
TEST(PivotCorrection, CorrectedSolvesAreCheckedWhereOnlyPerturbedOnesWouldBe) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  std::uniform_real_distribution<double> u(-1, 1);
  const index_t n = 733;
  int corrected = 0;
  for (int draw = 0; draw < 10 && corrected == 0; ++draw) {
    const SparseMatrix pattern = test::random_pattern_with_diagonal(n, 3, rng);
    Options o = corrected_solves_only(n);
    o.solve_check = SolveCheck::after_perturbed_pivots;
    o.refinement_max_steps = Options{}.refinement_max_steps;
    o.gmres_max_iterations = Options{}.gmres_max_iterations;
    Solver s(o);
    s.factorize(test::with_values(pattern, 20.0, rng));
    std::vector<double> b(n);
    for (double& v : b) v = u(rng);
    s.refactorize(test::with_values(pattern, 20.0, rng));
    ASSERT_EQ(s.stats().factor.fixed_order_perturbed_pivots, 0);
    s.solve(b);
    EXPECT_TRUE(std::isnan(s.stats().solve.backward_error));

    SparseMatrix a2 = test::with_values(pattern, 8.0, rng);
    test::zero_some_diagonal(a2, 50, rng);
    std::vector<double> ref = b;
    if (!test::dense_solve(test::to_dense(a2), n, ref, 1) || !test::structurally_nonsingular(a2))
      continue;
    const double kappa = test::condition_inf(a2);
    if (!(kappa < 1e10)) continue;
    s.refactorize(a2);
    if (s.stats().factor.corrected_pivots == 0) continue;  // delayed instead: drawn again
    ++corrected;
    const std::vector<double> x = s.solve(b);
    const SolveStats& ss = s.stats().solve;
    ASSERT_FALSE(std::isnan(ss.backward_error));
    EXPECT_LE(ss.backward_error, 1e-14);
    EXPECT_TRUE(ss.refinement_converged);
    EXPECT_LE(test::relative_difference(x, ref), std::max(1e-12, 1e-14 * n * kappa));
  }
  EXPECT_EQ(corrected, 1);
}

// Stars of five nodes (three leaves joined to two roots, numbered leaves first) and, for
// n not a multiple of five, a dense diagonal block of the rest. Analysis values: diagonal
// 10, off-diagonal entries in [-1, 1]. Refactorized values: in the first three stars (a
// few static pivots, as in the engine's Newton matrices) a leaf with diagonal delta joined
// to both roots by 1 (a pivot that is small but not static when delta is, and a Schur
// complement of rank one and size 1/delta at the roots) and a leaf with a zero diagonal
// (a static pivot, corrected); every other leaf regular, the root blocks dominant
// (diagonals ±(10 + [0.5, 1]), so that no shift brings the factor near a singular one).
SparseMatrix stars(index_t n, bool refactorized, double delta, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(0.5, 1.0);
  std::bernoulli_distribution sign(0.5);
  auto draw = [&] { return sign(rng) ? u(rng) : -u(rng); };
  std::vector<std::vector<std::pair<index_t, double>>> col(n);
  auto add = [&](index_t i, index_t j, double v) { col[j].push_back({i, v}); };
  const index_t n_stars = n / 5;
  for (index_t s = 0; s < n_stars; ++s) {
    const index_t b = 5 * s, r1 = b + 3, r2 = b + 4;
    for (index_t l = b; l < b + 3; ++l) {
      double diag = 10, to1 = draw(), to2 = draw(), from1 = draw(), from2 = draw();
      if (refactorized) diag = 3 * u(rng);
      if (refactorized && s < 3 && l == b) diag = delta, to1 = to2 = from1 = from2 = 1.0;
      if (refactorized && s < 3 && l == b + 1) diag = 0;
      add(l, l, diag);
      add(r1, l, to1);
      add(r2, l, to2);
      add(l, r1, from1);
      add(l, r2, from2);
    }
    add(r1, r1, refactorized ? 10 + u(rng) : 10);
    add(r2, r2, refactorized ? -10 - u(rng) : 10);
    add(r1, r2, 0.5 * draw());
    add(r2, r1, 0.5 * draw());
  }
  for (index_t j = 5 * n_stars; j < n; ++j)
    for (index_t i = 5 * n_stars; i < n; ++i) add(i, j, i == j ? 10.0 : draw());
  SparseMatrix a;
  a.n_rows = a.n_cols = n;
  a.offsets.assign(1, 0);
  for (index_t j = 0; j < n; ++j) {
    for (const auto& [i, v] : col[j]) {
      a.indices.push_back(i);
      a.values.push_back(v);
    }
    a.offsets.push_back(static_cast<index_t>(a.indices.size()));
  }
  return a;
}

// A correction whose solves would miss the backward error of a checked solve: the fixed
// order's factor of A + E grows by 1/delta at a leaf's small pivot that is not a static
// one, so the probe's corrected solve (core/pivot_correction.hpp) fails the test and
// delayed pivoting factors instead, with dgesv's solution; the same stars with a regular
// small leaf (delta = 0.5) are corrected.
TEST(PivotCorrection, CorrectionThatMissesTheProbeGoesToDelayedPivoting) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  std::uniform_real_distribution<double> u(-1, 1);
  for (index_t n : {5, 733}) {
    for (double delta : {0.5, 1e-6}) {
      SCOPED_TRACE("n=" + std::to_string(n) + " delta=" + std::to_string(delta));
      Options o = corrected_solves_only(n);
      o.ordering = OrderingMethod::natural;  // every leaf before its roots
      Solver s(o);
      s.factorize(stars(n, false, delta, rng));
      ASSERT_EQ(s.stats().factor.fixed_order_perturbed_pivots, 0);
      const SparseMatrix a2 = stars(n, true, delta, rng);
      std::vector<double> b(n);
      for (double& v : b) v = u(rng);
      std::vector<double> ref = b;
      ASSERT_TRUE(test::dense_solve(test::to_dense(a2), n, ref, 1));
      const double kappa = test::condition_inf(a2);
      s.refactorize(a2);
      const FactorStats& f = s.stats().factor;
      const index_t zero_leaves = std::min<index_t>(n / 5, 3);
      EXPECT_EQ(f.fixed_order_perturbed_pivots, zero_leaves);
      EXPECT_EQ(f.perturbed_pivots, 0);
      ASSERT_TRUE(std::isfinite(f.correction_backward_error));  // the probe decided
      if (delta < 1e-3) {
        EXPECT_GT(f.correction_backward_error, 1e-13);
        EXPECT_EQ(f.corrected_pivots, 0);
        EXPECT_TRUE(f.delayed_pivoting);
      } else {
        EXPECT_LE(f.correction_backward_error, 1e-14);
        EXPECT_EQ(f.corrected_pivots, zero_leaves);
        EXPECT_FALSE(f.delayed_pivoting);
      }
      // unrefined (refinement_max_steps 0): the probe's right-hand side reached a checked
      // solve's level; another one within a factor 10 of it
      const std::vector<double> x = s.solve(b);
      EXPECT_LE(
          s.stats().solve.backward_error,
          10 * std::max(Options{}.refinement_tolerance, s.stats().solve.backward_error_floor));
      EXPECT_LE(test::relative_difference(x, ref), std::max(1e-12, 1e-14 * n * kappa))
          << "kappa " << kappa;
    }
  }
}

// A nonsingular 1×1 matrix needs no static pivot: nothing to correct.
TEST(PivotCorrection, OneByOneNeedsNone) {
  auto rng = test::fresh_rng();
  std::uniform_real_distribution<double> u(0.5, 2);
  SparseMatrix a = test::with_values(test::random_pattern_with_diagonal(1, 1, rng), 1.0, rng);
  a.values[0] = -u(rng);
  Solver s(corrected_solves_only(64));
  s.factorize(a);
  EXPECT_EQ(s.stats().factor.corrected_pivots, 0);
  EXPECT_EQ(s.stats().factor.perturbed_pivots, 0);
  EXPECT_TRUE(std::isnan(s.stats().factor.correction_backward_error));  // no probe ran
  const std::vector<double> x = s.solve(std::vector<double>{3.0});
  EXPECT_NEAR(x[0], 3.0 / a.values[0], 1e-15 * std::abs(x[0]));
}

// More static pivots than max_corrected_pivots: delayed pivoting factors instead, with the
// solution of dense LAPACK.
TEST(PivotCorrection, TooManyPivotsGoToDelayedPivoting) {
  auto rng = test::fresh_rng();
  std::uniform_real_distribution<double> u(-1, 1);
  const index_t n = 733;
  const SparseMatrix pattern = test::random_pattern_with_diagonal(n, 3, rng);
  SparseMatrix a2 = test::with_values(pattern, 1.0, rng);
  test::zero_some_diagonal(a2, 10, rng);
  std::vector<double> b(n);
  for (double& v : b) v = u(rng);
  std::vector<double> ref = b;
  if (!test::dense_solve(test::to_dense(a2), n, ref, 1) || !test::structurally_nonsingular(a2))
    GTEST_SKIP() << "a singular draw";
  Solver one(corrected_solves_only(1));
  one.factorize(test::with_values(pattern, 20.0, rng));
  one.refactorize(a2);
  const FactorStats& f = one.stats().factor;
  ASSERT_GT(f.fixed_order_perturbed_pivots, 1);
  EXPECT_EQ(f.corrected_pivots, 0);
  EXPECT_TRUE(f.delayed_pivoting);
  EXPECT_EQ(f.perturbed_pivots, 0);
  const double kappa = test::condition_inf(a2);
  EXPECT_LE(test::relative_difference(one.solve(b), ref), std::max(1e-12, 1e-14 * n * kappa));
}

// A numerically singular matrix: its correction's k×k matrix is singular, so delayed
// pivoting factors it and reports the static pivots it needs at the root.
TEST(PivotCorrection, SingularMatrixIsStillReported) {
  auto rng = test::fresh_rng();
  for (index_t n : {2, 5, 733}) {
    SCOPED_TRACE("n=" + std::to_string(n));
    const SparseMatrix pattern = test::random_pattern_with_diagonal(n, 3, rng);
    Solver s(corrected_solves_only(n));
    s.factorize(test::with_values(pattern, 20.0, rng));
    SparseMatrix a2 = test::with_values(pattern, 0.0, rng);
    const index_t dead = n / 2;
    for (index_t j = 0; j < n; ++j)
      for (index_t p = a2.offsets[j]; p < a2.offsets[j + 1]; ++p)
        if (a2.indices[p] == dead) a2.values[p] = 0.0;
    s.refactorize(a2);
    EXPECT_EQ(s.stats().factor.corrected_pivots, 0);
    EXPECT_GE(s.stats().factor.perturbed_pivots, 1);
    EXPECT_FALSE(s.stats().factor.inertia_valid);
  }
}

// The pivoting by name, as the CLI's --pivoting and the Python options give it.
TEST(PivotCorrection, ParsedByName) {
  Options o;
  set_option(o, "pivoting", "corrected");
  EXPECT_EQ(o.pivoting, Pivoting::corrected);
  set_option(o, "max_corrected_pivots", "7");
  EXPECT_EQ(o.max_corrected_pivots, 7);
  set_option(o, "max_corrected_pivots", "-1");
  EXPECT_THROW(validate(o), InvalidInput);
}

}  // namespace
}  // namespace strata
