// strata — the patterns the analysis derives from its input: the graph of the symmetric
// pattern that the ordering and the symbolic phase work on, and the assembly map of the
// input's entries into the fronts (analysis/patterns.cpp). Internal to the analysis.
#pragma once

#include <vector>

#include "analysis/analysis.hpp"
#include "ordering/graph.hpp"
#include "strata/sparse_matrix.hpp"

namespace strata::detail {

/// The graph of B + Bᵀ, the pattern that the ordering and the symbolic phase work on:
/// for each column of B + Bᵀ its rows other than the diagonal, sorted, no duplicates
/// (ordering::Graph: n vertices, 0-based, every edge in both directions). For symmetric
/// matrices `c` is the canonical lower triangle and B its symmetric expansion; for general
/// ones `c` is canonical full CSC and B = A(:, q) with q the matching's column permutation
/// (Analysis::matching_perm: column k of B is column q[k] of A; empty: B = A).
/// `diagonal_entries`, when given, receives the number of diagonal entries of B (so that
/// nnz(B + Bᵀ) = edges + diagonal entries). Runs on the threads of the calling arena, the
/// same result for every thread count.
ordering::Graph symmetric_graph(const SparseMatrix& c, bool symmetric,
                                const std::vector<index_t>& q, index_t* diagonal_entries = nullptr);

/// Where every entry of the canonical input `c` lands: its front (the front of the
/// smaller of its two permuted indices) and its position in that front's dense m × m
/// column-major block (symmetric: the lower triangle), a front's entries ordered by that
/// column (AssemblyMap says why). Needs an.tree, an.iperm and
/// an.matching_perm. Runs on the threads of the calling arena, the same result for every
/// thread count.
AssemblyMap build_assembly_map(const SparseMatrix& c, const Analysis& an);

}  // namespace strata::detail
