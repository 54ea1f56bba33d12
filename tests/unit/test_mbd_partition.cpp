// strata::mbd — the partition check's quality (PartitionMonitor) against a dense
// elimination written here: rows in order, each reduced by every earlier pivot row in
// increasing order with the pivot columns forced, |pivot| / max |entry| per row. Both
// perform the same operations on the nonzeros (a zero multiplier is skipped in both), so
// the results must be bitwise equal; random Jacobians are drawn afresh, with explicit
// zeros in the pattern and rows that cancel exactly. Also: the monitor against
// partition_coordinates' own quality, its reuse for new values, and the engine's Φ_q with
// the elements' whole pattern against the Φ_q without its zeros.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "mbd/generators.hpp"
#include "mbd/integrator.hpp"
#include "mbd/model_io.hpp"
#include "mbd/partition.hpp"
#include "support/mbd_test_support.hpp"
#include "support/test_support.hpp"

namespace strata::mbd {
namespace {

// Dense reference of partition_quality (see the file comment).
double dense_quality(const SparseRows& jac, const std::vector<index_t>& dependent) {
  const index_t m = jac.n_rows(), n = jac.n_cols;
  std::vector<std::vector<double>> piv_rows;  // reduced rows, pivot column zeroed
  std::vector<double> piv_vals;
  std::vector<char> pivoted(n, 0);
  double quality = 1;
  for (index_t r = 0; r < m; ++r) {
    std::vector<double> w(n, 0.0);
    for (index_t p = jac.ptr[r]; p < jac.ptr[r + 1]; ++p) w[jac.cols[p]] += jac.vals[p];
    for (index_t k = 0; k < r; ++k) {
      const index_t c = dependent[k];
      const double x = w[c];
      w[c] = 0.0;
      if (x == 0.0) continue;
      const double mult = x / piv_vals[k];
      for (index_t j = 0; j < n; ++j) w[j] += -mult * piv_rows[k][j];
    }
    double big = 0;
    for (index_t j = 0; j < n; ++j)
      if (!pivoted[j]) big = std::max(big, std::abs(w[j]));
    const index_t d = dependent[r];
    const double piv = pivoted[d] ? 0.0 : w[d];
    if (big == 0 || piv == 0) return 0;
    quality = std::min(quality, std::abs(piv) / big);
    w[d] = 0.0;
    for (index_t j = 0; j < n; ++j)
      if (pivoted[j]) w[j] = 0.0;
    piv_rows.push_back(std::move(w));
    piv_vals.push_back(piv);
    pivoted[d] = 1;
  }
  return quality;
}

// A random m×n Jacobian-like pattern: each row a few columns near a band (as elements
// couple nearby coordinates) plus a few anywhere; `zeros` of the entries exactly zero;
// some rows the negated sum of two earlier rows (exact cancellation is then possible).
SparseRows random_rows(index_t m, index_t n, double zeros, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0), p01(0.0, 1.0);
  std::uniform_int_distribution<index_t> any(0, n - 1);
  SparseRows rows;
  rows.n_cols = n;
  for (index_t r = 0; r < m; ++r) {
    std::vector<index_t> cols;
    const index_t center = n * r / std::max<index_t>(m, 1);
    for (index_t j = std::max<index_t>(0, center - 2); j < std::min(n, center + 3); ++j)
      if (p01(rng) < 0.7) cols.push_back(j);
    for (int e = 0; e < 2; ++e)
      if (p01(rng) < 0.3) cols.push_back(any(rng));
    if (cols.empty()) cols.push_back(any(rng));
    std::sort(cols.begin(), cols.end());
    cols.erase(std::unique(cols.begin(), cols.end()), cols.end());
    for (const index_t c : cols) {
      rows.cols.push_back(c);
      rows.vals.push_back(p01(rng) < zeros ? 0.0 : u(rng) * std::pow(10.0, 3 * u(rng)));
    }
    rows.ptr.push_back(static_cast<index_t>(rows.cols.size()));
  }
  return rows;
}

std::vector<index_t> some_dependent(const SparseRows& rows, std::mt19937_64& rng) {
  // a column of each row not taken by an earlier row when there is one (else any)
  std::vector<char> taken(rows.n_cols, 0);
  std::vector<index_t> dep;
  for (index_t r = 0; r < rows.n_rows(); ++r) {
    std::vector<index_t> free;
    for (index_t p = rows.ptr[r]; p < rows.ptr[r + 1]; ++p)
      if (!taken[rows.cols[p]]) free.push_back(rows.cols[p]);
    index_t c = free.empty()
                    ? rows.cols[rows.ptr[r]]
                    : free[std::uniform_int_distribution<std::size_t>(0, free.size() - 1)(rng)];
    taken[c] = 1;
    dep.push_back(c);
  }
  return dep;
}

TEST(MbdPartition, MonitorEqualsDenseEliminationBitwise) {
  unsigned long long seed = 0;
  std::mt19937_64 rng = strata::test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed) + " (STRATA_TEST_SEED replays it)");
  int nonzero = 0;
  for (const index_t m : {1, 2, 3, 5, 40, 733})
    for (const double zeros : {0.0, 0.2}) {
      const index_t n = m + m / 5 + 1;
      SparseRows rows = random_rows(m, n, zeros, rng);
      const std::vector<index_t> dep = some_dependent(rows, rng);
      SCOPED_TRACE("m = " + std::to_string(m) + ", zeros " + std::to_string(zeros));
      PartitionMonitor monitor(rows, dep);
      EXPECT_TRUE(monitor.matches(rows, dep));
      for (int draw = 0; draw < 3; ++draw) {  // new values on the same pattern
        if (draw > 0) {
          std::uniform_real_distribution<double> u(-1.0, 1.0);
          for (double& v : rows.vals) v = u(rng) < -0.8 ? 0.0 : u(rng);
        }
        const double want = dense_quality(rows, dep);
        const double got = monitor.quality(rows);
        EXPECT_EQ(got, want) << "draw " << draw;
        EXPECT_EQ(partition_quality(rows, dep), want);
        nonzero += want > 0;
      }
    }
  EXPECT_GT(nonzero, 0);  // the draws are not all degenerate
}

