// strata — fill-reducing orderings and the separator tree of nested dissection.
#pragma once

#include <vector>

#include "ordering/graph.hpp"
#include "strata/options.hpp"

namespace strata::ordering {

/// The separator tree of a nested dissection: one node per separator and per leaf.
/// Node v owns the pivots begin..end-1 of the permuted order (its separator's vertices,
/// or the whole leaf subgraph). Nodes are stored in postorder: children come before
/// their parent and the root is last; a node's subtree covers a contiguous range of
/// pivots ending at its own `end`. Disconnected components hang under a root with an
/// empty separator (begin == end). `work` is filled by the symbolic phase (factor flops
/// of the node's subtree) so that the multi-GPU split can balance by work.
struct SeparatorTree {
  struct Node {
    index_t begin = 0;
    index_t end = 0;
    index_t parent = -1;
    std::vector<index_t> children;
    index_t subtree_begin = 0;  ///< first pivot of the node's subtree
    double work = 0;
  };
  std::vector<Node> nodes;
  bool empty() const { return nodes.empty(); }
};

/// Options of the nested dissection driver.
struct NestedDissectionOptions {
  index_t leaf_size = 128;  ///< subgraphs of at most this many vertices are leaves (AMD)
  int seed = 1;             ///< METIS seed, for reproducibility
  /// METIS separators tried (the best kept) at each of the top three bisection levels;
  /// deeper levels use METIS_NodeND's own rule (see Options::nd_top_separators).
  int top_separators = 1;
  /// METIS separators tried at each deeper level; 0: METIS_NodeND's rule (2 when
  /// compression removed more than a third of the vertices, else 1; see
  /// Options::nd_separators).
  int separators = 0;
  /// Balance by work (several workers, Options::balance_by_work): the bisections of the
  /// top `balance_levels` levels are redone with weighted vertices when the estimated
  /// factorization work of their two sides differs by more than balance_tolerance
  /// (max side / mean side − 1), at most balance_attempts times each; 0 levels: off.
  int balance_levels = 0;
  double balance_tolerance = 0.05;
  int balance_attempts = 2;
};

/// Vertices that an ordering keeps together and numbers consecutively: group g holds the
/// vertices members[ptr[g] .. ptr[g+1]−1], numbered in that order. Every vertex is in
/// exactly one group.
struct VertexGroups {
  std::vector<index_t> ptr{0};
  std::vector<index_t> members;
  index_t n_groups() const { return static_cast<index_t>(ptr.size()) - 1; }
  index_t size(index_t g) const { return ptr[g + 1] - ptr[g]; }
};

/// Result of an ordering: perm[k] is the original index of the k-th pivot (new to old).
struct OrderingResult {
  std::vector<index_t> perm;
  /// The method that made perm (OrderingMethod::automatic resolves to amd or
  /// nested_dissection).
  OrderingMethod method = OrderingMethod::nested_dissection;
  SeparatorTree tree;          ///< empty unless nested_dissection
  index_t rebisections = 0;    ///< bisections redone to balance work (balance_levels)
  double balance_seconds = 0;  ///< time spent estimating work and redoing bisections
  /// Nested dissection: subgraphs dissected side by side on the arena's threads (0 on one
  /// thread, or where METIS's random numbers cannot be made per thread: metis_random.hpp).
  index_t side_by_side = 0;
};

/// The nested-dissection options requested by `opts` for `workers` workers (balance
/// levels ⌈log₂(workers × subtrees_per_gpu)⌉ when balance_by_work and workers > 1);
/// throws InvalidInput for a leaf size below 1 or a negative separator count.
NestedDissectionOptions nd_options(const Options& opts, int workers = 1);

/// strata's nested dissection: recursive vertex-separator bisection with
/// METIS_ComputeVertexSeparator, connected components split first, AMD inside leaves;
/// numbering left part, right part, separator last. Records the separator tree.
/// Method: George 1973 (nested dissection); Karypis & Kumar 1998 (METIS).
OrderingResult nested_dissection(const Graph& g, const NestedDissectionOptions& opts);

/// Nested dissection of a graph whose vertices stand for groups of pivots: vertex v of
/// `q` is group v of `groups`, of weight groups.size(v). Bisection balances the weights;
/// leaves are ordered by AMD on `q`. The result is a permutation of all the members
/// (Σ group sizes), every group's members consecutive and in the group's order; the tree's
/// pivot ranges count members. `groups` must have q.n groups.
OrderingResult nested_dissection(const Graph& q, const NestedDissectionOptions& opts,
                                 const VertexGroups& groups);

/// METIS_NodeND on the whole graph; `vertex_weights` (empty, or one positive weight per
/// vertex) are passed to METIS as vwgt.
std::vector<index_t> metis_ordering(const Graph& g,
                                    const std::vector<index_t>& vertex_weights = {});

/// SuiteSparse AMD (Amestoy, Davis & Duff 1996) on the whole graph.
std::vector<index_t> amd_ordering(const Graph& g);

/// What AMD's ordering implies for a Cholesky factor of the graph's matrix (amd_l2's
/// Info, no symbolic factorization): nnz(L) with the diagonal, and the flops of an LDLᵀ
/// factorization (divisions + 2 × multiply-subtract pairs) — exact, or slightly above
/// where AMD's aggressive absorption kept approximate degrees.
struct AmdCounts {
  double nnz_l = 0;
  double flops = 0;
};
std::vector<index_t> amd_ordering(const Graph& g, AmdCounts* counts);

/// OrderingMethod::automatic's test of an AMD ordering (CHOLMOD's rule for its default
/// orderings, cholmod_analyze with nmethods = 0): AMD is kept when flops / nnz(L) < 500 or
/// nnz(L) / nnz(tril(A)) < 5, with nnz(tril(A)) = n + the graph's edges.
bool amd_is_good_enough(const AmdCounts& counts, const Graph& g);

/// Computes the ordering requested by `opts` (user_permutation is checked: throws
/// InvalidInput naming the first repeated or out-of-range entry).
OrderingResult compute_ordering(const Graph& g, const Options& opts, int workers = 1);

/// Inverse permutation: result[perm[k]] = k.
std::vector<index_t> invert_permutation(const std::vector<index_t>& perm);

/// True when perm is a permutation of 0..n-1.
bool is_permutation(const std::vector<index_t>& perm, index_t n);

}  // namespace strata::ordering
