// strata — solver integration tests: every factorization type through the public API,
// checked against independent references (dense LAPACK, CHOLMOD, eigenvalue signs).
#include <cholmod.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <span>
#include <utility>

#include "base/blas.hpp"
#include "base/device.hpp"
#include "sparse/generators.hpp"
#include "strata/strata.hpp"
#include "support/test_support.hpp"

namespace strata {
namespace {

using test::RandomKind;

struct Case {
  RandomKind kind;
  MatrixType type;
  const char* name;
};
const Case kCases[] = {{RandomKind::spd, MatrixType::spd, "spd"},
                       {RandomKind::symmetric_indefinite, MatrixType::symmetric_indefinite, "ldlt"},
                       {RandomKind::general, MatrixType::general, "lu"}};

// Solves a random system of each type and size and compares with dgesv on the dense copy.
TEST(Solver, RandomMatricesMatchDenseLapack) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  for (const Case& c : kCases)
    for (index_t n : {1, 2, 3, 5, 17, 733}) {
      SCOPED_TRACE(std::string(c.name) + " n=" + std::to_string(n));
      SparseMatrix a = test::random_sparse(n, 3, c.kind, rng);
      const index_t nrhs = n == 17 ? 3 : 1;
      std::vector<double> b(n * nrhs);
      std::uniform_real_distribution<double> u(-1, 1);
      for (double& v : b) v = u(rng);
      std::vector<double> ref = b;
      ASSERT_TRUE(test::dense_solve(test::to_dense(a), n, ref, nrhs));
      for (index_t block : {index_t{4}, index_t{256}}) {
        Options o;
        o.type = c.type;
        o.max_block_size = block;
        Solver s(o);
        s.analyze(a);
        s.factorize(a);
        std::vector<double> x(b.size());
        s.solve(b.data(), x.data(), nrhs);
        EXPECT_LT(test::relative_difference(x, ref), 1e-8);
        for (index_t r = 0; r < nrhs; ++r)
          EXPECT_LT(test::backward_error(a, x.data() + r * n, b.data() + r * n), 1e-14);
        EXPECT_LT(s.stats().solve.backward_error, 1e-14);
      }
    }
}

// Automatic type: spd when Cholesky succeeds, LDLᵀ for symmetric indefinite, LU otherwise.
// Enough right-hand sides of a large enough matrix that a solve's permutation and scaling
// loops run over the host's threads (core/solve_phase.cpp), for LU (matching, row and
// column scalings, column permutation) and Cholesky: every column's backward error at the
// rounding level, and, without refinement, each column the same to rounding as its solve
// alone (the serial loops).
TEST(Solver, ManyRightHandSidesOverTheHostThreads) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  const index_t n = 4200, nrhs = 8;  // 33,600 entries: over the loops' serial limit
  for (const Case& c : {kCases[0], kCases[2]}) {
    SCOPED_TRACE(c.name);
    SparseMatrix a = test::random_sparse(n, 3, c.kind, rng);
    std::vector<double> b(n * nrhs);
    std::uniform_real_distribution<double> u(-1, 1);
    for (double& v : b) v = u(rng);
    Options o;
    o.type = c.type;
    o.num_threads = 2;
    Solver s(o);
    s.analyze(a);
    s.factorize(a);
    std::vector<double> x(b.size());
    s.solve(b.data(), x.data(), nrhs);
    for (index_t r = 0; r < nrhs; ++r)
      EXPECT_LT(test::backward_error(a, x.data() + r * n, b.data() + r * n), 1e-14);
    // the first application of the factor alone (refinement would mend a wrong one)
    Options once = o;
    once.solve_check = SolveCheck::after_perturbed_pivots;
    Solver s1(once);
    s1.analyze(a);
    s1.factorize(a);
    ASSERT_EQ(s1.stats().factor.perturbed_pivots, 0);
    s1.solve(b.data(), x.data(), nrhs);
    for (index_t r = 0; r < nrhs; ++r) {
      const std::vector<double> one(b.begin() + r * n, b.begin() + (r + 1) * n);
      const std::vector<double> x_one = s1.solve(one);
      const std::vector<double> x_r(x.begin() + r * n, x.begin() + (r + 1) * n);
      EXPECT_LT(test::relative_difference(x_r, x_one), 1e-10) << "column " << r;
    }
  }
}

TEST(Solver, AutomaticTypeResolution) {
  auto rng = test::fresh_rng();
  const std::pair<RandomKind, MatrixType> expect[] = {
      {RandomKind::spd, MatrixType::spd},
      {RandomKind::symmetric_indefinite, MatrixType::symmetric_indefinite},
      {RandomKind::general, MatrixType::general}};
  for (auto [kind, type] : expect) {
    SparseMatrix a = test::random_sparse(200, 4, kind, rng);
    Solver s;
    s.factorize(a);
    EXPECT_EQ(s.matrix_type(), type);
    std::vector<double> b(200, 1.0);
    auto x = s.solve(b);
    EXPECT_LT(test::backward_error(a, x.data(), b.data()), 1e-14);
  }
}

