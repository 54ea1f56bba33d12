// strata tests — the split of the assembly tree for several workers
// (schedule/tree_partition.hpp): disjoint subtrees closed under descendants, the top part
// is the rest and closed under parents, work and balance figures recomputed here, and
// every part's own level schedule, memory plan and arena layout valid for the part alone.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <numeric>
#include <string>

#include "analysis/analysis.hpp"
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

// Layer of part `id`: 0 for a subtree, l for a part of upper layer l, L + 1 for the top.
int layer_of(const schedule::TreePartition& p, index_t id) {
  const index_t s = p.top_id();
  if (id < s) return 0;
  if (id == s) return p.n_upper_layers() + 1;
  const index_t k = id - s - 1;
  for (int l = 1; l <= p.n_upper_layers(); ++l)
    if (k < p.upper_layer_offsets[l]) return l;
  ADD_FAILURE() << "upper part " << k << " in no layer";
  return -1;
}

// LPT makespan of `owners` over `workers` with these works.
double makespan_of(const std::vector<double>& work, const std::vector<int>& owners, int workers) {
  std::vector<double> load(workers, 0.0);
  for (std::size_t i = 0; i < work.size(); ++i) load[owners[i]] += work[i];
  return work.empty() ? 0.0 : *std::max_element(load.begin(), load.end());
}

