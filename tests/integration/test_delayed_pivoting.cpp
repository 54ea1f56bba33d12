// Delayed pivoting (Options::pivoting; numeric/delayed.hpp) through the Solver:
// an analysis made for values whose matching is wrong for the values refactorized — the
// Newton loop of a simulation whose contacts and rotations changed — must still factor
// without static pivots, with the solution of dense LAPACK (dgesv) and log|det| and sign
// of its LU (dgetrf), a backward error at the tolerance (without GMRES where delayed
// pivoting computed the factor), and the statistics saying which mechanism was used. A numerically
// singular matrix is still reported as such (static pivots at the root). Options::solve_check skips
// the check of a solution only when no pivot was perturbed.
#include <gtest/gtest.h>

#include <cfloat>
#include <cmath>
#include <functional>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "base/blas.hpp"
#include "sparse/generators.hpp"
#include "strata/strata.hpp"
#include "support/test_support.hpp"

namespace strata {
namespace {

// LU on the CPU with fundamental supernodes only (no amalgamation): leaf fronts of one
// pivot, which a zero diagonal leaves without a pivot in the analysis's order.
Options leaf_fronts() {
  Options o;
  o.type = MatrixType::general;
  o.backend = Backend::cpu;
  o.relax_small = 0;
  o.relax_zeros_1 = o.relax_zeros_2 = o.relax_zeros_3 = 0;
  return o;
}

// Delayed pivoting with the triangular solves alone (no refinement, no GMRES).
Options delayed_solves_only() {
  Options o = leaf_fronts();
  o.pivoting = Pivoting::delayed;
  o.refinement_max_steps = 0;
  o.gmres_max_iterations = 0;
  return o;
}

// ‖A‖∞·‖x‖∞/‖b‖∞: a lower bound on κ∞(A) that sets the forward-error tolerance.
double kappa_lower(const SparseMatrix& a, const std::vector<double>& x,
                   const std::vector<double>& b) {
  std::vector<double> row(a.n_rows, 0.0);
  for (index_t j = 0; j < a.n_cols; ++j)
    for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p)
      row[a.indices[p]] += std::abs(a.values[p]);
  double an = 0, xn = 0, bn = 0;
  for (double v : row) an = std::max(an, v);
  for (double v : x) xn = std::max(xn, std::abs(v));
  for (double v : b) bn = std::max(bn, std::abs(v));
  return an * xn / std::max(bn, 1e-300);
}

// The analysis is made for a dominant diagonal (the matching takes it); the values
// refactorized have a zero diagonal, so every pivot of the analysis's order is zero.
TEST(DelayedPivoting, StaleMatchingFactorsWithoutStaticPivots) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  std::uniform_real_distribution<double> u(-1, 1);
  for (index_t n : {2, 3, 5, 733}) {
    SCOPED_TRACE("n=" + std::to_string(n));
    const SparseMatrix pattern = test::random_pattern_with_diagonal(n, 3, rng);
    const SparseMatrix a1 = test::with_values(pattern, 20.0, rng);
    SparseMatrix a2 = test::with_values(pattern, 0.0, rng);
    const Options o = leaf_fronts();
    Solver s(o);
    s.factorize(a1);
    EXPECT_FALSE(s.stats().factor.delayed_pivoting);
    std::vector<double> b(n), ref;
    for (double& v : b) v = u(rng);
    ref = b;
    if (!test::dense_solve(test::to_dense(a2), n, ref, 1)) continue;  // singular draw
    if (!test::structurally_nonsingular(a2)) continue;  // singular exactly, whatever LU rounds to
    s.refactorize(a2);
    const FactorStats& f = s.stats().factor;
    EXPECT_EQ(f.perturbed_pivots, 0);
    // small matrices may be one front, where pivoting among its rows suffices
    const bool delayed = f.delayed_pivoting;
    if (n == 733) {
      EXPECT_TRUE(f.delayed_pivoting);
      EXPECT_GT(f.fixed_order_perturbed_pivots, 0);
      EXPECT_GT(f.delayed_pivots, 0);
    }
    EXPECT_TRUE(f.inertia_valid);
    double logdet = 0;
    int sign = 0;
    test::dense_logdet(a2, &logdet, &sign);
    EXPECT_NEAR(f.log_abs_determinant, logdet, 1e-9 * std::max(1.0, std::abs(logdet)));
    EXPECT_EQ(f.determinant_sign, sign);
    const std::vector<double> x = s.solve(b);
    EXPECT_LE(s.stats().solve.backward_error, 1e-14);
    EXPECT_EQ(s.stats().solve.gmres_iterations, 0);
    EXPECT_LE(test::relative_difference(x, ref),
              std::max(1e-10, 1e-13 * std::sqrt(double(n)) * kappa_lower(a2, ref, b)));
    // the same values again: the same factor, bit for bit (no state carried over)
    s.refactorize(a2);
    EXPECT_EQ(s.stats().factor.delayed_pivoting, delayed);
    const std::vector<double> x2 = s.solve(b);
    EXPECT_EQ(x2, x);
    // Pivoting::delayed: the delayed factorization directly, the same solution
    Options od = o;
    od.pivoting = Pivoting::delayed;
    Solver sd(od);
    sd.analyze(a1);
    sd.factorize(a2);
    EXPECT_TRUE(sd.stats().factor.delayed_pivoting);
    EXPECT_EQ(sd.stats().factor.fixed_order_perturbed_pivots, 0);
    EXPECT_EQ(sd.stats().factor.perturbed_pivots, 0);
    EXPECT_LE(test::relative_difference(sd.solve(b), ref),
              std::max(1e-10, 1e-13 * std::sqrt(double(n)) * kappa_lower(a2, ref, b)));
    // set_pivoting: the next factorizations use the new choice, the analysis stays
    s.set_pivoting(Pivoting::delayed);
    s.refactorize(a1);
    EXPECT_TRUE(s.stats().factor.delayed_pivoting);
    EXPECT_EQ(s.stats().factor.fixed_order_perturbed_pivots, 0);
    s.set_pivoting(Pivoting::automatic);
    s.refactorize(a1);
    EXPECT_FALSE(s.stats().factor.delayed_pivoting);
  }
}

