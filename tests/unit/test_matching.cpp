// strata tests — maximum product matching and scaling (src/ordering/matching.cpp).
//
// Independent references: brute force over all permutations (n <= 8), a dense Hungarian
// algorithm (n ~ 50), and a plain augmenting-path maximum cardinality matching for the
// structural rank.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>
#include <string>
#include <vector>

#include "ordering/matching.hpp"
#include "strata/errors.hpp"
#include "strata/matrix_market.hpp"
#include "strata/sparse_matrix.hpp"
#include "support/test_support.hpp"

namespace strata {
namespace {

using ordering::Matching;
using ordering::maximum_product_matching;
using ordering::maximum_product_matching_canonical;

// Builds a canonical CSC matrix from a dense column-major array (zeros dropped, except
// where `keep_zero` marks an explicit zero to be stored).
SparseMatrix from_dense(const std::vector<double>& d, index_t n,
                        const std::vector<char>* keep_zero = nullptr) {
  SparseMatrix a;
  a.n_rows = a.n_cols = n;
  a.offsets.assign(1, 0);
  for (index_t j = 0; j < n; ++j) {
    for (index_t i = 0; i < n; ++i) {
      const double x = d[i + j * n];
      if (x != 0.0 || (keep_zero && (*keep_zero)[i + j * n])) {
        a.indices.push_back(i);
        a.values.push_back(x);
      }
    }
    a.offsets.push_back(static_cast<index_t>(a.indices.size()));
  }
  return a;
}

bool is_permutation(const std::vector<index_t>& p, index_t n) {
  if (static_cast<index_t>(p.size()) != n) return false;
  std::vector<char> seen(n, 0);
  for (index_t x : p) {
    if (x < 0 || x >= n || seen[x]) return false;
    seen[x] = 1;
  }
  return true;
}

// Structural rank by simple augmenting paths (Kuhn), iterative DFS. Reference only.
index_t structural_rank(const SparseMatrix& a_in) {
  const SparseMatrix a = expand_symmetric(a_in);
  const index_t n = a.n_cols;
  std::vector<index_t> row_match(n, -1), stamp(n, -1);
  index_t rank = 0;
  for (index_t j0 = 0; j0 < n; ++j0) {
    // DFS over columns; stack of (column, next entry position), parent row per column.
    std::vector<std::pair<index_t, index_t>> stack{{j0, a.offsets[j0]}};
    std::vector<index_t> via_row;  // via_row[k]: row that led to stack[k+1]
    bool found = false;
    while (!stack.empty() && !found) {
      auto& [j, p] = stack.back();
      if (p == a.offsets[j + 1]) {
        stack.pop_back();
        if (!via_row.empty()) via_row.pop_back();
        continue;
      }
      const index_t i = a.indices[p++];
      if (!a.values.empty() && a.values[p - 1] == 0.0) continue;
      if (stamp[i] == j0) continue;
      stamp[i] = j0;
      if (row_match[i] == -1) {
        // augment along the stack
        index_t r = i;
        for (index_t k = static_cast<index_t>(stack.size()) - 1; k >= 0; --k) {
          const index_t col = stack[k].first;
          index_t prev_row = k > 0 ? via_row[k - 1] : -1;
          row_match[r] = col;
          r = prev_row;
        }
        found = true;
      } else {
        via_row.push_back(i);
        const index_t jj = row_match[i];
        stack.push_back({jj, a.offsets[jj]});
      }
    }
    if (found) ++rank;
  }
  return rank;
}

// Value of entry (i, j) of a canonical CSC matrix (0 when not stored).
double entry(const SparseMatrix& a, index_t i, index_t j) {
  auto b = a.indices.begin() + a.offsets[j], e = a.indices.begin() + a.offsets[j + 1];
  auto it = std::lower_bound(b, e, i);
  return (it != e && *it == i) ? a.values[it - a.indices.begin()] : 0.0;
}

// Checks every property of a matching result that does not need a reference optimum:
// permutation, n_matched / flag consistent with the nonzero diagonal, n_matched equal to
// the structural rank, scaled entries <= 1 and matched ones == 1. Returns the full matrix.
SparseMatrix check_matching(const SparseMatrix& a_in, const Matching& m, bool check_rank = true) {
  const SparseMatrix a = expand_symmetric(a_in);
  const index_t n = a.n_cols;
  EXPECT_TRUE(is_permutation(m.column_permutation, n));
  if (!is_permutation(m.column_permutation, n)) return a;
  EXPECT_EQ(static_cast<index_t>(m.row_scaling.size()), n);
  EXPECT_EQ(static_cast<index_t>(m.column_scaling.size()), n);
  index_t nonzero_diag = 0;
  for (index_t i = 0; i < n; ++i)
    if (entry(a, i, m.column_permutation[i]) != 0.0) ++nonzero_diag;
  // A maximum matching leaves no free column adjacent to a free row, so the completed
  // permutation puts nonzeros on the diagonal exactly at the matched positions.
  EXPECT_EQ(nonzero_diag, m.n_matched);
  EXPECT_EQ(m.structurally_singular, m.n_matched < n);
  if (check_rank) EXPECT_EQ(m.n_matched, structural_rank(a));
  double max_scaled = 0.0, worst_matched = 0.0;
  for (index_t j = 0; j < n; ++j)
    for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p) {
      const index_t i = a.indices[p];
      const double s = std::abs(m.row_scaling[i] * a.values[p] * m.column_scaling[j]);
      EXPECT_TRUE(std::isfinite(s));
      max_scaled = std::max(max_scaled, s);
      if (m.column_permutation[i] == j && a.values[p] != 0.0)
        worst_matched = std::max(worst_matched, std::abs(s - 1.0));
    }
  EXPECT_LE(max_scaled, 1.0 + 1e-12);
  EXPECT_LE(worst_matched, 1e-12);
  return a;
}

// Σ log|a_{i, perm[i]}| over the diagonal of the permuted matrix (-inf if a zero).
double log_diag_product(const SparseMatrix& full, const Matching& m) {
  double s = 0.0;
  for (index_t i = 0; i < full.n_cols; ++i)
    s += std::log(std::abs(entry(full, i, m.column_permutation[i])));
  return s;
}

// Random n×n matrix with the given density; magnitudes spread over `decades` decades.
std::vector<double> random_dense(index_t n, double density, double decades, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u01(0.0, 1.0), expo(-decades / 2, decades / 2);
  std::vector<double> d(n * n, 0.0);
  for (auto& x : d)
    if (u01(rng) < density) x = (u01(rng) < 0.5 ? -1.0 : 1.0) * std::pow(10.0, expo(rng));
  return d;
}

// Dense Hungarian algorithm (potentials, O(n^3)) minimizing Σ cost[i][σ(i)]; cost is
// row-major n×n. Returns σ (row → column).
std::vector<index_t> hungarian(const std::vector<double>& cost, index_t n) {
  const double inf = std::numeric_limits<double>::infinity();
  std::vector<double> u(n + 1, 0.0), v(n + 1, 0.0);
  std::vector<index_t> p(n + 1, 0), way(n + 1, 0);  // p[col] = row (1-based), 0 = none
  for (index_t i = 1; i <= n; ++i) {
    p[0] = i;
    index_t j0 = 0;
    std::vector<double> minv(n + 1, inf);
    std::vector<char> used(n + 1, 0);
    do {
      used[j0] = 1;
      const index_t i0 = p[j0];
      double delta = inf;
      index_t j1 = 0;
      for (index_t j = 1; j <= n; ++j) {
        if (used[j]) continue;
        const double cur = cost[(i0 - 1) * n + (j - 1)] - u[i0] - v[j];
        if (cur < minv[j]) {
          minv[j] = cur;
          way[j] = j0;
        }
        if (minv[j] < delta) {
          delta = minv[j];
          j1 = j;
        }
      }
      for (index_t j = 0; j <= n; ++j) {
        if (used[j]) {
          u[p[j]] += delta;
          v[j] -= delta;
        } else {
          minv[j] -= delta;
        }
      }
      j0 = j1;
    } while (p[j0] != 0);
    do {
      const index_t j1 = way[j0];
      p[j0] = p[j1];
      j0 = j1;
    } while (j0 != 0);
  }
  std::vector<index_t> sigma(n, -1);
  for (index_t j = 1; j <= n; ++j) sigma[p[j] - 1] = j - 1;
  return sigma;
}

// Σ log|a_{i,σ(i)}| of a maximum-product matching of the dense column-major n×n d (one
// with a perfect matching), by the dense Hungarian algorithm on cost = −log|a_ij| with a
// large finite penalty on zeros.
double optimal_log_product(const std::vector<double>& d, index_t n) {
  std::vector<double> cost(n * n);
  for (index_t i = 0; i < n; ++i)
    for (index_t j = 0; j < n; ++j)
      cost[i * n + j] = d[i + j * n] != 0.0 ? -std::log(std::abs(d[i + j * n])) : 1e5;
  const std::vector<index_t> ref = hungarian(cost, n);
  double ref_log = 0.0;
  for (index_t i = 0; i < n; ++i) ref_log += std::log(std::abs(d[i + ref[i] * n]));
  return ref_log;
}

// One of four magnitudes, {1, 1/2, 1/4, 1e-3}, each with probability 1/4: many costs
// exactly equal, so that the searches cross whole regions of tight edges at one distance
// (as on the multibody Newton matrices).
double tied_magnitude(std::mt19937_64& rng) {
  static constexpr double kLevels[] = {1.0, 0.5, 0.25, 1e-3};
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  return kLevels[static_cast<int>(u01(rng) * 4) % 4];
}

// A random dense column-major n×n matrix (values from draw()) with a perfect matching:
// about 3 entries per column plus a random transversal; saddle (n even): [H Gᵀ; G 0] with
// H's diagonal, G with a transversal and Gᵀ with G's pattern and values of its own.
template <class Draw>
std::vector<double> with_transversal(index_t n, bool saddle, Draw&& draw, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  const double density = std::min(1.0, 3.0 / n + 0.05);
  std::vector<double> d(n * n, 0.0);
  std::vector<index_t> sigma(n);
  std::iota(sigma.begin(), sigma.end(), 0);
  if (saddle) {
    const index_t k = n / 2;
    std::shuffle(sigma.begin(), sigma.begin() + k, rng);
    for (index_t j = 0; j < k; ++j)
      for (index_t i = 0; i < k; ++i) {
        if (i == j || u01(rng) < density) d[i + j * n] = draw();
        if (sigma[j] == i || u01(rng) < density) {
          d[(k + i) + j * n] = draw();  // G(i, j)
          d[j + (k + i) * n] = draw();  // Gᵀ(j, i), its own value
        }
      }
  } else {
    std::shuffle(sigma.begin(), sigma.end(), rng);
    for (index_t j = 0; j < n; ++j)
      for (index_t i = 0; i < n; ++i)
        if (u01(rng) < density) d[i + j * n] = draw();
    for (index_t i = 0; i < n; ++i)
      if (d[i + sigma[i] * n] == 0.0) d[i + sigma[i] * n] = draw();
  }
  return d;
}

TEST(Matching, RandomGeneralNonzeroDiagonalAndScaling) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  for (index_t n : {1, 2, 3, 5, 17, 733})
    for (index_t per_column : {1, 2, 4, 8}) {
      SCOPED_TRACE("n " + std::to_string(n) + " per_column " + std::to_string(per_column));
      const SparseMatrix a = test::random_sparse(n, per_column, test::RandomKind::general, rng);
      const Matching m = maximum_product_matching(a);
      check_matching(a, m);
      // random_sparse may leave an empty row when per_column is small; otherwise the
      // diagonal of the permuted matrix is nonzero.
      if (!m.structurally_singular) EXPECT_EQ(m.n_matched, n);
    }
}