// The upper layers: every part is its root and the root's descendants in no lower layer
// (closed under its own fronts' parents up to the root), reads blocks only from strictly
// lower layers, and is listed in decreasing work within its layer; part ids, part() and
// worker_of agree; the list schedule the driver runs is replayed here: each upper part's
// owner finishes it first, and estimated_time is that schedule's end + the top's work.
void check_upper_layers(const AssemblyTree& t, const schedule::TreePartition& p, int workers) {
  const index_t nf = t.n_fronts();
  const index_t s = p.top_id();
  ASSERT_EQ(static_cast<index_t>(p.part_id.size()), nf);
  ASSERT_GE(p.upper_layer_offsets.size(), 1u);
  EXPECT_EQ(p.upper_layer_offsets.front(), 0);
  EXPECT_EQ(p.upper_layer_offsets.back(), static_cast<index_t>(p.upper.size()));
  EXPECT_LE(p.n_upper_layers(), schedule::kMaxUpperLayers);
  ASSERT_EQ(p.upper_owner.size(), p.upper.size());
  EXPECT_EQ(p.n_parts(), static_cast<int>(p.subtrees.size() + 1 + p.upper.size()));
  for (index_t f = 0; f < nf; ++f) {
    const index_t id = p.part_id[f];
    ASSERT_GE(id, 0);
    ASSERT_LT(id, p.n_parts());
    EXPECT_EQ(p.part_of[f], id < s ? id : -1) << "front " << f;
    const auto& fr = p.part(static_cast<int>(id)).fronts;
    EXPECT_TRUE(std::binary_search(fr.begin(), fr.end(), f)) << "front " << f;
  }
  EXPECT_EQ(&p.part(static_cast<int>(s)), &p.top);
  EXPECT_EQ(p.worker_of(static_cast<int>(s)), 0);
  {  // layers(): every part id once, each in the layer layer_of says, in increasing order
    const auto layers = p.layers();
    ASSERT_EQ(static_cast<int>(layers.size()), p.n_upper_layers() + 2);
    std::vector<int> seen(p.n_parts(), 0);
    for (std::size_t l = 0; l < layers.size(); ++l)
      for (std::size_t q = 0; q < layers[l].size(); ++q) {
        const int id = layers[l][q];
        ASSERT_GE(id, 0);
        ASSERT_LT(id, p.n_parts());
        ++seen[id];
        EXPECT_EQ(layer_of(p, id), static_cast<int>(l)) << "part " << id;
        if (q > 0) EXPECT_LT(layers[l][q - 1], id);
      }
    for (int id = 0; id < p.n_parts(); ++id) EXPECT_EQ(seen[id], 1) << "part " << id;
    EXPECT_EQ(layers.back(), std::vector<int>{static_cast<int>(s)});
  }
  EXPECT_THROW(p.part(p.n_parts()), InvalidInput);
  EXPECT_THROW(p.part(-1), InvalidInput);
  // the list schedule the driver runs: each worker's subtrees in order, then its upper
  // parts in order, each starting when its worker is free and its inputs are done
  ASSERT_EQ(p.owner.size(), p.subtrees.size());
  std::vector<double> free(workers, 0.0), finish(p.n_parts(), 0.0);
  for (std::size_t i = 0; i < p.subtrees.size(); ++i) {
    ASSERT_GE(p.owner[i], 0);
    ASSERT_LT(p.owner[i], workers);
    finish[i] = free[p.owner[i]] += p.subtrees[i].work;
  }
  for (int l = 1; l <= p.n_upper_layers(); ++l) {
    const index_t b = p.upper_layer_offsets[l - 1], e = p.upper_layer_offsets[l];
    EXPECT_GE(e - b, 1) << "an empty layer";
    for (index_t k = b; k < e; ++k) {
      const FactorPart& u = p.upper[k];
      const int id = static_cast<int>(s + 1 + k);
      SCOPED_TRACE("upper layer " + std::to_string(l) + ", part " + std::to_string(k));
      EXPECT_EQ(&p.part(id), &u);
      ASSERT_GE(p.upper_owner[k], 0);
      ASSERT_LT(p.upper_owner[k], workers);
      EXPECT_EQ(p.worker_of(id), p.upper_owner[k]);
      if (k > b) EXPECT_GE(p.upper[k - 1].work, u.work) << "not largest first";
      ASSERT_GE(u.root, 0);
      ASSERT_FALSE(u.fronts.empty());
      EXPECT_EQ(u.fronts.back(), u.root) << "the root is the part's last front (postorder)";
      double work = 0;
      for (index_t f : u.fronts) {
        EXPECT_EQ(p.part_id[f], id);
        work += symbolic::front_flops(t, f);
        // closed under parents up to the root
        if (f != u.root) EXPECT_EQ(p.part_id[t.parent[f]], id) << "front " << f;
        // complete: every child is in the part or in a strictly lower layer
        for (index_t q = t.child_offsets[f]; q < t.child_offsets[f + 1]; ++q) {
          const index_t c = t.children[q];
          if (p.part_id[c] != id) EXPECT_LT(layer_of(p, p.part_id[c]), l) << "child " << c;
        }
      }
      EXPECT_NEAR(u.work, work, 1e-9 * std::max(1.0, work));
      // the root's parent is in a higher layer, or the top
      if (t.parent[u.root] >= 0) EXPECT_GT(layer_of(p, p.part_id[t.parent[u.root]]), l);
      for (index_t c : u.imports) EXPECT_LT(layer_of(p, p.part_id[c]), l) << "import " << c;
      check_part(t, u);
      // its owner is the worker that finishes it first (ties: the lowest)
      double ready = 0;
      for (index_t c : u.imports) ready = std::max(ready, finish[p.part_id[c]]);
      const auto done_on = [&](int x) { return std::max(free[x], ready) + u.work; };
      const double mine = done_on(p.upper_owner[k]);
      for (int x = 0; x < workers; ++x) {
        EXPECT_LE(mine, done_on(x) * (1 + 1e-12)) << "worker " << x << " finishes it first";
        if (x < p.upper_owner[k]) EXPECT_GT(done_on(x), mine * (1 - 1e-12)) << "tie: " << x;
      }
      finish[id] = free[p.upper_owner[k]] = mine;
    }
  }
  for (index_t c : p.top.imports) EXPECT_LE(layer_of(p, p.part_id[c]), p.n_upper_layers());
  const double estimate = *std::max_element(free.begin(), free.end()) + p.top.work;
  EXPECT_NEAR(p.estimated_time, estimate, 1e-9 * std::max(1.0, estimate));
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
    // the root's parent is above the subtrees (an upper part or the top part), or absent
    if (t.parent[sub.root] >= 0) EXPECT_EQ(p.part_of[t.parent[sub.root]], -1);
    EXPECT_TRUE(sub.imports.empty());
    check_part(t, sub);
    work += w;
  }
  // the upper parts and the top part are the rest; the top is closed under parents
  double wupper = 0;
  for (const FactorPart& u : p.upper) {
    for (index_t f : u.fronts) ++seen[f];
    wupper += u.work;
  }
  double wtop = 0;
  for (index_t f : p.top.fronts) {
    ++seen[f];
    EXPECT_EQ(p.part_of[f], -1);
    if (t.parent[f] >= 0) EXPECT_EQ(p.part_id[t.parent[f]], p.top_id()) << "top not closed";
    wtop += symbolic::front_flops(t, f);
  }
  check_part(t, p.top);
  for (index_t f = 0; f < nf; ++f) EXPECT_EQ(seen[f], 1) << "front " << f;
  EXPECT_NEAR(p.top.work, wtop, 1e-9 * std::max(1.0, wtop));
  EXPECT_NEAR(p.total_work, work + wupper + wtop, 1e-9 * std::max(1.0, p.total_work));
  EXPECT_NEAR(an.stats.factor_flops, p.total_work, 1e-9 * std::max(1.0, p.total_work));
  EXPECT_EQ(an.stats.upper_layers, p.n_upper_layers());
  EXPECT_EQ(an.stats.upper_parts, static_cast<index_t>(p.upper.size()));
  check_upper_layers(t, p, workers);
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