// A contact-like sequence: between refactorizations, random rows are multiplied by 10^±6
// (stiff contacts closing and opening) and the diagonal, which the first values' matching
// chose, is redrawn in (-1, 1). No static pivot and a backward error at the tolerance, both
// for Pivoting::automatic and Pivoting::delayed. Only the delayed factorization bounds its
// multipliers by 1/pivot_threshold over whole columns, so only it is held to a solve
// without GMRES: the fixed order, which the automatic choice keeps while no pivot is tiny,
// bounds them within the fully summed rows alone, and a diagonal near zero (one draw in
// several hundred) can leave its first solve with a backward error near 1e-3, which
// refinement and GMRES then bring to the tolerance.
TEST(DelayedPivoting, ValuesChangingBySixDecadesBetweenRefactorizations) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  std::uniform_real_distribution<double> u(-1, 1);
  std::uniform_int_distribution<int> coin(0, 9);
  const index_t n = 733;
  const SparseMatrix pattern = test::random_pattern_with_diagonal(n, 4, rng);
  SparseMatrix a = test::with_values(pattern, 10.0, rng);
  Options o;
  o.type = MatrixType::general;
  o.backend = Backend::cpu;
  Solver s(o);
  s.factorize(a);
  Options od = o;
  od.pivoting = Pivoting::delayed;
  Solver sd(od);
  sd.analyze(a);
  for (int step = 0; step < 6; ++step) {
    SCOPED_TRACE("step " + std::to_string(step));
    SparseMatrix b_mat = test::with_values(pattern, u(rng), rng);
    std::vector<double> rs(n);
    for (double& r : rs) r = coin(rng) == 0 ? 1e6 : coin(rng) == 0 ? 1e-6 : 1.0;
    for (index_t j = 0; j < n; ++j)
      for (index_t p = b_mat.offsets[j]; p < b_mat.offsets[j + 1]; ++p)
        b_mat.values[p] *= rs[b_mat.indices[p]];
    std::vector<double> rhs(n), ref;
    for (double& v : rhs) v = u(rng);
    ref = rhs;
    if (!test::dense_solve(test::to_dense(b_mat), n, ref, 1)) continue;
    s.refactorize(b_mat);
    EXPECT_EQ(s.stats().factor.perturbed_pivots, 0);
    s.solve(rhs);
    EXPECT_LE(s.stats().solve.backward_error, 1e-14);
    EXPECT_TRUE(s.stats().solve.refinement_converged);
    sd.factorize(b_mat);
    EXPECT_TRUE(sd.stats().factor.delayed_pivoting);
    EXPECT_EQ(sd.stats().factor.perturbed_pivots, 0);
    sd.solve(rhs);
    EXPECT_LE(sd.stats().solve.backward_error, 1e-14);
    EXPECT_EQ(sd.stats().solve.gmres_iterations, 0);
  }
}

