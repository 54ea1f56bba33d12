// strata tests — the depth-first plan of the CPU factorization (schedule/stack_plan): every
// front once, children before parents, and no two contribution blocks that are alive at
// the same time share memory, checked by replaying the plan with its concurrency; plus
// the lower-panel storage the Cholesky blocks use.
#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "analysis/analysis.hpp"
#include "base/lower_panels.hpp"
#include "schedule/stack_plan.hpp"
#include "sparse/generators.hpp"
#include "support/test_support.hpp"

namespace strata {
namespace {

using schedule::StackPlan;
using symbolic::AssemblyTree;

TEST(LowerPanels, EveryElementHasItsOwnPlaceInsideTheSize) {
  for (index_t n : {0, 1, 2, 3, 5, 127, 128, 129, 300, 733})
    for (index_t width : {1, 2, 3, 5, 128, 733, 1000}) {
      SCOPED_TRACE("n=" + std::to_string(n) + " width=" + std::to_string(width));
      const std::size_t size = LowerPanels::size(n, width);
      std::size_t expected = 0;  // Σ over panels of rows × columns
      for (index_t j0 = 0; j0 < n; j0 += std::min(width, n)) {
        const index_t w = std::min(width >= n ? n : width, n - j0);
        expected += static_cast<std::size_t>(width >= n ? n : n - j0) * w;
      }
      EXPECT_EQ(size, expected);
      std::vector<char> used(size, 0);
      LowerPanels p{nullptr, n, width, n};
      std::vector<double> store(size + 1);
      p.data = store.data();
      std::size_t count = 0;
      for (index_t j = 0; j < n; ++j)
        for (index_t i = j; i < n; ++i) {
          const std::ptrdiff_t at = p.diag(j) + (i - j) - store.data();
          ASSERT_GE(at, 0);
          ASSERT_LT(static_cast<std::size_t>(at), size);
          ASSERT_FALSE(used[at]) << "(" << i << ", " << j << ")";
          used[at] = 1;
          ++count;
        }
      EXPECT_EQ(count, static_cast<std::size_t>(n) * (n + 1) / 2);
      if (width < n) {  // panels are contiguous, each column-major with ld = rows
        for (index_t q = 0; q < p.panels(); ++q) EXPECT_EQ(p.diag(p.panel_first(q)), p.panel(q));
      }
    }
}

// A live block: [begin, end) in memory space `space` (-1: the arena's main part, r ≥ 0:
// thread region r).
struct Live {
  int space;
  std::size_t begin, end;
  index_t front;
};

class Replay {
 public:
  Replay(const AssemblyTree& t, const StackPlan& p) : t_(t), p_(p), done_(t.n_fronts(), 0) {}

  void run() {
    ASSERT_EQ(p_.step_front.size() + 1, p_.group_offsets.size());
    for (std::size_t i = 0; i < p_.step_front.size(); ++i) {
      // the subtrees of a group run at once: each in its own region; regions are empty
      // between subtrees, their roots' blocks go to the main space
      int region = 0;
      for (index_t q = p_.group_offsets[i]; q < p_.group_offsets[i + 1]; ++q) {
        const index_t s = p_.group[q];
        ASSERT_GE(s, 0);
        ASSERT_LT(s, static_cast<index_t>(p_.subtree_root.size()));
        const int r = p_.regions == 1 ? 0 : region++ % p_.regions;
        for (index_t f = p_.subtree_first[s]; f <= p_.subtree_root[s]; ++f) {
          EXPECT_EQ(p_.subtree_of[f], s);
          front(f, r);
        }
        for (const Live& l : live_) EXPECT_NE(l.space, r) << "a block left in region " << r;
      }
      const index_t f = p_.step_front[i];
      if (f >= 0) {
        EXPECT_EQ(p_.subtree_of[f], -1);
        front(f, -1);
      }
    }
    for (index_t f = 0; f < t_.n_fronts(); ++f) EXPECT_TRUE(done_[f]) << "front " << f;
    EXPECT_TRUE(live_.empty());
  }

  std::size_t main_peak = 0, region_peak = 0;

 private:
  int space_of(index_t f, int region) const { return p_.in_region(f) ? region : -1; }

  void place(index_t f, int space, std::size_t off, const char* what) {
    const std::size_t b = p_.block_doubles(t_, f);
    if (b == 0) return;
    const std::size_t end = off + b;
    (space < 0 ? main_peak : region_peak) = std::max(space < 0 ? main_peak : region_peak, end);
    EXPECT_LE(end, space < 0 ? p_.main_size : p_.region_size) << what << " of front " << f;
    for (const Live& l : live_)
      if (l.space == space && off < l.end && l.begin < end)
        ADD_FAILURE() << what << " of front " << f << " overlaps the block of front " << l.front;
  }

