// strata tests — the split of the assembly tree for several workers
// (schedule/tree_partition.hpp): disjoint subtrees closed under descendants, the top part
// is the rest and closed under parents, work and balance figures recomputed here, and
// every part's own level schedule, memory plan and arena layout valid for the part alone.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <string>

#include "core/analysis.hpp"
#include "sparse/generators.hpp"
#include "strata/strata.hpp"
#include "support/test_support.hpp"

namespace strata {
namespace {

using schedule::FactorPart;
using symbolic::AssemblyTree;

// Subtree of r as a set (independent of the postorder numbering).
std::vector<char> descendants(const AssemblyTree& t, index_t r) {
  std::vector<char> in(t.n_fronts(), 0);
  in[r] = 1;
  for (index_t f = r; f >= 0; --f)  // parents after children: walk down from r
    if (f != r && t.parent[f] >= 0 && in[t.parent[f]]) in[f] = 1;
  return in;
}

// A part's schedule, plan and arena layout, checked against the part alone.
void check_part(const AssemblyTree& t, const FactorPart& p) {
  const auto& s = p.schedule;
  std::vector<char> in(t.n_fronts(), 0);
  for (index_t f : p.fronts) in[f] = 1;
  // schedule: the part's fronts once each; a child in the part is one level below
  std::vector<index_t> listed = s.fronts;
  std::sort(listed.begin(), listed.end());
  EXPECT_EQ(listed, p.fronts);
  for (index_t f : p.fronts) {
    const index_t q = t.parent[f];
    if (q >= 0 && in[q]) EXPECT_EQ(s.level_of[q], s.level_of[f] + 1);
    if (q < 0 || !in[q]) EXPECT_EQ(s.level_of[f], s.n_levels() - 1) << "a root of the part";
  }
  // plan: batches cover the schedule positions in order, one level each
  index_t next = 0;
  for (const BatchInfo& b : p.plan.batches) {
    EXPECT_EQ(b.begin, next);
    EXPECT_GT(b.end, b.begin);
    for (index_t q = b.begin; q < b.end; ++q) EXPECT_EQ(s.level_of[s.fronts[q]], b.level);
    next = b.end;
  }
  EXPECT_EQ(next, static_cast<index_t>(s.fronts.size()));
  // imports: exactly the children outside the part that pass a block
  std::vector<index_t> imports;
  for (index_t f : p.fronts)
    for (index_t k = t.child_offsets[f]; k < t.child_offsets[f + 1]; ++k)
      if (!in[t.children[k]] && t.cb_size(t.children[k]) > 0) imports.push_back(t.children[k]);
  std::sort(imports.begin(), imports.end());
  EXPECT_EQ(imports, p.imports);
  // arena: blocks alive at the same time never overlap and fit in arena_size. Step 2l
  // allocates level l's blocks, step 2l+1 releases the blocks its fronts read; imports are
  // allocated at step -1; a block whose parent is outside the part lives to the end.
  struct Block {
    std::size_t off, size;
    index_t born, dies;
  };
  std::vector<Block> blocks;
  const index_t end = 2 * s.n_levels() + 2;
  for (index_t c : p.imports) {
    const auto sz = static_cast<std::size_t>(t.cb_size(c)) * t.cb_size(c);
    blocks.push_back({p.cb_layout.cb_offset[c], sz, -1, 2 * s.level_of[t.parent[c]] + 1});
  }
  for (index_t f : p.fronts) {
    if (t.parent[f] < 0 || t.cb_size(f) == 0) continue;
    const auto sz = static_cast<std::size_t>(t.cb_size(f)) * t.cb_size(f);
    const index_t q = t.parent[f];
    blocks.push_back(
        {p.cb_layout.cb_offset[f], sz, 2 * s.level_of[f], in[q] ? 2 * s.level_of[q] + 1 : end});
  }
  for (std::size_t i = 0; i < blocks.size(); ++i) {
    EXPECT_LE(blocks[i].off + blocks[i].size, p.cb_layout.arena_size);
    for (std::size_t j = i + 1; j < blocks.size(); ++j) {
      const Block &a = blocks[i], &b = blocks[j];
      const bool live_together = a.born < b.dies && b.born < a.dies;
      const bool overlap = a.off < b.off + b.size && b.off < a.off + a.size;
      EXPECT_FALSE(live_together && overlap) << "blocks " << i << " and " << j;
    }
  }
}

void check_partition(const Analysis& an, int workers, int per_worker) {
  const AssemblyTree& t = an.tree;
  const auto& p = an.partition;
  const index_t nf = t.n_fronts();
  ASSERT_EQ(p.workers, workers);
  ASSERT_EQ(static_cast<index_t>(p.part_of.size()), nf);
  std::vector<int> seen(nf, 0);
  double work = 0;
  for (std::size_t i = 0; i < p.subtrees.size(); ++i) {
    const FactorPart& sub = p.subtrees[i];
    // closed under descendants: exactly the subtree of its root
    const std::vector<char> d = descendants(t, sub.root);
    std::vector<index_t> expect;
    for (index_t f = 0; f < nf; ++f)
      if (d[f]) expect.push_back(f);
    EXPECT_EQ(sub.fronts, expect) << "subtree " << i;
    double w = 0;
    for (index_t f : sub.fronts) {
      ++seen[f];
      EXPECT_EQ(p.part_of[f], static_cast<index_t>(i));
      w += symbolic::front_flops(t, f);
    }
    EXPECT_NEAR(sub.work, w, 1e-9 * std::max(1.0, w));
    if (i > 0) EXPECT_GE(p.subtrees[i - 1].work, sub.work) << "not largest first";
    // the root's parent is in the top part (or absent)
    if (t.parent[sub.root] >= 0) EXPECT_EQ(p.part_of[t.parent[sub.root]], -1);
    check_part(t, sub);
    work += w;
  }
  // the top part is the rest, closed under parents
  double wtop = 0;
  for (index_t f : p.top.fronts) {
    ++seen[f];
    EXPECT_EQ(p.part_of[f], -1);
    if (t.parent[f] >= 0) EXPECT_EQ(p.part_of[t.parent[f]], -1) << "top not closed under parents";
    wtop += symbolic::front_flops(t, f);
  }
  check_part(t, p.top);
  for (index_t f = 0; f < nf; ++f) EXPECT_EQ(seen[f], 1) << "front " << f;
  EXPECT_NEAR(p.top.work, wtop, 1e-9 * std::max(1.0, wtop));
  EXPECT_NEAR(p.total_work, work + wtop, 1e-9 * std::max(1.0, p.total_work));
  EXPECT_NEAR(an.stats.factor_flops, p.total_work, 1e-9 * std::max(1.0, p.total_work));
  // the balance figure from the owners
  std::vector<double> load(workers, 0.0);
  ASSERT_EQ(p.owner.size(), p.subtrees.size());
  for (std::size_t i = 0; i < p.subtrees.size(); ++i) {
    ASSERT_GE(p.owner[i], 0);
    ASSERT_LT(p.owner[i], workers);
    load[p.owner[i]] += p.subtrees[i].work;
  }
  const double mean = work / workers;
  const double makespan = *std::max_element(load.begin(), load.end());
  EXPECT_NEAR(p.balance, work > 0 ? makespan / mean : 1.0, 1e-12 * std::max(1.0, p.balance));
  EXPECT_GE(p.balance, 1.0 - 1e-12);
  // list scheduling: the last item of the busiest worker went to the least loaded one,
  // so the makespan is at most the mean load plus the largest item
  EXPECT_LE(makespan, mean + (p.subtrees.empty() ? 0.0 : p.subtrees.front().work) + 1e-9);
  (void)per_worker;
}

Analysis analyze(const SparseMatrix& a, MatrixType type, int workers, int per_worker,
                 bool balance = true) {
  Options o;
  o.type = type;
  o.subtrees_per_gpu = per_worker;
  o.balance_by_work = balance;
  return analyze_matrix(a, o, workers);
}

TEST(TreePartition, InvariantsOnGeneratedAndSharedMatrices) {
  auto rng = test::fresh_rng();
  std::vector<std::pair<std::string, SparseMatrix>> problems;
  for (index_t n : {1, 2, 3, 5, 733})
    problems.push_back(
        {"random spd " + std::to_string(n), test::random_sparse(n, 3, test::RandomKind::spd, rng)});
  problems.push_back({"lap3d 14", generators::laplacian_3d(14, 14, 14)});
  problems.push_back({"elasticity 6x5x7", generators::elasticity_3d(6, 5, 7)});
  problems.push_back({"bcsstk16", read_matrix_market(test::matrix_path("bcsstk16")).matrix});
  for (const auto& [name, a] : problems)
    for (int workers : {2, 3, 4})
      for (int per : {1, 2, 4}) {
        SCOPED_TRACE(name + ", " + std::to_string(workers) + " workers x " + std::to_string(per));
        const Analysis an = analyze(a, MatrixType::spd, workers, per);
        check_partition(an, workers, per);
        if (a.n_rows > 2000) {  // a tree this size yields enough subtrees
          EXPECT_GE(an.partition.subtrees.size(), static_cast<std::size_t>(workers * per));
          EXPECT_EQ(an.stats.subtrees, static_cast<index_t>(an.partition.subtrees.size()));
          EXPECT_LT(an.stats.top_flops_fraction, 1.0);
        }
      }
}

TEST(TreePartition, UnsymmetricAndIndefiniteTypes) {
  auto rng = test::fresh_rng();
  for (auto [kind, type] :
       {std::pair{test::RandomKind::general, MatrixType::general},
        std::pair{test::RandomKind::symmetric_indefinite, MatrixType::symmetric_indefinite}}) {
    SparseMatrix a = test::random_sparse(1500, 4, kind, rng);
    SCOPED_TRACE(to_string(type));
    for (int workers : {2, 4}) check_partition(analyze(a, type, workers, 3), workers, 3);
  }
}

// The memory budget applies to every part's plan as to the whole tree's.
TEST(TreePartition, PartsPlannedUnderTheBudget) {
  const SparseMatrix a = generators::laplacian_3d(12, 12, 12);
  Options o;
  o.type = MatrixType::spd;
  o.device_memory_limit = 2 << 20;
  const Analysis an = analyze_matrix(a, o, 3);
  check_partition(an, 3, o.subtrees_per_gpu);
  for (const auto* p : {&an.partition.top, &an.partition.subtrees.front()})
    for (const BatchInfo& b : p->plan.batches)
      if (!b.tiled) EXPECT_LE(b.bytes, o.device_memory_limit);
}

// One worker analysis is not split; bad arguments are refused.
TEST(TreePartition, OneWorkerAndBadArguments) {
  const SparseMatrix a = generators::laplacian_3d(6, 6, 6);
  Options o;
  const Analysis an = analyze_matrix(a, o, 1);
  EXPECT_TRUE(an.partition.subtrees.empty());
  EXPECT_EQ(an.stats.workers, 1);
  EXPECT_THROW(analyze_matrix(a, o, 0), InvalidInput);
  o.subtrees_per_gpu = 0;
  EXPECT_THROW(analyze_matrix(a, o, 2), InvalidInput);
  schedule::PartitionOptions po;
  po.workers = 0;
  EXPECT_THROW(schedule::partition_tree(an.tree, po), InvalidInput);
  Options neg;
  neg.num_gpus = -1;
  Solver s(neg);
  EXPECT_THROW(s.analyze(a), InvalidInput);
  // the CPU backend ignores num_gpus: one worker, no split
  Options cpu;
  cpu.num_gpus = 3;
  Solver c(cpu);
  c.analyze(a);
  EXPECT_EQ(c.stats().analysis.workers, 1);
}

// The subset schedule of every front is the whole-tree schedule.
TEST(TreePartition, SubsetScheduleOfAllFrontsIsTheSchedule) {
  const SparseMatrix a = generators::elasticity_3d(5, 6, 4);
  const Analysis an = analyze_matrix(a, Options{}, 1);
  std::vector<index_t> all(an.tree.n_fronts());
  std::iota(all.begin(), all.end(), index_t{0});
  const auto s = symbolic::level_schedule(an.tree, all);
  EXPECT_EQ(s.fronts, an.schedule.fronts);
  EXPECT_EQ(s.level_offsets, an.schedule.level_offsets);
  EXPECT_EQ(s.level_of, an.schedule.level_of);
  EXPECT_THROW(symbolic::level_schedule(an.tree, {1, 0}), InvalidInput);
}

// LPT on known inputs: Graham's example with 2 workers.
TEST(TreePartition, LargestProcessingTimeFirst) {
  double makespan = 0;
  const auto owner = schedule::lpt_assign({7, 5, 4, 3, 3}, 2, &makespan);
  EXPECT_EQ(owner, (std::vector<int>{0, 1, 1, 0, 1}));
  EXPECT_DOUBLE_EQ(makespan, 12.0);
  EXPECT_EQ(schedule::lpt_assign({}, 3, &makespan).size(), 0u);
  EXPECT_DOUBLE_EQ(makespan, 0.0);
}

}  // namespace
}  // namespace strata
