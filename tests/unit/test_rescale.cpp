// Ruiz equilibration of a refactorization's values (core/rescale.hpp): rows and columns
// scaled by powers of two end with their largest magnitude in [1/2, 2]; the scaled values
// are exactly diag(row)·B·diag(col); a matrix within a factor 2 is left alone; the passes
// in column blocks on several threads give bitwise the sequential result.
#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "core/rescale.hpp"
#include "support/test_support.hpp"

namespace strata {
namespace {

// Rows and columns multiplied by 10^k, k uniform in [−e, e]: far from equilibrium.
SparseMatrix badly_scaled(index_t n, test::RandomKind kind, int e, std::mt19937_64& rng) {
  SparseMatrix a = test::random_sparse(n, 6, kind, rng);
  std::uniform_int_distribution<int> k(-e, e);
  std::vector<double> d(n);
  for (double& v : d) v = std::pow(10.0, k(rng));
  for (index_t j = 0; j < n; ++j)
    for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p)
      a.values[p] *= d[a.indices[p]] * d[j];  // symmetric kinds stay symmetric
  return a;
}

// The largest magnitude of each row and column of the full matrix (lower: mirrored).
void maxima(const SparseMatrix& a, bool symmetric, const std::vector<double>& v,
            std::vector<double>& rmax, std::vector<double>& cmax) {
  rmax.assign(a.n_rows, 0.0);
  cmax.assign(a.n_cols, 0.0);
  for (index_t j = 0; j < a.n_cols; ++j)
    for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p) {
      const index_t i = a.indices[p];
      rmax[i] = std::max(rmax[i], std::abs(v[p]));
      cmax[j] = std::max(cmax[j], std::abs(v[p]));
      if (symmetric) {
        rmax[j] = std::max(rmax[j], std::abs(v[p]));
        cmax[i] = std::max(cmax[i], std::abs(v[p]));
      }
    }
}

TEST(Rescale, EquilibratesExactlyAndThreadsGiveTheSameBits) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  tbb::task_arena arena(2);
  for (const bool symmetric : {false, true})
    for (index_t n : {1, 2, 3, 5, 733, 20000}) {  // 20000: past the threshold for blocks
      SCOPED_TRACE(std::string(symmetric ? "symmetric" : "general") + " n=" + std::to_string(n));
      const auto kind =
          symmetric ? test::RandomKind::symmetric_indefinite : test::RandomKind::general;
      const SparseMatrix a = badly_scaled(n, kind, 4, rng);
      std::vector<double> seq = a.values, par = a.values, work;
      const Rescaling rs = rescale_values(a, symmetric, seq, 20);
      const Rescaling rp = rescale_values(a, symmetric, par, 20, &arena, &work);
      EXPECT_EQ(seq, par);
      EXPECT_EQ(rs.row, rp.row);
      EXPECT_EQ(rs.col, rp.col);
      EXPECT_EQ(rs.sweeps, rp.sweeps);
      if (rs.row.empty()) continue;  // already within a factor 2
      if (symmetric) EXPECT_EQ(rs.row, rs.col);
      for (index_t j = 0; j < n; ++j)
        for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p) {
          const double expect = a.values[p] * rs.row[a.indices[p]] * rs.col[j];
          ASSERT_EQ(seq[p], expect);  // powers of two: exact
          int e = 0;
          ASSERT_EQ(std::frexp(rs.row[a.indices[p]], &e), 0.5);  // a power of two
        }
      std::vector<double> rmax, cmax;
      maxima(a, symmetric, seq, rmax, cmax);
      if (rs.sweeps < 20) {  // converged: every nonempty line within [1/2, 2]
        for (double v : rmax) EXPECT_TRUE(v == 0 || (v >= 0.5 && v <= 2)) << v;
        for (double v : cmax) EXPECT_TRUE(v == 0 || (v >= 0.5 && v <= 2)) << v;
      }
      // a second call finds nothing to do
      std::vector<double> again = seq;
      if (rs.sweeps < 20) EXPECT_TRUE(rescale_values(a, symmetric, again, 20).row.empty());
    }
}

}  // namespace
}  // namespace strata
