// The stable bucket sort of a pattern's entries (sparse/bucket_entries.hpp) against a
// sequential reference (std::stable_sort of the entries by key), on 1, 2, 3 and 8 threads
// and chunk sizes down to one entry; and the analysis's patterns built on it
// (analysis/patterns.hpp, symbolic::permute_symmetric_pattern) against plain
// definitions, bitwise the same analysis for every thread count.
#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <numeric>
#include <random>
#include <set>
#include <utility>
#include <vector>

#include "analysis/analysis.hpp"
#include "analysis/patterns.hpp"
#include "ordering/ordering.hpp"
#include "sparse/bucket_entries.hpp"
#include "sparse/generators.hpp"
#include "strata/solver.hpp"
#include "support/test_support.hpp"
#include "symbolic/symbolic.hpp"

namespace strata {
namespace {

struct Lines {
  std::vector<index_t> begin, end, key;  // line j: entries [begin[j], end[j]); key per entry
};

// n_lines lines of random lengths (empty ones too) laid out in a shuffled order in one
// array, so that lines are neither contiguous nor in order; keys in [0, n_buckets).
Lines random_lines(index_t n_lines, index_t n_buckets, std::mt19937_64& rng) {
  std::uniform_int_distribution<index_t> len(0, 6), bucket(0, n_buckets - 1);
  std::vector<index_t> order(n_lines);
  std::iota(order.begin(), order.end(), index_t{0});
  std::shuffle(order.begin(), order.end(), rng);
  Lines l;
  l.begin.resize(n_lines);
  l.end.resize(n_lines);
  for (index_t j : order) {
    l.begin[j] = static_cast<index_t>(l.key.size());
    for (index_t k = len(rng); k > 0; --k) l.key.push_back(bucket(rng));
    l.end[j] = static_cast<index_t>(l.key.size());
  }
  return l;
}

TEST(BucketEntries, EqualsTheSequentialStableSortOnEveryThreadCount) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed) + " (STRATA_TEST_SEED replays it)");
  for (const index_t n_lines : {1, 2, 3, 5, 733, 20000})
    for (const index_t n_buckets : {1, 2, 5, 733}) {
      const Lines l = random_lines(n_lines, n_buckets, rng);
      const index_t nnz = static_cast<index_t>(l.key.size());
      // reference: (line, entry) pairs in the sequential visiting order, stably by key
      std::vector<std::pair<index_t, index_t>> ref;
      for (index_t j = 0; j < n_lines; ++j)
        for (index_t p = l.begin[j]; p < l.end[j]; ++p) ref.push_back({j, p});
      std::stable_sort(ref.begin(), ref.end(), [&](const auto& x, const auto& y) {
        return l.key[x.second] < l.key[y.second];
      });
      std::vector<index_t> ref_offsets(n_buckets + 1, 0);
      for (index_t k : l.key) ++ref_offsets[k + 1];
      std::partial_sum(ref_offsets.begin(), ref_offsets.end(), ref_offsets.begin());
      for (const int threads : {1, 2, 3, 8})
        for (const index_t min_chunk : {index_t{1}, index_t{7}, index_t{1} << 15}) {
          SCOPED_TRACE(std::to_string(n_lines) + " lines, " + std::to_string(n_buckets) +
                       " buckets, " + std::to_string(threads) + " threads, chunks of " +
                       std::to_string(min_chunk));
          std::vector<std::pair<index_t, index_t>> got(nnz, {-1, -1});
          std::vector<int> written(nnz, 0);
          std::vector<index_t> offsets;
          tbb::task_arena(threads).execute([&] {
            offsets = detail::bucket_entries(
                n_lines, n_buckets,
                [&](index_t j) {
                  return std::pair<index_t, index_t>{l.begin[j], l.end[j]};
                },
                [&](index_t, index_t p) { return l.key[p]; },
                [&](index_t slot, index_t j, index_t p) {
                  got[slot] = {j, p};
                  ++written[slot];
                },
                min_chunk);
          });
          EXPECT_EQ(offsets, ref_offsets);
          EXPECT_EQ(got, ref);
          EXPECT_TRUE(std::all_of(written.begin(), written.end(), [](int w) { return w == 1; }));
        }
    }
}