TEST(Matching, ZeroDiagonal) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  std::uniform_real_distribution<double> val(0.5, 2.0);
  for (index_t n : {2, 3, 5, 17, 733}) {
    // A permuted diagonal with a zero diagonal (a derangement): the only perfect matching.
    std::vector<index_t> sigma(n);
    std::iota(sigma.begin(), sigma.end(), 0);
    std::shuffle(sigma.begin(), sigma.end(), rng);
    for (index_t i = 0; i < n; ++i)
      if (sigma[i] == i) std::swap(sigma[i], sigma[(i + 1) % n]);
    SparseMatrix a;
    a.n_rows = a.n_cols = n;
    a.layout = Layout::csr;  // row i holds one entry, in column sigma[i]
    a.offsets.assign(n + 1, 0);
    for (index_t i = 0; i < n; ++i) {
      a.offsets[i + 1] = i + 1;
      a.indices.push_back(sigma[i]);
      a.values.push_back(val(rng));
    }
    const Matching m = maximum_product_matching(a);
    check_matching(a, m);
    EXPECT_FALSE(m.structurally_singular);
    EXPECT_EQ(m.column_permutation, sigma);

    // A random general matrix with its whole diagonal removed, plus a derangement so that
    // it stays structurally nonsingular.
    const SparseMatrix r = test::random_sparse(n, 4, test::RandomKind::general, rng);
    std::vector<double> d = test::to_dense(r);
    for (index_t i = 0; i < n; ++i) {
      d[i + sigma[i] * n] = val(rng);
      d[i + i * n] = 0.0;
    }
    const SparseMatrix b = from_dense(d, n);
    const Matching mb = maximum_product_matching(b);
    check_matching(b, mb);
    EXPECT_FALSE(mb.structurally_singular);
    for (index_t i = 0; i < n; ++i) EXPECT_NE(mb.column_permutation[i], i);
  }
}

