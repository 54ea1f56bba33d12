// strata — symbolic factorization: elimination tree, postorder, column counts,
// supernodes, relaxed amalgamation, separator blocking, assembly tree, level schedule.
//
// Every function here takes the pattern of a symmetric matrix already permuted by the
// fill-reducing ordering, as a full (both triangles) canonical CSC SparseMatrix (values
// ignored). For `general` matrices that is the pattern of P(A + Aᵀ)Pᵀ.
//
// Sources: Liu 1990 (elimination tree); Gilbert, Ng & Peyton 1994 (column counts in
// near-linear time); Ashcraft & Grimes 1989 (relaxed supernode amalgamation);
// Davis, "Direct Methods for Sparse Linear Systems" (SIAM 2006), ch. 4.
#pragma once

#include <cstddef>
#include <vector>

#include "strata/options.hpp"
#include "strata/sparse_matrix.hpp"

namespace strata::symbolic {

/// The full canonical CSC pattern of P A Pᵀ (values dropped) for a symmetric pattern A
/// (a lower/upper matrix is expanded first) and perm new→old: row and column k of the
/// result are row and column perm[k] of A. O(n + nnz). Throws InvalidInput for a
/// non-square matrix or a perm that is not a permutation of 0..n-1.
SparseMatrix permute_symmetric_pattern(const SparseMatrix& full, const std::vector<index_t>& perm);

/// The same for a symmetric pattern given by its full CSC arrays: n + 1 offsets and the
/// offsets[n] sorted rows of the columns (`indices`), e.g. an ordering::Graph's xadj and
/// adjncy.data() (the result then
/// has no diagonal either, which no function here needs). Same errors.
SparseMatrix permute_symmetric_pattern(index_t n, const std::vector<index_t>& offsets,
                                       const index_t* indices, const std::vector<index_t>& perm);

/// The inverse (old→new) of the new→old permutation perm of a symmetric pattern of n
/// columns given by offsets_size = n + 1 column offsets. Throws InvalidInput naming `who`
/// for either size wrong or an entry of perm out of range or repeated.
std::vector<index_t> checked_inverse(index_t n, std::size_t offsets_size,
                                     const std::vector<index_t>& perm, const char* who);

/// Elimination tree: parent[j] is the parent of column j, -1 for a root.
std::vector<index_t> elimination_tree(const SparseMatrix& a);

/// Postorder of a forest given by parent[] (children visited in increasing order):
/// post[k] is the k-th node visited.
std::vector<index_t> postorder(const std::vector<index_t>& parent);

/// Column counts of the Cholesky factor L (diagonal included): colcount[j] = nnz(L(:,j)).
/// `post` is a postorder of `parent`. Gilbert–Ng–Peyton with Tarjan's disjoint sets.
std::vector<index_t> column_counts(const SparseMatrix& a, const std::vector<index_t>& parent,
                                   const std::vector<index_t>& post);

/// The assembly tree of fronts. Columns are in the permuted, postordered numbering.
/// Front f eliminates the pivot columns first_pivot[f] .. first_pivot[f+1]-1; its rows
/// are rows[row_offsets[f] .. row_offsets[f+1]-1], sorted ascending, the first
/// n_pivots(f) of them being its pivot columns. Fronts are numbered in postorder
/// (children before parents), so first_pivot is increasing and covers 0..n.
struct AssemblyTree {
  index_t n = 0;
  std::vector<index_t> first_pivot{0};  ///< size n_fronts + 1
  std::vector<index_t> row_offsets{0};  ///< size n_fronts + 1
  std::vector<index_t> rows;
  std::vector<index_t> parent;            ///< parent front, -1 for a root
  std::vector<index_t> child_offsets{0};  ///< children of f: children[child_offsets[f]..]
  std::vector<index_t> children;
  std::vector<index_t> front_of_column;  ///< front that eliminates column j

