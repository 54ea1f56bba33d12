// strata — the depth-first plan of the CPU factorization: which fronts run on which
// thread, in which order, and where every contribution block lives on a stack.
//
// The level schedule (symbolic/level_schedule.cpp) suits a GPU, which factors a whole level
// at once; on a CPU it keeps every pending contribution block of a level alive. A
// depth-first (postorder) traversal with the blocks on a stack holds only the blocks of
// the path being climbed, as the multifrontal codes for CPUs do (Liu 1986; MUMPS; SPRAL
// SSIDS). See stack_plan.cpp for the algorithm.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "base/lower_panels.hpp"
#include "symbolic/symbolic.hpp"

namespace strata::schedule {

/// Fronts whose partial factorization costs more than this many flops
/// (symbolic::front_flops) are "large": the CPU executor factors them one at a time with
/// all its threads inside BLAS; smaller fronts get one BLAS thread each.
constexpr double kLargeFrontFlops = 2e7;

/// From this many threads on, the plan runs a layer of independent subtrees (large fronts
/// included) one BLAS thread each, rather than only the subtrees of small fronts.
constexpr int kLayerThreads = 4;
/// The share of `threads` × one thread's rate that the layer's choice expects the top's
/// fronts to reach with all threads inside BLAS.
constexpr double kTopEfficiency = 0.5;

/// The plan (see the file header). Fronts are those of the AssemblyTree it was made for,
/// whose numbering is a postorder: the subtree of front r is the range [r − size + 1, r].
///
/// Memory is one arena of arena_size() doubles: the main stack [0, main_size) and
/// `regions` thread regions of region_size doubles each, region i at main_size + i ·
/// region_size. A small subtree runs on one thread, in the region of that thread; its
/// root's block is written to the main stack. Offsets are in doubles; a block takes
/// block_doubles(f): with lower_panels (Cholesky) its lower triangle in panels of
/// kLowerPanelWidth columns (base/lower_panels.hpp), else the cb_size(f)² square.
struct StackPlan {
  int threads = 1;            ///< the executor thread count the plan was made for
  bool lower_panels = false;  ///< blocks stored as lower triangles in panels (Cholesky)
  /// Small subtrees (every front small, the subtree's work within the per-thread share; with
  /// kLayerThreads threads or more, the subtrees of the chosen layer): subtree s is the
  /// range [subtree_first[s], subtree_root[s]] of the postorder.
  std::vector<index_t> subtree_first;
  std::vector<index_t> subtree_root;
  /// Per front: its small subtree, or -1 for a front of the top (run by the calling
  /// thread, one after another, in increasing order).
  std::vector<index_t> subtree_of;
  /// The traversal: steps in order; step i runs the subtrees
  /// group[group_offsets[i] .. group_offsets[i + 1]) concurrently, then its top front
  /// step_front[i] (−1: none).
  std::vector<index_t> step_front;
  std::vector<index_t> group_offsets{0};
  std::vector<index_t> group;
  /// Per front with a parent and a contribution block: where its block stays until the
  /// parent is assembled (cb_offset), and where it is formed (build_offset; it is moved
  /// down to cb_offset after the front is factored when the two differ). Relative to the
  /// thread's region for the fronts inside a small subtree but its root, to the arena
  /// otherwise.
  std::vector<std::size_t> cb_offset;
  std::vector<std::size_t> build_offset;
  /// Whether the small subtrees' roots have blocks of their own below the stack (all
  /// subtrees run in one first step), or are pushed on the stack just before their parent.
  bool subtrees_first = false;
  std::size_t main_size = 0;    ///< doubles
  std::size_t region_size = 0;  ///< doubles
  int regions = 1;

  /// True for a front inside a small subtree but not its root (offsets relative to a region).
  bool in_region(index_t f) const {
    const index_t s = subtree_of[static_cast<std::size_t>(f)];
    return s >= 0 && subtree_root[static_cast<std::size_t>(s)] != f;
  }
  /// Doubles of front f's stored block (0 for a front without a parent).
  std::size_t block_doubles(const symbolic::AssemblyTree& t, index_t f) const {
    if (t.parent[static_cast<std::size_t>(f)] < 0) return 0;
    const index_t c = t.cb_size(f);
    return LowerPanels::size(c, lower_panels ? kLowerPanelWidth : c);
  }
  /// The block of front f at `data` (its storage as above).
  LowerPanels block(const symbolic::AssemblyTree& t, index_t f, double* data) const {
    const index_t c = t.cb_size(f);
    LowerPanels b;
    b.data = data;
    b.n = c;
    b.width = lower_panels ? kLowerPanelWidth : (c > 0 ? c : 1);
    b.ld = c;
    return b;
  }
  std::size_t arena_size() const {
    return main_size + static_cast<std::size_t>(regions) * region_size;
  }
};

/// The plan of `t` for an executor of `threads` threads (≥ 1), with the blocks in lower
/// panels (a Cholesky factorization) or as squares (LDLᵀ, LU). O(n_fronts + Σ children)
/// time. Throws InternalError when t's numbering is not a postorder.
StackPlan plan_stack(const symbolic::AssemblyTree& t, int threads, bool lower_panels);

}  // namespace strata::schedule