TEST(Matching, OptimalAgainstBruteForce) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  std::uniform_real_distribution<double> density(0.2, 0.8);
  index_t singular_seen = 0;
  for (int trial = 0; trial < 300; ++trial) {
    const index_t n = 1 + trial % 8;
    const double decades = trial % 3 == 0 ? 0.0 : (trial % 3 == 1 ? 2.0 : 12.0);
    std::vector<double> d = random_dense(n, density(rng), decades, rng);
    if (decades == 0.0)  // many ties: magnitudes 1..3
      for (auto& x : d)
        if (x != 0.0) x = std::copysign(1.0 + static_cast<double>(rng() % 3), x);
    const SparseMatrix a = from_dense(d, n);
    // brute force max Π |a_{i, σ(i)}|
    std::vector<index_t> sigma(n);
    std::iota(sigma.begin(), sigma.end(), 0);
    double best = 0.0;
    do {
      double prod = 1.0;
      for (index_t i = 0; i < n && prod != 0.0; ++i) prod *= std::abs(d[i + sigma[i] * n]);
      best = std::max(best, prod);
    } while (std::next_permutation(sigma.begin(), sigma.end()));
    const Matching m = maximum_product_matching(a);
    SCOPED_TRACE("trial " + std::to_string(trial) + " n " + std::to_string(n));
    check_matching(a, m);
    EXPECT_EQ(m.structurally_singular, best == 0.0);
    if (best == 0.0) {
      ++singular_seen;
      continue;
    }
    double prod = 1.0;
    for (index_t i = 0; i < n; ++i) prod *= std::abs(d[i + m.column_permutation[i] * n]);
    EXPECT_NEAR(prod / best, 1.0, 1e-12);
  }
  EXPECT_GT(singular_seen, 0);  // the singular branch was exercised too
}

