// strata — the result of the analysis phase: everything the numeric phases need that
// depends on the pattern alone (plus, for `general` and `symmetric_indefinite`, the
// matching-based scaling (and pairs) computed from the values given at analysis and reused
// by every refactorization).
#pragma once

#include <cstdint>
#include <vector>

#include "ordering/ordering.hpp"
#include "schedule/memory_plan.hpp"
#include "schedule/stack_plan.hpp"
#include "schedule/tree_partition.hpp"
#include "strata/options.hpp"
#include "strata/sparse_matrix.hpp"
#include "strata/stats.hpp"
#include "symbolic/symbolic.hpp"

namespace strata::ordering {
struct Matching;  // ordering/matching.hpp
}  // namespace strata::ordering

namespace strata {

/// Where each stored entry of the canonical input lands in the fronts: the entries that
/// front f receives are entry_src[entry_offsets[f] .. entry_offsets[f+1]-1] (indices into
/// the canonical input's values) added at the column-major offsets entry_dst[...] of the
/// n_rows(f)×n_rows(f) front, distinct within a front. A front's entries are ordered by
/// the front's column they land in (entry_dst / n_rows(f), non-decreasing; within a column
/// in the order of the input), so that any range of columns receives a contiguous range.
struct AssemblyMap {
  std::vector<index_t> entry_offsets{0};
  std::vector<index_t> entry_src;
  std::vector<index_t> entry_dst;
};

/// The contribution-block arena layout (schedule/memory_plan.hpp).
using CbLayout = schedule::CbLayout;

/// Factor storage layout: front f keeps its first k = n_pivots(f) columns (n_rows×k,
/// L11 / U11 packed with L21) at panel_offset[f]; for LU also the k×(n_rows−k) block
/// U12 right after it (panel_size doubles in all). Panels are placed in level-schedule
/// order (not front order), so each batch's panels are contiguous.
struct FactorLayout {
  std::vector<std::size_t> panel_offset;  ///< size n_fronts + 1; the last entry is total
  std::size_t total = 0;                  ///< doubles
};

/// Doubles of front f's stored factor: n_rows·n_pivots, plus n_pivots·(n_rows−n_pivots)
/// for LU.
inline std::size_t panel_size(const symbolic::AssemblyTree& t, index_t f, bool lu) {
  const std::size_t m = t.n_rows(f), k = t.n_pivots(f);
  return m * k + (lu ? k * (m - k) : 0);
}

struct Analysis {
  std::uint64_t id = 0;  ///< unique per analysis, so executors can cache what they uploaded
  index_t n = 0;
  MatrixType type = MatrixType::automatic;  ///< spd, symmetric_indefinite or general;
                                            ///< automatic here means "symmetric, try spd"
  bool symmetric = true;                    ///< uses the lower triangle of a symmetric matrix
  /// Canonical pattern of the input as analyzed (lower triangle for symmetric types, full
  /// for general): refactorize checks that new values come with this pattern.
  std::vector<index_t> pattern_offsets;
  std::vector<index_t> pattern_indices;
  Storage input_storage = Storage::full;
  // Matching and scaling (original numbering); empty when not used.
  // general: B = Dr·A(:, q)·Dc with q = matching_perm (Duff & Koster 2001).
  // symmetric_indefinite: B = D·A·D with row_scaling == col_scaling == D and no column
  // permutation (matching_perm stays empty), plus the 2×2 pivot pairs (Duff & Pralet 2005).
  std::vector<index_t> matching_perm;  ///< column j of B is column matching_perm[j] of A
  std::vector<double> row_scaling;
  std::vector<double> col_scaling;
  /// symmetric_indefinite: the kept pivot groups of the symmetric matching (pairs, and
  /// short odd cycles; ordering/pairing.hpp), original numbering, members in elimination order.
  /// Consecutive members that the ordering placed side by side (all of them, except under
  /// the natural and user orderings) are consecutive in perm and pivots of one front.
  /// Empty when no pairing was computed.
  ordering::VertexGroups pivot_groups;
  bool structurally_singular = false;
  /// Pivot order: pivot k is column perm[k] of B (new to old); iperm is its inverse.
  std::vector<index_t> perm;
  std::vector<index_t> iperm;
  /// analyze_with_order: the order it kept, the perm of the last analysis that computed
  /// one (so a chain of kept-order analyses depends only on that analysis and the last
  /// pattern); empty for an analysis that computed its order.
  std::vector<index_t> kept_order;
  ordering::SeparatorTree separator_tree;
  symbolic::AssemblyTree tree;
  symbolic::ChildRowMap child_rows;  ///< the tree's extend-add map (derived from tree)
  symbolic::LevelSchedule schedule;
  schedule::MemoryPlan plan;
  AssemblyMap assembly;
  CbLayout cb_layout;
  /// The CPU executor's depth-first traversal and contribution-block stack, for
  /// Options::num_threads threads (an executor with another thread count makes its own).
  schedule::StackPlan stack_plan;
  FactorLayout factor_layout;
  /// The split into subtrees for several workers (schedule/tree_partition.hpp); made when
  /// the analysis is asked for more than one worker, else empty (workers == 1).
  schedule::TreePartition partition;
  AnalysisStats stats;
};

/// Runs the analysis phase (see Solver::analyze). `a` must be square. `workers` > 1 also
/// splits the tree for that many workers (Options::subtrees_per_gpu subtrees each) and,
/// with Options::balance_by_work and nested dissection, balances the top bisections by
/// work. Throws InvalidInput for workers < 1.
Analysis analyze_matrix(const SparseMatrix& a, const Options& opts, int workers = 1);

/// analyze_matrix for an `a` that the caller has validated, with what that one pass over
/// its entries found: `canonical_full` = detail::is_canonical_full(a) (Solver::analyze),
/// so that the entries are not checked again.
Analysis analyze_validated(const SparseMatrix& a, bool canonical_full, const Options& opts,
                           int workers);
/// analyze_validated with the unsymmetric matching of a general matrix started from
/// `start` (ordering::maximum_product_matching_canonical; checked by the caller), when
/// given and the matrix is general with matching_and_scaling.
Analysis analyze_validated(const SparseMatrix& a, bool canonical_full, const Options& opts,
                           int workers, const ordering::Matching* start);

/// The analysis of a pattern that contains previous's (entries added, none removed: a
/// contact that closed in a Newton loop) with previous's matching, scaling, pivot groups
/// and fill-reducing order kept: only steps 4–7 of analysis.cpp are redone (tree, level
/// schedule, plan, layouts), so the cost is that of the symbolic phase, not of the
/// ordering. The kept order stays a valid elimination order for any pattern; the new
/// entries may only add fill. Throws InvalidInput when the size differs or an entry of
/// previous's pattern is missing (naming it), or for workers < 1.
Analysis analyze_with_order(const SparseMatrix& a, const Analysis& previous, const Options& opts,
                            int workers = 1);

/// The entries of L (AnalysisStats::nnz_l: Σ of the column counts, diagonal included,
/// before amalgamation) that analyze_with_order(a, previous) would give, computed from the
/// elimination tree and column counts of a's symmetrized pattern in the kept order
/// (Gilbert, Ng & Peyton, SIMAX 15, 1994) without the rest of the analysis: a cheap test
/// of whether keeping the order is worth it. Throws InvalidInput as analyze_with_order.
index_t factor_entries_with_order(const SparseMatrix& a, const Analysis& previous);

/// The analysis of a pattern that differs from previous's (contact pairs that closed and
/// others that opened) with previous's matching, scaling and pivot groups kept and a new
/// fill-reducing order computed for it: the analysis without the matching (steps 3–7 of
/// analysis.cpp). A general matrix's pattern must hold every matched entry (A(j, q[j])); a
/// symmetric indefinite one with 2×2 pivots must contain previous's pattern. Throws
/// InvalidInput when the size differs or such an entry is missing (naming it), when a row
/// or column is empty, or for workers < 1.
Analysis analyze_with_matching(const SparseMatrix& a, const Analysis& previous, const Options& opts,
                               int workers = 1);

/// The analysis of previous's pattern (a general matrix) in the pivot sequence that a
/// factorization with delayed pivots took (numeric/delayed.hpp): row_sequence[k] and
/// col_sequence[k] are the row and the column (previous's tree numbering: index t stands
/// for row / column perm[t] of previous's B) of the k-th pivot, so that that factor is
/// L·U = B(perm∘row_sequence, perm∘col_sequence). The new analysis's column matching
/// puts those pivots on B's diagonal and its order takes them in that sequence, up to a
/// postordering of the new elimination tree; its scaling is previous's times
/// (row_rescaling, col_rescaling) (that factorization's extra equilibration, original
/// numbering; empty: none). A fixed-order factorization of the same values then takes the
/// same pivots (LU without interchanges in a given order is unique), all of which passed
/// the delayed pivoting's threshold test; nearby values usually keep them. Only steps 4–7
/// of analysis.cpp are run (as analyze_with_order). Throws InternalError when a sequence is
/// not a permutation of 0..n−1 or previous is not of a general matrix, InvalidInput for
/// workers < 1.
Analysis analyze_with_pivot_sequence(const Analysis& previous,
                                     const std::vector<index_t>& row_sequence,
                                     const std::vector<index_t>& col_sequence,
                                     const std::vector<double>& row_rescaling,
                                     const std::vector<double>& col_rescaling, const Options& opts,
                                     int workers = 1);

/// The number of workers the numeric factorization will use under `opts`: the GPUs
/// (Options::num_gpus, 0 meaning all visible) when the CUDA backend is chosen (or chosen
/// by Backend::automatic), else 1. Throws InvalidInput when num_gpus is negative or asks
/// for more GPUs than are visible.
int resolve_workers(const Options& opts);

/// The separator block size the analysis uses for a matrix of (resolved) type `type`:
/// Options::max_block_size, or when it is 0 the backend's and type's default (see there).
index_t resolve_max_block_size(const Options& opts, MatrixType type);

/// The canonical form the numeric phases read values from: lower triangle (symmetric
/// types, from any storage) or full (general), CSC, sorted, duplicates summed. Throws
/// InvalidInput if its pattern differs from the analyzed one.
SparseMatrix canonical_values(const Analysis& an, const SparseMatrix& a);

}  // namespace strata
