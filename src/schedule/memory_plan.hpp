// strata — memory plan: cut each level of the schedule into batches that fit a budget.
//
// Working set of a batch (bytes, 8-byte scalars): for each of its fronts, the dense front
// (n_rows² entries, holding the factor panel and the contribution block in place), the
// contribution blocks of its children that it reads (Σ cb_size(c)²), and the
// contribution block it writes out for its parent (cb_size(f)²). A front whose own
// working set exceeds the budget forms a batch alone, marked `tiled`.
//
// Both the memory plan and the contribution-block arena layout work on a level schedule
// of the whole tree or of a part of it (multi-worker factorization, schedule/
// tree_partition.hpp): a part's children outside it (subtree roots factored elsewhere)
// hand their contribution blocks in before the part starts, so these are pending from
// the start and placed first in the part's arena.
#pragma once

#include <cstddef>
#include <vector>

#include "strata/stats.hpp"
#include "symbolic/symbolic.hpp"

namespace strata::schedule {

/// Working-set bytes of one front as defined above.
std::size_t front_working_bytes(const symbolic::AssemblyTree& t, index_t f);

struct MemoryPlan {
  std::size_t budget = 0;          ///< 0: unlimited (one batch per level)
  std::vector<BatchInfo> batches;  ///< in processing order; positions index LevelSchedule::fronts
  std::size_t peak_in_core_bytes =
      0;  ///< peak of (pending contribution blocks + batch) over the schedule
  std::size_t factor_bytes = 0;  ///< Σ n_pivots·n_rows·8 (LLᵀ); LU doubles the off-diagonal part
};

/// Cuts every level into consecutive batches whose working set fits `budget` (0 means
/// no limit). `unsymmetric` counts the U part of LU factor panels. `s` may schedule a
/// part of the tree (symbolic::level_schedule with a front list): the peak then counts
/// the contribution blocks imported from children outside the part as pending from the
/// start, and factor_bytes covers the part's fronts only.
MemoryPlan plan_memory(const symbolic::AssemblyTree& t, const symbolic::LevelSchedule& s,
                       std::size_t budget, bool unsymmetric);

/// Contribution blocks live in one arena whose layout is planned once: cb_offset[f] is
/// where front f's contribution block (cb_size(f)² doubles, column-major) starts.
/// The layout is a first-fit simulation of the level schedule, so blocks whose lifetimes
/// overlap never overlap in memory. cb_offset is indexed by front (size n_fronts); only
/// the entries of the scheduled fronts with a parent, and of the children imported from
/// outside the part, are meaningful.
struct CbLayout {
  std::vector<std::size_t> cb_offset;
  std::size_t arena_size = 0;  ///< doubles
};

/// First-fit placement of the contribution blocks in the order of the schedule `s` (whole
/// tree or a part): the blocks of children outside the part first (they are all live when
/// the part starts), then level by level, a level's blocks allocated before its
/// children's blocks are released (a block written by a front may not share memory with
/// one read by another front of the same level). A part's blocks whose parent lies
/// outside it (a subtree root's) stay allocated to the end, to be exported.
CbLayout plan_cb_layout(const symbolic::AssemblyTree& t, const symbolic::LevelSchedule& s);

/// The children, outside the part scheduled by `s`, of the part's fronts that pass a
/// non-empty contribution block (increasing front order). Empty for the whole tree.
std::vector<index_t> imported_children(const symbolic::AssemblyTree& t,
                                       const symbolic::LevelSchedule& s);

}  // namespace strata::schedule