TEST(Matching, OptimalAgainstDenseHungarian) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  for (int trial = 0; trial < 20; ++trial) {
    const index_t n = 40 + trial % 21;
    const double decades = trial % 2 == 0 ? 4.0 : 20.0;
    std::vector<double> d = random_dense(n, 0.15, decades, rng);
    // a random permutation of nonzeros guarantees a perfect matching exists; on odd trials
    // it is a derangement and the diagonal is zeroed
    std::vector<index_t> sigma(n);
    std::iota(sigma.begin(), sigma.end(), 0);
    std::shuffle(sigma.begin(), sigma.end(), rng);
    if (trial % 2) {
      for (index_t i = 0; i < n; ++i)
        if (sigma[i] == i) std::swap(sigma[i], sigma[(i + 1) % n]);
      for (index_t i = 0; i < n; ++i) d[i + i * n] = 0.0;
    }
    for (index_t i = 0; i < n; ++i)
      if (d[i + sigma[i] * n] == 0.0) d[i + sigma[i] * n] = 1e-3;
    const SparseMatrix a = from_dense(d, n);
    ASSERT_EQ(structural_rank(a), n);
    const double ref_log = optimal_log_product(d, n);
    const Matching m = maximum_product_matching(a);
    SCOPED_TRACE("trial " + std::to_string(trial) + " n " + std::to_string(n));
    const SparseMatrix full = check_matching(a, m);
    EXPECT_FALSE(m.structurally_singular);
    // relative 1e-12 on the product is about absolute 1e-12 on its logarithm; the sums of
    // n logs carry rounding of their own, hence the slightly wider margin
    EXPECT_NEAR(log_diag_product(full, m), ref_log, 1e-11 * std::max(1.0, std::abs(ref_log)));
  }
}

