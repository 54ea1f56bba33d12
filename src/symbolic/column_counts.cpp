// strata — column counts of the Cholesky factor in near-linear time (see symbolic.hpp).
//
// Source: Gilbert, Ng & Peyton, "An efficient algorithm to compute row and column counts
// for sparse Cholesky factorization", SIAM J. Matrix Anal. Appl. 15(4), 1994; the
// presentation in Davis, "Direct Methods for Sparse Linear Systems" (SIAM 2006), §4.5.
//
// The facts used:
//  * The nonzeros of row i of L (left of the diagonal) form the "row subtree" T_i of the
//    elimination tree: the union of the tree paths from every j < i with A(i, j) != 0
//    up to i. The count of column j is the number of row subtrees containing j.
//  * Each node j gets a weight delta[j] such that its column count is the sum of the
//    weights over the subtree rooted at j. A row subtree T_i (rooted at i, diagonal
//    included) adds +1 at each of its leaves and -1 at the least common ancestor of each
//    pair of consecutive leaves (in postorder); summed over subtrees this counts T_i once
//    at every node of T_i and also at every proper ancestor of i, which a -1 at the parent
//    of every non-root node cancels. T_j is the single node j exactly when j is a leaf of
//    the etree (a child c of j always has L(j, c) != 0): those get +1 for their diagonal.
//  * j is a leaf of T_i exactly when A(i, j) != 0, i > j, and first[j] (the postorder
//    number of the first descendant of j) exceeds the largest first-descendant number
//    seen so far among the previous leaves of row i ("maxfirst"). Visiting the columns in
//    postorder makes the leaves of every row subtree arrive in postorder.
//  * The least common ancestor of consecutive leaves p (previous) and j (current) is the
//    root of p's set in a Tarjan disjoint-set forest whose sets are merged into their
//    parents as the postorder traversal leaves each node ("ancestor" array with path
//    compression): Tarjan, J. ACM 26(4), 1979.
// With path compression alone the total time is O(nnz(A) · log n) in the worst case and
// near-linear in practice, with O(n) extra memory. The entries of a column are distinct
// rows with state of their own, so their order does not matter: the pass also runs on a
// permuted pattern read through its permutation (pattern_view.hpp).
#include <string>

#include "strata/errors.hpp"
#include "symbolic/pattern_view.hpp"
#include "symbolic/symbolic.hpp"

namespace strata::symbolic {

template <class Columns>
std::vector<index_t> column_counts_of(const Columns& cols, const std::vector<index_t>& parent,
                                      const std::vector<index_t>& post) {
  const index_t n = cols.n;
  if (static_cast<index_t>(parent.size()) != n || static_cast<index_t>(post.size()) != n)
    throw InvalidInput("column_counts: pattern, parent and post must all be of order n");

  std::vector<index_t> delta(n, 0);
  // first[j]: postorder number of the first (lowest-numbered) descendant of j. A node
  // reached for the first time from the k-th node of the postorder is an ancestor of it
  // whose subtree starts at k; such a node is a leaf only when it is that node itself.
  std::vector<index_t> first(n, -1);
  for (index_t k = 0; k < n; ++k) {
    index_t j = post[k];
    delta[j] = (first[j] == -1) ? 1 : 0;  // leaf of the etree: its diagonal entry
    for (; j != -1 && first[j] == -1; j = parent[j]) first[j] = k;
  }

  std::vector<index_t> maxfirst(n, -1);  // per row i: largest first[] of its leaves so far
  std::vector<index_t> prevleaf(n, -1);  // per row i: its previous leaf
  std::vector<index_t> ancestor(n);      // Tarjan disjoint sets (root = set representative)
  for (index_t i = 0; i < n; ++i) ancestor[i] = i;

  for (index_t k = 0; k < n; ++k) {
    const index_t j = post[k];
    if (parent[j] != -1) --delta[parent[j]];  // j is not a root
    cols.for_each(j, [&](index_t i) {
      // Only entries below the diagonal, and only when j starts a new branch of T_i.
      if (i <= j || first[j] <= maxfirst[i]) return;
      maxfirst[i] = first[j];
      const index_t prev = prevleaf[i];
      prevleaf[i] = j;
      ++delta[j];              // j is a leaf of the row subtree of i
      if (prev == -1) return;  // first leaf of T_i: its subtree root is i itself
      // Subsequent leaf: subtract at the least common ancestor of prev and j, the root of
      // prev's disjoint set, compressing the path to it.
      index_t q = prev;
      while (q != ancestor[q]) q = ancestor[q];
      for (index_t s = prev; s != q;) {
        const index_t up = ancestor[s];
        ancestor[s] = q;
        s = up;
      }
      --delta[q];
    });
    if (parent[j] != -1) ancestor[j] = parent[j];  // j's subtree is done: join its parent
  }

  // Sum the weights over subtrees: children come before parents in the numbering.
  for (index_t j = 0; j < n; ++j)
    if (parent[j] != -1) delta[parent[j]] += delta[j];
  return delta;
}

template std::vector<index_t> column_counts_of(const CscColumns&, const std::vector<index_t>&,
                                               const std::vector<index_t>&);
template std::vector<index_t> column_counts_of(const RelabeledColumns&, const std::vector<index_t>&,
                                               const std::vector<index_t>&);

std::vector<index_t> column_counts(const SparseMatrix& a, const std::vector<index_t>& parent,
                                   const std::vector<index_t>& post) {
  if (a.layout != Layout::csc || a.n_rows != a.n_cols)
    throw InvalidInput("column_counts: pattern, parent and post must all be of order n");
  return column_counts_of(CscColumns{a.offsets.data(), a.indices.data(), a.n_cols}, parent, post);
}

}  // namespace strata::symbolic