// Backend::cuda where no GPU is visible (CI): the analysis (whose device set-up starts on a
// thread of its own) succeeds, every factorization throws NotSupported saying so, the solve
// refuses (no factor), and the Solver, its analysis kept, neither crashes nor hangs; the
// same with the symmetric and unsymmetric types, sizes 1 to 733.
TEST(Solver, CudaBackendWithoutAGpuIsReportedAtEveryFactorization) {
  if (numeric::cuda_available())
    GTEST_SKIP() << "a CUDA GPU is present: this test is for machines without";
  auto rng = test::fresh_rng();
  for (const Case& c : kCases)
    for (index_t n : {1, 2, 3, 5, 733}) {
      SCOPED_TRACE(std::string(c.name) + " n " + std::to_string(n));
      const SparseMatrix a = test::random_sparse(n, 4, c.kind, rng);
      Options o;
      o.type = c.type;
      o.backend = Backend::cuda;
      Solver s(o);
      ASSERT_NO_THROW(s.analyze(a));
      EXPECT_GT(s.stats().analysis.nnz_l, 0);
      for (int attempt = 0; attempt < 2; ++attempt) {
        try {
          s.factorize(a);
          ADD_FAILURE() << "factorize succeeded without a GPU";
        } catch (const NotSupported& e) {
          EXPECT_NE(std::string(e.what()).find("CUDA"), std::string::npos) << e.what();
        }
      }
      std::vector<double> b(n, 1.0);
      EXPECT_THROW(s.solve(b), InvalidState);
      EXPECT_EQ(s.stats().analysis.n, n);
    }
}

// Backend::automatic factors a factor below Options::gpu_min_flops on the host, GPU or
// not (the analysis and the factorization say so), with the solution of the CPU backend
// bit for bit; Backend::cpu stays on the host whatever the threshold. Types LU and
// Cholesky, sizes 1 to 733.
TEST(Solver, AutomaticBackendPutsSmallFactorsOnTheHost) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  for (const Case& c : {kCases[0], kCases[2]})
    for (index_t n : {1, 2, 3, 5, 733}) {
      SCOPED_TRACE(std::string(c.name) + " n " + std::to_string(n));
      const SparseMatrix a = test::random_sparse(n, 4, c.kind, rng);
      Options automatic;
      automatic.type = c.type;
      automatic.backend = Backend::automatic;
      automatic.gpu_min_flops = 1e10;
      Solver s(automatic);
      s.factorize(a);
      ASSERT_LT(s.stats().analysis.factor_flops, automatic.gpu_min_flops);
      EXPECT_EQ(s.stats().analysis.backend, Backend::cpu);
      EXPECT_EQ(s.stats().factor.backend, Backend::cpu);
      EXPECT_EQ(s.stats().analysis.workers, 1);
      Options cpu = automatic;
      cpu.backend = Backend::cpu;
      cpu.gpu_min_flops = 0;
      Solver h(cpu);
      h.factorize(a);
      EXPECT_EQ(h.stats().analysis.backend, Backend::cpu);
      std::vector<double> b(n);
      std::uniform_real_distribution<double> u(-1, 1);
      for (double& v : b) v = u(rng);
      const auto x = s.solve(b);
      EXPECT_EQ(x, h.solve(b));
      EXPECT_LT(test::backward_error(a, x.data(), b.data()), 1e-14);
    }
}

// Inertia of LDLᵀ equals the signs of the eigenvalues of the dense matrix (KKT systems).
TEST(Solver, LdltInertiaMatchesEigenvalues) {
  auto rng = test::fresh_rng();
  for (index_t n : {2, 5, 17, 60, 150}) {
    SparseMatrix a = test::random_sparse(n, 3, RandomKind::symmetric_indefinite, rng);
    std::vector<double> d = test::to_dense(a);
    std::vector<double> w(n);
    int ni = static_cast<int>(n), lwork = -1, info = 0;
    double q = 0;
    dsyev_("N", "L", &ni, d.data(), &ni, w.data(), &q, &lwork, &info);
    lwork = static_cast<int>(q);
    std::vector<double> work(lwork);
    dsyev_("N", "L", &ni, d.data(), &ni, w.data(), work.data(), &lwork, &info);
    ASSERT_EQ(info, 0);
    index_t pos = 0, neg = 0;
    for (double e : w) (e > 0 ? pos : neg)++;
    Options o;
    o.type = MatrixType::symmetric_indefinite;
    Solver s(o);
    s.factorize(a);
    EXPECT_EQ(s.stats().factor.inertia_positive, pos) << "n=" << n;
    EXPECT_EQ(s.stats().factor.inertia_negative, neg) << "n=" << n;
    EXPECT_EQ(s.stats().factor.perturbed_pivots, 0);
  }
}

// Random KKT matrices [[H, Bᵀ], [B, 0]] (H SPD, B of full row rank, interleaved by a
// random permutation, optionally scaled over ±4 decades): with the symmetric matching
// scaling and 2×2 pairing (Duff & Pralet 2005) LDLᵀ needs no perturbed pivot and its
// inertia is exactly (n1, n2, 0), for every ordering and block size.
TEST(Solver, RandomKktExactInertiaWithoutPerturbation) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  for (index_t n : {5, 17, 733})
    for (double decades : {0.0, 4.0}) {
      SCOPED_TRACE("n=" + std::to_string(n) + " decades " + std::to_string(decades));
      const SparseMatrix a = test::random_kkt(n, rng, decades);
      const index_t n2 = n / 3, n1 = n - n2;
      std::vector<double> b(n);
      std::uniform_real_distribution<double> u(-1, 1);
      for (double& v : b) v = u(rng);
      std::vector<double> ref = b;
      ASSERT_TRUE(test::dense_solve(test::to_dense(a), n, ref, 1));
      // log|det| of the dense LU (the scaling D enters det(DAD) = det(D)² det(A))
      double logdet = 0;
      {
        std::vector<double> d = test::to_dense(a);
        std::vector<int> ipiv(n);
        int ni = static_cast<int>(n), info = 0;
        dgetrf_(&ni, &ni, d.data(), &ni, ipiv.data(), &info);
        ASSERT_EQ(info, 0);
        for (index_t i = 0; i < n; ++i) logdet += std::log(std::abs(d[i + i * n]));
      }
      for (OrderingMethod m :
           {OrderingMethod::nested_dissection, OrderingMethod::metis, OrderingMethod::amd})
        for (index_t block : {index_t{2}, index_t{256}}) {
          SCOPED_TRACE(std::string(to_string(m)) + " block " + std::to_string(block));
          Options o;
          o.type = MatrixType::symmetric_indefinite;
          o.ordering = m;
          o.max_block_size = block;
          Solver s(o);
          s.factorize(a);
          const FactorStats& f = s.stats().factor;
          EXPECT_EQ(f.perturbed_pivots, 0);
          EXPECT_EQ(f.inertia_positive, n1);
          EXPECT_EQ(f.inertia_negative, n2);
          EXPECT_EQ(f.inertia_zero, 0);
          EXPECT_EQ(f.determinant_sign, n2 % 2 ? -1 : 1);
          EXPECT_NEAR(f.log_abs_determinant, logdet, 1e-9 * std::max(1.0, std::abs(logdet)));
          const auto x = s.solve(b);
          EXPECT_LE(test::backward_error(a, x.data(), b.data()), 1e-14);
          if (decades == 0) EXPECT_LT(test::relative_difference(x, ref), 1e-8);
        }
    }
}