// Magnitudes from four values only ({1, 1/2, 1/4, 1e-3}, random signs), so that many costs
// are exactly equal and the searches cross whole regions of tight edges at one distance
// (as on the multibody Newton matrices): general sparse matrices, and saddle-point ones
// [H Gᵀ; G 0] with a zero (2,2) block. Optimal against the dense Hungarian algorithm.
TEST(Matching, EqualMagnitudesAgainstDenseHungarian) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  auto draw = [&] {
    const double m = tied_magnitude(rng);
    return u01(rng) < 0.5 ? -m : m;
  };
  const index_t sizes[] = {1, 2, 3, 5, 8, 24, 40, 61, 80};
  for (int trial = 0; trial < 36; ++trial) {
    const index_t n = sizes[trial % 9];
    const bool saddle = trial % 2 == 1 && n % 2 == 0;
    const std::vector<double> d = with_transversal(n, saddle, draw, rng);
    const SparseMatrix a = from_dense(d, n);
    ASSERT_EQ(structural_rank(a), n);
    const double ref_log = optimal_log_product(d, n);
    const Matching m = maximum_product_matching(a);
    SCOPED_TRACE("trial " + std::to_string(trial) + " n " + std::to_string(n) +
                 (saddle ? " saddle point" : ""));
    const SparseMatrix full = check_matching(a, m);
    EXPECT_FALSE(m.structurally_singular);
    EXPECT_NEAR(log_diag_product(full, m), ref_log, 1e-11 * std::max(1.0, std::abs(ref_log)));
  }
}