// The set of (row, column) of a CSC pattern.
std::set<std::pair<index_t, index_t>> entries(const SparseMatrix& a) {
  std::set<std::pair<index_t, index_t>> s;
  for (index_t j = 0; j < a.n_cols; ++j)
    for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p) s.insert({a.indices[p], j});
  return s;
}

bool canonical(const SparseMatrix& a) {
  for (index_t j = 0; j < a.n_cols; ++j)
    for (index_t p = a.offsets[j] + 1; p < a.offsets[j + 1]; ++p)
      if (a.indices[p] <= a.indices[p - 1]) return false;
  return true;
}

TEST(AnalysisPatterns, SymmetricGraphAndPermutationMatchTheirDefinitions) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed) + " (STRATA_TEST_SEED replays it)");
  for (const index_t n : {1, 2, 3, 5, 733})
    for (const auto kind : {test::RandomKind::general, test::RandomKind::spd}) {
      const bool symmetric = kind != test::RandomKind::general;
      const SparseMatrix a = test::random_sparse(n, 4, kind, rng);
      const SparseMatrix c = symmetric ? canonicalize(a) : expand_symmetric(a);
      std::vector<index_t> q(n);  // a random column permutation for B = A(:, q)
      std::iota(q.begin(), q.end(), index_t{0});
      std::shuffle(q.begin(), q.end(), rng);
      const std::vector<index_t> q_inv =
          symmetric ? std::vector<index_t>{} : ordering::invert_permutation(q);
      // B + Bᵀ off its diagonal, and B's diagonal entries, by definition
      std::set<std::pair<index_t, index_t>> want;
      index_t want_diagonal = 0;
      for (const auto& [i, j] : entries(c)) {
        const index_t bj = symmetric ? j : q_inv[j];
        want_diagonal += i == bj;
        if (i == bj) continue;
        want.insert({i, bj});
        want.insert({bj, i});
      }
      std::vector<index_t> perm(n);
      std::iota(perm.begin(), perm.end(), index_t{0});
      std::shuffle(perm.begin(), perm.end(), rng);
      const std::vector<index_t> iperm = ordering::invert_permutation(perm);
      std::set<std::pair<index_t, index_t>> want_permuted;
      for (const auto& [i, j] : want) want_permuted.insert({iperm[i], iperm[j]});
      SparseMatrix first;
      for (const int threads : {1, 2, 3, 8}) {
        SCOPED_TRACE("n " + std::to_string(n) + (symmetric ? " symmetric" : " general") + ", " +
                     std::to_string(threads) + " threads");
        tbb::task_arena(threads).execute([&] {
          index_t diagonal = -1;
          const ordering::Graph g = detail::symmetric_graph(
              c, symmetric, symmetric ? std::vector<index_t>{} : q, &diagonal);
          SparseMatrix u;
          u.n_rows = u.n_cols = n;
          u.offsets = g.xadj;
          u.indices.assign(g.adjncy.begin(), g.adjncy.end());
          EXPECT_TRUE(canonical(u));
          EXPECT_EQ(entries(u), want);
          EXPECT_EQ(diagonal, want_diagonal);
          const SparseMatrix p =
              symbolic::permute_symmetric_pattern(n, g.xadj, g.adjncy.data(), perm);
          EXPECT_TRUE(canonical(p));
          EXPECT_EQ(entries(p), want_permuted);
          if (threads == 1) first = p;
          EXPECT_EQ(p.offsets, first.offsets);
          EXPECT_EQ(p.indices, first.indices);
        });
      }
    }
}