// Numerically singular: a row of zero values (its pattern kept). The root has nothing to
// pivot on: a static pivot, counted, and the statistics say the matrix is singular.
TEST(DelayedPivoting, SingularMatrixIsStillReported) {
  auto rng = test::fresh_rng();
  for (index_t n : {1, 2, 5, 733}) {
    SCOPED_TRACE("n=" + std::to_string(n));
    const SparseMatrix pattern = test::random_pattern_with_diagonal(n, 3, rng);
    Solver s(leaf_fronts());
    s.factorize(test::with_values(pattern, 20.0, rng));
    SparseMatrix a2 = test::with_values(pattern, 0.0, rng);
    const index_t dead = n / 2;
    for (index_t j = 0; j < n; ++j)
      for (index_t p = a2.offsets[j]; p < a2.offsets[j + 1]; ++p)
        if (a2.indices[p] == dead) a2.values[p] = 0.0;
    s.refactorize(a2);
    EXPECT_GE(s.stats().factor.perturbed_pivots, 1);
    EXPECT_FALSE(s.stats().factor.inertia_valid);
  }
}

// A 3D grid's pattern (even, so that the zero diagonal leaves it structurally nonsingular)
// with a stale matching: analyzed with the values a1 (diagonal 20), factored with a2 (zero
// diagonal), so that pivots are delayed across the subtrees' roots into the top of the
// tree; nrhs random right-hand sides b and dense LAPACK's (dgesv) solution ref.
struct StaleGrid {
  index_t n = 0;
  SparseMatrix a1, a2;
  std::vector<double> b, ref;
  double kappa = 0;  // LAPACK's estimate of κ∞(a2)
  StaleGrid(index_t nx, index_t ny, index_t nz, int nrhs, std::mt19937_64& rng) {
    std::uniform_real_distribution<double> u(-1, 1);
    const SparseMatrix grid = expand_symmetric(generators::laplacian_3d(nx, ny, nz));
    n = grid.n_rows;
    a1 = test::with_values(grid, 20.0, rng);
    a2 = test::with_values(grid, 0.0, rng);
    b.resize(static_cast<std::size_t>(nrhs) * n);
    for (double& v : b) v = u(rng);
    ref = b;
    EXPECT_TRUE(test::dense_solve(test::to_dense(a2), n, ref, nrhs));
    kappa = test::condition_inf(a2);
  }
  // The delayed factor's solution on `threads` threads, and the threads its solve used.
  std::vector<double> solve(int threads, int* host_threads) const {
    Options o = delayed_solves_only();
    o.num_threads = threads;
    Solver s(o);
    s.analyze(a1);
    s.factorize(a2);
    EXPECT_GT(s.stats().factor.delayed_pivots, 0);
    const std::vector<double> x = s.solve(b);
    *host_threads = s.stats().solve.host_threads;
    EXPECT_EQ(s.solve(b), x);  // bit for bit the same from one solve to the next
    return x;
  }
  // The tolerance against ref of column c: the lower bound ‖A‖‖x‖/‖b‖ of κ can be far
  // below κ for a zero-diagonal draw, so LAPACK's estimate of κ∞ sets it too (both
  // solutions are backward stable).
  double tolerance(int c) const {
    const std::vector<double> rc(ref.begin() + c * n, ref.begin() + (c + 1) * n);
    const std::vector<double> bc(b.begin() + c * n, b.begin() + (c + 1) * n);
    return std::max(1e-10, 1e-13 * std::sqrt(double(n)) * std::max(kappa_lower(a2, rc, bc), kappa));
  }
};

