// strata::mbd — the pattern builder (mbd/pattern_builder.hpp) against references written
// out plainly: the pattern of random pairs against a std::set of them, the groups of
// random targets against a stable sort of the indices, triplet sums against sums in the
// order of the triplets; each on 1 to 4 threads (the same bits) and on sizes 1, 2, 3, 5,
// 733 and some large enough for the threaded passes (and, for the groups, for the coarse
// buckets of more than 2^21 targets). Inputs are drawn afresh.
#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <map>
#include <numeric>
#include <random>
#include <set>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "base/serial_scope.hpp"
#include "mbd/pattern_builder.hpp"
#include "strata/errors.hpp"
#include "support/test_support.hpp"

namespace strata::mbd {
namespace {

// f() on `threads` threads of their own arena (1: inside a SerialScope, as a caller with
// no arena does it).
template <class F>
void on_threads(int threads, F&& f) {
  if (threads == 1) {
    detail::SerialScope serial(true);
    f();
    return;
  }
  tbb::task_arena arena(threads);
  arena.execute(f);
}

struct Pairs {
  index_t rows = 0, cols = 0;
  std::vector<index_t> r, c;
};

Pairs random_pairs(index_t rows, index_t cols, std::size_t count, std::mt19937_64& rng) {
  Pairs p{rows, cols, {}, {}};
  std::uniform_int_distribution<index_t> ur(0, rows - 1), uc(0, cols - 1);
  for (std::size_t k = 0; k < count; ++k) {
    // repeat an earlier pair now and then: duplicates must collapse
    if (k > 0 && rng() % 4 == 0) {
      const std::size_t j = rng() % k;
      p.r.push_back(p.r[j]);
      p.c.push_back(p.c[j]);
    } else {
      p.r.push_back(ur(rng));
      p.c.push_back(uc(rng));
    }
  }
  return p;
}

void check_pattern(const Pairs& p, int threads) {
  SCOPED_TRACE(std::to_string(p.r.size()) + " pairs, " + std::to_string(threads) + " threads");
  std::set<std::pair<index_t, index_t>> ref;  // (column, row)
  for (std::size_t k = 0; k < p.r.size(); ++k) ref.insert({p.c[k], p.r[k]});
  PatternBuilder pb(p.rows, p.cols);
  // half the pairs one at a time, half in a block the threads fill
  const std::size_t half = p.r.size() / 2;
  for (std::size_t k = 0; k < half; ++k) pb.add(p.r[k], p.c[k]);
  const std::size_t at = pb.grow(p.r.size() - half);
  ASSERT_EQ(at, half);
  for (std::size_t k = half; k < p.r.size(); ++k) pb.set(k, p.r[k], p.c[k]);
  SparseMatrix a;
  on_threads(threads, [&] { a = pb.finish(); });
  ASSERT_EQ(a.n_rows, p.rows);
  ASSERT_EQ(a.n_cols, p.cols);
  ASSERT_EQ(a.offsets.size(), static_cast<std::size_t>(p.cols) + 1);
  ASSERT_EQ(static_cast<std::size_t>(a.nnz()), ref.size());
  ASSERT_EQ(a.values, std::vector<double>(ref.size(), 0.0));
  auto it = ref.begin();
  for (index_t c = 0; c < p.cols; ++c)
    for (index_t q = a.offsets[c]; q < a.offsets[c + 1]; ++q, ++it) {
      ASSERT_EQ(it->first, c);
      ASSERT_EQ(it->second, a.indices[q]);
      EXPECT_EQ(entry_position(a, a.indices[q], c), q);
    }
  EXPECT_THROW(entry_position(a, p.rows, 0), std::logic_error);  // past column 0's last row
}

TEST(MbdPatternBuilder, PatternIsTheSetOfPairsOnAnyThreads) {
  std::mt19937_64 rng = test::fresh_rng();
  for (std::size_t count : {1, 2, 3, 5, 733, 300000})
    for (int threads : {1, 2, 3, 4}) {
      const index_t n = count < 10 ? 3 : 2000;
      check_pattern(random_pairs(n, n + 7, count, rng), threads);
    }
  // one row, one column
  check_pattern(random_pairs(1, 1, 5, rng), 2);
  // a pair is kept in 64 bits: larger dimensions are refused
  EXPECT_THROW(PatternBuilder((index_t{1} << 32) + 1, 1), InvalidInput);
  EXPECT_THROW(PatternBuilder(1, (index_t{1} << 31) + 1), InvalidInput);
  EXPECT_NO_THROW(PatternBuilder(index_t{1} << 32, index_t{1} << 31));
}

void check_groups(const std::vector<index_t>& target_of, index_t targets, int threads) {
  SCOPED_TRACE(std::to_string(target_of.size()) + " indices, " + std::to_string(targets) +
               " targets, " + std::to_string(threads) + " threads");
  std::vector<std::size_t> order(target_of.size());
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t x, std::size_t y) { return target_of[x] < target_of[y]; });
  TargetGroups g;
  on_threads(threads, [&] { g = group_by_target(target_of, targets); });
  EXPECT_EQ(std::vector<std::size_t>(g.slot.begin(), g.slot.end()), order);
  ASSERT_EQ(g.first.size(), g.target.size() + 1);
  EXPECT_EQ(g.first.front(), 0u);
  EXPECT_EQ(g.first.back(), target_of.size());
  std::vector<index_t> distinct(target_of);
  std::sort(distinct.begin(), distinct.end());
  distinct.erase(std::unique(distinct.begin(), distinct.end()), distinct.end());
  EXPECT_EQ(g.target, distinct);
  for (std::size_t t = 0; t < g.target.size(); ++t) {
    ASSERT_LT(g.first[t], g.first[t + 1]);
    for (std::size_t i = g.first[t]; i < g.first[t + 1]; ++i)
      ASSERT_EQ(target_of[g.slot[i]], g.target[t]);
  }
}

