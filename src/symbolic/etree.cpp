// strata — elimination tree and postorder (see symbolic.hpp).
//
// Elimination tree: Liu, "The role of elimination trees in sparse factorization", SIAM J.
// Matrix Anal. Appl. 11(1), 1990, §3 — the parent of column j is the smallest i > j with
// L(i, j) != 0. Columns are visited in increasing order; for each entry A(i, k) with
// i < k the path from i to the root of its current subtree is followed and k becomes the
// new root. A separate "virtual ancestor" array, overwritten with k along the path, is
// the path compression that makes the whole pass O(nnz(A) · α) in practice (Liu 1990;
// Davis, "Direct Methods for Sparse Linear Systems", SIAM 2006, §4.1). The order of the
// entries within a column does not matter (the tree is unique), so the pass also runs on
// a permuted pattern read through its permutation (pattern_view.hpp).
//
// Postorder: an iterative depth-first search of the forest, children visited in
// increasing order, roots in increasing order (Davis 2006, §4.3). No recursion, so
// degenerate trees (paths of a million nodes) are fine.
#include <string>

#include "strata/errors.hpp"
#include "symbolic/pattern_view.hpp"
#include "symbolic/symbolic.hpp"

namespace strata::symbolic {

template <class Columns>
std::vector<index_t> elimination_tree_of(const Columns& cols) {
  const index_t n = cols.n;
  std::vector<index_t> parent(n, -1);
  std::vector<index_t> ancestor(n, -1);  // virtual ancestor (path-compressed)
  for (index_t k = 0; k < n; ++k) {
    cols.for_each(k, [&](index_t i) {
      // Entry A(i, k) with i < k: the upper triangle of column k is row k of the lower
      // triangle, i.e. the entries of row k left of the diagonal.
      while (i != -1 && i < k) {
        const index_t next = ancestor[i];
        ancestor[i] = k;                // compress the path towards k
        if (next == -1) parent[i] = k;  // i was a root: k adopts it
        i = next;
      }
    });
  }
  return parent;
}

template std::vector<index_t> elimination_tree_of(const CscColumns&);
template std::vector<index_t> elimination_tree_of(const RelabeledColumns&);

std::vector<index_t> elimination_tree(const SparseMatrix& a) {
  if (a.layout != Layout::csc || a.n_rows != a.n_cols)
    throw InvalidInput("elimination_tree needs a square CSC pattern");
  return elimination_tree_of(CscColumns{a.offsets.data(), a.indices.data(), a.n_cols});
}

std::vector<index_t> postorder(const std::vector<index_t>& parent) {
  const index_t n = static_cast<index_t>(parent.size());
  // Child lists as linked lists; inserting in decreasing order leaves each list sorted
  // in increasing order.
  std::vector<index_t> head(n, -1), next(n, -1);
  for (index_t j = n - 1; j >= 0; --j) {
    const index_t p = parent[j];
    if (p < -1 || p >= n || p == j)
      throw InvalidInput("postorder: parent[" + std::to_string(j) + "] = " + std::to_string(p) +
                         " is not a valid parent");
    if (p != -1) {
      next[j] = head[p];
      head[p] = j;
    }
  }
  std::vector<index_t> post;
  post.reserve(n);
  std::vector<index_t> stack;
  for (index_t root = 0; root < n; ++root) {
    if (parent[root] != -1) continue;
    stack.push_back(root);
    while (!stack.empty()) {
      const index_t v = stack.back();
      const index_t c = head[v];
      if (c == -1) {  // all children done: emit v
        stack.pop_back();
        post.push_back(v);
      } else {  // descend into the next child, unlinking it from v's list
        head[v] = next[c];
        stack.push_back(c);
      }
    }
  }
  if (static_cast<index_t>(post.size()) != n) throw InvalidInput("postorder: parent[] has a cycle");
  return post;
}

}  // namespace strata::symbolic
