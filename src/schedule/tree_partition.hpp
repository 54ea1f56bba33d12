// strata — the split of the assembly tree into subtrees for several workers (GPUs), and
// the largest-processing-time-first assignment of those subtrees to the workers.
//
// Multi-worker factorization (DESIGN.md §3, docs/multigpu.md): the tree is cut into
// disjoint subtrees, each factored by one worker on its own (its own level schedule,
// memory plan and contribution-block arena, in any order relative to the other subtrees),
// and the "top" part above them, factored after all subtrees with the contribution
// blocks of the subtree roots handed in.
#pragma once

#include <vector>

#include "schedule/memory_plan.hpp"
#include "symbolic/symbolic.hpp"

namespace strata::schedule {

/// A part of the assembly tree that one worker factors on its own: a subtree (all
/// descendants of `root`, a contiguous range of front numbers ending at root) or the top
/// part (every front in no subtree; closed under parents).
struct FactorPart {
  index_t root = -1;                 ///< the subtree's root front; -1 for the top part
  double work = 0;                   ///< Σ symbolic::front_flops over the part's fronts
  std::vector<index_t> fronts;       ///< the part's fronts, increasing
  symbolic::LevelSchedule schedule;  ///< the part's own levels (see level_schedule)
  MemoryPlan plan;                   ///< batches of that schedule under the same budget
  CbLayout cb_layout;                ///< the part's own arena
  std::vector<index_t> imports;      ///< children outside the part whose blocks it reads
};

/// How to split (see partition_tree).
struct PartitionOptions {
  int workers = 1;              ///< ≥ 1
  int subtrees_per_worker = 4;  ///< ≥ 1: at least workers × this many subtrees when possible
  double tolerance = 0.05;      ///< accepted LPT makespan above the mean subtree load
  std::size_t budget = 0;       ///< device memory budget of each part's plan (0: none)
  bool unsymmetric = false;     ///< LU factor sizes in the plans
};

/// The split of an assembly tree.
struct TreePartition {
  int workers = 1;
  std::vector<FactorPart> subtrees;  ///< disjoint; decreasing work (ties: increasing root)
  FactorPart top;                    ///< the rest of the tree
  std::vector<index_t> part_of;      ///< per front: index into subtrees, or -1 (top)
  std::vector<int> owner;            ///< worker of each subtree under LPT
  double total_work = 0;             ///< Σ front_flops over the tree
  /// LPT makespan over the subtrees divided by the mean load Σ subtree work / workers
  /// (≥ 1; 1 is a perfect balance; 1 when there is no subtree work).
  double balance = 1;
  index_t splits = 0;  ///< subtrees split into their children to get here
};

/// Splits the tree in the manner of Geist & Ng, "Task scheduling for parallel sparse
/// Cholesky factorization", Int. J. Parallel Programming 18 (1989): start from the roots'
/// subtrees; while there are fewer than workers × subtrees_per_worker of them, or their
/// LPT assignment onto the workers has a makespan above (1 + tolerance) × the mean load,
/// replace the heaviest subtree by its children's subtrees (its root front joins the top
/// part), stopping when the heaviest is a single front. Every state of that sequence is
/// scored by its estimated time — LPT makespan plus the top part's work, which one worker
/// factors after the subtrees — and the best-scoring state with enough subtrees (or the
/// best of all, when the tree never yields enough) is kept, so splitting never trades a
/// small gain in balance for a large sequential top. Work is symbolic::front_flops.
/// Throws InvalidInput for workers or subtrees_per_worker below 1.
TreePartition partition_tree(const symbolic::AssemblyTree& t, const PartitionOptions& opts);

/// Largest-processing-time-first (Graham 1969): items in the given order (callers sort
/// them by decreasing work) each go to the least-loaded worker (ties: lowest index).
/// Returns the worker of each item; *makespan (if given) receives the largest load.
std::vector<int> lpt_assign(const std::vector<double>& work, int workers,
                            double* makespan = nullptr);

}  // namespace strata::schedule