  void front(index_t f, int region) {
    ASSERT_FALSE(done_[f]) << "front " << f << " twice";
    const int space = space_of(f, region);
    const bool has_block = p_.block_doubles(t_, f) > 0;
    // its children are done and their blocks are live; it forms its block at build_offset
    for (index_t q = t_.child_offsets[f]; q < t_.child_offsets[f + 1]; ++q)
      EXPECT_TRUE(done_[t_.children[q]]) << "front " << f << " before its child";
    if (has_block) place(f, space, p_.build_offset[f], "the forming block");
    // the children's blocks are read and freed, then its block is moved to cb_offset
    for (index_t q = t_.child_offsets[f]; q < t_.child_offsets[f + 1]; ++q) {
      const index_t c = t_.children[q];
      if (p_.block_doubles(t_, c) == 0) continue;
      const auto it =
          std::find_if(live_.begin(), live_.end(), [&](const Live& l) { return l.front == c; });
      ASSERT_NE(it, live_.end()) << "block of child " << c << " of front " << f << " not live";
      live_.erase(it);
    }
    if (has_block) {
      place(f, space, p_.cb_offset[f], "the kept block");
      EXPECT_LE(p_.cb_offset[f], p_.build_offset[f]) << "a block moves down, never up";
      live_.push_back({space, p_.cb_offset[f], p_.cb_offset[f] + p_.block_doubles(t_, f), f});
    }
    done_[f] = 1;
  }

  const AssemblyTree& t_;
  const StackPlan& p_;
  std::vector<char> done_;
  std::vector<Live> live_;
};

void check_plans(const AssemblyTree& t) {
  for (int threads : {1, 2, 3, 8})
    for (bool panels : {false, true}) {
      SCOPED_TRACE("threads " + std::to_string(threads) + (panels ? ", lower panels" : ""));
      const StackPlan p = schedule::plan_stack(t, threads, panels);
      EXPECT_EQ(p.threads, threads);
      EXPECT_EQ(p.regions, threads > 1 ? threads + 1 : 1);
      Replay r(t, p);
      r.run();
      EXPECT_EQ(r.main_peak, p.main_size) << "the stack is as large as its peak, no larger";
      EXPECT_LE(r.region_peak, p.region_size);
      // with lower panels no block is larger than its square
      for (index_t f = 0; f < t.n_fronts(); ++f)
        if (t.parent[f] >= 0)
          EXPECT_LE(p.block_doubles(t, f), static_cast<std::size_t>(t.cb_size(f)) *
                                               static_cast<std::size_t>(t.cb_size(f)));
    }
}

Analysis analyze(const SparseMatrix& a, MatrixType type) {
  Options o;
  o.type = type;
  o.num_threads = 2;
  return analyze_matrix(a, o, 1);
}

TEST(StackPlan, Laplacian3dTreesReplayWithoutOverlap) {
  for (index_t g : {1, 2, 3, 5, 12}) {
    SCOPED_TRACE("lap3d " + std::to_string(g));
    check_plans(analyze(generators::laplacian_3d(g, g, g), MatrixType::spd).tree);
  }
}

TEST(StackPlan, ElasticityAndRandomPatternsReplayWithoutOverlap) {
  check_plans(analyze(generators::elasticity_3d(4, 4, 4), MatrixType::spd).tree);
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  for (index_t n : {1, 2, 3, 5, 733}) {
    SCOPED_TRACE("random n=" + std::to_string(n));
    const SparseMatrix a = test::random_sparse(n, 3, test::RandomKind::general, rng);
    check_plans(analyze(a, MatrixType::general).tree);
  }
}

TEST(StackPlan, TheLargeTopRunsOnTheCallingThreadAndTheSmallSubtreesCoverTheRest) {
  const Analysis an = analyze(generators::laplacian_3d(20, 20, 20), MatrixType::spd);
  const auto& t = an.tree;
  const StackPlan p = schedule::plan_stack(t, 2, true);
  ASSERT_GT(p.subtree_root.size(), 1u);
  for (index_t f = 0; f < t.n_fronts(); ++f) {
    if (symbolic::front_flops(t, f) > schedule::kLargeFrontFlops) {
      EXPECT_EQ(p.subtree_of[f], -1) << "large front " << f << " in a subtree";
    }
    if (p.subtree_of[f] >= 0 && t.parent[f] >= 0 && p.subtree_of[t.parent[f]] >= 0) {
      EXPECT_EQ(p.subtree_of[f], p.subtree_of[t.parent[f]]);
    }
  }
  // the stack holds less than the level schedule's arena of square blocks
  EXPECT_LT(p.arena_size(), an.cb_layout.arena_size);
}

}  // namespace
}  // namespace strata
