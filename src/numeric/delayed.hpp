// strata — the multifrontal factorization with delayed pivots, and its solve.
//
// The fixed-layout factorization (numeric/factor.hpp) sizes every front, panel and
// contribution block at analysis, so a pivot the analysis's order cannot take must be
// perturbed (static pivoting). When the values have drifted from those the analysis saw
// (a Newton loop under contact and large rotations), that leaves many perturbed pivots.
// This factorization takes the same assembly tree and lets each front refuse pivots that
// fail a relative threshold test (numeric/cpu/delayed_front.hpp): their rows and columns
// join the parent's front as extra fully summed rows and columns, so front sizes follow
// the values. The factor owns its storage (sized as the fronts come) and its solve, in the
// manner of SPRAL SSIDS's numeric subtrees. Fronts are factored level by level of the
// analysis's level schedule (deepest first), those of a level concurrently; each keeps its
// contribution block until its parent has been assembled.
//
// General matrices (LU): rows and columns permute independently, so each front keeps a
// row list and a column list. Symmetric indefinite matrices: each front is held whole and
// eliminated with symmetric interchanges by 1×1 and 2×2 pivots (numeric/cpu/
// delayed_front.hpp), so a delayed variable's row and column travel together and the
// pivots give the inertia; the factor is stored as an LU as well (a 2×2 pivot as two
// elimination steps), so both types share the layout and the solve. The factor is of B =
// the scaled, matched, ordered matrix of the analysis, in tree numbering: L·U = B(σr, σc)
// for the row and column pivot sequences σr, σc (each front's first k rows / columns,
// fronts in postorder).
#pragma once

#include <tbb/task_arena.h>

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <utility>
#include <vector>

#include "analysis/analysis.hpp"
#include "base/default_init.hpp"
#include "numeric/cpu/delayed_front.hpp"

namespace strata::numeric {

/// One front of a factorization with delayed pivots: m rows and columns, k pivots; its
/// row and column lists (tree numbering; the first k are the pivot rows / columns in
/// elimination order, the next `delayed` the rows and columns it passed to its parent);
/// `lu`, what the solve reads: the pivot block (k×k column-major: U11 on and above the
/// diagonal, unit L11 below it), then L21 without its zero rows (l21_rows.size() × k,
/// column-major) and U12 without its zero columns (k × u12_cols.size(), column-major);
/// `l21_rows` / `u12_cols`: the rows / columns (tree numbering) of those kept rows of L21
/// and columns of U12; `cb`: the contribution block ((m−k)×(m−k), rows rows[k..m), columns
/// cols[k..m)), kept until the parent is assembled. The vectors keep their capacity from
/// one factorization to the next; `lu` and `cb` are written whole before they are read, so
/// growing them does not zero them first.
struct DelayedFront {
  index_t m = 0, k = 0, delayed = 0;
  std::vector<index_t> rows, cols;
  std::vector<index_t> l21_rows, u12_cols;
  UninitVector<double> lu, cb;
  PivotStats stats;
};

/// How the solve spreads over threads: disjoint subtrees of the assembly tree (each a
/// range [first, last] of front numbers, a front and its descendants in postorder) in one
/// bin per thread, balanced by the fronts' sizes, and the top part above them. Made by
/// factorize_delayed for its arena's threads; `row_bin` is per factorization (a delayed
/// pivot moves up the tree).
struct DelayedSolvePlan {
  std::uint64_t analysis_id = 0;
  int threads = 0;
  std::vector<std::vector<std::pair<index_t, index_t>>> bins;
  std::vector<index_t> top;  ///< fronts in no bin, increasing (closed under parents)
  /// Per row (tree numbering): the bin of its pivot's front, or −1 − t for the row
  /// top_rows[t] pivoted in the top part.
  std::vector<index_t> row_bin;
  std::vector<index_t> top_rows;  ///< the rows pivoted in the top part
};

/// The factor of one factorization with delayed pivots (see above), front by front in
/// the assembly tree's (postorder) numbering.
struct DelayedFactor {
  MatrixType type = MatrixType::general;
  std::vector<DelayedFront> fronts;
  index_t delayed = 0;          ///< Σ over fronts of the pivots passed on to the parent
  index_t fronts_delaying = 0;  ///< fronts that passed pivots on
  index_t largest_front = 0;    ///< the largest m
  bool valid = false;
  DelayedSolvePlan solve_plan;
};

/// Per-thread work arrays of factorize_delayed, kept from one factorization to the next.
struct DelayedWorkspace {
  struct Thread {
    std::vector<double> front;
    std::vector<index_t> row_pos, col_pos, row_perm, col_perm, scratch, kept, rel;
    std::vector<char> nonzero;
  };
  std::vector<Thread> threads;
  /// Per front: children not yet factored (the parallel traversal), and the leaves.
  std::unique_ptr<std::atomic<index_t>[]> pending;
  std::size_t pending_size = 0;
  std::vector<index_t> leaves;
};

/// Factors the scaled canonical values `scaled_values` (in the analysis's entry order,
/// Analysis::assembly) of type `type` over an.tree with delayed pivots: threshold
/// `threshold` in (0, 1]; a pivot no larger than static_pivot is not taken below a root;
/// at a root the remaining candidates are eliminated with partial pivoting and pivots
/// under static_pivot replaced by ±static_pivot (counted in front_stats' perturbed).
/// The fronts are factored concurrently in `arena`, each once its children are (one BLAS
/// thread each; a large front's panel updates are split by column blocks over the arena's
/// threads), each from its children's blocks in child order, so the factor does not
/// depend on the thread count. `scaled_values` of a symmetric_indefinite matrix are its
/// lower triangle (the analysis's symmetric entry order). Throws NotSupported for a type
/// other than general and symmetric_indefinite, InvalidInput for a threshold outside
/// (0, 1], OutOfMemory when the fronts grow beyond the memory.
void factorize_delayed(const Analysis& an, const double* scaled_values, MatrixType type,
                       double threshold, double static_pivot, DelayedFactor& factor,
                       DelayedWorkspace& work, tbb::task_arena& arena);

/// The solve plan of `factor` (DelayedFactor::solve_plan) for `threads` threads: the
/// subtree split when the analysis or the thread count changed, the rows' bins always.
/// At most `threads` bins, fewer on a small factor (each bin gets a least share of the
/// factor's entries).
/// factorize_delayed calls it with its arena's thread count; one thread: no bins.
void plan_delayed_solve(const Analysis& an, int threads, DelayedFactor& factor);

/// Solves with the factor: b (tree numbering of the rows, n × nrhs column-major) is
/// overwritten by the solution (tree numbering of the columns). With `arena` and a solve
/// plan of several bins, the bins' subtrees are solved concurrently (forward: their updates
/// of the top part's rows gathered per bin and added in bin order; backward: no shared
/// writes), so the result depends on the thread count but not on the schedule.
void solve_delayed(const Analysis& an, const DelayedFactor& factor, double* b, index_t nrhs,
                   tbb::task_arena* arena = nullptr);

/// The factor's row and column pivot sequences σr, σc (tree numbering; L·U = B(σr, σc)):
/// each front's first k rows and columns, fronts in postorder.
void delayed_pivot_sequence(const Analysis& an, const DelayedFactor& factor,
                            std::vector<index_t>& rows, std::vector<index_t>& cols);

/// The sign of det(B) from the factor: the sign of Π u_ii times the parities of the row and
/// column pivot sequences (0 when a pivot is zero); log|det B| is Σ front_stats' log_abs_det.
int delayed_determinant_sign(const Analysis& an, const DelayedFactor& factor);

}  // namespace strata::numeric