// log|det| against the dense LU of the same matrix; one Solver analyzes each new matrix
// (its scalings and matching differ: the determinant's terms of the analysis are redone),
// then refactorizes it with rows and columns scaled by 10^±4, far from the analysis's
// values (equilibrated again: the rescaling's factors enter the determinant). A
// factorization that perturbed pivots (static pivoting: now and then an LDLᵀ
// refactorization of the far values, whose pivot order is the analysis's) has the
// determinant of the nearby matrix it factored, and says so (inertia_valid false): its
// determinant is not compared, and such draws must stay rare.
TEST(Solver, LogDeterminantMatchesDense) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  auto dense_logdet = [](const SparseMatrix& a, int* sign) {
    const index_t n = a.n_rows;
    std::vector<double> d = test::to_dense(a);
    std::vector<int> ipiv(n);
    int ni = n, info = 0;
    dgetrf_(&ni, &ni, d.data(), &ni, ipiv.data(), &info);
    double logdet = 0;
    *sign = 1;
    for (index_t i = 0; i < n; ++i) {
      logdet += std::log(std::abs(d[i + i * n]));
      if (d[i + i * n] < 0) *sign = -*sign;
      if (ipiv[i] != i + 1) *sign = -*sign;
    }
    return logdet;
  };
  int compared = 0, perturbed = 0;
  // the determinant of the last factorization against the dense one, or (pivots
  // perturbed) the statistics' mark that it is not A's
  auto check = [&](const Solver& s, double logdet, int sign, const std::string& what) {
    const FactorStats& f = s.stats().factor;
    if (f.perturbed_pivots > 0) {
      EXPECT_FALSE(f.inertia_valid) << what;
      ++perturbed;
      return;
    }
    ++compared;
    EXPECT_TRUE(f.inertia_valid) << what;
    EXPECT_NEAR(f.log_abs_determinant, logdet, 1e-9 * std::max(1.0, std::abs(logdet))) << what;
    EXPECT_EQ(f.determinant_sign, sign) << what;
  };
  for (const Case& c : kCases) {
    Options o;
    o.type = c.type;
    Solver s(o);
    for (index_t n : {40, 1, 2, 3, 5, 40}) {
      const SparseMatrix a = test::random_sparse(n, 3, c.kind, rng);
      int sign = 0;
      double logdet = dense_logdet(a, &sign);
      s.analyze(a);
      s.factorize(a);
      check(s, logdet, sign, std::string(c.name) + ", n = " + std::to_string(n));
      // the same pattern, rows and columns i ≡ 0, 1 (mod 3) scaled by 10⁴ and 10⁻⁴
      // (symmetrically: the symmetric kinds stay symmetric)
      SparseMatrix far = a;
      auto f = [](index_t i) { return i % 3 == 0 ? 1e4 : i % 3 == 1 ? 1e-4 : 1.0; };
      for (index_t j = 0; j < n; ++j)
        for (index_t p = far.offsets[j]; p < far.offsets[j + 1]; ++p)
          far.values[p] *= f(far.indices[p]) * f(j);
      logdet = dense_logdet(far, &sign);
      s.refactorize(far);
      if (c.type != MatrixType::spd && n >= 5)
        EXPECT_GT(s.stats().factor.rescaling_sweeps, 0) << c.name << ", n = " << n;
      check(
          s, logdet, sign,
          std::string(c.name) + ", n = " + std::to_string(n) + ", values far from the analysis's");
    }
  }
  // nonsingular draws: delayed pivoting (LU and LDLᵀ, Options::pivoting) leaves no static
  // pivot, so every determinant is compared
  EXPECT_EQ(perturbed, 0) << "of " << compared + perturbed << " factorizations";
}

// Refactorization with new values equals a fresh factorization, bitwise.
// The CPU backend has no device to prepare at analysis.
TEST(Solver, CpuAnalysisHasNoDeviceSetup) {
  Solver s;
  s.analyze(generators::laplacian_3d(5, 5, 5));
  EXPECT_EQ(s.stats().analysis.device_setup_seconds, 0.0);
}

TEST(Solver, RefactorizationEqualsFactorization) {
  auto rng = test::fresh_rng();
  for (const Case& c : kCases) {
    SparseMatrix a = test::random_sparse(300, 4, c.kind, rng);
    SparseMatrix a2 = a;
    std::uniform_real_distribution<double> u(0.5, 1.5);
    for (double& v : a2.values) v *= u(rng);
    Options o;
    o.type = c.type;
    Solver s1(o), s2(o);
    s1.factorize(a);
    s1.refactorize(a2);
    s2.analyze(a);  // same analysis (and, for LU, the same matching) as s1
    s2.factorize(a2);
    std::vector<double> b(300);
    for (double& v : b) v = u(rng);
    auto x1 = s1.solve(b);
    auto x2 = s2.solve(b);
    EXPECT_EQ(x1, x2) << c.name;
    EXPECT_LT(test::backward_error(a2, x1.data(), b.data()), 1e-14);
  }
}