// Every input entry lands once, at its own place in its front; and the analysis is the
// same for every thread count (order, tree, assembly map).
TEST(AnalysisPatterns, AssemblyMapPlacesEveryEntryAndAnalysisIgnoresThreads) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed) + " (STRATA_TEST_SEED replays it)");
  // random patterns, and a 3D Laplacian large enough for several chunks per pass (its
  // values made unsymmetric for the general case)
  for (const index_t n : {1, 2, 3, 5, 733, 3000, 27000})
    for (const auto kind : {test::RandomKind::general, test::RandomKind::spd,
                            test::RandomKind::symmetric_indefinite}) {
      SparseMatrix a;
      if (n < 27000) {
        a = test::random_sparse(n, 5, kind, rng);
      } else {
        if (kind == test::RandomKind::symmetric_indefinite) continue;
        a = generators::laplacian_3d(30, 30, 30);
        if (kind == test::RandomKind::general) {
          a = expand_symmetric(a);
          std::uniform_real_distribution<double> u(0.5, 1.5);
          for (double& v : a.values) v *= u(rng);
        }
      }
      Options o;
      o.type = kind == test::RandomKind::general ? MatrixType::general
               : kind == test::RandomKind::spd   ? MatrixType::spd
                                                 : MatrixType::symmetric_indefinite;
      o.num_threads = 1;
      const Analysis one = analyze_matrix(a, o, 1);
      // each entry once; its place is (row, column) of the permuted entry in the front
      const SparseMatrix c = one.symmetric ? canonicalize(a) : expand_symmetric(a);
      const auto& t = one.tree;
      const auto& m = one.assembly;
      ASSERT_EQ(m.entry_src.size(), static_cast<std::size_t>(c.nnz()));
      std::vector<int> seen(c.nnz(), 0);
      std::vector<index_t> column(c.nnz());
      for (index_t j = 0; j < c.n_cols; ++j)
        for (index_t p = c.offsets[j]; p < c.offsets[j + 1]; ++p) column[p] = j;
      std::vector<index_t> q_inv;
      if (!one.matching_perm.empty()) q_inv = ordering::invert_permutation(one.matching_perm);
      for (index_t f = 0; f < t.n_fronts(); ++f) {
        const index_t rows = t.n_rows(f);
        for (index_t k = m.entry_offsets[f]; k < m.entry_offsets[f + 1]; ++k) {
          const index_t p = m.entry_src[k];
          ++seen[p];
          // by the front's column they land in, in input order within a column
          if (k > m.entry_offsets[f]) {
            const index_t prev = m.entry_dst[k - 1] / rows, now = m.entry_dst[k] / rows;
            EXPECT_LE(prev, now);
            if (prev == now) EXPECT_LT(m.entry_src[k - 1], p);
          }
          const index_t pi = one.iperm[c.indices[p]];
          const index_t pj = one.iperm[q_inv.empty() ? column[p] : q_inv[column[p]]];
          const index_t lo = std::min(pi, pj), hi = std::max(pi, pj);
          ASSERT_EQ(t.front_of_column[lo], f);
          const index_t dst = m.entry_dst[k], r = dst % rows, col = dst / rows;
          const index_t* fr = t.rows_of(f);
          if (one.symmetric || pi >= pj) {
            EXPECT_EQ(fr[r], hi);
            EXPECT_EQ(t.first_pivot[f] + col, lo);
          } else {
            EXPECT_EQ(fr[col], hi);
            EXPECT_EQ(t.first_pivot[f] + r, lo);
          }
        }
      }
      EXPECT_TRUE(std::all_of(seen.begin(), seen.end(), [](int s) { return s == 1; }));
      for (const int threads : {2, 3, 8}) {
        SCOPED_TRACE("n " + std::to_string(n) + ", " + std::to_string(threads) + " threads");
        o.num_threads = threads;
        const Analysis an = analyze_matrix(a, o, 1);
        EXPECT_EQ(an.perm, one.perm);
        EXPECT_EQ(an.tree.child_offsets, one.tree.child_offsets);
        EXPECT_EQ(an.assembly.entry_offsets, m.entry_offsets);
        EXPECT_EQ(an.assembly.entry_src, m.entry_src);
        EXPECT_EQ(an.assembly.entry_dst, m.entry_dst);
        EXPECT_EQ(an.stats.nnz_l, one.stats.nnz_l);
      }
    }
}

}  // namespace
}  // namespace strata
