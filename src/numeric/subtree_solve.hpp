// strata — the host's triangular solves with the factor, over threads by subtrees.
//
// The multifrontal solve (numeric/triangular_solve.cpp, Liu 1992 §6) visits the fronts
// children-first forward and parents-first backward; one front's work is a TRSM and a
// GEMM on its panel, memory-bound for a few right-hand sides. On one thread a large
// factor is read at one core's memory bandwidth, twice. The tree gives the parallelism,
// as in the factorization (Geist & Ng's subtree-to-thread mapping; SPRAL SSIDS solves
// each numeric subtree on its own): disjoint subtrees are independent but for the
// forward updates they make to the rows of their ancestors, and the backward step of a
// subtree reads only those rows once the fronts above it are done.
//
// The plan cuts the tree, from the analysis alone, into the largest subtrees whose solve
// work (the entries of their panels) is at most 1/kSolveSubtrees of the whole, and the
// top fronts above them. Forward, each subtree runs on some thread; its updates of rows
// outside it go to slots of its own (the rows it updates outside, listed once per
// analysis), added into x in subtree order once every subtree is done; then the top
// fronts run in order, a large one with every BLAS thread. Backward, the top fronts
// first, then the subtrees over the threads. Since the cut and the order of every sum
// depend on the analysis only, the solution is bitwise the same for every thread count.
#pragma once

#include <tbb/task_arena.h>

#include <cstdint>
#include <utility>
#include <vector>

#include "numeric/factor.hpp"

namespace strata::numeric {

/// Subtrees per solve plan, about: a subtree holds at most 1/kSolveSubtrees of the
/// factor's entries, so the threads of a 16-core host get several each.
constexpr int kSolveSubtrees = 64;

/// The cut of the assembly tree for the host solve (see the file header).
///   subtrees: [first, last] front ranges (postorder: a front and its descendants),
///             increasing;
///   top:      the fronts in no subtree, increasing (every ancestor of a subtree root);
///   slot_offsets: per subtree + 1, into slot_row: the rows (tree numbering) outside the
///             subtree that its fronts update in the forward solve, increasing;
///   row_slot: per front row (the layout of AssemblyTree::rows): for a row of a subtree's
///             front that lies outside that subtree, its slot (an index into the
///             subtree's range of slot_row), else −1.
struct SubtreeSolvePlan {
  std::uint64_t analysis_id = 0;
  std::vector<std::pair<index_t, index_t>> subtrees;
  std::vector<index_t> top;
  std::vector<index_t> slot_offsets{0};
  std::vector<index_t> slot_row;
  std::vector<index_t> row_slot;
};

/// The plan of `an` (see SubtreeSolvePlan). O(fronts + front rows) time and memory.
SubtreeSolvePlan plan_subtree_solve(const Analysis& an);

/// Solves with the factor as solve_in_place (x: tree numbering, n × nrhs column-major,
/// the right-hand sides in and the solutions out), the subtrees of `plan` (made for `an`)
/// over the threads of `arena` and the top fronts on the calling thread, whose large ones
/// use `top_blas_threads` BLAS threads (1: bitwise the same as with more; the BLAS is left
/// at one thread). The result does not depend on the arena's thread count. Throws
/// InternalError when the plan was made for another analysis.
void solve_by_subtrees(const Analysis& an, const NumericFactor& fac, const SubtreeSolvePlan& plan,
                       double* x, index_t nrhs, tbb::task_arena& arena, int top_blas_threads);

}  // namespace strata::numeric
