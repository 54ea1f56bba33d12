// strata tests — the pieces of the distributed solver that run without MPI: the analysis
// survives the round trip through bytes that rank 0 broadcasts (every field compared);
// cut or padded bytes are refused (upper layers included); the rank layout covers every
// pivot once and the ranks' factor shares add up to the factor (upper layers refused); the
// scaled values a rank is sent (value_positions) are exactly the entries whose earlier
// pivot lies in its subtrees, and with only those values (every other one NaN) a rank's
// subtrees factor to bitwise the one-process panels; DistributedSolver on the one-process
// communicator is the Solver (solutions against a dense LAPACK solve); an error raised on
// one rank reaches the others with its type, message and data (an InternalError stays a
// bug report, not "bad input").
#include <gtest/gtest.h>

#include <cstring>
#include <limits>

#include "analysis/analysis.hpp"
#include "distributed/distributed_internal.hpp"
#include "distributed/serialize.hpp"
#include "numeric/factor.hpp"
#include "ordering/ordering.hpp"
#include "sparse/generators.hpp"
#include "strata/distributed.hpp"
#include "strata/strata.hpp"
#include "support/test_support.hpp"

namespace strata {
namespace {

void expect_same_part(const schedule::FactorPart& x, const schedule::FactorPart& y) {
  EXPECT_EQ(x.root, y.root);
  EXPECT_EQ(x.work, y.work);
  EXPECT_EQ(x.fronts, y.fronts);
  EXPECT_EQ(x.schedule.level_offsets, y.schedule.level_offsets);
  EXPECT_EQ(x.schedule.fronts, y.schedule.fronts);
  EXPECT_EQ(x.schedule.level_of, y.schedule.level_of);
  EXPECT_EQ(x.plan.budget, y.plan.budget);
  ASSERT_EQ(x.plan.batches.size(), y.plan.batches.size());
  for (std::size_t i = 0; i < x.plan.batches.size(); ++i) {
    EXPECT_EQ(x.plan.batches[i].begin, y.plan.batches[i].begin);
    EXPECT_EQ(x.plan.batches[i].end, y.plan.batches[i].end);
    EXPECT_EQ(x.plan.batches[i].bytes, y.plan.batches[i].bytes);
  }
  EXPECT_EQ(x.plan.peak_in_core_bytes, y.plan.peak_in_core_bytes);
  EXPECT_EQ(x.cb_layout.cb_offset, y.cb_layout.cb_offset);
  EXPECT_EQ(x.cb_layout.arena_size, y.cb_layout.arena_size);
  EXPECT_EQ(x.imports, y.imports);
}

void expect_same(const Analysis& x, const Analysis& y) {
  EXPECT_EQ(x.id, y.id);
  EXPECT_EQ(x.n, y.n);
  EXPECT_EQ(x.type, y.type);
  EXPECT_EQ(x.symmetric, y.symmetric);
  EXPECT_EQ(x.pattern_offsets, y.pattern_offsets);
  EXPECT_EQ(x.pattern_indices, y.pattern_indices);
  EXPECT_EQ(x.input_storage, y.input_storage);
  EXPECT_EQ(x.matching_perm, y.matching_perm);
  EXPECT_EQ(x.row_scaling, y.row_scaling);
  EXPECT_EQ(x.col_scaling, y.col_scaling);
  EXPECT_EQ(x.pivot_groups.ptr, y.pivot_groups.ptr);
  EXPECT_EQ(x.pivot_groups.members, y.pivot_groups.members);
  EXPECT_EQ(x.perm, y.perm);
  EXPECT_EQ(x.iperm, y.iperm);
  ASSERT_EQ(x.separator_tree.nodes.size(), y.separator_tree.nodes.size());
  for (std::size_t i = 0; i < x.separator_tree.nodes.size(); ++i) {
    EXPECT_EQ(x.separator_tree.nodes[i].begin, y.separator_tree.nodes[i].begin);
    EXPECT_EQ(x.separator_tree.nodes[i].children, y.separator_tree.nodes[i].children);
    EXPECT_EQ(x.separator_tree.nodes[i].work, y.separator_tree.nodes[i].work);
  }
  EXPECT_EQ(x.tree.first_pivot, y.tree.first_pivot);
  EXPECT_EQ(x.tree.row_offsets, y.tree.row_offsets);
  EXPECT_EQ(x.tree.rows, y.tree.rows);
  EXPECT_EQ(x.tree.parent, y.tree.parent);
  EXPECT_EQ(x.tree.children, y.tree.children);
  EXPECT_EQ(x.tree.front_of_column, y.tree.front_of_column);
  EXPECT_EQ(x.schedule.fronts, y.schedule.fronts);
  EXPECT_EQ(x.plan.batches.size(), y.plan.batches.size());
  EXPECT_EQ(x.assembly.entry_offsets, y.assembly.entry_offsets);
  EXPECT_EQ(x.assembly.entry_src, y.assembly.entry_src);
  EXPECT_EQ(x.assembly.entry_dst, y.assembly.entry_dst);
  EXPECT_EQ(x.cb_layout.cb_offset, y.cb_layout.cb_offset);
  EXPECT_EQ(x.factor_layout.panel_offset, y.factor_layout.panel_offset);
  EXPECT_EQ(x.factor_layout.total, y.factor_layout.total);
  EXPECT_EQ(x.partition.workers, y.partition.workers);
  ASSERT_EQ(x.partition.subtrees.size(), y.partition.subtrees.size());
  for (std::size_t i = 0; i < x.partition.subtrees.size(); ++i)
    expect_same_part(x.partition.subtrees[i], y.partition.subtrees[i]);
  expect_same_part(x.partition.top, y.partition.top);
  ASSERT_EQ(x.partition.upper.size(), y.partition.upper.size());
  for (std::size_t i = 0; i < x.partition.upper.size(); ++i)
    expect_same_part(x.partition.upper[i], y.partition.upper[i]);
  EXPECT_EQ(x.partition.upper_layer_offsets, y.partition.upper_layer_offsets);
  EXPECT_EQ(x.partition.upper_owner, y.partition.upper_owner);
  EXPECT_EQ(x.partition.part_id, y.partition.part_id);
  EXPECT_EQ(x.partition.estimated_time, y.partition.estimated_time);
  EXPECT_EQ(x.partition.part_of, y.partition.part_of);
  EXPECT_EQ(x.partition.owner, y.partition.owner);
  EXPECT_EQ(x.partition.balance, y.partition.balance);
  EXPECT_EQ(x.stats.nnz_l, y.stats.nnz_l);
  EXPECT_EQ(x.stats.factor_flops, y.stats.factor_flops);
  EXPECT_EQ(x.stats.fronts_per_level, y.stats.fronts_per_level);
  EXPECT_EQ(x.stats.subtrees, y.stats.subtrees);
  EXPECT_EQ(x.stats.upper_layers, y.stats.upper_layers);
  EXPECT_EQ(x.stats.upper_parts, y.stats.upper_parts);
  EXPECT_EQ(x.stats.upper_flops_fraction, y.stats.upper_flops_fraction);
  EXPECT_EQ(x.stats.estimated_speedup, y.stats.estimated_speedup);
  EXPECT_EQ(x.stats.total_seconds, y.stats.total_seconds);
}

TEST(DistributedSerialize, RoundTripEveryType) {
  auto rng = test::fresh_rng();
  struct Case {
    SparseMatrix a;
    MatrixType type;
    int workers;
  };
  std::vector<Case> cases;
  int upper_layers = 0;  // cases whose analysis has upper layers
  cases.push_back({generators::laplacian_3d(9, 9, 9), MatrixType::spd, 4});
  cases.push_back({generators::laplacian_3d(16, 16, 16), MatrixType::spd, 4});  // upper layers
  cases.push_back({test::random_kkt(301, rng), MatrixType::symmetric_indefinite, 3});
  cases.push_back(
      {test::random_sparse(257, 3, test::RandomKind::general, rng), MatrixType::general, 2});
  cases.push_back({test::random_sparse(1, 1, test::RandomKind::spd, rng), MatrixType::spd, 2});
  for (const Case& c : cases) {
    Options o;
    o.type = c.type;
    const Analysis an = analyze_matrix(c.a, o, c.workers);
    upper_layers += an.partition.n_upper_layers() > 0;
    const std::vector<char> bytes = distributed::serialize(an);
    const Analysis back = distributed::deserialize(bytes);
    expect_same(an, back);
    std::vector<char> cut(bytes.begin(), bytes.end() - 1), longer = bytes;
    longer.push_back(0);
    EXPECT_THROW(distributed::deserialize(cut), InternalError);
    EXPECT_THROW(distributed::deserialize(longer), InternalError);
  }
  EXPECT_GT(upper_layers, 0) << "no case had upper layers to carry";
}

// For R ranks × G workers: every pivot column is in exactly one subtree or the top part,
// and the ranks' local factor layouts add up to the whole factor. The analysis is made as
// the distributed solver makes it, without upper layers; one with them is refused.
TEST(DistributedSerialize, RankLayoutsCoverTheFactor) {
  auto rng = test::fresh_rng();
  const SparseMatrix a = generators::laplacian_3d(11, 11, 11);
  for (auto [ranks, per_rank] : {std::pair{2, 1}, std::pair{4, 1}, std::pair{2, 2}}) {
    SCOPED_TRACE(std::to_string(ranks) + " x " + std::to_string(per_rank));
    Options o;
    o.type = MatrixType::spd;
    const Analysis layered = analyze_matrix(a, o, ranks * per_rank);
    if (layered.partition.n_upper_layers() > 0)
      EXPECT_THROW(distributed::make_layout(layered, ranks, 0, per_rank), InternalError);
    o.split_top = false;
    const Analysis an = analyze_matrix(a, o, ranks * per_rank);
    std::vector<int> seen(an.n, 0);
    std::size_t total = 0;
    for (int r = 0; r < ranks; ++r) {
      const distributed::RankLayout l = distributed::make_layout(an, ranks, r, per_rank);
      if (r == 0)
        for (index_t c : l.top_cols) ++seen[c];
      for (int i : l.subtrees_of[r])
        for (index_t c = l.col_begin[i]; c < l.col_end[i]; ++c) ++seen[c];
      Analysis mine = an;
      distributed::localize_factor_layout(mine, l);
      total += mine.factor_layout.total;
      for (index_t f : l.my_fronts)  // my panels fit in my share
        EXPECT_LE(mine.factor_layout.panel_offset[f] + panel_size(an.tree, f, false),
                  mine.factor_layout.total);
    }
    for (index_t c = 0; c < an.n; ++c) ASSERT_EQ(seen[c], 1) << "column " << c;
    EXPECT_EQ(total, an.factor_layout.total);
  }
}

using ScatterCase = test::NamedMatrix;

// Every type (with the matching's column permutation for general), awkward sizes.
std::vector<ScatterCase> scatter_cases(std::mt19937_64& rng) {
  std::vector<ScatterCase> c;
  c.push_back({"lap3d 9", generators::laplacian_3d(9, 9, 9), MatrixType::spd});
  for (index_t n : {1, 2, 3, 5, 733})
    c.push_back({"random spd " + std::to_string(n),
                 test::random_sparse(n, 3, test::RandomKind::spd, rng), MatrixType::spd});
  c.push_back({"random kkt 301", test::random_kkt(301, rng), MatrixType::symmetric_indefinite});
  c.push_back({"random indefinite 5",
               test::random_sparse(5, 2, test::RandomKind::symmetric_indefinite, rng),
               MatrixType::symmetric_indefinite});
  c.push_back({"random general 257", test::random_sparse(257, 3, test::RandomKind::general, rng),
               MatrixType::general});
  c.push_back({"random general 3", test::random_sparse(3, 2, test::RandomKind::general, rng),
               MatrixType::general});
  return c;
}

const std::pair<int, int> kRankShapes[] = {{2, 1}, {3, 1}, {4, 1}, {2, 2}};

// The analysis of a scatter case split for ranks × per_rank workers, without upper layers,
// as the distributed solver analyzes.
Analysis analyze_for_ranks(const ScatterCase& c, int ranks, int per_rank) {
  Options o;
  o.type = c.type;
  o.split_top = false;
  return analyze_matrix(c.a, o, ranks * per_rank);
}

// The values each rank is sent are exactly the stored entries (i, j) of the canonical
// input whose earlier pivot, min(position of row i, position of column j) (after the
// matching's column permutation), lies in the pivot columns of one of its subtrees —
// enumerated here from the ordering and the subtrees' column ranges, not from the
// assembly map. Every entry goes to one rank at most; the rest are the top part's.
TEST(DistributedSerialize, ValuePositionsAreTheSubtreesEntries) {
  auto rng = test::fresh_rng();
  for (const ScatterCase& c : scatter_cases(rng))
    for (auto [ranks, per_rank] : kRankShapes) {
      SCOPED_TRACE(c.name + ", " + std::to_string(ranks) + " x " + std::to_string(per_rank));
      const Analysis an = analyze_for_ranks(c, ranks, per_rank);
      const distributed::RankLayout l0 = distributed::make_layout(an, ranks, 0, per_rank);
      std::vector<int> rank_of_pivot(an.n, -1);  // -1: the top part
      for (std::size_t i = 0; i < l0.subtree_rank.size(); ++i)
        for (index_t k = l0.col_begin[i]; k < l0.col_end[i]; ++k)
          rank_of_pivot[k] = l0.subtree_rank[i];
      std::vector<index_t> q_inv;
      if (!an.matching_perm.empty()) q_inv = ordering::invert_permutation(an.matching_perm);
      std::vector<std::vector<index_t>> expect(ranks);
      std::size_t top = 0;
      for (index_t j = 0; j < an.n; ++j)
        for (index_t p = an.pattern_offsets[j]; p < an.pattern_offsets[j + 1]; ++p) {
          const index_t pi = an.iperm[an.pattern_indices[p]];
          const index_t pj = an.iperm[q_inv.empty() ? j : q_inv[j]];
          const int r = rank_of_pivot[std::min(pi, pj)];
          if (r >= 0)
            expect[r].push_back(p);
          else
            ++top;
        }
      std::size_t sent = 0;
      for (int r = 0; r < ranks; ++r) {
        const distributed::RankLayout l = distributed::make_layout(an, ranks, r, per_rank);
        const std::vector<index_t> got = distributed::value_positions(an, l, r);
        EXPECT_EQ(got, expect[r]) << "rank " << r;
        if (r > 0) sent += got.size();
      }
      EXPECT_EQ(sent + expect[0].size() + top, an.pattern_indices.size());
    }
}

// A rank that has only the values value_positions names (every other entry NaN) factors
// its subtrees to bitwise the panels of the one-process factorization with all values:
// a value it needs and is not sent would leave a NaN (or a different number) in a panel.
TEST(DistributedSerialize, SubtreesFactorFromTheirScatteredValues) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed) + " (STRATA_TEST_SEED replays it)");
  for (const ScatterCase& c : scatter_cases(rng))
    for (auto [ranks, per_rank] : kRankShapes) {
      SCOPED_TRACE(c.name + ", " + std::to_string(ranks) + " x " + std::to_string(per_rank));
      const Analysis an = analyze_for_ranks(c, ranks, per_rank);
      double pivot = 0;
      const std::vector<double> v = test::scaled_values(an, c.a, &pivot);
      // the level schedule's kernels, which each rank runs on its parts (test_support.hpp)
      const numeric::NumericFactor one = test::level_schedule_factor(an, v, c.type, pivot);
      for (int r = 1; r < ranks; ++r) {
        SCOPED_TRACE("rank " + std::to_string(r));
        const distributed::RankLayout l = distributed::make_layout(an, ranks, r, per_rank);
        std::vector<double> mine(v.size(), std::numeric_limits<double>::quiet_NaN());
        for (const index_t p : distributed::value_positions(an, l, r)) mine[p] = v[p];
        std::vector<std::unique_ptr<numeric::Executor>> own;
        std::vector<numeric::Executor*> execs;
        for (int g = 0; g < per_rank; ++g) {
          own.push_back(numeric::make_cpu_executor(1));
          execs.push_back(own.back().get());
        }
        numeric::MultiWorkerConfig cfg;  // as rank r runs it, without the top part
        cfg.first_worker = r * per_rank;
        cfg.factor_top = false;
        cfg.exchange = [](std::vector<numeric::CbTransfer>&, std::exception_ptr failed) {
          if (failed) std::rethrow_exception(failed);
        };
        numeric::NumericFactor part;
        std::vector<std::vector<double>> arenas;
        numeric::factorize_multi(an, mine, c.type, pivot, execs, part, arenas, cfg, nullptr);
        for (const index_t f : l.my_fronts) {
          const std::size_t at = an.factor_layout.panel_offset[f];
          const std::size_t len = panel_size(an.tree, f, !an.symmetric);
          std::size_t differ = 0;
          for (std::size_t k = at; k < at + len; ++k)
            differ += std::memcmp(&part.panels[k], &one.panels[k], sizeof(double)) != 0 ? 1 : 0;
          ASSERT_EQ(differ, 0u) << "front " << f << ": " << differ << " of " << len
                                << " panel entries differ from the one-process factor";
        }
      }
    }
}