// A complete binary tree of `depth` levels, fronts numbered in postorder, as nested
// dissection of a 3D grid makes it: the fronts at depth d have pivots[d] pivots, and
// every ancestor's pivots as the rows of their contribution block. When `lopsided`, the
// root's first child's subtree has one level more (an unbalanced tree).
AssemblyTree binary_tree(int depth, const std::vector<index_t>& pivots, bool lopsided) {
  AssemblyTree t;
  std::vector<int> level;  // depth of each front
  // postorder: children first; returns the front number
  std::function<index_t(int, int)> build = [&](int d, int levels) -> index_t {
    std::vector<index_t> kids;
    if (d + 1 < levels) {
      const bool deeper = lopsided && d == 0;
      kids.push_back(build(d + 1, deeper ? levels + 1 : levels));
      kids.push_back(build(d + 1, levels));
    }
    const index_t f = static_cast<index_t>(t.parent.size());
    t.parent.push_back(-1);
    level.push_back(d);
    for (index_t c : kids) t.parent[c] = f;
    return f;
  };
  build(0, depth);
  const index_t nf = static_cast<index_t>(t.parent.size());
  for (index_t f = 0; f < nf; ++f)
    t.first_pivot.push_back(t.first_pivot.back() +
                            pivots[std::min<std::size_t>(level[f], pivots.size() - 1)]);
  t.n = t.first_pivot.back();
  for (index_t f = 0; f < nf; ++f) {
    for (index_t j = t.first_pivot[f]; j < t.first_pivot[f + 1]; ++j) {
      t.rows.push_back(j);
      t.front_of_column.push_back(f);
    }
    for (index_t a = t.parent[f]; a >= 0; a = t.parent[a])  // ancestors: larger columns
      for (index_t j = t.first_pivot[a]; j < t.first_pivot[a + 1]; ++j) t.rows.push_back(j);
    t.row_offsets.push_back(static_cast<index_t>(t.rows.size()));
  }
  std::vector<std::vector<index_t>> kids(nf);
  for (index_t f = 0; f < nf; ++f)
    if (t.parent[f] >= 0) kids[t.parent[f]].push_back(f);
  for (index_t f = 0; f < nf; ++f) {
    t.children.insert(t.children.end(), kids[f].begin(), kids[f].end());
    t.child_offsets.push_back(static_cast<index_t>(t.children.size()));
  }
  return t;
}

