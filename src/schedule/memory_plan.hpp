// strata — memory plan: cut each level of the schedule into batches that fit a budget.
//
// Working set of a batch (bytes, 8-byte scalars): for each of its fronts, the dense front
// (n_rows² entries, holding the factor panel and the contribution block in place), the
// contribution blocks of its children that it reads (Σ cb_size(c)²), and the
// contribution block it writes out for its parent (cb_size(f)²). A front whose own
// working set exceeds the budget forms a batch alone, marked `tiled`.
#pragma once

#include <cstddef>
#include <vector>

#include "strata/stats.hpp"
#include "symbolic/symbolic.hpp"

namespace strata::schedule {

/// Working-set bytes of one front as defined above.
std::size_t front_working_bytes(const symbolic::AssemblyTree& t, index_t f);

struct MemoryPlan {
  std::size_t budget = 0;            ///< 0: unlimited (one batch per level)
  std::vector<BatchInfo> batches;    ///< in processing order; positions index LevelSchedule::fronts
  std::size_t peak_in_core_bytes = 0;  ///< peak of (pending contribution blocks + batch) over the schedule
  std::size_t factor_bytes = 0;        ///< Σ n_pivots·n_rows·8 (LLᵀ); LU doubles the off-diagonal part
};

/// Cuts every level into consecutive batches whose working set fits `budget` (0 means
/// no limit). `unsymmetric` counts the U part of LU factor panels.
MemoryPlan plan_memory(const symbolic::AssemblyTree& t, const symbolic::LevelSchedule& s,
                       std::size_t budget, bool unsymmetric);

}  // namespace strata::schedule
