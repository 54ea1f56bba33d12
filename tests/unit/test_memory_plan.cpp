// strata tests — memory plan: batches of each level under a byte budget, the working-set
// model, the simulated in-core peak and the factor size.
#include <gtest/gtest.h>
#include <metis.h>

#include <algorithm>
#include <numeric>
#include <string>
#include <vector>

#include "schedule/memory_plan.hpp"
#include "sparse/generators.hpp"
#include "support/test_support.hpp"
#include "symbolic/symbolic.hpp"

namespace strata {
namespace {

using schedule::MemoryPlan;
using symbolic::AssemblyTree;
using symbolic::LevelSchedule;

/// METIS_NodeND permutation (new→old) of a full symmetric pattern.
std::vector<index_t> metis_order(const SparseMatrix& full) {
  const index_t n = full.n_cols;
  std::vector<idx_t> xadj(n + 1, 0), adj;
  for (index_t j = 0; j < n; ++j) {
    for (index_t p = full.offsets[j]; p < full.offsets[j + 1]; ++p)
      if (full.indices[p] != j) adj.push_back(static_cast<idx_t>(full.indices[p]));
    xadj[j + 1] = static_cast<idx_t>(adj.size());
  }
  std::vector<index_t> order(n);
  std::iota(order.begin(), order.end(), 0);
  if (n <= 2 || adj.empty()) return order;
  idx_t nv = static_cast<idx_t>(n);
  idx_t options[METIS_NOPTIONS];
  METIS_SetDefaultOptions(options);
  std::vector<idx_t> perm(n), iperm(n);
  EXPECT_EQ(METIS_NodeND(&nv, xadj.data(), adj.data(), nullptr, options, perm.data(), iperm.data()),
            METIS_OK);
  std::copy(perm.begin(), perm.end(), order.begin());
  return order;
}

struct Analysis {
  symbolic::SymbolicFactorization sf;
  LevelSchedule schedule;
};

Analysis analyze(const SparseMatrix& lower, index_t max_block_size) {
  const SparseMatrix full = expand_symmetric(lower);
  const SparseMatrix b = symbolic::permute_symmetric_pattern(full, metis_order(full));
  symbolic::AmalgamationOptions o;
  o.max_block_size = max_block_size;
  Analysis a;
  a.sf = symbolic::analyze_pattern(b, o);
  a.schedule = symbolic::level_schedule(a.sf.tree);
  return a;
}

std::size_t sq(index_t k) { return static_cast<std::size_t>(k * k) * 8; }

/// The header's working set, recomputed here.
std::size_t expected_working_bytes(const AssemblyTree& t, index_t f) {
  std::size_t b = sq(t.n_rows(f)) + sq(t.cb_size(f));
  for (index_t c = t.child_offsets[f]; c < t.child_offsets[f + 1]; ++c)
    b += sq(t.cb_size(t.children[c]));
  return b;
}

/// Peak of (pending contribution blocks + batch working set), simulated front by front:
/// a contribution block is live from the end of the batch that writes it to the end of
/// the batch that reads it; while a batch runs, the blocks it reads are counted in its
/// working set, not as pending.
std::size_t expected_peak(const AssemblyTree& t, const LevelSchedule& s, const MemoryPlan& plan) {
  const index_t nf = t.n_fronts();
  std::vector<char> produced(nf, 0), consumed(nf, 0);
  std::size_t peak = 0;
  for (const BatchInfo& b : plan.batches) {
    std::vector<char> read_now(nf, 0);
    for (index_t p = b.begin; p < b.end; ++p) {
      const index_t f = s.fronts[p];
      for (index_t c = t.child_offsets[f]; c < t.child_offsets[f + 1]; ++c)
        read_now[t.children[c]] = 1;
    }
    std::size_t pending = 0;
    for (index_t f = 0; f < nf; ++f)
      if (produced[f] && !consumed[f] && !read_now[f]) pending += sq(t.cb_size(f));
    peak = std::max(peak, pending + b.bytes);
    for (index_t f = 0; f < nf; ++f)
      if (read_now[f]) {
        EXPECT_TRUE(produced[f]) << "front " << f << " read before it was factored";
        consumed[f] = 1;
      }
    for (index_t p = b.begin; p < b.end; ++p) produced[s.fronts[p]] = 1;
  }
  return peak;
}

/// Every property of a plan for `budget`.
void check_plan(const AssemblyTree& t, const LevelSchedule& s, const MemoryPlan& plan,
                std::size_t budget) {
  SCOPED_TRACE("budget " + std::to_string(budget));
  EXPECT_EQ(plan.budget, budget);
  const index_t nf = t.n_fronts();
  // Batches in processing order tile the schedule: consecutive, each inside one level,
  // levels in increasing order.
  index_t pos = 0;
  std::vector<index_t> batches_per_level(s.n_levels(), 0);
  for (std::size_t k = 0; k < plan.batches.size(); ++k) {
    const BatchInfo& b = plan.batches[k];
    ASSERT_EQ(b.begin, pos) << "batch " << k;
    ASSERT_LT(b.begin, b.end) << "empty batch " << k;
    ASSERT_GE(b.level, 0);
    ASSERT_LT(b.level, s.n_levels());
    EXPECT_GE(b.begin, s.level_offsets[b.level]);
    EXPECT_LE(b.end, s.level_offsets[b.level + 1]);
    if (k > 0) EXPECT_LE(plan.batches[k - 1].level, b.level);
    ++batches_per_level[b.level];
    std::size_t bytes = 0;
    for (index_t p = b.begin; p < b.end; ++p) {
      EXPECT_EQ(schedule::front_working_bytes(t, s.fronts[p]),
                expected_working_bytes(t, s.fronts[p]));
      bytes += expected_working_bytes(t, s.fronts[p]);
    }
    EXPECT_EQ(b.bytes, bytes) << "batch " << k;
    if (budget == 0) {
      EXPECT_FALSE(b.tiled);
    } else if (b.tiled) {
      EXPECT_EQ(b.end - b.begin, 1) << "a tiled batch holds one front";
      EXPECT_GT(b.bytes, budget);
    } else {
      EXPECT_LE(b.bytes, budget) << "batch " << k;
    }
    // Greedy: a batch is closed only when the next front of its level would not fit.
    if (budget != 0 && !b.tiled && b.end < s.level_offsets[b.level + 1])
      EXPECT_GT(b.bytes + expected_working_bytes(t, s.fronts[b.end]), budget) << "batch " << k;
    pos = b.end;
  }
  EXPECT_EQ(pos, nf);
  for (index_t l = 0; l < s.n_levels(); ++l) {
    EXPECT_GE(batches_per_level[l], 1);
    if (budget == 0) EXPECT_EQ(batches_per_level[l], 1) << "level " << l;
  }
  if (budget == 0) EXPECT_EQ(static_cast<index_t>(plan.batches.size()), s.n_levels());
  EXPECT_EQ(plan.peak_in_core_bytes, expected_peak(t, s, plan));
  std::size_t largest = 0;
  for (const BatchInfo& b : plan.batches) largest = std::max(largest, b.bytes);
  EXPECT_GE(plan.peak_in_core_bytes, largest);
}

TEST(MemoryPlan, EmptyTree) {
  const AssemblyTree t;
  const LevelSchedule s = symbolic::level_schedule(t);
  const MemoryPlan p = schedule::plan_memory(t, s, 1000, false);
  EXPECT_TRUE(p.batches.empty());
  EXPECT_EQ(p.peak_in_core_bytes, 0u);
  EXPECT_EQ(p.factor_bytes, 0u);
}

TEST(MemoryPlan, WorkingBytesOfAChain) {
  // Tridiagonal n = 6, every column merged into one front and blocked by 2 pivots:
  // fronts {0,1}+row 2, {2,3}+row 4, {4,5}: rows 3, 3, 2 and cb 1, 1, 0.
  SparseMatrix low = generators::laplacian_2d(6, 1);
  symbolic::AmalgamationOptions o;
  o.relax_small = 6;
  o.max_block_size = 2;
  const symbolic::SymbolicFactorization sf = symbolic::analyze_pattern(expand_symmetric(low), o);
  const AssemblyTree& t = sf.tree;
  ASSERT_EQ(t.n_fronts(), 3);
  EXPECT_EQ(schedule::front_working_bytes(t, 0), 8u * (9 + 0 + 1));
  EXPECT_EQ(schedule::front_working_bytes(t, 1), 8u * (9 + 1 + 1));
  EXPECT_EQ(schedule::front_working_bytes(t, 2), 8u * (4 + 1 + 0));
  const LevelSchedule s = symbolic::level_schedule(t);
  ASSERT_EQ(s.n_levels(), 3);
  const MemoryPlan p = schedule::plan_memory(t, s, 0, false);
  ASSERT_EQ(p.batches.size(), 3u);
  // Peak: batch 1 holds front 1 (reading front 0's cb, counted in its working set).
  EXPECT_EQ(p.peak_in_core_bytes, 88u);
  EXPECT_EQ(p.factor_bytes, 8u * (2 * 3 + 2 * 3 + 2 * 2));
  const MemoryPlan u = schedule::plan_memory(t, s, 0, true);
  EXPECT_EQ(u.factor_bytes, 8u * (2 * 3 + 2 * 1 + 2 * 3 + 2 * 1 + 2 * 2));
  check_plan(t, s, p, 0);
  // A budget below every front: three tiled batches.
  const MemoryPlan tiny = schedule::plan_memory(t, s, 8, false);
  check_plan(t, s, tiny, 8);
  for (const BatchInfo& b : tiny.batches) EXPECT_TRUE(b.tiled);
}

TEST(MemoryPlan, BudgetsOnA3dGrid) {
  const Analysis a = analyze(generators::laplacian_3d(14, 13, 12), 32);
  const AssemblyTree& t = a.sf.tree;
  const LevelSchedule& s = a.schedule;
  std::size_t largest = 0, level_max = 0;
  for (index_t f = 0; f < t.n_fronts(); ++f) {
    largest = std::max(largest, expected_working_bytes(t, f));
  }
  for (index_t l = 0; l < s.n_levels(); ++l) {
    std::size_t sum = 0;
    for (index_t p = s.level_offsets[l]; p < s.level_offsets[l + 1]; ++p)
      sum += expected_working_bytes(t, s.fronts[p]);
    level_max = std::max(level_max, sum);
  }
  const MemoryPlan unlimited = schedule::plan_memory(t, s, 0, false);
  check_plan(t, s, unlimited, 0);
  std::size_t factor = 0, factor_lu = 0;
  for (index_t f = 0; f < t.n_fronts(); ++f) {
    factor += 8 * static_cast<std::size_t>(t.n_pivots(f) * t.n_rows(f));
    factor_lu += 8 * static_cast<std::size_t>(t.n_pivots(f) * (2 * t.n_rows(f) - t.n_pivots(f)));
  }
  EXPECT_EQ(unlimited.factor_bytes, factor);
  EXPECT_EQ(schedule::plan_memory(t, s, 0, true).factor_bytes, factor_lu);

  std::size_t previous_batches = 0;
  std::vector<std::size_t> budgets{level_max * 2, level_max,    level_max / 3, largest,
                                   largest / 2,   largest / 10, 4096,          1};
  std::sort(budgets.rbegin(), budgets.rend());  // decreasing
  for (std::size_t budget : budgets) {
    const MemoryPlan p = schedule::plan_memory(t, s, budget, false);
    check_plan(t, s, p, budget);
    if (HasFatalFailure()) return;
    // Cutting levels finer never raises the peak above the one-batch-per-level plan.
    EXPECT_LE(p.peak_in_core_bytes, unlimited.peak_in_core_bytes);
    EXPECT_EQ(p.factor_bytes, factor);
    // Smaller budgets, more batches.
    EXPECT_GE(p.batches.size(), previous_batches);
    previous_batches = p.batches.size();
    const bool any_tiled =
        std::any_of(p.batches.begin(), p.batches.end(), [](const BatchInfo& b) { return b.tiled; });
    EXPECT_EQ(any_tiled, budget < largest);
    if (budget >= level_max) EXPECT_EQ(static_cast<index_t>(p.batches.size()), s.n_levels());
  }
  // A budget of one byte: every front is a tiled batch of its own.
  EXPECT_EQ(static_cast<index_t>(schedule::plan_memory(t, s, 1, false).batches.size()),
            t.n_fronts());
}

TEST(MemoryPlan, ElasticityAndBlockSizes) {
  for (index_t mbs : {8, 64, 100000}) {
    SCOPED_TRACE("max_block_size " + std::to_string(mbs));
    const Analysis a = analyze(generators::elasticity_3d(6, 6, 5), mbs);
    const AssemblyTree& t = a.sf.tree;
    std::size_t largest = 0;
    for (index_t f = 0; f < t.n_fronts(); ++f)
      largest = std::max(largest, schedule::front_working_bytes(t, f));
    for (std::size_t budget : {std::size_t{0}, largest * 3, largest, largest / 4}) {
      check_plan(t, a.schedule, schedule::plan_memory(t, a.schedule, budget, false), budget);
      if (HasFatalFailure()) return;
    }
  }
}

}  // namespace
}  // namespace strata