TEST(MbdPartition, MonitorTakesPartitionCoordinatesOwnQuality) {
  unsigned long long seed = 0;
  std::mt19937_64 rng = strata::test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed) + " (STRATA_TEST_SEED replays it)");
  for (const index_t m : {1, 2, 3, 5, 733}) {
    // full row rank (a dominant diagonal), rows coupled by the band
    SparseRows rows;
    const index_t n = m + 3;
    rows.n_cols = n;
    std::uniform_real_distribution<double> u(0.5, 2.0);
    for (index_t r = 0; r < m; ++r) {
      for (index_t j = r; j < std::min(n, r + 4); ++j) {
        rows.cols.push_back(j);
        rows.vals.push_back(j == r ? 4.0 * u(rng) : u(rng) - 1.25);
      }
      rows.ptr.push_back(static_cast<index_t>(rows.cols.size()));
    }
    const Partition part =
        partition_coordinates(rows, 0.25, 1e-9, [](index_t) { return std::string("row"); });
    PartitionMonitor monitor(rows, part.dependent);
    EXPECT_EQ(monitor.quality(rows), part.quality) << "m = " << m;
    EXPECT_EQ(monitor.quality(rows), dense_quality(rows, part.dependent));
  }
}

TEST(MbdPartition, VanishingAndRepeatedPivotsGiveZero) {
  SparseRows rows;
  rows.n_cols = 3;
  rows.ptr = {0, 2, 4};
  rows.cols = {0, 1, 0, 1};
  rows.vals = {1.0, 2.0, 2.0, 4.0};  // row 1 = 2 · row 0: reduces to zero
  EXPECT_EQ(PartitionMonitor(rows, {0, 1}).quality(rows), 0.0);
  EXPECT_EQ(dense_quality(rows, {0, 1}), 0.0);
  rows.vals = {1.0, 2.0, 2.0, 5.0};
  EXPECT_EQ(PartitionMonitor(rows, {0, 1}).quality(rows), dense_quality(rows, {0, 1}));
  EXPECT_GT(dense_quality(rows, {0, 1}), 0.0);
  EXPECT_EQ(PartitionMonitor(rows, {0, 0}).quality(rows), 0.0);  // a column twice
  EXPECT_EQ(PartitionMonitor(rows, {0, 2}).quality(rows), 0.0);  // not in the row
  PartitionMonitor monitor(rows, {0, 1});
  EXPECT_FALSE(monitor.matches(rows, {1, 0}));
  SparseRows other = rows;
  other.cols[3] = 2;
  EXPECT_FALSE(monitor.matches(other, {0, 1}));
  EXPECT_THROW(PartitionMonitor(rows, {0}), InvalidInput);
  EXPECT_THROW(PartitionMonitor(rows, {0, 3}), InvalidInput);
  other.cols[3] = 7;
  EXPECT_THROW(PartitionMonitor(other, {0, 1}), InvalidInput);
}

TEST(MbdPartition, WholeElementPatternHoldsTheSameJacobian) {
  test::InitializedModel t("tracked:20");
  Integrator& in = t.in;
  NewtonSystem& sys = in.system();
  std::vector<double> q = in.q();
  unsigned long long seed = 0;
  std::mt19937_64 rng = strata::test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed) + " (STRATA_TEST_SEED replays it)");
  std::uniform_real_distribution<double> u(-1e-3, 1e-3);
  for (double& x : q) x += u(rng);
  for (const int threads : {1, 3}) {
    sys.set_threads(threads);
    const SparseRows sparse = sys.constraint_jacobian(q.data(), 0.0);
    SparseRows full;
    sys.constraint_jacobian_full(q.data(), 0.0, full);
    ASSERT_EQ(full.n_rows(), sparse.n_rows());
    ASSERT_EQ(full.n_cols, sparse.n_cols);
    for (index_t r = 0; r < sparse.n_rows(); ++r) {  // the same entries, zeros aside
      std::vector<std::pair<index_t, double>> a, b;
      for (index_t p = sparse.ptr[r]; p < sparse.ptr[r + 1]; ++p)
        a.emplace_back(sparse.cols[p], sparse.vals[p]);
      for (index_t p = full.ptr[r]; p < full.ptr[r + 1]; ++p)
        if (full.vals[p] != 0.0) b.emplace_back(full.cols[p], full.vals[p]);
      ASSERT_EQ(a, b) << "row " << r;
    }
    const std::vector<index_t> dep = partition_coordinates(sparse, 0.25, 1e-9, [](index_t) {
                                       return std::string("row");
                                     }).dependent;
    EXPECT_EQ(PartitionMonitor(full, dep).quality(full), partition_quality(sparse, dep));
    EXPECT_EQ(PartitionMonitor(full, dep).quality(full), dense_quality(sparse, dep));
  }
}

}  // namespace
}  // namespace strata::mbd