// The same tree split with and without upper layers. Without: no layer, and the
// estimate is the subtrees' LPT makespan + the top part's work. With: layer 0 may differ
// (each layer-0 state is judged with its upper layers), the estimate is no larger, and
// with layers it is below what the same subtrees would give with everything above them
// in the top part.
void check_on_off(const schedule::TreePartition& on, const schedule::TreePartition& off,
                  const AssemblyTree& t) {
  EXPECT_TRUE(off.upper.empty());
  EXPECT_EQ(off.n_upper_layers(), 0);
  for (index_t f = 0; f < t.n_fronts(); ++f)
    EXPECT_EQ(off.part_id[f], off.part_of[f] >= 0 ? off.part_of[f] : off.top_id());
  std::vector<double> w;
  for (const auto& sub : off.subtrees) w.push_back(sub.work);
  const double off_time = makespan_of(w, off.owner, off.workers) + off.top.work;
  EXPECT_NEAR(off.estimated_time, off_time, 1e-9 * off_time);
  // each keeps the fewest parts within fewer_parts_slack of its best estimate, and the
  // best with layers is no worse than the best without
  EXPECT_LE(on.estimated_time,
            off.estimated_time * (1 + schedule::PartitionOptions{}.fewer_parts_slack + 1e-12));
  if (!on.upper.empty()) {
    std::vector<double> won;
    for (const auto& sub : on.subtrees) won.push_back(sub.work);
    double above = on.top.work;
    for (const FactorPart& u : on.upper) above += u.work;
    EXPECT_LT(on.estimated_time, makespan_of(won, on.owner, on.workers) + above);
  }
}

// Upper layers on nested-dissection trees from the analysis: on 3D grids the top part is
// split (at least one layer with 2 or more workers and the default 4 subtrees per worker;
// with 1 per worker the top can be a single chain of separator fronts), every invariant
// holds, and the estimate drops; Options::split_top off gives the split without them.
TEST(TreePartition, UpperLayersOnNestedDissectionTrees) {
  for (const auto& [name, a] :
       {std::pair{std::string("lap3d 20"), generators::laplacian_3d(20, 20, 20)},
        std::pair{std::string("elasticity 10"), generators::elasticity_3d(10, 10, 10)}})
    for (int workers : {2, 3, 4})
      for (int per : {1, 4}) {
        SCOPED_TRACE(name + ", " + std::to_string(workers) + " workers x " + std::to_string(per));
        Options o;
        o.type = MatrixType::spd;
        o.subtrees_per_gpu = per;
        const Analysis on = analyze_matrix(a, o, workers);
        o.split_top = false;
        const Analysis off = analyze_matrix(a, o, workers);
        ASSERT_EQ(on.tree.parent, off.tree.parent);
        check_partition(on, workers, per);
        check_partition(off, workers, per);
        if (per == 4) {  // the default; with 1 subtree per worker the top may be one chain
          EXPECT_GE(on.partition.n_upper_layers(), 1) << "the top part of a 3D grid was not split";
          EXPECT_GT(on.stats.upper_flops_fraction, 0.0);
          EXPECT_LT(on.stats.top_flops_fraction, off.stats.top_flops_fraction);
        }
        // the estimate, as the statistics report it: no worse with the layers
        EXPECT_GE(on.stats.estimated_speedup,
                  off.stats.estimated_speedup /
                      (1 + schedule::PartitionOptions{}.fewer_parts_slack + 1e-12));
        EXPECT_LE(on.stats.estimated_speedup, workers * (1 + 1e-12));
        EXPECT_NEAR(on.stats.estimated_speedup,
                    on.partition.total_work / on.partition.estimated_time, 1e-12);
        EXPECT_EQ(off.stats.upper_layers, 0);
        check_on_off(on.partition, off.partition, on.tree);
      }
}

