// strata — rescaling the values of a refactorization whose analysis scaling has gone stale.
//
// The matching and scaling of a general or symmetric indefinite matrix (Duff & Koster
// 2001; ordering/matching.hpp) are computed from the values the analysis saw: every
// entry of B = Dr·A(:,Q)·Dc at most 1 in magnitude, the matched ones 1. A refactorization
// reuses them (the order of the factorization depends on Q), but when the values have
// changed by orders of magnitude (a Newton loop whose step size changed, a contact closed)
// some rows and columns of B are far from 1, the norm that sets the static pivot threshold
// is dominated by them, and pivots of ordinary size look tiny. Here B is equilibrated
// again, in O(nnz) per sweep, by the iteration of Ruiz ("A scaling algorithm to
// equilibrate both rows and columns norms in matrices", RAL-TR-2001-034): each sweep
// divides row i by √(max_j |b_ij|) and column j by √(max_i |b_ij|), which drives every
// row and column maximum to 1. The factors are rounded to powers of two, so scaling is
// exact in floating point and a matrix already within a factor 2 of equilibrium is left
// bitwise unchanged. (The Solver does not rescale the first factorization after an
// analysis: its scaling was computed from those values.)
#pragma once

#include <tbb/task_arena.h>

#include <cstdint>
#include <span>
#include <vector>

#include "strata/sparse_matrix.hpp"

namespace strata {

/// A number no earlier call returned (thread-safe; never 0).
std::uint64_t next_rescaling_id();

/// The extra scaling of one factorization: B' = diag(row)·B·diag(col) (original numbering
/// of A's rows and columns; symmetric: row == col). Empty when B needed none.
struct Rescaling {
  std::vector<double> row, col;
  int sweeps = 0;  ///< equilibration sweeps made (0: B was within a factor 2 already)
  /// Names these factors (numeric::RescaleView::id): a new number for every Rescaling
  /// made, which its copies keep; row and col are set once, right after it is made.
  std::uint64_t id = next_rescaling_id();
};

/// Equilibrates `values` (B's values in the entry order of `pattern`, canonical CSC; lower
/// storage when `symmetric`, mirrored for the row and column maxima) in place: at most
/// `max_sweeps` Ruiz sweeps with power-of-two factors (each halves the logarithm of every
/// row's and column's distance from 1), stopping once every nonempty row's and column's
/// largest magnitude is in [1/2, 2]. Returns the scaling applied (empty when
/// none was needed). Rows and columns with no nonzero value keep factor 1. With `arena`
/// and `work` (scratch, resized as needed) a large matrix's passes run in column blocks on
/// the arena's threads, with the same result. `row_max` and `col_max`, when given, are the
/// row and column maxima of |B| as it is (symmetric: the full rows', col_max empty; for
/// instance refactor_values'), and the pass that would find them is skipped.
Rescaling rescale_values(const SparseMatrix& pattern, bool symmetric, std::vector<double>& values,
                         int max_sweeps = 3, tbb::task_arena* arena = nullptr,
                         std::vector<double>* work = nullptr, std::span<const double> row_max = {},
                         std::span<const double> col_max = {});

/// rescale_values' stopping rule for the row or column maxima of |B|: every nonzero one in
/// [1/2, 2].
bool within_factor_two(std::span<const double> maxima);

/// values[p] *= r.row[i]·r.col[j] for every entry p = (i, j) of `pattern` (canonical CSC;
/// symmetric: lower storage): the extra scaling `r` (rescale_values' result, or a device's
/// pass's) applied in one pass to values scaled by the analysis's scaling alone. Its
/// factors are powers of two, so every product is exact and the bits are those the
/// sweeps gave. Nothing when r is empty. With `arena`, large patterns in column blocks on
/// its threads.
void apply_rescaling(const SparseMatrix& pattern, const Rescaling& r, std::vector<double>& values,
                     tbb::task_arena* arena = nullptr);

}  // namespace strata