// A with `extra` more entries (random positions, values of a tenth of A's scale; for spd,
// diagonal dominance kept by adding each new entry's magnitude to its two diagonals).
SparseMatrix grown(const SparseMatrix& a, index_t extra, RandomKind kind, std::mt19937_64& rng) {
  const index_t n = a.n_cols;
  std::vector<std::vector<std::pair<index_t, double>>> cols(n);
  for (index_t j = 0; j < n; ++j)
    for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p)
      cols[j].push_back({a.indices[p], a.values[p]});
  std::uniform_int_distribution<index_t> pick(0, n - 1);
  std::uniform_real_distribution<double> u(-0.1, 0.1);
  for (index_t k = 0; k < extra; ++k) {
    index_t i = pick(rng), j = pick(rng);
    if (kind != RandomKind::general && i < j) std::swap(i, j);  // lower storage
    const double v = u(rng);
    cols[j].push_back({i, v});
    if (kind == RandomKind::spd && i != j) {
      cols[i].push_back({i, std::abs(v)});
      cols[j].push_back({j, std::abs(v)});
    }
  }
  SparseMatrix g;
  g.n_rows = g.n_cols = n;
  g.storage = a.storage;
  g.offsets.assign(1, 0);
  for (index_t j = 0; j < n; ++j) {
    for (const auto& [i, v] : cols[j]) {
      g.indices.push_back(i);
      g.values.push_back(v);
    }
    g.offsets.push_back(static_cast<index_t>(g.indices.size()));
  }
  return canonicalize(g);  // duplicates summed
}

// A solver that analyzed a, then a1 and a2 by a member such as
// Solver::analyze_keeping_order, and factorized a2; b random, x its solution.
struct KeptChain {
  Solver chain;
  std::vector<double> b, x;
};

// The chain of c's type; a second solver analyzes a, then a2 by `keep`: the same
// permutation, the same solution of a2, and that solution against dense LAPACK's.
template <class Keep>
KeptChain keep_chain(const Case& c, const SparseMatrix& a, const SparseMatrix& a1,
                     const SparseMatrix& a2, Keep keep, std::mt19937_64& rng) {
  const index_t n = a.n_cols;
  Options o;
  o.type = c.type;
  KeptChain k{Solver(o), std::vector<double>(n), {}};
  Solver& chain = k.chain;
  std::vector<double>& b = k.b;
  std::uniform_real_distribution<double> u(-1, 1);
  for (double& v : b) v = u(rng);
  std::vector<double> ref = b;
  EXPECT_TRUE(test::dense_solve(test::to_dense(a2), n, ref, 1));
  Solver direct(o);
  chain.analyze(a);
  direct.analyze(a);
  (chain.*keep)(a1);
  (chain.*keep)(a2);
  (direct.*keep)(a2);
  EXPECT_EQ(chain.permutation(), direct.permutation());
  chain.factorize(a2);
  direct.factorize(a2);
  const std::vector<double> x = chain.solve(b), y = direct.solve(b);
  EXPECT_EQ(x, y);
  EXPECT_LT(test::relative_difference(x, ref), 1e-8);
  EXPECT_LT(test::backward_error(a2, x.data(), b.data()), 1e-14);
  k.x = x;
  return k;
}

// An analysis keeping the order of the one before solves a grown pattern as a dense LU
// does; a chain of such analyses gives what one from the first analysis gives; a pattern
// that lost an analyzed entry is refused and the solver keeps its analysis.
TEST(Solver, AnalysisKeepingOrderSolvesGrownPatterns) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  for (const Case& c : kCases)
    for (index_t n : {1, 2, 3, 5, 733}) {
      SCOPED_TRACE(std::string(c.name) + " n=" + std::to_string(n));
      const SparseMatrix a = test::random_sparse(n, 3, c.kind, rng);
      const SparseMatrix a1 = grown(a, std::max<index_t>(1, n / 50), c.kind, rng);
      const SparseMatrix a2 = grown(a1, std::max<index_t>(1, n / 20), c.kind, rng);
      KeptChain k = keep_chain(c, a, a1, a2, &Solver::analyze_keeping_order, rng);
      Solver& chain = k.chain;
      const std::vector<double>&b = k.b, &x = k.x;
      EXPECT_TRUE(chain.stats().analysis.order_kept);
      // a pattern without one of the analyzed entries: refused, the analysis of a2 kept
      SparseMatrix lost = a2;
      if (lost.nnz() > 0 && n > 1) {
        lost.indices.erase(lost.indices.begin());
        lost.values.erase(lost.values.begin());
        for (index_t j = 1; j <= n; ++j) --lost.offsets[j];
        EXPECT_THROW(chain.analyze_keeping_order(lost), InvalidInput);
        chain.refactorize(a2);
        EXPECT_EQ(chain.solve(b), x);
      }
    }
}