// The solve of a delayed factor by subtrees on several threads: dense LAPACK's solution
// for 2 and 4 threads as for 1, on a grid whose factor has enough entries for a share on
// each of 4 threads (see SmallFactorSolvesOnFewerThreads), two right-hand sides.
TEST(DelayedPivoting, SolveBySubtreesOnSeveralThreadsMatchesDenseLu) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  const StaleGrid g(16, 15, 15, 2, rng);
  const index_t n = g.n;
  const double tol[2] = {g.tolerance(0), g.tolerance(1)};
  std::vector<double> one_thread;
  for (int threads : {1, 2, 4}) {
    SCOPED_TRACE("threads " + std::to_string(threads));
    int used = 0;
    const std::vector<double> x = g.solve(threads, &used);
    EXPECT_EQ(used, threads);
    if (threads == 1) one_thread = x;
    for (int c = 0; c < 2; ++c) {
      const std::vector<double> xc(x.begin() + c * n, x.begin() + (c + 1) * n);
      const std::vector<double> x1(one_thread.begin() + c * n, one_thread.begin() + (c + 1) * n);
      const std::vector<double> rc(g.ref.begin() + c * n, g.ref.begin() + (c + 1) * n);
      // Without refinement the delayed factor's backward error shows the growth that
      // threshold pivoting allows (Higham 2002, §9.5; up to 5e-9 seen on these draws,
      // against 1e-16 for dgesv), so the forward error is bounded by κ times both
      // solutions' backward errors where that exceeds the plain bound.
      const std::vector<double> bc(g.b.begin() + c * n, g.b.begin() + (c + 1) * n);
      const double eta = test::backward_error(g.a2, xc.data(), bc.data());
      EXPECT_LE(eta, 1e-6);  // a factor of a2, not something else
      const double eta_ref = test::backward_error(g.a2, rc.data(), bc.data());
      const double bound = std::max(tol[c], 4 * g.kappa * (eta + eta_ref));
      EXPECT_LE(test::relative_difference(xc, rc), bound);
      EXPECT_LE(test::relative_difference(xc, x1), bound);  // the sums differ only in order
    }
  }
}

// The delayed factorization on several threads (a front starts when its last child is
// done, in whatever order the threads finish) gives the factor of one thread: the same
// delayed pivots and, bit for bit, the same determinant (summed front by front in tree
// order, so one front factored differently would show).
TEST(DelayedPivoting, FactorDoesNotDependOnTheThreads) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  const StaleGrid g(12, 11, 11, 1, rng);
  auto factor = [&](int threads) {
    Options o = delayed_solves_only();
    o.num_threads = threads;
    Solver s(o);
    s.analyze(g.a1);
    s.factorize(g.a2);
    return s.stats().factor;
  };
  const FactorStats one = factor(1);
  EXPECT_GT(one.delayed_pivots, 0);
  for (int threads : {2, 3, 5, 8}) {
    SCOPED_TRACE("threads " + std::to_string(threads));
    for (int rep = 0; rep < 3; ++rep) {  // a race would show in some repetition
      const FactorStats f = factor(threads);
      EXPECT_EQ(f.delayed_pivots, one.delayed_pivots);
      EXPECT_EQ(f.fronts_delaying, one.fronts_delaying);
      EXPECT_EQ(f.perturbed_pivots, one.perturbed_pivots);
      EXPECT_EQ(f.determinant_sign, one.determinant_sign);
      EXPECT_EQ(f.log_abs_determinant, one.log_abs_determinant);
    }
  }
}

// A small factor is solved on fewer threads than the solver has: each thread of the solve
// gets a least share of the factor's entries (numeric/delayed.cpp, kMinBinWork), and a
// 7-point grid of 810 unknowns has less than two shares. Its solution is still dense
// LAPACK's, on 4 threads as on 1.
TEST(DelayedPivoting, SmallFactorSolvesOnFewerThreads) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  const StaleGrid g(10, 9, 9, 1, rng);
  const double tol = g.tolerance(0);
  for (int threads : {1, 4}) {
    SCOPED_TRACE("threads " + std::to_string(threads));
    int used = 0;
    const std::vector<double> x = g.solve(threads, &used);
    EXPECT_EQ(used, 1);
    EXPECT_LE(test::relative_difference(x, g.ref), tol);
  }
}

