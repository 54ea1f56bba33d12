// Ruiz equilibration of a refactorization's values (core/rescale.hpp): rows and columns
// scaled by powers of two end with their largest magnitude in [1/2, 2]; the scaled values
// are exactly diag(row)·B·diag(col), also when the factors are applied in one pass
// (apply_rescaling); a matrix within a factor 2 is left alone; the passes in column blocks
// on several threads give bitwise the sequential result.
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
      // the factors applied to the unscaled values in one pass (apply_rescaling, as after
      // a device's sweeps): the sweeps' bits, on one thread and in blocks
      std::vector<double> once = a.values, once_par = a.values;
      apply_rescaling(a, rs, once);
      apply_rescaling(a, rs, once_par, &arena);
      EXPECT_EQ(once, seq);
      EXPECT_EQ(once_par, seq);
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

// The documented iteration written plainly: at most `sweeps` Ruiz sweeps, each scaling
// row i by the power of two nearest to 1/√(max_j |b_ij|) and column j likewise (frexp's
// exponent e: 2^−⌊(e−1)/2⌋), stopping before a sweep once every nonempty row and column
// maximum is in [1/2, 2].
Rescaling ruiz_reference(const SparseMatrix& a, bool symmetric, std::vector<double>& v,
                         int sweeps) {
  const index_t n = a.n_cols;
  auto pow2 = [](double x) {
    int e = 0;
    std::frexp(x, &e);
    return std::ldexp(1.0, -((e - 1) / 2));
  };
  auto within = [](const std::vector<double>& m) {
    for (double x : m)
      if (x != 0 && (x < 0.5 || x > 2)) return false;
    return true;
  };
  Rescaling out;
  std::vector<double> rmax, cmax;
  maxima(a, symmetric, v, rmax, cmax);
  if (within(rmax) && within(cmax)) return out;
  out.row.assign(n, 1.0);
  out.col.assign(n, 1.0);
  for (; out.sweeps < sweeps; ++out.sweeps) {
    if (out.sweeps > 0) {
      maxima(a, symmetric, v, rmax, cmax);
      if (within(rmax) && within(cmax)) break;
    }
    std::vector<double> r(n), c(n);
    for (index_t i = 0; i < n; ++i) r[i] = rmax[i] > 0 ? pow2(rmax[i]) : 1.0;
    for (index_t j = 0; j < n; ++j) c[j] = cmax[j] > 0 ? pow2(cmax[j]) : 1.0;
    for (index_t j = 0; j < n; ++j)
      for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p) v[p] *= r[a.indices[p]] * c[j];
    for (index_t i = 0; i < n; ++i) out.row[i] *= r[i];
    for (index_t j = 0; j < n; ++j) out.col[j] *= c[j];
  }
  return out;
}

// A limited number of sweeps (the Solver makes at most 3): the same values, factors and
// count as the plain iteration, sequential and in column blocks on two threads.
TEST(Rescale, FewSweepsEqualThePlainIteration) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  tbb::task_arena arena(2);
  for (const bool symmetric : {false, true})
    for (index_t n : {1, 2, 3, 5, 733, 20000})
      for (int sweeps : {0, 1, 2, 3}) {
        SCOPED_TRACE(std::string(symmetric ? "symmetric" : "general") + " n=" + std::to_string(n) +
                     " sweeps=" + std::to_string(sweeps));
        const auto kind =
            symmetric ? test::RandomKind::symmetric_indefinite : test::RandomKind::general;
        const SparseMatrix a = badly_scaled(n, kind, 6, rng);
        std::vector<double> ref = a.values, seq = a.values, par = a.values, work;
        const Rescaling rr = ruiz_reference(a, symmetric, ref, sweeps);
        const Rescaling rs = rescale_values(a, symmetric, seq, sweeps);
        const Rescaling rp = rescale_values(a, symmetric, par, sweeps, &arena, &work);
        EXPECT_EQ(seq, ref);
        EXPECT_EQ(par, ref);
        EXPECT_EQ(rs.row, rr.row);
        EXPECT_EQ(rs.col, rr.col);
        EXPECT_EQ(rs.sweeps, rr.sweeps);
        EXPECT_EQ(rp.sweeps, rr.sweeps);
      }
}

}  // namespace
}  // namespace strata