// One process: DistributedSolver is the Solver, for every type, against dense LAPACK.
TEST(DistributedSerialize, OneProcessSolverMatchesDense) {
  auto rng = test::fresh_rng();
  EXPECT_EQ(Communicator().size(), 1);
  EXPECT_EQ(Communicator().rank(), 0);
  for (auto [kind, type] :
       {std::pair{test::RandomKind::spd, MatrixType::spd},
        std::pair{test::RandomKind::symmetric_indefinite, MatrixType::symmetric_indefinite},
        std::pair{test::RandomKind::general, MatrixType::general}})
    for (index_t n : {1, 3, 200}) {
      const SparseMatrix a = test::random_sparse(n, 3, kind, rng);
      std::vector<double> b(n);
      std::uniform_real_distribution<double> u(-1, 1);
      for (double& v : b) v = u(rng);
      Options o;
      o.type = type;
      DistributedSolver ds(Communicator(), o);
      ds.factorize(a);
      const std::vector<double> x = ds.solve(b);
      std::vector<double> xd = b;
      ASSERT_TRUE(test::dense_solve(test::to_dense(a), n, xd, 1));
      EXPECT_LT(test::relative_difference(x, xd), 1e-8);
      EXPECT_EQ(ds.size(), n);
      EXPECT_EQ(ds.distributed_stats().ranks, 1);
    }
}