// nnz(L), diagonal included, of the Cholesky factor of the symmetric pattern of `a` (both
// triangles of each stored entry) in the order `perm` (new to old), by dense boolean
// elimination: row sets as bit sets, each pivot's lower rows joined into one another's.
index_t dense_symbolic_entries(const SparseMatrix& a, const std::vector<index_t>& perm) {
  const index_t n = a.n_cols, words = (n + 63) / 64;
  std::vector<index_t> iperm(n);
  for (index_t k = 0; k < n; ++k) iperm[perm[k]] = k;
  std::vector<std::uint64_t> s(static_cast<std::size_t>(n * words), 0);
  auto set = [&](index_t i, index_t j) { s[i * words + j / 64] |= std::uint64_t{1} << (j % 64); };
  for (index_t j = 0; j < n; ++j)
    for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p) {
      set(iperm[a.indices[p]], iperm[j]);
      set(iperm[j], iperm[a.indices[p]]);
    }
  index_t entries = n;
  for (index_t k = 0; k < n; ++k) {
    std::vector<index_t> below;  // rows i > k of column k of the filled pattern
    for (index_t i = k + 1; i < n; ++i)
      if (s[k * words + i / 64] >> (i % 64) & 1) below.push_back(i);
    entries += static_cast<index_t>(below.size());
    for (index_t i : below)
      for (index_t w = 0; w < words; ++w) s[i * words + w] |= s[k * words + w];
  }
  return entries;
}

// The kept order's factor entries, counted without analyzing, are those of the analysis
// keeping the order; for a symmetric positive definite matrix (no matching) they equal a
// dense symbolic elimination's in that order. The solver is not changed; a pattern that
// lost an analyzed entry is refused as analyze_keeping_order refuses it.
TEST(Solver, FactorEntriesKeepingOrderCountWhatTheAnalysisGives) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  Solver fresh;
  EXPECT_THROW(
      (void)fresh.factor_entries_keeping_order(test::random_sparse(3, 2, RandomKind::spd, rng)),
      InvalidState);
  for (const Case& c : kCases)
    for (index_t n : {1, 2, 3, 5, 733}) {
      SCOPED_TRACE(std::string(c.name) + " n=" + std::to_string(n));
      const SparseMatrix a = test::random_sparse(n, 3, c.kind, rng);
      const SparseMatrix a2 = grown(a, std::max<index_t>(1, n / 10), c.kind, rng);
      Options o;
      o.type = c.type;
      Solver counted(o), kept(o);
      counted.analyze(a);
      kept.analyze(a);
      const std::vector<index_t> order = counted.permutation();
      const index_t entries = counted.factor_entries_keeping_order(a2);
      kept.analyze_keeping_order(a2);
      EXPECT_EQ(entries, kept.stats().analysis.nnz_l);
      EXPECT_GE(entries, counted.stats().analysis.nnz_l);  // entries only added
      if (c.type == MatrixType::spd) EXPECT_EQ(entries, dense_symbolic_entries(a2, order));
      // unchanged: the analysis of a, its factor solving a
      EXPECT_EQ(counted.permutation(), order);
      EXPECT_FALSE(counted.stats().analysis.order_kept);
      counted.factorize(a);
      std::vector<double> b(n, 1.0);
      const std::vector<double> x = counted.solve(b);
      EXPECT_LT(test::backward_error(a, x.data(), b.data()), 1e-14);
      if (n > 1 && a.offsets[1] > 0) {  // a2 without a's first entry
        SparseMatrix lost = a2;
        const auto p =
            std::find(lost.indices.begin(), lost.indices.begin() + lost.offsets[1], a.indices[0]);
        ASSERT_NE(p, lost.indices.begin() + lost.offsets[1]);
        lost.values.erase(lost.values.begin() + (p - lost.indices.begin()));
        lost.indices.erase(p);
        for (index_t j = 1; j <= n; ++j) --lost.offsets[j];
        EXPECT_THROW((void)counted.factor_entries_keeping_order(lost), InvalidInput);
      }
    }
}

// A with the entries of `from` that are not in `base` (the pairs a contact added) left out:
// `from`'s pattern is base's plus additions (grown), and the result has base's pattern with
// from's values there.
SparseMatrix without_additions(const SparseMatrix& from, const SparseMatrix& base) {
  SparseMatrix r;
  r.n_rows = r.n_cols = from.n_cols;
  r.storage = from.storage;
  r.offsets.assign(1, 0);
  for (index_t j = 0; j < from.n_cols; ++j) {
    for (index_t p = from.offsets[j]; p < from.offsets[j + 1]; ++p)
      if (std::binary_search(base.indices.begin() + base.offsets[j],
                             base.indices.begin() + base.offsets[j + 1], from.indices[p])) {
        r.indices.push_back(from.indices[p]);
        r.values.push_back(from.values[p]);
      }
    r.offsets.push_back(static_cast<index_t>(r.indices.size()));
  }
  return r;
}

// An analysis keeping the matching and scaling of the one before orders a changed pattern
// anew: it solves as a dense LU does; from the first analysis through one pattern to
// another (entries added, then those taken away and others added: contact pairs closing and
// opening) it gives the order that one step from the first analysis gives, which is not a
// kept order; a general pattern that lost a matched entry (or has an empty column) is
// refused and the solver keeps its analysis and factor.
TEST(Solver, AnalysisKeepingMatchingOrdersChangedPatternsAnew) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  for (const Case& c : kCases)
    for (index_t n : {1, 2, 3, 5, 733}) {
      SCOPED_TRACE(std::string(c.name) + " n=" + std::to_string(n));
      const SparseMatrix a = test::random_sparse(n, 3, c.kind, rng);
      const SparseMatrix a1 = grown(a, std::max<index_t>(1, n / 20), c.kind, rng);
      // general: a1's additions gone, others made (a changed pattern); symmetric
      // indefinite (its 2×2 pivots need the analyzed pattern): a1 grown further
      const SparseMatrix a2 =
          c.type == MatrixType::general
              ? grown(without_additions(a1, a), std::max<index_t>(1, n / 20), c.kind, rng)
              : grown(a1, std::max<index_t>(1, n / 20), c.kind, rng);
      KeptChain k = keep_chain(c, a, a1, a2, &Solver::analyze_keeping_matching, rng);
      Solver& chain = k.chain;
      const std::vector<double>&b = k.b, &x = k.x;
      EXPECT_TRUE(chain.stats().analysis.matching_kept);
      EXPECT_FALSE(chain.stats().analysis.order_kept);
      // an empty column: refused, the analysis and factor of a2 kept
      if (c.type == MatrixType::general && n > 1) {
        SparseMatrix empty = a2;
        const index_t gone = empty.offsets[1];
        empty.indices.erase(empty.indices.begin(), empty.indices.begin() + gone);
        empty.values.erase(empty.values.begin(), empty.values.begin() + gone);
        for (index_t j = 1; j <= n; ++j) empty.offsets[j] -= gone;
        EXPECT_THROW(chain.analyze_keeping_matching(empty), InvalidInput);
        EXPECT_TRUE(chain.stats().analysis.matching_kept);
        EXPECT_EQ(chain.solve(b), x);
      }
    }
}