  index_t n_fronts() const { return static_cast<index_t>(parent.size()); }
  index_t n_pivots(index_t f) const { return first_pivot[f + 1] - first_pivot[f]; }
  index_t n_rows(index_t f) const { return row_offsets[f + 1] - row_offsets[f]; }
  /// Order of the contribution block (update matrix) front f passes to its parent.
  index_t cb_size(index_t f) const { return n_rows(f) - n_pivots(f); }
  const index_t* rows_of(index_t f) const { return rows.data() + row_offsets[f]; }
};

/// Where each front's contribution block lands in its parent (the extend-add map): for a
/// front c with a parent p, rel[offsets[c] + i] is the position in p's rows (rows_of(p))
/// of c's i-th contribution row, rows_of(c)[n_pivots(c) + i]; increasing in i, as both
/// row lists are sorted. offsets has n_fronts + 1 entries, c's range holds cb_size(c)
/// entries (-1 for a root's). Computed once per analysis (Analysis::child_rows) for the
/// CPU and CUDA executors' assembly and the device solve's plan.
struct ChildRowMap {
  std::vector<index_t> offsets{0};
  std::vector<index_t> rel;
  const index_t* of(index_t c) const { return rel.data() + offsets[c]; }
};

/// The map of `t` (see ChildRowMap): O(Σ rows of the fronts) time, O(n) workspace.
ChildRowMap child_row_map(const AssemblyTree& t);

/// Everything the symbolic phase computes.
struct SymbolicFactorization {
  std::vector<index_t> parent;    ///< elimination tree of the input pattern
  std::vector<index_t> post;      ///< its postorder
  std::vector<index_t> colcount;  ///< exact column counts, in the INPUT numbering
  index_t nnz_l = 0;              ///< Σ colcount (exact, no amalgamation)
  AssemblyTree tree;              ///< in the postordered numbering
  /// The tree's numbering is the input numbering permuted by `post`: column k of the
  /// tree is column post[k] of the input.
};

/// Relaxed amalgamation and blocking parameters (see Options for the meaning).
struct AmalgamationOptions {
  index_t relax_small = 4;
  index_t relax_size_1 = 16;
  index_t relax_size_2 = 48;
  double relax_zeros_1 = 0.8;
  double relax_zeros_2 = 0.1;
  double relax_zeros_3 = 0.05;
  index_t max_block_size = 256;  ///< separator blocking; <= 0 disables
  /// Columns that must share a front with the next one (2×2 pivot pairs, see
  /// ordering/pairing.hpp). Empty, or one flag per column in the INPUT numbering of
  /// analyze_pattern: keep_with_next[j] != 0 asks that columns j and j+1 be pivots of the
  /// same front. (j+1, j) must then be an entry of the pattern, which makes j+1 the etree
  /// parent of j and puts j right before j+1 in the postorder; amalgamation then always
  /// merges across that boundary and separator blocking never cuts there: a piece ends
  /// early instead, or, when a chain of flagged columns (flags on consecutive columns chain
  /// them: j, j+1, j+2, ... in one front) is longer than max_block_size, holds the chain
  /// whole and exceeds max_block_size.
  std::vector<char> keep_with_next;
};

/// Whether analyze_pattern checks its pattern's symmetry: `full` (in O(nnz), on the
/// canonical, sorted form), or `trusted` for a pattern its caller built symmetric with
/// sorted columns and indices in range (the analysis's permuted B + Bᵀ).
enum class PatternCheck { full, trusted };

/// Runs the whole symbolic phase: etree, postorder, column counts, fundamental
/// supernodes, relaxed amalgamation, separator blocking, row structures of the fronts.
/// Time and memory are near-linear in n + nnz(A) + Σ rows of the fronts. Throws
/// InvalidInput when the pattern is not square or (PatternCheck::full) not symmetric, or
/// when opts.keep_with_next has the wrong size or flags a column j whose etree parent is
/// not j+1.
SymbolicFactorization analyze_pattern(const SparseMatrix& a, const AmalgamationOptions& opts,
                                      PatternCheck check = PatternCheck::full);

/// analyze_pattern(permute_symmetric_pattern(n, offsets, indices, perm), opts,
/// PatternCheck::trusted) without forming the permuted pattern: the same result (parent,
/// post and colcount in the numbering of perm, the tree), for a symmetric pattern given by
/// its full CSC arrays (n + 1 offsets and offsets[n] rows, an ordering::Graph's xadj and
/// adjncy.data(); the order of the rows within a column does not matter) and perm
/// new→old. Same errors as both.
SymbolicFactorization analyze_permuted_graph(index_t n, const std::vector<index_t>& offsets,
                                             const index_t* indices,
                                             const std::vector<index_t>& perm,
                                             const AmalgamationOptions& opts);

/// Factor flops of front f for Cholesky: Σ over its pivots of (number of rows below and
/// including the pivot)² — the usual count Σ_j c_j² for c_j = rows of L(:,j) in the front.
double front_flops(const AssemblyTree& t, index_t f);

/// The paper's level schedule (BFS reverse-level traversal): level of a front is its
/// depth in the tree; levels are processed deepest first, so schedule level 0 is the
/// deepest depth. All fronts of one level are independent.
struct LevelSchedule {
  std::vector<index_t> level_offsets{0};  ///< size n_levels + 1
  std::vector<index_t> fronts;            ///< fronts of level l: fronts[level_offsets[l]..]
  std::vector<index_t> level_of;          ///< level of each front
  index_t n_levels() const { return static_cast<index_t>(level_offsets.size()) - 1; }
};

LevelSchedule level_schedule(const AssemblyTree& t);

/// The level schedule of a subset of the fronts (a "part": a subtree, or the top of the
/// tree above a set of subtrees), used by the multi-worker factorization. `fronts` lists
/// the part's fronts in increasing order. Depth is counted within the part: a front whose
/// parent is not in the part is at depth 0. Levels are numbered as above (deepest first,
/// every child in the part one level below its parent), fronts within a level in
/// increasing order; level_of is sized n_fronts and is −1 outside the part. With every
/// front listed this is level_schedule(t). Throws InvalidInput when `fronts` is not
/// strictly increasing or out of range.
LevelSchedule level_schedule(const AssemblyTree& t, const std::vector<index_t>& fronts);

}  // namespace strata::symbolic
