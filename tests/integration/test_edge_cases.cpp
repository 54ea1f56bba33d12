// strata — numerical edge cases and bad input through the public Solver API, each with
// the outcome docs/reliability.md ("Bad input and numerical edge cases") promises:
// n = 0 and 1, diagonal, arrow (one dense row and column), disconnected components,
// explicit zeros, values near the overflow and underflow thresholds, singular and nearly
// singular matrices, an indefinite matrix declared spd, empty rows and columns. Every
// case runs for the three factorizations (spd, symmetric_indefinite, general) where it
// applies; solutions are checked against dense LAPACK (dgesv) or closed forms.
#include <gtest/gtest.h>

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <random>
#include <string>
#include <tuple>
#include <vector>

#include "strata/strata.hpp"
#include "support/test_support.hpp"

namespace strata {
namespace {

using Triplet = std::tuple<index_t, index_t, double>;

// n×n CSC matrix from (row, column, value) triplets; duplicates summed, explicit zeros kept.
SparseMatrix from_triplets(index_t n, Storage storage, const std::vector<Triplet>& t) {
  SparseMatrix a;
  a.n_rows = a.n_cols = n;
  a.storage = storage;
  a.offsets.assign(n + 1, 0);
  for (const auto& [i, j, v] : t) ++a.offsets[j + 1];
  for (index_t j = 0; j < n; ++j) a.offsets[j + 1] += a.offsets[j];
  a.indices.resize(t.size());
  a.values.resize(t.size());
  std::vector<index_t> next(a.offsets.begin(), a.offsets.end() - 1);
  for (const auto& [i, j, v] : t) {
    a.indices[next[j]] = i;
    a.values[next[j]++] = v;
  }
  return canonicalize(a);
}

// The lower triangle (Storage::lower) of a symmetric full matrix, or the matrix itself
// for `general`: the storage each type is given in these tests.
SparseMatrix stored_for(const SparseMatrix& full, MatrixType t) {
  if (t == MatrixType::general) return full;
  std::vector<Triplet> low;
  for (index_t j = 0; j < full.n_cols; ++j)
    for (index_t p = full.offsets[j]; p < full.offsets[j + 1]; ++p)
      if (full.indices[p] >= j) low.emplace_back(full.indices[p], j, full.values[p]);
  return from_triplets(full.n_rows, Storage::lower, low);
}

struct TypeCase {
  MatrixType type;
  const char* name;
};
const TypeCase kTypes[] = {{MatrixType::spd, "spd"},
                           {MatrixType::symmetric_indefinite, "symmetric_indefinite"},
                           {MatrixType::general, "general"}};

Options with_type(MatrixType t) {
  Options o;
  o.type = t;
  return o;
}

// Factorizes and solves A x = b with a solver of type t; the solver is returned for its
// statistics.
std::vector<double> solve_with(Solver& s, const SparseMatrix& a, const std::vector<double>& b) {
  s.analyze(a);
  s.factorize(a);
  return s.solve(b);
}

std::vector<double> random_vector(index_t n, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<double> v(n);
  for (double& x : v) x = u(rng);
  return v;
}

// Dense reference solution (dgesv) of the full matrix A.
std::vector<double> reference(const SparseMatrix& a, std::vector<double> b) {
  EXPECT_TRUE(test::dense_solve(test::to_dense(a), a.n_rows, b, 1)) << "reference is singular";
  return b;
}

bool all_finite(const std::vector<double>& x) {
  return std::all_of(x.begin(), x.end(), [](double v) { return std::isfinite(v); });
}

// A full symmetric (or, for `general`, unsymmetric) random matrix of order n with the
// given pattern density, strictly diagonally dominant: positive diagonal for spd, mixed
// signs for symmetric_indefinite and general.
SparseMatrix dominant(index_t n, index_t per_column, MatrixType t, std::mt19937_64& rng) {
  std::uniform_int_distribution<index_t> pick(0, n - 1);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<Triplet> e;
  std::vector<double> rowsum(n, 0.0);
  for (index_t j = 0; j < n; ++j)
    for (index_t k = 0; k < per_column; ++k) {
      const index_t i = pick(rng);
      if (i == j) continue;
      const double v = u(rng);
      e.emplace_back(i, j, v);
      rowsum[i] += std::abs(v);
      rowsum[j] += std::abs(v);
      if (t != MatrixType::general) e.emplace_back(j, i, v);
    }
  for (index_t i = 0; i < n; ++i) {
    const double sign = t == MatrixType::spd || i % 3 != 1 ? 1.0 : -1.0;
    e.emplace_back(i, i, sign * (rowsum[i] + 1.0));
  }
  return from_triplets(n, Storage::full, e);
}

// ---------------------------------------------------------------------------------------

// n = 0: every phase succeeds, the solution is empty, the statistics are those of an
// empty product (det = 1).
TEST(EdgeCases, EmptyMatrix) {
  for (MatrixType t : {MatrixType::automatic, MatrixType::spd, MatrixType::symmetric_indefinite,
                       MatrixType::general}) {
    SCOPED_TRACE(to_string(t));
    SparseMatrix a;  // 0×0, offsets {0}
    Solver s(with_type(t));
    s.analyze(a);
    s.factorize(a);
    EXPECT_TRUE(s.solve(std::vector<double>{}).empty());
    s.solve(nullptr, nullptr, 3);
    EXPECT_EQ(s.size(), 0);
    const Stats& st = s.stats();
    EXPECT_EQ(st.analysis.nnz_l, 0);
    EXPECT_EQ(st.factor.perturbed_pivots, 0);
    EXPECT_EQ(st.factor.inertia_positive + st.factor.inertia_negative + st.factor.inertia_zero, 0);
    EXPECT_EQ(st.factor.log_abs_determinant, 0.0);
    EXPECT_EQ(st.factor.determinant_sign, 1);
    EXPECT_EQ(st.solve.backward_error, 0.0);
    EXPECT_THROW(s.solve(std::vector<double>{1.0}), InvalidInput);
  }
}

// n = 1: x = b / a to the last bit or two, for magnitudes across the whole double range
// (a subnormal a included, with a b that keeps b / a representable). When b / a
// overflows, solve refuses with "no representable solution" instead of returning Inf.
TEST(EdgeCases, OneByOne) {
  struct Case {
    double a, b;
  };
  const Case cases[] = {{3.0, 0.75},    {-2.0, 0.75},    {1e-300, 0.75},
                        {-1e300, 0.75}, {DBL_MAX, 0.75}, {4.9e-324, 1e-320}};
  for (const TypeCase& c : kTypes)
    for (const Case& k : cases) {
      SCOPED_TRACE(std::string(c.name) + " a = " + std::to_string(k.a));
      const SparseMatrix a = from_triplets(
          1, c.type == MatrixType::general ? Storage::full : Storage::lower, {{0, 0, k.a}});
      Solver s(with_type(c.type));
      if (c.type == MatrixType::spd && k.a < 0) {
        try {
          s.factorize(a);
          FAIL() << "expected NotPositiveDefinite";
        } catch (const NotPositiveDefinite& e) {
          EXPECT_EQ(e.column(), 0);
          EXPECT_EQ(e.pivot(), k.a);
        }
        continue;
      }
      const std::vector<double> x = solve_with(s, a, {k.b});
      ASSERT_EQ(x.size(), 1u);
      EXPECT_NEAR(x[0], k.b / k.a, 4.5e-16 * std::abs(k.b / k.a));
      EXPECT_EQ(s.stats().factor.perturbed_pivots, 0);
      EXPECT_EQ(s.stats().factor.determinant_sign, k.a > 0 ? 1 : -1);
      EXPECT_NEAR(s.stats().factor.log_abs_determinant, std::log(std::abs(k.a)),
                  1e-14 * std::abs(std::log(std::abs(k.a))));
      if (std::abs(k.a) < 1e-320) {  // 0.75 / a = 1.5e323 does not exist as a double
        try {
          s.solve(std::vector<double>{0.75});
          FAIL() << "expected InvalidInput";
        } catch (const InvalidInput& e) {
          EXPECT_NE(std::string(e.what()).find("no representable solution"), std::string::npos)
              << e.what();
        }
        // the factorization stays usable
        EXPECT_NEAR(s.solve(std::vector<double>{k.b})[0], k.b / k.a, 1e-12 * (k.b / k.a));
      }
    }
}

// A diagonal matrix: x_i = b_i / d_i, inertia = signs of d, no perturbation.
TEST(EdgeCases, Diagonal) {
  auto rng = test::fresh_rng();
  std::uniform_real_distribution<double> expo(-5, 5);
  for (const TypeCase& c : kTypes)
    for (index_t n : {2, 3, 5, 733}) {
      SCOPED_TRACE(std::string(c.name) + " n=" + std::to_string(n));
      std::vector<Triplet> e;
      std::vector<double> d(n);
      index_t negative = 0;
      for (index_t i = 0; i < n; ++i) {
        d[i] = std::pow(10.0, expo(rng)) * (c.type != MatrixType::spd && i % 2 ? -1 : 1);
        negative += d[i] < 0;
        e.emplace_back(i, i, d[i]);
      }
      const SparseMatrix a =
          from_triplets(n, c.type == MatrixType::general ? Storage::full : Storage::lower, e);
      const std::vector<double> b = random_vector(n, rng);
      Solver s(with_type(c.type));
      const std::vector<double> x = solve_with(s, a, b);
      for (index_t i = 0; i < n; ++i) EXPECT_NEAR(x[i], b[i] / d[i], 1e-15 * std::abs(b[i] / d[i]));
      const FactorStats& f = s.stats().factor;
      EXPECT_EQ(f.perturbed_pivots, 0);
      if (c.type != MatrixType::general) {
        EXPECT_EQ(f.inertia_negative, negative);
        EXPECT_EQ(f.inertia_positive, n - negative);
        EXPECT_EQ(f.inertia_zero, 0);
      }
      EXPECT_EQ(f.determinant_sign, negative % 2 ? -1 : 1);
      EXPECT_EQ(s.stats().analysis.nnz_l, n);
    }
}

// An arrow matrix: one dense row and column (a hub coupled to every unknown) on a
// diagonal. The ordering must put the hub last; the solution matches dense LAPACK.
TEST(EdgeCases, ArrowMatrix) {
  auto rng = test::fresh_rng();
  std::uniform_real_distribution<double> u(-1, 1);
  for (const TypeCase& c : kTypes)
    for (index_t n : {2, 5, 733}) {
      for (index_t hub : {index_t{0}, n / 2, n - 1}) {
        SCOPED_TRACE(std::string(c.name) + " n=" + std::to_string(n) + " hub " +
                     std::to_string(hub));
        std::vector<Triplet> e;
        double hubsum = 0;
        for (index_t i = 0; i < n; ++i) {
          if (i == hub) continue;
          const double v = u(rng), w = c.type == MatrixType::general ? u(rng) : v;
          e.emplace_back(i, hub, v);
          e.emplace_back(hub, i, w);
          const double sign = c.type == MatrixType::spd || i % 2 ? 1.0 : -1.0;
          e.emplace_back(i, i, sign * (std::abs(v) + std::abs(w) + 0.5));
          hubsum += std::abs(v) + std::abs(w);
        }
        e.emplace_back(hub, hub, hubsum + 1.0);
        const SparseMatrix full = from_triplets(n, Storage::full, e);
        const std::vector<double> b = random_vector(n, rng);
        const std::vector<double> ref = reference(full, b);
        Solver s(with_type(c.type));
        const std::vector<double> x = solve_with(s, stored_for(full, c.type), b);
        EXPECT_LT(test::relative_difference(x, ref), 1e-12);
        EXPECT_LT(s.stats().solve.backward_error, 1e-14);
        EXPECT_EQ(s.stats().factor.perturbed_pivots, 0);
        // no fill: L has the arrow's pattern when the hub is eliminated last
        EXPECT_EQ(s.stats().analysis.nnz_l, 2 * n - 1);
      }
    }
}

// Disconnected components (a forest of assembly trees): blocks of awkward sizes, isolated
// unknowns, in an interleaved numbering.
TEST(EdgeCases, DisconnectedComponents) {
  auto rng = test::fresh_rng();
  for (const TypeCase& c : kTypes) {
    SCOPED_TRACE(c.name);
    std::vector<Triplet> e;
    index_t n = 0;
    for (index_t size : {1, 2, 3, 5, 1, 17, 1, 733}) {
      const SparseMatrix blk = dominant(size, 3, c.type, rng);
      for (index_t j = 0; j < size; ++j)
        for (index_t p = blk.offsets[j]; p < blk.offsets[j + 1]; ++p)
          e.emplace_back(n + blk.indices[p], n + j, blk.values[p]);
      n += size;
    }
    // interleave the components with a random symmetric permutation
    std::vector<index_t> perm(n);
    for (index_t i = 0; i < n; ++i) perm[i] = i;
    std::shuffle(perm.begin(), perm.end(), rng);
    for (auto& [i, j, v] : e) {
      i = perm[i];
      j = perm[j];
    }
    const SparseMatrix full = from_triplets(n, Storage::full, e);
    const std::vector<double> b = random_vector(n, rng);
    const std::vector<double> ref = reference(full, b);
    for (OrderingMethod o : {OrderingMethod::nested_dissection, OrderingMethod::amd,
                             OrderingMethod::metis, OrderingMethod::natural}) {
      SCOPED_TRACE(to_string(o));
      Options opts = with_type(c.type);
      opts.ordering = o;
      Solver s(opts);
      const std::vector<double> x = solve_with(s, stored_for(full, c.type), b);
      EXPECT_LT(test::relative_difference(x, ref), 1e-12);
      EXPECT_LT(s.stats().solve.backward_error, 1e-14);
    }
  }
}

// Explicit zeros are part of the pattern: they change nothing numerically, a
// refactorization may fill them in, and a stored zero on the diagonal of an indefinite or
// unsymmetric matrix is handled by pivoting (KKT-like).
TEST(EdgeCases, ExplicitZerosInThePattern) {
  auto rng = test::fresh_rng();
  std::uniform_int_distribution<index_t> pick(0, 49);
  for (const TypeCase& c : kTypes) {
    SCOPED_TRACE(c.name);
    const index_t n = 50;
    const SparseMatrix base = dominant(n, 2, c.type, rng);
    std::vector<Triplet> e, filled;
    for (index_t j = 0; j < n; ++j)
      for (index_t p = base.offsets[j]; p < base.offsets[j + 1]; ++p)
        e.emplace_back(base.indices[p], j, base.values[p]);
    filled = e;
    for (int k = 0; k < 40; ++k) {
      const index_t i = pick(rng), j = pick(rng);
      if (i == j) continue;
      e.emplace_back(i, j, 0.0);
      e.emplace_back(j, i, 0.0);
      filled.emplace_back(i, j, 1e-3);
      filled.emplace_back(j, i, 1e-3);
    }
    const SparseMatrix with_zeros = from_triplets(n, Storage::full, e);
    const std::vector<double> b = random_vector(n, rng);
    Solver plain(with_type(c.type)), zeros(with_type(c.type));
    const std::vector<double> x0 = solve_with(plain, stored_for(base, c.type), b);
    const std::vector<double> x1 = solve_with(zeros, stored_for(with_zeros, c.type), b);
    EXPECT_LT(test::relative_difference(x1, x0), 1e-13);
    EXPECT_GT(zeros.stats().analysis.nnz_a, plain.stats().analysis.nnz_a);
    // same pattern, the zeros now nonzero
    const SparseMatrix full_filled = from_triplets(n, Storage::full, filled);
    ASSERT_EQ(full_filled.indices, with_zeros.indices);
    zeros.refactorize(stored_for(full_filled, c.type));
    const std::vector<double> x2 = zeros.solve(b);
    EXPECT_LT(test::relative_difference(x2, reference(full_filled, b)), 1e-12);
  }
  // a stored zero on the diagonal: [[0, 1], [1, 0]] (and a 2×2 KKT block inside a
  // larger matrix) is nonsingular; LDLᵀ and LU solve it, Cholesky must refuse it
  const SparseMatrix swap =
      from_triplets(2, Storage::full, {{0, 0, 0.0}, {1, 0, 1.0}, {0, 1, 1.0}, {1, 1, 0.0}});
  for (const TypeCase& c : kTypes) {
    SCOPED_TRACE(std::string("[[0,1],[1,0]] ") + c.name);
    Solver s(with_type(c.type));
    if (c.type == MatrixType::spd) {
      EXPECT_THROW(solve_with(s, stored_for(swap, c.type), {1, 2}), NotPositiveDefinite);
      continue;
    }
    const std::vector<double> x = solve_with(s, stored_for(swap, c.type), {1, 2});
    EXPECT_EQ(x, (std::vector<double>{2, 1}));
    EXPECT_EQ(s.stats().factor.perturbed_pivots, 0);
    if (c.type == MatrixType::symmetric_indefinite) {
      EXPECT_EQ(s.stats().factor.inertia_positive, 1);
      EXPECT_EQ(s.stats().factor.inertia_negative, 1);
    }
  }
}

// Values near the ends of the double range: a well-conditioned matrix scaled by 1e300 or
// 1e-300 (and a symmetric diagonal scaling spreading 1e-150..1e150 over the unknowns)
// solves as accurately as the unscaled one, with no perturbed pivot.
TEST(EdgeCases, ValuesNearOverflowAndUnderflow) {
  auto rng = test::fresh_rng();
  for (const TypeCase& c : kTypes)
    for (index_t n : {1, 3, 40}) {
      const SparseMatrix a = dominant(n, 3, c.type, rng);
      const std::vector<double> b = random_vector(n, rng);
      const std::vector<double> ref = reference(a, b);
      for (double scale : {1e300, 1e-300}) {
        SCOPED_TRACE(std::string(c.name) + " n=" + std::to_string(n) + " scale " +
                     std::to_string(std::log10(scale)));
        SparseMatrix sa = a;
        for (double& v : sa.values) v *= scale;
        std::vector<double> sb = b;
        for (double& v : sb) v *= scale;
        Solver s(with_type(c.type));
        const std::vector<double> x = solve_with(s, stored_for(sa, c.type), sb);
        EXPECT_LT(test::relative_difference(x, ref), 1e-12);
        EXPECT_EQ(s.stats().factor.perturbed_pivots, 0);
        EXPECT_LT(s.stats().solve.backward_error, 1e-14);
        EXPECT_TRUE(std::isfinite(s.stats().factor.log_abs_determinant));
      }
      // D A D with d_i = 10^(±150): entries from 1e-300 to 1e300 in one matrix
      SCOPED_TRACE(std::string(c.name) + " n=" + std::to_string(n) + " graded");
      std::vector<double> d(n);
      for (index_t i = 0; i < n; ++i) d[i] = std::pow(10.0, i % 2 ? 150.0 : -150.0);
      SparseMatrix ga = a;
      for (index_t j = 0; j < n; ++j)
        for (index_t p = ga.offsets[j]; p < ga.offsets[j + 1]; ++p)
          ga.values[p] *= d[ga.indices[p]] * d[j];
      std::vector<double> gb(n);
      for (index_t i = 0; i < n; ++i) gb[i] = b[i] * d[i];
      Solver s(with_type(c.type));
      const std::vector<double> x = solve_with(s, stored_for(ga, c.type), gb);
      ASSERT_TRUE(all_finite(x));
      // x = D⁻¹ x_ref
      std::vector<double> xs(n);
      for (index_t i = 0; i < n; ++i) xs[i] = x[i] * d[i];
      EXPECT_LT(test::relative_difference(xs, ref), 1e-10);
      EXPECT_LT(s.stats().solve.backward_error, 1e-14);
    }
}

// A matrix whose norm overflows (rows summing past DBL_MAX) is refused with an error
// that says so, not solved with an infinite norm (which made every pivot "tiny" and
// every backward error 0).
TEST(EdgeCases, NormThatOverflowsIsRefused) {
  for (const TypeCase& c : kTypes) {
    SCOPED_TRACE(c.name);
    const double big = 0.75 * DBL_MAX;
    const SparseMatrix full =
        from_triplets(2, Storage::full,
                      {{0, 0, big},
                       {1, 0, big},
                       {0, 1, big},
                       {1, 1, c.type == MatrixType::spd ? 2 * 0.5 * big : -big}});
    Solver s(with_type(c.type));
    try {
      solve_with(s, stored_for(full, c.type), {1, 1});
      FAIL() << "expected InvalidInput";
    } catch (const InvalidInput& e) {
      EXPECT_NE(std::string(e.what()).find("overflow"), std::string::npos) << e.what();
    }
  }
}

// Singular matrices. Cholesky stops at the zero pivot naming its column; LDLᵀ and LU
// replace it by a static pivot, count it, and report through the backward error whether
// the result solves the system: small for a consistent right-hand side (b in the range),
// large — and refinement_converged false — for an inconsistent one. The 1×1 zero matrix
// has no nonzero to match: LDLᵀ and LU refuse it as structurally singular.
TEST(EdgeCases, SingularMatrix) {
  // rank one: every entry 1 (n = 4), plus the 1×1 zero matrix
  for (index_t n : {1, 4}) {
    std::vector<Triplet> e;
    for (index_t i = 0; i < n; ++i)
      for (index_t j = 0; j < n; ++j) e.emplace_back(i, j, n == 1 ? 0.0 : 1.0);
    const SparseMatrix full = from_triplets(n, Storage::full, e);
    for (const TypeCase& c : kTypes) {
      SCOPED_TRACE(std::string(c.name) + " n=" + std::to_string(n));
      Solver s(with_type(c.type));
      const SparseMatrix a = stored_for(full, c.type);
      if (c.type == MatrixType::spd) {
        try {
          s.factorize(a);
          FAIL() << "expected NotPositiveDefinite";
        } catch (const NotPositiveDefinite& err) {
          EXPECT_GE(err.column(), 0);
          EXPECT_LT(err.column(), n);
          EXPECT_EQ(err.pivot(), 0.0);
          EXPECT_NE(std::string(err.what()).find("column " + std::to_string(err.column())),
                    std::string::npos);
        }
        continue;
      }
      if (n == 1) {
        // an explicit zero is no entry for the matching: structurally singular
        try {
          s.analyze(a);
          FAIL() << "expected InvalidInput";
        } catch (const InvalidInput& err) {
          EXPECT_NE(std::string(err.what()).find("row 0 (0-based) is left unmatched"),
                    std::string::npos)
              << err.what();
        }
        continue;
      }
      s.factorize(a);
      EXPECT_EQ(s.stats().factor.perturbed_pivots, n - 1);
      // inconsistent: b = e_1 - e_2 is not in the range
      std::vector<double> b(n, 0.0);
      b[0] = 1;
      b[1] = -1;
      std::vector<double> x = s.solve(b);
      EXPECT_TRUE(all_finite(x));
      // no x solves it: x blows up (to ~1/static pivot), which can make the normwise
      // backward error small (x solves a matrix perturbed by about the static pivot); the
      // residual relative to b cannot fall below b's distance from the range
      EXPECT_FALSE(s.stats().solve.singular_consistent);
      EXPECT_GT(s.stats().solve.relative_residual, 0.1);
      EXPECT_GT(s.stats().solve.condition_lower_bound, 1e6);
      EXPECT_GT(*std::max_element(x.begin(), x.end()), 1e6);
      EXPECT_NEAR(test::backward_error(full, x.data(), b.data()), s.stats().solve.backward_error,
                  1e-6);
      // consistent: b = A·1
      std::vector<double> ones(n, 1.0), bc(n);
      multiply(full, ones.data(), bc.data());
      x = s.solve(bc);
      EXPECT_LT(s.stats().solve.backward_error, 1e-14);
      EXPECT_LT(test::backward_error(full, x.data(), bc.data()), 1e-14);
    }
  }
}

// A positive semidefinite finite-element mass matrix with a large null space: the
// 8-node hexahedra of an ne³ mesh (3 displacement components per node) integrated at two
// points, so each element's mass has rank 2 per component and most hourglass modes carry
// no mass. LDLᵀ perturbs the pivots of the null space. For a consistent right-hand side
// (b = A·x0) the solve converges — to the tolerance or the rounding floor — says that A is
// singular and b in its range, and does not run GMRES to its limit; for an inconsistent
// one (a unit vector: its null-space component is not zero) the residual relative to b
// stays large (a small normwise backward error is possible there: x grows along the null
// space and solves the perturbed matrix) and consistency is not claimed. The
// inertia and log-determinant are those of the perturbed matrix: marked invalid. The
// reference is the residual and the floor computed here from A.
TEST(EdgeCases, ConsistentSingularSystem) {
  auto rng = test::fresh_rng();
  std::uniform_real_distribution<double> density(1.0, 1.5);
  for (index_t ne : {1, 2, 3, 5}) {
    SCOPED_TRACE("ne=" + std::to_string(ne));
    const index_t nn = ne + 1, n = 3 * nn * nn * nn;
    auto node = [&](index_t i, index_t j, index_t k) { return (i * nn + j) * nn + k; };
    std::vector<Triplet> e;
    for (index_t i = 0; i < ne; ++i)
      for (index_t j = 0; j < ne; ++j)
        for (index_t k = 0; k < ne; ++k) {
          index_t nodes[8];
          int c = 0;
          for (index_t a : {0, 1})
            for (index_t b : {0, 1})
              for (index_t d : {0, 1}) nodes[c++] = node(i + a, j + b, k + d);
          const double w = density(rng);
          for (int q = 0; q < 2; ++q) {  // shape functions at two points
            double shape[8];
            for (int a = 0; a < 8; ++a) shape[a] = 0.125 + 0.025 * (q - 0.5) * (a % 2 ? -1 : 1);
            for (int a = 0; a < 8; ++a)
              for (int b = 0; b < 8; ++b)
                for (index_t d = 0; d < 3; ++d)
                  e.emplace_back(3 * nodes[a] + d, 3 * nodes[b] + d, w * shape[a] * shape[b]);
          }
        }
    const SparseMatrix full = from_triplets(n, Storage::full, e);
    Options o = with_type(MatrixType::symmetric_indefinite);
    Solver s(o);
    s.factorize(stored_for(full, MatrixType::symmetric_indefinite));
    const FactorStats& f = s.stats().factor;
    ASSERT_GT(f.perturbed_pivots, 0);
    EXPECT_FALSE(f.inertia_valid);
    // the rounding floor: (m+1)·u for the most entries m in a row
    index_t most = 0;
    std::vector<index_t> per_row(n, 0);
    for (index_t p = 0; p < full.nnz(); ++p) most = std::max(most, ++per_row[full.indices[p]]);
    const double floor = (most + 1) * 0.5 * DBL_EPSILON;
    const double enough = std::max(o.refinement_tolerance, floor);

    const std::vector<double> x0 = random_vector(n, rng);
    std::vector<double> b(n);
    multiply(full, x0.data(), b.data());
    const std::vector<double> x = s.solve(b);
    const SolveStats& st = s.stats().solve;
    EXPECT_DOUBLE_EQ(st.backward_error_floor, floor);
    EXPECT_TRUE(st.refinement_converged);
    EXPECT_TRUE(st.singular_consistent);
    EXPECT_LT(st.gmres_iterations, o.gmres_max_iterations);
    EXPECT_LE(test::backward_error(full, x.data(), b.data()), 2 * enough);

    std::vector<double> unit(n, 0.0);
    unit[0] = 1;
    s.solve(unit);
    // the residual cannot fall below b's distance from the range
    EXPECT_FALSE(s.stats().solve.singular_consistent);
    EXPECT_GT(s.stats().solve.relative_residual, 1e-3);
  }
}

// A nearly singular matrix (pivot 1e-12 of ‖A‖, condition ~1e12, beside a larger
// well-conditioned block): the fixed order of LU and LDLᵀ perturbs the tiny pivot, and
// delayed pivoting then takes it unperturbed at the root (it is no zero of a singular
// matrix), the solution at backward error ≤ 1e-14; Cholesky needs no perturbation (the
// pivot is positive).
TEST(EdgeCases, NearlySingularMatrix) {
  auto rng = test::fresh_rng();
  const double delta = 1e-12;
  for (const TypeCase& c : kTypes) {
    SCOPED_TRACE(c.name);
    const index_t m = 60;
    const SparseMatrix blk = dominant(m, 3, c.type, rng);
    std::vector<Triplet> e;
    for (index_t j = 0; j < m; ++j)
      for (index_t p = blk.offsets[j]; p < blk.offsets[j + 1]; ++p)
        e.emplace_back(blk.indices[p], j, blk.values[p]);
    // [[1, 1], [1, 1 + δ]] as a component of its own: coupled to the rest, pivoting may
    // go through the coupling entries and avoid the tiny pivot (no perturbation then)
    e.insert(e.end(), {{m, m, 1.0}, {m + 1, m, 1.0}, {m, m + 1, 1.0}, {m + 1, m + 1, 1.0 + delta}});
    const index_t n = m + 2;
    const SparseMatrix full = from_triplets(n, Storage::full, e);
    const std::vector<double> b = random_vector(n, rng);
    const std::vector<double> ref = reference(full, b);
    Solver s(with_type(c.type));
    const std::vector<double> x = solve_with(s, stored_for(full, c.type), b);
    const FactorStats& f = s.stats().factor;
    EXPECT_EQ(f.perturbed_pivots, 0);
    if (c.type != MatrixType::spd) {
      EXPECT_TRUE(f.delayed_pivoting);
      EXPECT_EQ(f.fixed_order_perturbed_pivots, 1);
    }
    EXPECT_LT(s.stats().solve.backward_error, 1e-14);
    EXPECT_LT(test::backward_error(full, x.data(), b.data()), 1e-14);
    // forward error bounded by condition (~4/δ) × backward error
    EXPECT_LT(test::relative_difference(x, ref), 1e-2);
  }
}

// An indefinite matrix declared spd: NotPositiveDefinite naming the column (original
// numbering) and the pivot; `automatic` falls back to LDLᵀ and solves it.
TEST(EdgeCases, IndefiniteDeclaredSpd) {
  // [[4, 2, 0], [2, 1, 0], [0, 0, 1]]: eliminating column 0 leaves 1 - 2·2/4 = 0 in
  // column 1; [[1, 2], [2, 1]]: 1 - 4 = -3 in column 1 (natural ordering).
  struct Case {
    SparseMatrix a;
    index_t column;
    double pivot;
  };
  const Case cases[] = {
      {from_triplets(3, Storage::lower, {{0, 0, 4.0}, {1, 0, 2.0}, {1, 1, 1.0}, {2, 2, 1.0}}), 1,
       0.0},
      {from_triplets(2, Storage::lower, {{0, 0, 1.0}, {1, 0, 2.0}, {1, 1, 1.0}}), 1, -3.0}};
  for (const Case& c : cases) {
    Options o = with_type(MatrixType::spd);
    o.ordering = OrderingMethod::natural;
    Solver s(o);
    try {
      s.factorize(c.a);
      FAIL() << "expected NotPositiveDefinite";
    } catch (const NotPositiveDefinite& e) {
      EXPECT_EQ(e.column(), c.column);
      EXPECT_EQ(e.pivot(), c.pivot);
      EXPECT_NE(std::string(e.what()).find("at column " + std::to_string(c.column)),
                std::string::npos)
          << e.what();
    }
    // the solver stays usable: nothing factorized, solve refuses
    EXPECT_THROW(s.solve(std::vector<double>(c.a.n_rows, 1.0)), InvalidState);
  }
  // automatic: Cholesky fails, LDLᵀ solves it
  const SparseMatrix a = cases[1].a;
  Solver s;
  const std::vector<double> x = solve_with(s, a, {3, 3});
  EXPECT_EQ(s.matrix_type(), MatrixType::symmetric_indefinite);
  EXPECT_NEAR(x[0], 1.0, 1e-15);
  EXPECT_NEAR(x[1], 1.0, 1e-15);
  EXPECT_EQ(s.stats().factor.inertia_negative, 1);
}

// Empty rows and columns: "structurally singular" naming the row or column (0-based), for
// every type, before any numeric work. A row of stored zeros is structurally present
// but numerically zero: Cholesky stops at its column with a zero pivot; for LDLᵀ and LU
// the matching of the analysis (which does not count explicit zeros) finds no entry for
// it and names it as structurally singular.
TEST(EdgeCases, ZeroRowsAndColumns) {
  // row 1 empty (general), column 2 empty (general), row/column 1 empty (symmetric)
  const SparseMatrix no_row =
      from_triplets(3, Storage::full, {{0, 0, 1.0}, {2, 1, 1.0}, {0, 2, 1.0}, {2, 2, 1.0}});
  const SparseMatrix no_col =
      from_triplets(3, Storage::full, {{0, 0, 1.0}, {1, 1, 1.0}, {2, 1, 1.0}, {2, 0, 1.0}});
  const SparseMatrix sym =
      from_triplets(3, Storage::lower, {{0, 0, 1.0}, {2, 0, 1.0}, {2, 2, 1.0}});
  struct Case {
    const SparseMatrix* a;
    std::vector<MatrixType> types;
    std::string expect;
  };
  const Case cases[] = {
      {&no_row, {MatrixType::general, MatrixType::automatic}, "row 1 (0-based) has no entry"},
      {&no_col, {MatrixType::general, MatrixType::automatic}, "column 2 (0-based) has no entry"},
      {&sym,
       {MatrixType::spd, MatrixType::symmetric_indefinite, MatrixType::automatic},
       "row 1 (0-based) has no entry"}};
  for (const Case& c : cases)
    for (MatrixType t : c.types) {
      SCOPED_TRACE(std::string(to_string(t)) + ": " + c.expect);
      Solver s(with_type(t));
      try {
        s.analyze(*c.a);
        FAIL() << "expected InvalidInput";
      } catch (const InvalidInput& e) {
        const std::string what = e.what();
        EXPECT_NE(what.find("structurally singular"), std::string::npos) << what;
        EXPECT_NE(what.find(c.expect), std::string::npos) << what;
      }
    }
  // row/column 1 of stored zeros
  std::vector<Triplet> e = {{0, 0, 2.0}, {1, 0, 0.0}, {0, 1, 0.0}, {1, 1, 0.0}, {2, 1, 0.0},
                            {1, 2, 0.0}, {2, 2, 3.0}, {2, 0, 1.0}, {0, 2, 1.0}};
  const SparseMatrix zeros = from_triplets(3, Storage::full, e);
  for (const TypeCase& c : kTypes) {
    SCOPED_TRACE(std::string("stored zeros, ") + c.name);
    Options o = with_type(c.type);
    Solver s(o);
    if (c.type == MatrixType::spd) {
      try {
        s.factorize(stored_for(zeros, c.type));
        FAIL() << "expected NotPositiveDefinite";
      } catch (const NotPositiveDefinite& err) {
        EXPECT_EQ(err.column(), 1);
        EXPECT_EQ(err.pivot(), 0.0);
      }
      continue;
    }
    try {
      s.analyze(stored_for(zeros, c.type));
      FAIL() << "expected InvalidInput";
    } catch (const InvalidInput& err) {
      // the matching sees no entry to put on the diagonal of row 1
      const std::string what = err.what();
      EXPECT_NE(what.find("structurally singular"), std::string::npos) << what;
      EXPECT_NE(what.find("row 1 (0-based) is left unmatched"), std::string::npos) << what;
    }
  }
}

}  // namespace
}  // namespace strata
