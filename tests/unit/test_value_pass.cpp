// The refactorization's pass over the values (core/value_pass.hpp): B = Dr·A(:,Q)·Dc
// written exactly, ‖A‖∞ and ‖B‖₁ against plain loops over the expanded matrix, whether B
// needs rescaling against rescale_values' own decision, bitwise one result for 1, 2 and 3
// threads, and a value that is not finite named by its position.
#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <mutex>
#include <random>
#include <string>
#include <vector>

#include "analysis/analysis.hpp"
#include "core/rescale.hpp"
#include "core/value_pass.hpp"
#include "strata/strata.hpp"
#include "support/test_support.hpp"

namespace strata {
namespace {

// Max row sum of |A| and max column sum of |B| over the full matrices (lower storage
// mirrored), computed entry by entry.
void reference_norms(const SparseMatrix& c, bool symmetric, const std::vector<double>& b,
                     double* norm_inf, double* norm1_b) {
  std::vector<double> row(c.n_rows, 0.0), col(c.n_cols, 0.0);
  for (index_t j = 0; j < c.n_cols; ++j)
    for (index_t p = c.offsets[j]; p < c.offsets[j + 1]; ++p) {
      const index_t i = c.indices[p];
      row[i] += std::abs(c.values[p]);
      col[j] += std::abs(b[p]);
      if (symmetric && i != j) {
        row[j] += std::abs(c.values[p]);
        col[i] += std::abs(b[p]);
      }
    }
  *norm_inf = *norm1_b = 0;
  for (double v : row) *norm_inf = std::max(*norm_inf, v);
  for (double v : col) *norm1_b = std::max(*norm1_b, v);
}

TEST(ValuePass, ScalesExactlyWithTheReferenceNormsOnEveryThreadCount) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  std::uniform_int_distribution<index_t> pick(0, 1 << 30);
  for (auto [kind, type] :
       {std::pair{test::RandomKind::general, MatrixType::general},
        std::pair{test::RandomKind::symmetric_indefinite, MatrixType::symmetric_indefinite},
        std::pair{test::RandomKind::spd, MatrixType::spd}})
    for (index_t n : {1, 2, 3, 5, 733, 9000}) {  // 9000: past kParallelValues entries
      SCOPED_TRACE(std::string(to_string(type)) + " n=" + std::to_string(n));
      const SparseMatrix a = test::random_sparse(n, 6, kind, rng);
      Options o;
      o.type = type;
      const Analysis an = analyze_matrix(a, o);
      const bool symmetric = an.symmetric, scaled = !an.row_scaling.empty();
      ASSERT_EQ(scaled, type != MatrixType::spd);
      // the analyzed values, then values that drifted: a few rows and columns × 10^±4
      SparseMatrix c = canonical_values(an, a);
      for (const bool drift : {false, true}) {
        SCOPED_TRACE(drift ? "drifted values" : "the analyzed values");
        if (drift)
          for (int k = 0; k < 3; ++k) {
            const index_t r = pick(rng) % n;
            const double f = k % 2 ? 1e4 : 1e-4;
            for (index_t j = 0; j < n; ++j)
              for (index_t p = c.offsets[j]; p < c.offsets[j + 1]; ++p)
                if (c.indices[p] == r || j == r) c.values[p] *= f;
          }
        tbb::task_arena one(1);
        ASSERT_TRUE(detail::has_analyzed_pattern(an, c, one));
        std::vector<double> work, b;
        const detail::ValueNorms ref =
            detail::refactor_values(an, c, c.values.data(), one, work, b);
        // B entry by entry: (a_ij·dr_i)·dc_j, the analysis's scaling of A(:,Q)
        ASSERT_EQ(b.size(), c.values.size());
        for (index_t j = 0; j < n; ++j)
          for (index_t p = c.offsets[j]; p < c.offsets[j + 1]; ++p) {
            const double want = scaled
                                    ? c.values[p] * an.row_scaling[c.indices[p]] * an.col_scaling[j]
                                    : c.values[p];
            ASSERT_EQ(b[p], want) << "entry " << p;
          }
        double norm_inf = 0, norm1 = 0;
        reference_norms(c, symmetric, b, &norm_inf, &norm1);
        const double tol = 64 * std::numeric_limits<double>::epsilon();
        EXPECT_NEAR(ref.norm_inf, norm_inf, tol * norm_inf);
        EXPECT_NEAR(ref.scaled_norm1, norm1, tol * norm1);
        // equilibrated exactly when rescale_values leaves B alone
        std::vector<double> again = b;
        const Rescaling rs = rescale_values(c, symmetric, again, 3);
        EXPECT_EQ(ref.equilibrated, scaled && rs.sweeps == 0 && rs.row.empty());
        if (drift && scaled && n >= 733) EXPECT_FALSE(ref.equilibrated);
        // B's maxima handed to rescale_values when it has work: the rows' and columns'
        // largest |b| (symmetric: of the full rows), and the same rescaling from them
        if (scaled && !ref.equilibrated) {
          std::vector<double> rmax(n, 0.0), cmax(n, 0.0);
          for (index_t j = 0; j < n; ++j)
            for (index_t p = c.offsets[j]; p < c.offsets[j + 1]; ++p) {
              const index_t i = c.indices[p];
              rmax[i] = std::max(rmax[i], std::abs(b[p]));
              cmax[j] = std::max(cmax[j], std::abs(b[p]));
              if (symmetric) rmax[j] = std::max(rmax[j], std::abs(b[p]));
            }
          EXPECT_EQ(ref.row_max, rmax);
          if (!symmetric) EXPECT_EQ(ref.col_max, cmax);
          if (symmetric) EXPECT_TRUE(ref.col_max.empty());
          std::vector<double> handed = b;
          const Rescaling rh =
              rescale_values(c, symmetric, handed, 3, nullptr, nullptr, ref.row_max, ref.col_max);
          EXPECT_EQ(handed, again);
          EXPECT_EQ(rh.row, rs.row);
          EXPECT_EQ(rh.col, rs.col);
          EXPECT_EQ(rh.sweeps, rs.sweeps);
        } else {
          EXPECT_TRUE(ref.row_max.empty());
          EXPECT_TRUE(ref.col_max.empty());
        }
        for (int threads : {2, 3}) {
          tbb::task_arena arena(threads);
          std::vector<double> w2, b2;
          const detail::ValueNorms r2 =
              detail::refactor_values(an, c, c.values.data(), arena, w2, b2);
          EXPECT_EQ(r2.norm_inf, ref.norm_inf) << threads << " threads";
          EXPECT_EQ(r2.scaled_norm1, ref.scaled_norm1) << threads << " threads";
          EXPECT_EQ(r2.equilibrated, ref.equilibrated) << threads << " threads";
          EXPECT_EQ(r2.row_max, ref.row_max) << threads << " threads";
          EXPECT_EQ(r2.col_max, ref.col_max) << threads << " threads";
          EXPECT_EQ(b2, b) << threads << " threads";
        }
      }
    }
}

TEST(ValuePass, NamesTheFirstValueThatIsNotFinite) {
  auto rng = test::fresh_rng();
  const SparseMatrix a = test::random_sparse(733, 6, test::RandomKind::general, rng);
  Options o;
  o.type = MatrixType::general;
  const Analysis an = analyze_matrix(a, o);
  for (const double bad :
       {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity()}) {
    SparseMatrix c = canonical_values(an, a);
    const std::size_t p = c.values.size() / 2;
    c.values[p] = bad;
    c.values[p + 7] = -bad;  // a later one is not named
    tbb::task_arena arena(2);
    std::vector<double> work, b;
    try {
      detail::refactor_values(an, c, c.values.data(), arena, work, b);
      ADD_FAILURE() << "no error for " << bad;
    } catch (const InvalidInput& e) {
      EXPECT_NE(std::string(e.what()).find("values[" + std::to_string(p) + "]"), std::string::npos)
          << e.what();
    }
  }
}

// stage_range copies every entry and reports disjoint pieces that cover [0, n), each after
// its entries are in place, on one thread and on several; sizes from empty to many pieces.
TEST(ValuePass, StageRangeReportsEveryPieceOnceItIsInPlace) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  std::uniform_real_distribution<double> u(-1, 1);
  constexpr std::size_t kPiece = std::size_t{1} << 17;
  for (int threads : {1, 4})
    for (std::size_t n :
         {std::size_t{0}, std::size_t{1}, std::size_t{2}, std::size_t{3}, std::size_t{5},
          std::size_t{733}, 2 * kPiece - 1, 2 * kPiece, 5 * kPiece + 7}) {
      SCOPED_TRACE("n " + std::to_string(n) + ", threads " + std::to_string(threads));
      std::vector<double> from(n), to(n, std::nan(""));
      for (double& v : from) v = u(rng);
      tbb::task_arena arena(threads);
      std::mutex m;
      std::vector<std::pair<std::size_t, std::size_t>> pieces;
      bool in_place = true;
      detail::stage_range(to.data(), from.data(), n, arena, [&](std::size_t b, std::size_t e) {
        bool same = true;
        for (std::size_t i = b; i < e; ++i) same = same && to[i] == from[i];
        const std::lock_guard<std::mutex> lock(m);
        in_place = in_place && same;
        pieces.emplace_back(b, e);
      });
      EXPECT_TRUE(in_place) << "a piece was reported before its entries were copied";
      EXPECT_EQ(to, from);
      std::sort(pieces.begin(), pieces.end());
      std::size_t covered = 0;
      for (const auto& [b, e] : pieces) {
        EXPECT_EQ(b, covered) << "pieces overlap or leave a gap";
        EXPECT_LE(e, n);
        covered = e;
      }
      EXPECT_EQ(covered, n);
      EXPECT_EQ(pieces.size(), n < 2 * kPiece ? 1u : (n + kPiece - 1) / kPiece);
    }
}

}  // namespace
}  // namespace strata