// Explicit zeros in the pattern (a contact problem's Newton matrix keeps the entries of
// pairs not in contact, with value 0): the solve skips the factor's zero rows of L21 and
// zero columns of U12, and must still give dense LAPACK's solution, for a dense and a
// sparse right-hand side, with the stale matching of the first values.
TEST(DelayedPivoting, ExplicitZerosSolveLikeDenseLu) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  std::uniform_real_distribution<double> u(-1, 1);
  for (index_t n : {1, 2, 3, 5, 733}) {
    SCOPED_TRACE("n=" + std::to_string(n));
    const SparseMatrix pattern = test::random_pattern_with_diagonal(n, 6, rng);
    const SparseMatrix a1 = test::with_values(pattern, 10.0, rng);
    SparseMatrix a2 = test::with_values(pattern, 0.0, rng);
    index_t zeros = 0;
    for (index_t j = 0; j < n; ++j)  // about two thirds of the off-diagonal entries zero
      for (index_t p = a2.offsets[j]; p < a2.offsets[j + 1]; ++p)
        if (a2.indices[p] == j) {
          a2.values[p] = u(rng);  // no longer dominant: the first values' matching is stale
        } else if (u(rng) < 0.33) {
          a2.values[p] = 0.0;
          ++zeros;
        }
    std::vector<double> b(2 * n, 0.0);
    for (index_t i = 0; i < n; ++i) b[i] = u(rng);
    b[n + (n - 1) / 2] = 1.0;  // sparse: one nonzero
    std::vector<double> ref = b;
    if (!test::dense_solve(test::to_dense(a2), n, ref, 2)) continue;  // singular draw
    if (!test::structurally_nonsingular(a2)) continue;  // singular exactly, whatever LU rounds to
    Solver s(delayed_solves_only());
    s.analyze(a1);
    s.factorize(a2);
    EXPECT_EQ(s.stats().factor.perturbed_pivots, 0);
    const std::vector<double> x = s.solve(b);
    for (int c = 0; c < 2; ++c) {
      const std::vector<double> xc(x.begin() + c * n, x.begin() + (c + 1) * n);
      const std::vector<double> rc(ref.begin() + c * n, ref.begin() + (c + 1) * n);
      const std::vector<double> bc(b.begin() + c * n, b.begin() + (c + 1) * n);
      const double tol = std::max(1e-10, 1e-13 * std::sqrt(double(n)) * kappa_lower(a2, rc, bc));
      EXPECT_LE(test::relative_difference(xc, rc), tol) << zeros << " explicit zeros";
    }
  }
}

// Options::solve_check = after_perturbed_pivots (the engine's Newton loop): a factor
// without perturbed pivots gives the triangular solves' x unchecked (bit for bit the x of
// a solve with refinement off, the backward error NaN, dense LAPACK's solution to the
// conditioning); a factor with perturbed pivots is still checked and refined (the
// backward error computed, as small as with the default).
TEST(DelayedPivoting, SolveCheckAfterPerturbedPivotsOnly) {
  auto rng = test::fresh_rng();
  std::uniform_real_distribution<double> u(-1, 1);
  for (index_t n : {1, 2, 3, 5, 733}) {
    SCOPED_TRACE("n=" + std::to_string(n));
    const SparseMatrix pattern = test::random_pattern_with_diagonal(n, 3, rng);
    const SparseMatrix a = test::with_values(pattern, 0.0, rng);
    std::vector<double> b(n);
    for (double& v : b) v = u(rng);
    std::vector<double> ref = b;
    if (!test::dense_solve(test::to_dense(a), n, ref, 1)) continue;  // singular draw
    Options unchecked = leaf_fronts(), plain = leaf_fronts();
    unchecked.pivoting = plain.pivoting = Pivoting::delayed;
    unchecked.solve_check = SolveCheck::after_perturbed_pivots;
    plain.refinement_max_steps = 0;
    plain.gmres_max_iterations = 0;
    Solver s(unchecked), p(plain);
    // a structurally singular draw (the zero diagonal leaves no perfect matching): singular
    // exactly, though the dense LU above may see only rounding-sized pivots
    if (!test::structurally_nonsingular(a)) {
      EXPECT_THROW(s.factorize(a), InvalidInput);
      continue;
    }
    s.factorize(a);
    p.factorize(a);
    if (s.stats().factor.perturbed_pivots > 0) continue;  // numerically singular draw
    const std::vector<double> x = s.solve(b);
    EXPECT_TRUE(std::isnan(s.stats().solve.backward_error));
    EXPECT_EQ(s.stats().solve.refinement_steps, 0);
    EXPECT_FALSE(s.stats().solve.refinement_converged);
    EXPECT_EQ(x, p.solve(b));
    EXPECT_LE(test::relative_difference(x, ref),
              std::max(1e-12, 1e-14 * std::sqrt(double(n)) * kappa_lower(a, ref, b)));
  }
  // numerically singular (a row and column of explicit zeros; b in the range): checked
  // and refined
  const index_t n = 5;
  const SparseMatrix pattern = test::random_pattern_with_diagonal(n, 3, rng);
  const SparseMatrix healthy = test::with_values(pattern, 20.0, rng);
  SparseMatrix a = healthy;
  for (index_t j = 0; j < n; ++j)
    for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p)
      if (a.indices[p] == 2 || j == 2) a.values[p] = 0.0;
  std::vector<double> x0(n, 1.0), b(n, 0.0);
  x0[2] = 0.0;
  for (index_t j = 0; j < n; ++j)
    for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p)
      b[a.indices[p]] += a.values[p] * x0[j];
  Options o = leaf_fronts();
  o.pivoting = Pivoting::delayed;
  o.solve_check = SolveCheck::after_perturbed_pivots;
  Solver s(o);
  s.factorize(healthy);  // the analysis: a singular matrix is refused there
  s.refactorize(a);
  ASSERT_GE(s.stats().factor.perturbed_pivots, 1);
  (void)s.solve(b);
  EXPECT_FALSE(std::isnan(s.stats().solve.backward_error));
  EXPECT_LE(s.stats().solve.backward_error, 1e-14);
}