// An analysis whose matching starts from an earlier one (Solver::analyze(a, start)):
// started from the analysis of the same pattern with other values, a general matrix's
// factor solves as a dense LU does, with the same product on the matched diagonal as a
// fresh analysis; for the symmetric types the start is not used (matching_start() is
// empty there) and the analysis is analyze's; an empty start is analyze; a start of another
// order, a bad scaling or column is refused by name and the solver keeps what it had.
TEST(Solver, AnalysisFromAnEarlierMatching) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  std::uniform_real_distribution<double> u(-1, 1);
  for (const Case& c : kCases)
    for (index_t n : {1, 2, 3, 5, 733}) {
      SCOPED_TRACE(std::string(c.name) + " n=" + std::to_string(n));
      const SparseMatrix a = test::random_sparse(n, 3, c.kind, rng);
      // the same pattern, values moved by up to a factor 3 (spd: D A D, which stays so)
      SparseMatrix moved = a;
      std::vector<double> d(n);
      for (double& x : d) x = std::pow(3.0, 0.5 * u(rng));
      for (index_t j = 0; j < n; ++j)
        for (index_t p = moved.offsets[j]; p < moved.offsets[j + 1]; ++p)
          moved.values[p] *=
              c.type == MatrixType::spd ? d[moved.indices[p]] * d[j] : std::pow(3.0, u(rng));
      Options o;
      o.type = c.type;
      Solver first(o), fresh(o), started(o);
      first.analyze(a);
      const MatchingStart start = first.matching_start();
      EXPECT_EQ(start.empty(), c.type != MatrixType::general);
      fresh.analyze(moved);
      started.analyze(moved, start);
      if (c.type != MatrixType::general) {
        EXPECT_EQ(started.permutation(), fresh.permutation());
      } else {
        ASSERT_EQ(static_cast<index_t>(start.row_scaling.size()), n);
        const MatchingStart mine = started.matching_start(), theirs = fresh.matching_start();
        const std::vector<double> dense = test::to_dense(moved);
        double log_mine = 0, log_theirs = 0;
        for (index_t i = 0; i < n; ++i) {
          log_mine += std::log(std::abs(dense[i + mine.matched_column[i] * n]));
          log_theirs += std::log(std::abs(dense[i + theirs.matched_column[i] * n]));
        }
        EXPECT_NEAR(log_mine, log_theirs, 1e-11 * std::max(1.0, std::abs(log_theirs)));
      }
      started.factorize(moved);
      std::vector<double> b(n);
      for (double& v : b) v = u(rng);
      std::vector<double> ref = b;
      ASSERT_TRUE(test::dense_solve(test::to_dense(moved), n, ref, 1));
      const std::vector<double> x = started.solve(b);
      EXPECT_LT(test::relative_difference(x, ref), 1e-8);
      EXPECT_LT(test::backward_error(moved, x.data(), b.data()), 1e-14);
      // an empty start is analyze
      Solver empty(o);
      empty.analyze(moved, MatchingStart{});
      EXPECT_EQ(empty.permutation(), fresh.permutation());
      if (c.type != MatrixType::general) continue;
      // refused: the solver keeps its analysis and factor
      MatchingStart bad = start;
      bad.row_scaling.push_back(1.0);
      EXPECT_THROW(started.analyze(moved, bad), InvalidInput);
      bad = start;
      bad.row_scaling[n / 2] = -1.0;
      EXPECT_THROW(started.analyze(moved, bad), InvalidInput);
      bad = start;
      bad.row_scaling[0] = std::numeric_limits<double>::infinity();
      EXPECT_THROW(started.analyze(moved, bad), InvalidInput);
      bad = start;
      bad.matched_column[n - 1] = n;
      EXPECT_THROW(started.analyze(moved, bad), InvalidInput);
      EXPECT_EQ(started.solve(b), x);
    }
}

// A new pattern for refactorize is an error; so are wrong sizes and NaN values.
TEST(Solver, BadInputIsReported) {
  auto rng = test::fresh_rng();
  SparseMatrix a = test::random_sparse(50, 3, RandomKind::spd, rng);
  Solver s;
  s.factorize(a);
  SparseMatrix other = test::random_sparse(50, 5, RandomKind::spd, rng);
  EXPECT_THROW(s.refactorize(other), InvalidInput);
  std::vector<double> wrong(49, 1.0);
  EXPECT_THROW(s.solve(wrong), InvalidInput);
  SparseMatrix nan = a;
  nan.values[3] = std::nan("");
  EXPECT_THROW(s.refactorize(nan), InvalidInput);
  // refused after its pass has read every other value (2A, the last one NaN): the factor
  // of A and A itself (the residual's matrix) are kept, so the solve still solves A x = b
  SparseMatrix twice = a;
  for (double& v : twice.values) v *= 2;
  twice.values.back() = std::nan("");
  EXPECT_THROW(s.refactorize(twice), InvalidInput);
  std::vector<double> b(50, 1.0);
  const std::vector<double> x = s.solve(b);
  EXPECT_LE(test::backward_error(a, x.data(), b.data()), 1e-14);
  EXPECT_LE(s.stats().solve.backward_error, 1e-14);
  Solver fresh;
  EXPECT_THROW(fresh.solve(b), InvalidState);
  SparseMatrix rect = a;
  rect.n_rows = 49;
  rect.storage = Storage::full;
  EXPECT_THROW(fresh.analyze(rect), InvalidInput);
}