TEST(MbdPatternBuilder, GroupsAreTheStableSortByTarget) {
  std::mt19937_64 rng = test::fresh_rng();
  for (std::size_t count : {1, 2, 3, 5, 733, 200000})
    for (index_t targets : {index_t{1}, index_t{7}, index_t{50000}, index_t{3} << 21})
      for (int threads : {1, 3}) {
        std::uniform_int_distribution<index_t> u(0, targets - 1);
        std::vector<index_t> target_of(count);
        for (index_t& t : target_of) t = u(rng);
        check_groups(target_of, targets, threads);
      }
  check_groups({}, 5, 2);  // nothing to group
}

TEST(MbdPatternBuilder, TripletsAreSummedInTheirOrderOnAnyThreads) {
  std::mt19937_64 rng = test::fresh_rng();
  std::uniform_real_distribution<double> u(-1, 1);
  for (std::size_t count : {1, 2, 3, 5, 733, 250000}) {
    const index_t n = count < 10 ? 2 : 500;
    const Pairs p = random_pairs(n, n, count, rng);
    std::vector<double> vals(count);
    for (double& v : vals) v = u(rng) * std::ldexp(1.0, static_cast<int>(rng() % 40) - 20);
    // reference: each entry's triplets added in the order of k, starting from zero
    std::map<std::pair<index_t, index_t>, double> ref;  // (column, row)
    for (std::size_t k = 0; k < count; ++k) ref[{p.c[k], p.r[k]}] += vals[k];
    for (int threads : {1, 2, 4}) {
      SCOPED_TRACE(std::to_string(count) + " triplets, " + std::to_string(threads) + " threads");
      tbb::task_arena arena(threads);
      const SparseMatrix a = from_triplets(n, n, p.r, p.c, vals, threads == 1 ? nullptr : &arena);
      ASSERT_EQ(static_cast<std::size_t>(a.nnz()), ref.size());
      auto it = ref.begin();
      for (index_t c = 0; c < n; ++c)
        for (index_t q = a.offsets[c]; q < a.offsets[c + 1]; ++q, ++it) {
          ASSERT_EQ(it->first, std::make_pair(c, a.indices[q]));
          ASSERT_EQ(std::memcmp(&it->second, &a.values[q], sizeof(double)), 0)
              << "entry (" << a.indices[q] << ", " << c << "): " << a.values[q] << " against "
              << it->second;
        }
    }
  }
}

}  // namespace
}  // namespace strata::mbd