// Solver::analyze_in_pivot_order: the order the delayed factorization took becomes the
// fixed order. A refactorization of the same values, and of values near them, then needs
// neither static nor delayed pivots, with dense LU's solution and determinant; the
// analysis keeps the pattern and reports where its order came from; a fixed-order factor
// (nothing delayed) has no such order to give.
TEST(DelayedPivoting, AnalysisInThePivotOrderFactorsInTheFixedOrder) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed) + " (STRATA_TEST_SEED replays it)");
  std::uniform_real_distribution<double> u(-1, 1);
  {  // n = 1: its one pivot is taken or perturbed, never delayed
    Solver s(leaf_fronts());
    s.factorize(test::with_values(test::random_pattern_with_diagonal(1, 3, rng), 20.0, rng));
    EXPECT_FALSE(s.stats().factor.delayed_pivoting);
    EXPECT_THROW(s.analyze_in_pivot_order(), InvalidState);
  }
  // with the matching and scaling (the default) and without them (the new analysis then
  // has a column permutation of its own and no scaling)
  for (const bool matching : {true, false})
    for (index_t n : {2, 3, 5, 733}) {
      SCOPED_TRACE("n=" + std::to_string(n) + (matching ? "" : ", no matching"));
      const test::StaleAnalysis m = test::stale_analysis(n, rng);
      Options o = leaf_fronts();
      o.matching_and_scaling = matching;
      o.refinement_max_steps = 0;
      o.gmres_max_iterations = 0;
      Solver s(o);
      s.factorize(m.analyzed);
      EXPECT_THROW(s.analyze_in_pivot_order(), InvalidState);  // the analysis's order was taken
      s.refactorize(m.stale);
      std::vector<double> ref = m.b;
      ASSERT_TRUE(test::dense_solve(test::to_dense(m.stale), n, ref, 1));
      const double tol =
          std::max(1e-10, 1e-13 * std::sqrt(double(n)) * kappa_lower(m.stale, ref, m.b));
      if (!s.stats().factor.delayed_pivoting) {  // one front: pivoting among its rows sufficed
        EXPECT_LT(n, 733);
        EXPECT_THROW(s.analyze_in_pivot_order(), InvalidState);
        continue;
      }
      s.analyze_in_pivot_order();
      EXPECT_TRUE(s.stats().analysis.order_from_pivots);
      EXPECT_FALSE(s.stats().analysis.order_kept);
      EXPECT_EQ(s.size(), n);
      EXPECT_GE(s.stats().analysis.nnz_l, n);
      EXPECT_THROW(s.solve(m.b), InvalidState);  // the factor was discarded
      EXPECT_THROW(s.analyze_in_pivot_order(), InvalidState);
      s.refactorize(m.stale);
      const FactorStats& f = s.stats().factor;
      EXPECT_FALSE(f.delayed_pivoting);
      EXPECT_EQ(f.perturbed_pivots, 0);
      EXPECT_TRUE(f.inertia_valid);
      double logdet = 0;
      int sign = 0;
      test::dense_logdet(m.stale, &logdet, &sign);
      EXPECT_NEAR(f.log_abs_determinant, logdet, 1e-9 * std::max(1.0, std::abs(logdet)));
      EXPECT_EQ(f.determinant_sign, sign);
      std::vector<double> x = s.solve(m.b);
      EXPECT_LE(test::relative_difference(x, ref), tol);
      // values near them (a Newton loop's next iterate): still the fixed order
      SparseMatrix near = m.stale;
      for (double& v : near.values) v *= 1 + 1e-9 * u(rng);
      s.refactorize(near);
      EXPECT_FALSE(s.stats().factor.delayed_pivoting);
      EXPECT_EQ(s.stats().factor.perturbed_pivots, 0);
      std::vector<double> near_ref = m.b;
      ASSERT_TRUE(test::dense_solve(test::to_dense(near), n, near_ref, 1));
      EXPECT_LE(test::relative_difference(s.solve(m.b), near_ref), tol);
      // a fresh analysis makes its own order again
      s.analyze(m.stale);
      EXPECT_FALSE(s.stats().analysis.order_from_pivots);
    }
}

