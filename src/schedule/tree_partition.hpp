// strata — the split of the assembly tree into subtrees for several workers (GPUs), and
// the largest-processing-time-first assignment of those subtrees to the workers.
//
// Multi-worker factorization (DESIGN.md §3, docs/multigpu.md): the tree is cut into
// disjoint subtrees (layer 0), each factored by one worker on its own (its own level
// schedule, memory plan and contribution-block arena, in any order relative to the other
// subtrees), and the "top" part above them. The top part is split again, layer by layer,
// by the same heuristic ("upper layers" 1, 2, …: disjoint subtrees of what is left of the
// top, each factored by one worker as soon as the parts below it are done, with the
// contribution blocks of its children in lower layers handed in); the final remainder is
// the top part, factored by worker 0 after all other parts. Its largest fronts (the root
// separators) still run on one worker: splitting one front across workers by tiles is
// later work.
#pragma once

#include <vector>

#include "schedule/memory_plan.hpp"
#include "symbolic/symbolic.hpp"

namespace strata::schedule {

/// A part of the assembly tree that one worker factors on its own: a subtree (all
/// descendants of `root`, a contiguous range of front numbers ending at root), an upper
/// part (`root` and its descendants that are in no lower layer), or the top part (every
/// front in no other part; closed under parents).
struct FactorPart {
  index_t root = -1;                 ///< the subtree's or upper part's root; -1 for the top
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
  /// Split the top part into upper layers (see partition_tree); false: the top part is
  /// everything above the subtrees, as before upper layers existed.
  bool upper_layers = true;
  /// Of the splits whose estimated_time is within this fraction of the best, the one
  /// with the fewest parts is kept: each part is factored by levels on its own, so many
  /// small parts batch worse on a GPU than a few large ones, which the flop estimate does
  /// not see.
  double fewer_parts_slack = 0.02;
};

/// The maximum number of upper layers partition_tree makes.
inline constexpr int kMaxUpperLayers = 8;

/// The split of an assembly tree. Parts are named by an id (numeric::PartView::id):
/// subtree i is i (0 ≤ i < S = subtrees.size()), the top part is S, upper part k is
/// S + 1 + k.
struct TreePartition {
  int workers = 1;
  std::vector<FactorPart> subtrees;  ///< layer 0: disjoint; decreasing work (ties: increasing root)
  /// Upper layers 1 .. L, all their parts in one list, layer by layer: layer l's parts are
  /// upper[upper_layer_offsets[l − 1] .. upper_layer_offsets[l]), decreasing work (ties:
  /// increasing root). Empty without upper layers.
  std::vector<FactorPart> upper;
  std::vector<index_t> upper_layer_offsets{0};  ///< size L + 1
  /// Worker of each upper part: the one that finishes it first in the list schedule
  /// (estimated_time). Static (no stealing), so that the exporter of a block knows which
  /// worker imports it.
  std::vector<int> upper_owner;
  FactorPart top;                ///< the rest of the tree (worker 0, after every layer)
  std::vector<index_t> part_of;  ///< per front: index into subtrees, or -1 (top or upper)
  std::vector<index_t> part_id;  ///< per front: the id of its part (see above)
  std::vector<int> owner;        ///< worker of each subtree under LPT
  double total_work = 0;         ///< Σ front_flops over the tree
  /// LPT makespan over the subtrees divided by the mean load Σ subtree work / workers
  /// (≥ 1; 1 is a perfect balance; 1 when there is no subtree work).
  double balance = 1;
  index_t splits = 0;  ///< subtrees split into their children to get here
  /// The estimate the split minimizes (flops): the end of the list schedule the driver
  /// runs — each worker factors its subtrees in order, then its upper parts in order, an
  /// upper part starting when its worker is free and the parts it imports from are done
  /// — plus the top part's work (no transfers counted). Without upper layers: the LPT
  /// makespan of the subtrees + the top part's work.
  double estimated_time = 0;

  /// Number of upper layers L.
  int n_upper_layers() const { return static_cast<int>(upper_layer_offsets.size()) - 1; }
  /// Id of the top part (S).
  int top_id() const { return static_cast<int>(subtrees.size()); }
  /// Number of part ids: S + 1 + upper.size().
  int n_parts() const { return static_cast<int>(subtrees.size() + 1 + upper.size()); }
  /// The part with this id; throws InvalidInput for an id out of range.
  const FactorPart& part(int id) const;
  /// The worker that factors part `id`: the LPT owner of a subtree (before any stealing),
  /// the owner of an upper part, 0 for the top part.
  int worker_of(int id) const;
  /// The part ids layer by layer, in the order a bottom-up pass over the tree takes them:
  /// the subtrees (layer 0, possibly none), each upper layer, then the top part alone;
  /// the parts of one layer depend on no other part of it.
  std::vector<std::vector<int>> layers() const;
};

/// Splits the tree in the manner of Geist & Ng, "Task scheduling for parallel sparse
/// Cholesky factorization", Int. J. Parallel Programming 18 (1989): start from the roots'
/// subtrees; while there are fewer than workers × subtrees_per_worker of them, or their
/// LPT assignment onto the workers has a makespan above (1 + tolerance) × the mean load,
/// replace the heaviest subtree by its children's subtrees (its root front joins the top
/// part), stopping when the heaviest is a single front. Every state of that sequence with
/// enough subtrees (or every state, when the tree never yields enough) is scored by its
/// estimated time (estimated_time, with its upper layers), and the best is kept, so
/// splitting never trades a small gain in balance for a large sequential top. Work is
/// symbolic::front_flops.
///
/// Upper layers (opts.upper_layers): the fronts left above the subtrees form a tree T'
/// whose leaves read the subtree roots' blocks. The same splitting runs on T', with the
/// work of a T' subtree counted over its T' fronts only: start from T''s roots, split the
/// heaviest into its T' children (its root front stays in the top); each state's parts
/// go, largest first, to the worker that finishes them first in the list schedule of the
/// parts placed so far, and the state is scored by that schedule's end + the bound on what
/// later layers can do with the fronts left above, max(their heaviest root-to-leaf chain,
/// their work / workers). When the best state (at least one split) cuts the estimate by
/// more than tolerance × the top's work, its parts (one or more) become the next layer
/// and the search runs again on what is left (at most kMaxUpperLayers layers); layers are
/// kept as far as they lower estimated_time; the final remainder is the top part.
/// Throws InvalidInput for workers or subtrees_per_worker below 1.
TreePartition partition_tree(const symbolic::AssemblyTree& t, const PartitionOptions& opts);

/// Largest-processing-time-first (Graham 1969): items in the given order (callers sort
/// them by decreasing work) each go to the least-loaded worker (ties: lowest index).
/// Returns the worker of each item; *makespan (if given) receives the largest load.
std::vector<int> lpt_assign(const std::vector<double>& work, int workers,
                            double* makespan = nullptr);

}  // namespace strata::schedule