// A matching started from another one (Solver::analyze(a, start)): from the matching of
// the same matrix, of the matrix with its values moved (a Newton loop's next analysis),
// and from a random start (scalings over twenty decades, a random permutation), the result
// is again optimal against the dense Hungarian algorithm, with the scaling's properties;
// general and saddle-point matrices, magnitudes spread or from four values (many ties).
TEST(Matching, StartedFromAnotherMatchingIsOptimal) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  const index_t sizes[] = {1, 2, 3, 5, 8, 24, 61, 80};
  for (int trial = 0; trial < 48; ++trial) {
    const index_t n = sizes[trial % 8];
    const bool ties = trial % 3 == 0;
    auto draw = [&] {
      const double m = ties ? tied_magnitude(rng) : std::pow(10.0, 8 * u01(rng) - 4);
      return u01(rng) < 0.5 ? -m : m;
    };
    const bool saddle = trial % 2 == 1 && n % 2 == 0;
    const std::vector<double> d = with_transversal(n, saddle, draw, rng);
    // the same pattern with every value moved by up to a factor 3 (ties: kept)
    std::vector<double> moved = d;
    if (!ties)
      for (double& x : moved) x *= std::pow(3.0, 2 * u01(rng) - 1);
    const SparseMatrix a = from_dense(d, n), b = from_dense(moved, n);
    ASSERT_EQ(structural_rank(b), n);
    const double ref_log = optimal_log_product(moved, n);
    Matching random_start;
    random_start.row_scaling.resize(n);
    for (double& x : random_start.row_scaling) x = std::pow(10.0, 20 * u01(rng) - 10);
    random_start.column_permutation.resize(n);
    std::iota(random_start.column_permutation.begin(), random_start.column_permutation.end(), 0);
    std::shuffle(random_start.column_permutation.begin(), random_start.column_permutation.end(),
                 rng);
    const Matching own = maximum_product_matching_canonical(b);
    const Matching earlier = maximum_product_matching_canonical(a);
    const std::pair<const char*, const Matching*> starts[] = {
        {"its own matching", &own},
        {"the matching before the values moved", &earlier},
        {"a random start", &random_start}};
    for (const auto& [what, start] : starts) {
      SCOPED_TRACE("trial " + std::to_string(trial) + " n " + std::to_string(n) +
                   (saddle ? " saddle point" : "") + (ties ? " ties" : "") + ", from " + what);
      const Matching m = maximum_product_matching_canonical(b, start);
      const SparseMatrix full = check_matching(b, m);
      EXPECT_FALSE(m.structurally_singular);
      EXPECT_NEAR(log_diag_product(full, m), ref_log, 1e-11 * std::max(1.0, std::abs(ref_log)));
    }
  }
  // n = 733, sparse: started from the matching of the values before they moved, the
  // product is the one a matching from scratch finds (optimal: the tests above)
  for (const index_t per_column : {2, 4, 8}) {
    const SparseMatrix a =
        canonicalize(test::random_sparse(733, per_column, test::RandomKind::general, rng));
    SparseMatrix b = a;
    for (double& x : b.values) x *= std::pow(3.0, 2 * u01(rng) - 1);
    const Matching cold = maximum_product_matching_canonical(b);
    if (cold.structurally_singular) continue;
    const Matching earlier = maximum_product_matching_canonical(a);
    const Matching m = maximum_product_matching_canonical(b, &earlier);
    const SparseMatrix full = check_matching(b, m);
    const double ref = log_diag_product(full, cold);
    EXPECT_NEAR(log_diag_product(full, m), ref, 1e-11 * std::max(1.0, std::abs(ref)));
  }
}

TEST(Matching, ScalingWideRangeAndDuality) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  // Entries across 60 decades; a structurally nonsingular pattern (random permutation).
  const index_t n = 300;
  std::vector<double> d = random_dense(n, 0.03, 60.0, rng);
  std::vector<index_t> sigma(n);
  std::iota(sigma.begin(), sigma.end(), 0);
  std::shuffle(sigma.begin(), sigma.end(), rng);
  for (index_t i = 0; i < n; ++i) d[i + sigma[i] * n] = 1e-20;
  const SparseMatrix a = from_dense(d, n);
  const Matching m = maximum_product_matching(a);
  const SparseMatrix full = check_matching(a, m);
  EXPECT_FALSE(m.structurally_singular);
  // Weak duality certificate: with |Dr A Dc| <= 1 and == 1 on the matching, for ANY perfect
  // matching τ, Π|a_iτ(i)| <= Π 1/(r_i c_τ(i)) = Π 1/(r_i c_i), which our matching attains.
  double log_bound = 0.0;
  for (index_t i = 0; i < n; ++i)
    log_bound -= std::log(m.row_scaling[i]) + std::log(m.column_scaling[i]);
  EXPECT_NEAR(log_diag_product(full, m), log_bound, 1e-10 * std::max(1.0, std::abs(log_bound)));
}