// Pivoting::fixed: static pivots as before.
TEST(DelayedPivoting, OffKeepsStaticPivoting) {
  auto rng = test::fresh_rng();
  const SparseMatrix pattern = test::random_pattern_with_diagonal(60, 3, rng);
  Options o = leaf_fronts();
  o.pivoting = Pivoting::fixed;
  Solver s(o);
  s.factorize(test::with_values(pattern, 20.0, rng));
  s.refactorize(test::with_values(pattern, 0.0, rng));
  EXPECT_FALSE(s.stats().factor.delayed_pivoting);
  EXPECT_GT(s.stats().factor.perturbed_pivots, 0);
}

// Symmetric indefinite matrices (LDLᵀ) --------------------------------------------------

// LDLᵀ on the CPU with fundamental supernodes only: a constraint row with a zero diagonal
// alone in a leaf front has no pivot in the analysis's order.
Options ldlt_leaf_fronts() {
  Options o = leaf_fronts();
  o.type = MatrixType::symmetric_indefinite;
  return o;
}

// The analysis is made with a positive constraint diagonal; the KKT matrix refactorized has
// zeros there, which the analysis's order may not be able to pivot on. Delayed pivots
// (1×1 and 2×2) then leave no static pivot: the inertia is the KKT matrix's, log|det| and
// its sign dense LU's, the solution dense LAPACK's with a backward error at the tolerance.
TEST(DelayedPivoting, SymmetricIndefiniteStaleAnalysisKeepsTheInertia) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  std::uniform_real_distribution<double> u(-1, 1);
  for (index_t n : {2, 3, 5, 733}) {
    SCOPED_TRACE("n=" + std::to_string(n));
    const test::StaleKkt k = test::stale_kkt(n, rng);
    std::vector<double> b(n);
    for (double& v : b) v = u(rng);
    std::vector<double> ref = b;
    ASSERT_TRUE(test::dense_solve(test::to_dense(k.kkt), n, ref, 1));
    double logdet = 0;
    int sign = 0;
    test::dense_logdet(k.kkt, &logdet, &sign);
    for (Pivoting pivoting : {Pivoting::automatic, Pivoting::delayed}) {
      SCOPED_TRACE(pivoting == Pivoting::delayed ? "delayed" : "automatic");
      Options o = ldlt_leaf_fronts();
      o.pivoting = pivoting;
      Solver s(o);
      s.analyze(k.analyzed);
      s.factorize(k.kkt);
      const FactorStats& f = s.stats().factor;
      EXPECT_EQ(f.perturbed_pivots, 0);
      if (n == 733) {
        EXPECT_TRUE(f.delayed_pivoting);
        EXPECT_GT(f.delayed_pivots, 0);
        if (pivoting == Pivoting::automatic) EXPECT_GT(f.fixed_order_perturbed_pivots, 0);
      }
      EXPECT_TRUE(f.inertia_valid);
      EXPECT_EQ(f.inertia_positive, n - k.constraints);
      EXPECT_EQ(f.inertia_negative, k.constraints);
      EXPECT_EQ(f.inertia_zero, 0);
      EXPECT_NEAR(f.log_abs_determinant, logdet, 1e-9 * std::max(1.0, std::abs(logdet)));
      EXPECT_EQ(f.determinant_sign, sign);
      const std::vector<double> x = s.solve(b);
      EXPECT_LE(s.stats().solve.backward_error, 1e-14);
      EXPECT_EQ(s.stats().solve.gmres_iterations, 0);
      EXPECT_LE(test::relative_difference(x, ref),
                std::max(1e-10, 1e-13 * std::sqrt(double(n)) * kappa_lower(k.kkt, ref, b)));
    }
  }
}