// Upper layers on hand-built trees (balanced and lopsided binary trees with growing
// separators), with tight and loose budgets; one worker never gets a layer.
TEST(TreePartition, UpperLayersOnHandBuiltTrees) {
  for (bool lopsided : {false, true})
    for (int depth : {1, 2, 3, 6, 8})
      for (int workers : {1, 2, 3, 4, 5}) {
        SCOPED_TRACE(std::string(lopsided ? "lopsided" : "balanced") + " depth " +
                     std::to_string(depth) + ", " + std::to_string(workers) + " workers");
        const AssemblyTree t = binary_tree(depth, {40, 30, 24, 18, 12, 9, 6, 4, 3}, lopsided);
        schedule::PartitionOptions po;
        po.workers = workers;
        po.subtrees_per_worker = 2;
        po.budget = lopsided ? 1 << 20 : 0;
        const auto on = schedule::partition_tree(t, po);
        po.upper_layers = false;
        const auto off = schedule::partition_tree(t, po);
        check_upper_layers(t, on, workers);
        check_upper_layers(t, off, workers);
        check_on_off(on, off, t);
        if (workers == 1) EXPECT_TRUE(on.upper.empty());
        if (depth >= 6 && workers > 1) EXPECT_GE(on.n_upper_layers(), 1);
        for (const FactorPart& u : on.upper) check_part(t, u);
      }
}

// Of the splits within fewer_parts_slack of the best estimate the one with the fewest
// parts is kept: against slack 0 (the best estimate), never more parts and an estimate at
// most that fraction above; both satisfy every invariant.
TEST(TreePartition, FewerPartsWithinTheSlack) {
  int fewer = 0;
  for (const index_t k : {16, 20})
    for (int workers : {2, 3, 4}) {
      SCOPED_TRACE("lap3d " + std::to_string(k) + ", " + std::to_string(workers) + " workers");
      Options o;
      o.type = MatrixType::spd;
      const Analysis an = analyze_matrix(generators::laplacian_3d(k, k, k), o, workers);
      schedule::PartitionOptions po;
      po.workers = workers;
      const auto slack = schedule::partition_tree(an.tree, po);
      po.fewer_parts_slack = 0;
      const auto exact = schedule::partition_tree(an.tree, po);
      check_upper_layers(an.tree, slack, workers);
      check_upper_layers(an.tree, exact, workers);
      EXPECT_LE(slack.n_parts(), exact.n_parts());
      EXPECT_LE(slack.estimated_time,
                exact.estimated_time * (1 + schedule::PartitionOptions{}.fewer_parts_slack) + 1e-9);
      EXPECT_GE(slack.estimated_time, exact.estimated_time * (1 - 1e-12));
      fewer += slack.n_parts() < exact.n_parts();
    }
  RecordProperty("cases_with_fewer_parts", fewer);
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
  Options neg_panel;
  neg_panel.gpu_panel_kernel_max_pivots = -1;
  EXPECT_THROW(analyze_matrix(a, neg_panel), InvalidInput);
  Options neg_lu_panel;
  neg_lu_panel.gpu_lu_strip_pivots = -1;
  EXPECT_THROW(analyze_matrix(a, neg_lu_panel), InvalidInput);
  Options neg_stream;
  neg_stream.gpu_tiled_stream_columns = -1;
  EXPECT_THROW(analyze_matrix(a, neg_stream), InvalidInput);
  for (double share : {-0.1, 1.0, std::nan("")}) {
    Options bad_share;
    bad_share.gpu_tiled_pool_share = share;
    EXPECT_THROW(analyze_matrix(a, bad_share), InvalidInput) << share;
  }
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