TEST(Matching, StructurallySingular) {
  // Empty column 1.
  {
    std::vector<double> d = {1, 2, 0, /*col1*/ 0, 0, 0, /*col2*/ 0, 3, 4};
    const SparseMatrix a = from_dense(d, 3);
    const Matching m = maximum_product_matching(a);
    check_matching(a, m);
    EXPECT_TRUE(m.structurally_singular);
    EXPECT_EQ(m.n_matched, 2);
  }
  // Columns 0 and 2 each have a single entry, both in row 1.
  {
    std::vector<double> d = {0, 5, 0, 0, /*c1*/ 1, 1, 0, 0, /*c2*/ 0, 7, 0, 0, /*c3*/ 0, 0, 1, 1};
    const SparseMatrix a = from_dense(d, 4);
    const Matching m = maximum_product_matching(a);
    check_matching(a, m);
    EXPECT_TRUE(m.structurally_singular);
    EXPECT_EQ(m.n_matched, 3);
  }
  // An empty row and a column of explicit zeros only.
  {
    std::vector<double> d = {1, 0, 1, /*c1*/ 0, 0, 0, /*c2*/ 2, 0, 3};
    std::vector<char> keep(9, 0);
    keep[3] = keep[5] = 1;  // explicit zeros in column 1 (rows 0 and 2)
    const SparseMatrix a = from_dense(d, 3, &keep);
    ASSERT_EQ(a.nnz(), 6);
    const Matching m = maximum_product_matching(a);
    check_matching(a, m);
    EXPECT_TRUE(m.structurally_singular);
    EXPECT_EQ(m.n_matched, 2);
    for (double s : m.row_scaling) EXPECT_TRUE(std::isfinite(s) && s > 0.0);
    for (double s : m.column_scaling) EXPECT_TRUE(std::isfinite(s) && s > 0.0);
  }
  // The only perfect matching would need an explicit zero.
  {
    std::vector<double> d = {0, 1, /*c1*/ 0, 2};
    std::vector<char> keep(4, 0);
    keep[0] = 1;
    const SparseMatrix a = from_dense(d, 2, &keep);
    const Matching m = maximum_product_matching(a);
    check_matching(a, m);
    EXPECT_TRUE(m.structurally_singular);
    EXPECT_EQ(m.n_matched, 1);
  }
  // Random: many deficient columns (columns removed at random from a random matrix).
  {
    unsigned long long seed = 0;
    auto rng = test::fresh_rng(&seed);
    SCOPED_TRACE("seed " + std::to_string(seed));
    const index_t n = 400;
    std::vector<double> d =
        test::to_dense(test::random_sparse(n, 3, test::RandomKind::general, rng));
    for (index_t k = 0; k < 20; ++k) {
      const index_t j = static_cast<index_t>(rng() % n), jj = static_cast<index_t>(rng() % n);
      for (index_t i = 0; i < n; ++i) d[i + j * n] = d[i + jj * n];  // duplicate pattern
    }
    const SparseMatrix a = from_dense(d, n);
    const Matching m = maximum_product_matching(a);
    check_matching(a, m);
  }
}