// A contact-like sequence for LDLᵀ: between refactorizations the KKT matrix's values are
// redrawn within a factor 2 and random variables scaled by 10^±6 (symmetrically, which
// keeps the inertia). No static pivot, the inertia kept, backward error at the tolerance.
TEST(DelayedPivoting, SymmetricValuesChangingBySixDecadesBetweenRefactorizations) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  std::uniform_real_distribution<double> u(-1, 1), factor(0.5, 1.5);
  std::uniform_int_distribution<int> coin(0, 9);
  const index_t n = 733;
  const test::StaleKkt k = test::stale_kkt(n, rng);
  Options o;
  o.type = MatrixType::symmetric_indefinite;
  o.backend = Backend::cpu;
  Solver s(o);
  s.factorize(k.analyzed);
  index_t delayed = 0;
  for (int step = 0; step < 6; ++step) {
    SCOPED_TRACE("step " + std::to_string(step));
    std::vector<double> d(n);
    for (double& v : d) v = coin(rng) == 0 ? 1e6 : coin(rng) == 0 ? 1e-6 : 1.0;
    SparseMatrix a = k.kkt;
    for (index_t j = 0; j < n; ++j)
      for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p)
        a.values[p] *= (a.indices[p] == j ? 1.0 : factor(rng)) * d[a.indices[p]] * d[j];
    std::vector<double> rhs(n);
    for (double& v : rhs) v = u(rng);
    s.refactorize(a);
    const FactorStats& f = s.stats().factor;
    EXPECT_EQ(f.perturbed_pivots, 0);
    EXPECT_TRUE(f.inertia_valid);
    EXPECT_EQ(f.inertia_negative, k.constraints);
    delayed += f.delayed_pivots;
    s.solve(rhs);
    EXPECT_LE(s.stats().solve.backward_error, 1e-14);
    EXPECT_EQ(s.stats().solve.gmres_iterations, 0);
  }
  EXPECT_GT(delayed, 0) << "no pivot was delayed: the case is not covered";
}

// A symmetric matrix singular to working precision (a constraint row of zeros, its pattern
// kept) is still reported: static pivots at the root, the inertia marked invalid.
TEST(DelayedPivoting, SymmetricSingularMatrixIsStillReported) {
  auto rng = test::fresh_rng();
  for (index_t n : {3, 5, 733}) {
    SCOPED_TRACE("n=" + std::to_string(n));
    const test::StaleKkt k = test::stale_kkt(n, rng);
    SparseMatrix a = k.kkt;
    // the last column's variable: every entry of its row and column zero
    const index_t dead = n - 1;
    for (index_t j = 0; j < n; ++j)
      for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p)
        if (a.indices[p] == dead || j == dead) a.values[p] = 0.0;
    Solver s(ldlt_leaf_fronts());
    s.analyze(k.analyzed);
    s.factorize(a);
    EXPECT_GE(s.stats().factor.perturbed_pivots, 1);
    EXPECT_FALSE(s.stats().factor.inertia_valid);
  }
}

// analyze_in_pivot_order keeps an LU's pivot sequences only: after a symmetric matrix's
// delayed factorization it says so and keeps the solver as it was.
TEST(DelayedPivoting, PivotOrderAnalysisIsForLuOnly) {
  auto rng = test::fresh_rng();
  const test::StaleKkt k = test::stale_kkt(60, rng);
  Options o = ldlt_leaf_fronts();
  o.pivoting = Pivoting::delayed;
  Solver s(o);
  s.analyze(k.analyzed);
  s.factorize(k.kkt);
  ASSERT_TRUE(s.stats().factor.delayed_pivoting);
  const std::vector<double> b(60, 1.0);
  const std::vector<double> x = s.solve(b);
  EXPECT_THROW(s.analyze_in_pivot_order(), NotSupported);
  EXPECT_EQ(s.solve(b), x);
}

}  // namespace
}  // namespace strata