// Aᵀ in canonical CSC: A's CSC arrays read as CSR are Aᵀ (a stored triangle becomes the
// other one).
SparseMatrix transposed(const SparseMatrix& a) {
  SparseMatrix t = a;
  t.layout = Layout::csr;
  if (a.storage != Storage::full)
    t.storage = a.storage == Storage::lower ? Storage::upper : Storage::lower;
  return canonicalize(t);
}

// Solver::refactorize(values): the values alone, in the analyzed matrix's own entry order,
// give the factor and the solution refactorize(A) gives, for LU, LLᵀ and LDLᵀ and sizes
// 1 to 733, and for matrices given in other forms (duplicates, CSR, a symmetric matrix's
// full or upper storage); a wrong count and a value that is not finite are refused,
// leaving the factor as it was.
TEST(Solver, RefactorizeWithValuesAloneEqualsWithTheMatrix) {
  auto rng = test::fresh_rng();
  for (const test::ValueChange& c : test::value_changes(rng)) {
    SCOPED_TRACE("type " + std::string(to_string(c.type)) + ", n = " + std::to_string(c.n));
    const SparseMatrix& a = c.a;
    const SparseMatrix& next = c.next;
    const std::vector<double> b(c.n, 1.0);
    Options o;
    o.type = c.type;
    Solver with_matrix(o), with_values(o);
    with_matrix.factorize(a);
    with_values.factorize(a);
    with_matrix.refactorize(next);
    with_values.refactorize(std::span<const double>(next.values));
    EXPECT_EQ(with_values.stats().factor.log_abs_determinant,
              with_matrix.stats().factor.log_abs_determinant);
    const std::vector<double> x = with_values.solve(b);
    EXPECT_EQ(x, with_matrix.solve(b));
    EXPECT_LE(test::backward_error(next, x.data(), b.data()), 1e-12);
  }
  const SparseMatrix a = test::random_sparse(40, 3, RandomKind::general, rng);
  Solver s;
  s.factorize(a);
  const std::vector<double> b(40, 1.0);
  const std::vector<double> x0 = s.solve(b);
  std::vector<double> short_values(a.values.begin(), a.values.end() - 1);
  EXPECT_THROW(s.refactorize(std::span<const double>(short_values)), InvalidInput);
  std::vector<double> nan = a.values;
  nan[5] = std::nan("");
  try {
    s.refactorize(std::span<const double>(nan));
    ADD_FAILURE() << "a NaN value was accepted";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("values[5] is not finite"), std::string::npos) << e.what();
  }
  EXPECT_EQ(s.solve(b), x0);
  // analyzed in another form: the values in that form's own order (a duplicate entry, a
  // CSR matrix, a symmetric matrix in full and in upper storage) give what the matrix gives
  SparseMatrix dup = a;
  dup.indices.insert(dup.indices.begin() + dup.offsets[1], dup.indices[dup.offsets[0]]);
  dup.values.insert(dup.values.begin() + dup.offsets[1], 0.0);
  for (index_t j = 1; j <= dup.n_cols; ++j) ++dup.offsets[j];
  const SparseMatrix spd = test::random_sparse(30, 3, RandomKind::spd, rng);
  const SparseMatrix full = expand_symmetric(spd), upper = transposed(spd);
  for (const SparseMatrix* m : {static_cast<const SparseMatrix*>(&dup), &full, &upper}) {
    for (bool csr : {false, true}) {
      SparseMatrix given = *m;
      if (csr) {  // the same entries by rows: the transpose's arrays read as CSR
        given = transposed(*m);
        given.layout = Layout::csr;
        given.storage = m->storage;
      }
      SCOPED_TRACE(std::string(csr ? "CSR" : "CSC") + ", storage " +
                   std::to_string(static_cast<int>(given.storage)));
      Options o;
      o.type = m == &dup ? MatrixType::general : MatrixType::spd;
      Solver by_matrix(o), by_values(o);
      by_matrix.analyze(given);
      by_values.analyze(given);
      SparseMatrix twice = given;
      for (double& v : twice.values) v *= 2;
      by_matrix.refactorize(twice);
      by_values.refactorize(std::span<const double>(twice.values));
      EXPECT_EQ(by_values.stats().factor.log_abs_determinant,
                by_matrix.stats().factor.log_abs_determinant);
      const std::vector<double> ones(given.n_rows, 1.0);
      EXPECT_EQ(by_values.solve(ones), by_matrix.solve(ones));
      std::vector<double> short_values(twice.values.begin(), twice.values.end() - 1);
      EXPECT_THROW(by_values.refactorize(std::span<const double>(short_values)), InvalidInput);
    }
  }
  Solver none;
  EXPECT_THROW(none.refactorize(std::span<const double>(a.values)), InvalidState);
}