TEST(Matching, EdgeCasesAndLayouts) {
  // n = 0
  {
    SparseMatrix a;
    const Matching m = maximum_product_matching(a);
    EXPECT_TRUE(m.column_permutation.empty());
    EXPECT_EQ(m.n_matched, 0);
    EXPECT_FALSE(m.structurally_singular);
  }
  // not square
  {
    SparseMatrix a;
    a.n_rows = 2;
    a.n_cols = 3;
    a.offsets = {0, 0, 0, 0};
    EXPECT_THROW(maximum_product_matching(a), InvalidInput);
  }
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  // symmetric storage is expanded: same result as the explicitly expanded matrix
  for (index_t n : {5, 60, 500}) {
    const SparseMatrix s = test::random_sparse(n, 3, test::RandomKind::symmetric_indefinite, rng);
    ASSERT_EQ(s.storage, Storage::lower);
    const Matching ms = maximum_product_matching(s);
    const Matching mf = maximum_product_matching(expand_symmetric(s));
    check_matching(s, ms);
    EXPECT_EQ(ms.column_permutation, mf.column_permutation);
    EXPECT_EQ(ms.row_scaling, mf.row_scaling);
    EXPECT_EQ(ms.column_scaling, mf.column_scaling);
    // upper storage of the same matrix (CSR of the lower triangle read as CSC of the upper)
    SparseMatrix up = s;
    up.layout = Layout::csr;
    up.storage = Storage::upper;
    const Matching mu = maximum_product_matching(up);
    EXPECT_EQ(mu.column_permutation, mf.column_permutation);
  }
  // CSR input: A in CSR is read as A; compare with the CSC form
  {
    const SparseMatrix a = test::random_sparse(200, 4, test::RandomKind::general, rng);
    SparseMatrix t = a;  // CSC of A read as CSR is A^T
    t.layout = Layout::csr;
    const Matching mt = maximum_product_matching(t);
    check_matching(t, mt);
    // product of the diagonal is the same for A and A^T at the optimum
    const Matching ma = maximum_product_matching(a);
    if (!ma.structurally_singular && !mt.structurally_singular) {
      const SparseMatrix fa = expand_symmetric(a), ft = expand_symmetric(t);
      EXPECT_NEAR(log_diag_product(fa, ma), log_diag_product(ft, mt), 1e-10 * a.n_cols);
    }
  }
  // a full CSC matrix whose rows are not sorted within its columns is sorted first: the
  // same result as the canonical one (which the matching reads as it is)
  {
    const SparseMatrix a = test::random_sparse(300, 4, test::RandomKind::general, rng);
    SparseMatrix r = a;
    for (index_t j = 0; j < r.n_cols; ++j) {
      std::reverse(r.indices.begin() + r.offsets[j], r.indices.begin() + r.offsets[j + 1]);
      std::reverse(r.values.begin() + r.offsets[j], r.values.begin() + r.offsets[j + 1]);
    }
    const Matching ma = maximum_product_matching(a), mr = maximum_product_matching(r);
    EXPECT_EQ(mr.column_permutation, ma.column_permutation);
    EXPECT_EQ(mr.row_scaling, ma.row_scaling);
    EXPECT_EQ(mr.column_scaling, ma.column_scaling);
  }
  // pattern only: a maximum cardinality matching
  {
    SparseMatrix a = test::random_sparse(300, 2, test::RandomKind::general, rng);
    a.values.clear();
    const Matching m = maximum_product_matching(a);
    EXPECT_TRUE(is_permutation(m.column_permutation, a.n_cols));
    EXPECT_EQ(m.n_matched, structural_rank(a));
    for (double s : m.row_scaling) EXPECT_EQ(s, 1.0);
  }
}

TEST(Matching, LargerRandomIsFast) {
  // n = 50 000, ~6 entries per column: exercises the heap paths at size; a few seconds
  // would mean something quadratic.
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  const SparseMatrix a = test::random_sparse(50000, 5, test::RandomKind::general, rng);
  const Matching m = maximum_product_matching(a);
  check_matching(a, m, /*check_rank=*/false);
}

TEST(Matching, SharedUnsymmetricMatrices) {
  for (const std::string name : {"west0067", "west0497", "bayer10", "rajat11", "rajat19", "watt_2",
                                 "olm1000", "cryg2500", "nnc1374", "ex6"}) {
    SCOPED_TRACE(name);
    const MMMatrix mm = read_matrix_market(test::matrix_path(name));
    const SparseMatrix& a = mm.matrix;
    const Matching m = maximum_product_matching(a);
    check_matching(a, m, /*check_rank=*/a.n_cols <= 3000);
    if (m.structurally_singular)
      ADD_FAILURE() << name << " reported structurally singular: " << m.n_matched << " of "
                    << a.n_cols << " matched";
    else
      EXPECT_EQ(m.n_matched, a.n_cols);
  }
}

}  // namespace
}  // namespace strata
