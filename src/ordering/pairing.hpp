// strata — symmetric matching-based scaling and 2×2 pairing for symmetric indefinite
// matrices (Duff & Pralet 2005), and orderings that keep groups of vertices together.
#pragma once

#include <vector>

#include "ordering/ordering.hpp"
#include "strata/sparse_matrix.hpp"

namespace strata::ordering {

/// Default of Options::pairing_threshold: a pair is kept when one of its two scaled
/// diagonal entries is below this in magnitude.
inline constexpr double kDefaultPairingThreshold = 0.01;

/// Result of symmetric_matching_pairing. Everything is in the original numbering.
struct SymmetricPairing {
  /// D: D·A·D is symmetric, has every entry at most 1 in magnitude, and (when the matching
  /// is perfect) every matched entry of magnitude 1 (up to rounding).
  std::vector<double> scaling;
  /// The maximum product matching σ: row i is matched to column matching[i] (the
  /// column_permutation of maximum_product_matching).
  std::vector<index_t> matching;
  /// The kept pivot groups: pairs, and short odd cycles kept whole (when even the best
  /// singleton of the cycle has a small diagonal; see pairing.cpp). Each group lists its
  /// members in the order they are to be eliminated; consecutive members are coupled by a
  /// nonzero entry. Unknowns in no group (singletons) are not listed.
  VertexGroups groups;
  /// Scaled |diagonal| |d_i a_ii d_i| (0 where the diagonal is structurally zero).
  std::vector<double> scaled_diagonal;
  bool structurally_singular = false;
  index_t first_unmatched_row = -1;  ///< see Matching::first_unmatched_row
};

/// Duff & Pralet's symmetric scaling and pairing of a symmetric matrix `a` (any storage;
/// `lower`/`upper` are expanded, `full` is taken as given and must be symmetric; values
/// required). Computes the maximum product matching of the whole matrix, the symmetric
/// scaling D = sqrt(Dr·Dc), decomposes the matching into cycles and splits them into pairs
/// and singletons, keeping a pair only when one of its scaled diagonal entries has
/// magnitude below `threshold` (structurally zero counts as 0), and keeping a short odd
/// cycle whole when its singleton's scaled diagonal would be below `threshold`.
/// Throws InvalidInput if `a` is not square or has no values.
SymmetricPairing symmetric_matching_pairing(const SparseMatrix& a, double threshold);

/// `multi` (groups of two or more vertices, disjoint) completed by one singleton group per
/// vertex of 0..n−1 it does not hold; groups are numbered in increasing order of their
/// smallest member and keep their members' order. Throws InvalidInput when a vertex is out
/// of range or in two groups.
VertexGroups complete_groups(index_t n, const VertexGroups& multi);

/// The quotient graph of `g` by `groups`: one vertex per group, adjacent when some member
/// of one is adjacent to some member of the other.
Graph quotient_graph(const Graph& g, const VertexGroups& groups);

/// The ordering requested by `opts`, computed on the quotient graph of `g` by `groups`
/// and expanded so that the members of every group are consecutive, in the group's order.
/// Group sizes are vertex weights where the method supports them (nested dissection,
/// METIS); AMD orders the quotient graph unweighted, and OrderingMethod::automatic applies
/// its rule to AMD's counts on the quotient graph. OrderingMethod::natural and ::user
/// ignore the groups (they return exactly what compute_ordering returns).
OrderingResult compute_grouped_ordering(const Graph& g, const VertexGroups& groups,
                                        const Options& opts, int workers = 1);

}  // namespace strata::ordering
