// strata — maximum weighted matching and scaling for unsymmetric matrices (MC64-style).
#pragma once

#include <vector>

#include "strata/sparse_matrix.hpp"

namespace strata::ordering {

/// Result of a maximum-product matching with scaling.
/// column_permutation[j] is the original column placed at position j, so that the
/// permuted matrix A(:, column_permutation) has the matched entries on its diagonal.
/// row_scaling / column_scaling (in ORIGINAL numbering) are exp(u_i), exp(v_j) of the
/// dual variables, so that Dr·A·Dc has |entries| <= 1 and |matched entries| == 1.
/// structurally_singular is true when no perfect matching exists; unmatched columns
/// are then placed on unmatched rows arbitrarily and n_matched < n, and
/// first_unmatched_row is the smallest row the maximum matching leaves unmatched (a row
/// of a set with fewer matchable columns than rows, e.g. a row of explicit zeros).
struct Matching {
  std::vector<index_t> column_permutation;
  std::vector<double> row_scaling;
  std::vector<double> column_scaling;
  index_t n_matched = 0;
  bool structurally_singular = false;
  index_t first_unmatched_row = -1;  ///< -1 when the matching is perfect
};

/// Maximum product transversal with scaling (Duff & Koster 2001, MC64 job 5): maximizes
/// the product of |diagonal| by a shortest augmenting path (Dijkstra) method on
/// c_ij = log max_k|a_kj| − log|a_ij|. Explicit zeros are not matched. A is square,
/// any layout and storage (symmetric storage is expanded). Throws InvalidInput if A is
/// not square.
Matching maximum_product_matching(const SparseMatrix& a);

/// The same for a matrix the caller has validated and knows to be canonical full CSC
/// (the analysis's canonical input): no check of A, no copy. With `start` (the
/// row_scaling and column_permutation of a matching of a matrix of the same order,
/// checked by the caller: n entries, finite positive scalings, columns in range), the
/// searches start from its row duals and from its pairs that are tight under them
/// (Solver::analyze(a, start) says how); the result is again a maximum-product matching.
Matching maximum_product_matching_canonical(const SparseMatrix& a, const Matching* start = nullptr);

}  // namespace strata::ordering