// Every error type strata throws crosses the ranks as itself: the header and message one
// rank sends (error_header) are thrown again on the others (throw_error) with the same
// type, the same what() and the same data (bytes, column and pivot).
TEST(DistributedErrors, ErrorsKeepTheirTypeAcrossRanks) {
  auto round_trip = [](std::exception_ptr e) -> std::exception_ptr {
    std::vector<char> message;
    const distributed::Header h = distributed::error_header(e, message);
    try {
      distributed::throw_error(h, message);
    } catch (...) {
      return std::current_exception();
    }
    return nullptr;
  };
  auto check = [&](const auto& error) {
    using E = std::decay_t<decltype(error)>;
    const std::exception_ptr back = round_trip(std::make_exception_ptr(error));
    try {
      std::rethrow_exception(back);
    } catch (const E& x) {
      EXPECT_STREQ(x.what(), error.what());
      return;
    } catch (const std::exception& x) {
      ADD_FAILURE() << "other type for \"" << error.what() << "\": " << x.what();
    }
  };
  check(InvalidInput("column 3 is empty"));
  check(NotSupported("no GPU"));
  check(DeviceError("cudaMalloc: out of memory"));
  check(InvalidState("solve before factorize"));
  check(InternalError("a front made no progress"));
  check(OutOfMemory(12345, "factorize: panels"));
  check(OutOfMemory(0, "solve"));
  check(NotPositiveDefinite(7, -2.5));
  try {
    std::rethrow_exception(round_trip(std::make_exception_ptr(OutOfMemory(777, "x"))));
  } catch (const OutOfMemory& x) {
    EXPECT_EQ(x.bytes_requested(), 777u);
  }
  try {
    std::rethrow_exception(round_trip(std::make_exception_ptr(NotPositiveDefinite(7, -2.5))));
  } catch (const NotPositiveDefinite& x) {
    EXPECT_EQ(x.column(), 7);
    EXPECT_EQ(x.pivot(), -2.5);
  }
  try {
    std::rethrow_exception(round_trip(std::make_exception_ptr(InternalError("x"))));
  } catch (const InternalError& x) {
    EXPECT_EQ(x.detail(), "x");
    EXPECT_STREQ(x.what(), "internal error: x");
  }
}

}  // namespace
}  // namespace strata