// An indefinite matrix declared spd stops with the original column of the bad pivot.
TEST(Solver, NotPositiveDefiniteNamesColumn) {
  // diag(1, 2, -3, 4) permuted by any ordering: the failing column is 2.
  SparseMatrix a;
  a.n_rows = a.n_cols = 4;
  a.storage = Storage::lower;
  a.offsets = {0, 1, 2, 3, 4};
  a.indices = {0, 1, 2, 3};
  a.values = {1, 2, -3, 4};
  Options o;
  o.type = MatrixType::spd;
  Solver s(o);
  try {
    s.factorize(a);
    FAIL() << "expected NotPositiveDefinite";
  } catch (const NotPositiveDefinite& e) {
    EXPECT_EQ(e.column(), 2);
  }
}

// Every shared matrix solves to backward error ≤ 1e-14, except the singular ex6, which
// must be flagged (perturbed pivots, or a condition bound beyond 1e12).
TEST(Solver, SharedMatrices) {
  for (const std::string& name : test::shared_matrix_names()) {
    SCOPED_TRACE(name);
    MMMatrix mm = read_matrix_market(test::matrix_path(name));
    const SparseMatrix& a = mm.matrix;
    std::vector<double> ones(a.n_rows, 1.0), b(a.n_rows);
    multiply(a, ones.data(), b.data());
    Solver s;
    s.factorize(a);
    auto x = s.solve(b);
    const double berr = test::backward_error(a, x.data(), b.data());
    if (name == "ex6") {
      // rank n − 1: static pivots in the analysis's order; delayed pivoting may find
      // pivots of ordinary size, and the singularity then shows in the solution's size
      const FactorStats& f = s.stats().factor;
      EXPECT_GT(f.perturbed_pivots + f.fixed_order_perturbed_pivots, 0);
      EXPECT_TRUE(f.perturbed_pivots > 0 || s.stats().solve.condition_lower_bound > 1e12)
          << "singular matrix not flagged";
    } else {
      EXPECT_LE(berr, 1e-14) << "type " << to_string(s.matrix_type());
    }
  }
}

// The shared KKT matrices (optimal control, zero (2,2) block): with the matching-based
// scaling and pairing no pivot is perturbed and the backward error is at the unit
// roundoff, for every ordering. Before pairing, static pivoting perturbed 180, 276 and 56
// pivots and refinement stalled near 1e-10.
TEST(Solver, SharedKktMatricesNeedNoStaticPivoting) {
  for (const char* name : {"hangGlider_2", "reorientation_1", "tumorAntiAngiogenesis_2"}) {
    SCOPED_TRACE(name);
    const MMMatrix mm = read_matrix_market(test::matrix_path(name));
    const SparseMatrix& a = mm.matrix;
    std::vector<double> ones(a.n_rows, 1.0), b(a.n_rows);
    multiply(a, ones.data(), b.data());
    for (OrderingMethod m :
         {OrderingMethod::nested_dissection, OrderingMethod::metis, OrderingMethod::amd}) {
      SCOPED_TRACE(to_string(m));
      Options o;  // automatic: the zero diagonal makes it symmetric_indefinite at analysis
      o.ordering = m;
      Solver s(o);
      s.factorize(a);
      EXPECT_EQ(s.stats().analysis.type, MatrixType::symmetric_indefinite);
      EXPECT_GT(s.stats().analysis.pairs, 0);
      EXPECT_EQ(s.stats().factor.perturbed_pivots, 0);
      EXPECT_EQ(s.stats().factor.inertia_zero, 0);
      const auto x = s.solve(b);
      EXPECT_LE(test::backward_error(a, x.data(), b.data()), 1e-14);
    }
  }
}

// On the shared SPD matrices the solution agrees with CHOLMOD's.
TEST(Solver, AgreesWithCholmodOnSpdMatrices) {
  for (const char* name : {"bcsstk09", "bcsstk13", "494_bus", "LFAT5", "bcsstk16"}) {
    SCOPED_TRACE(name);
    MMMatrix mm = read_matrix_market(test::matrix_path(name));
    const SparseMatrix& a = mm.matrix;  // lower, canonical
    const index_t n = a.n_rows;
    std::vector<double> b(n);
    auto rng = test::fresh_rng();
    std::uniform_real_distribution<double> u(-1, 1);
    for (double& v : b) v = u(rng);
    Options o;
    o.type = MatrixType::spd;
    Solver s(o);
    s.factorize(a);
    auto x = s.solve(b);

    cholmod_common cc;
    cholmod_l_start(&cc);
    cholmod_sparse* A = cholmod_l_allocate_sparse(n, n, a.nnz(), 1, 1, -1, CHOLMOD_REAL, &cc);
    std::copy(a.offsets.begin(), a.offsets.end(), static_cast<SuiteSparse_long*>(A->p));
    std::copy(a.indices.begin(), a.indices.end(), static_cast<SuiteSparse_long*>(A->i));
    std::copy(a.values.begin(), a.values.end(), static_cast<double*>(A->x));
    cholmod_dense* B = cholmod_l_allocate_dense(n, 1, n, CHOLMOD_REAL, &cc);
    std::copy(b.begin(), b.end(), static_cast<double*>(B->x));
    cholmod_factor* L = cholmod_l_analyze(A, &cc);
    cholmod_l_factorize(A, L, &cc);
    cholmod_dense* X = cholmod_l_solve(CHOLMOD_A, L, B, &cc);
    std::vector<double> xc(static_cast<double*>(X->x), static_cast<double*>(X->x) + n);
    cholmod_l_free_dense(&X, &cc);
    cholmod_l_free_dense(&B, &cc);
    cholmod_l_free_factor(&L, &cc);
    cholmod_l_free_sparse(&A, &cc);
    cholmod_l_finish(&cc);
    // both are backward stable; the forward difference is bounded by cond(A)·u, and the
    // refined strata solution is at least as accurate as CHOLMOD's unrefined one
    EXPECT_LT(test::relative_difference(x, xc), 1e-6);
  }
}

}  // namespace
}  // namespace strata
