// strata — maximum product transversal with row and column scaling (see matching.hpp).
//
// Why. LU with restricted (threshold) pivoting, as the multifrontal method does, may only
// choose pivots inside the fully summed block of a front; when the diagonal of A is small
// or zero the factorization must fall back on static pivoting (a tiny pivot replaced by
// ±ε‖A‖), which costs accuracy that iterative refinement then has to win back. Permuting
// the columns so that the product of |diagonal| is as large as possible, and scaling so that
// those diagonal entries are 1 and every other entry is at most 1 in magnitude, makes the
// diagonal pivots acceptable in the vast majority of cases, so static pivoting rarely
// triggers. This is what MC64 (job 5) does for SuperLU_DIST, MUMPS and PARDISO.
//
// Source. I. S. Duff and J. Koster, "On algorithms for permuting large entries to the
// diagonal of a sparse matrix", SIAM J. Matrix Anal. Appl. 22(4):973–996, 2001, Sections
// 4–5 (the maximum product transversal as a weighted bipartite matching problem, solved by
// successive shortest augmenting paths with Dijkstra's algorithm on reduced costs, and the
// scaling obtained from the optimal dual variables). This file is written from the paper's
// description and the linear-programming duality below, not from MC64's code.
//
// Conventions (everything in ORIGINAL numbering; rows i, columns j):
//
//   a_j  = max_k |a_kj|, the largest magnitude in column j. A column with a_j = 0 (no entry,
//          or only explicit zeros) cannot be matched.
//   c_ij = log a_j − log|a_ij| ≥ 0 for every nonzero a_ij. Explicit zeros are not edges.
//
//   For a perfect matching σ (row i ↔ column σ(i)), Σ_i c_{iσ(i)} = Σ_j log a_j −
//   log Π_i |a_{iσ(i)}|. The first sum does not depend on σ, so a minimum-cost perfect
//   matching is a maximum-product one.
//
//   Linear-programming dual of the assignment problem: maximize Σ u_i + Σ v_j subject to
//
//       r_ij := c_ij − u_i − v_j ≥ 0            on every edge (the reduced cost),
//
//   and by complementary slackness r_ij = 0 on the matched edges of an optimal matching.
//   The algorithm keeps both invariants (r ≥ 0 everywhere, r = 0 on matched edges) for the
//   partial matchings it builds, so at the end
//
//       Dr = diag(exp(u_i)),  Dc = diag(exp(v_j − log a_j)) = diag(exp(v_j) / a_j)
//
//   give |(Dr A Dc)_ij| = exp(u_i + log|a_ij| + v_j − log a_j) = exp(−r_ij) ≤ 1, with
//   equality on the matched entries. These are row_scaling and column_scaling.
//
// Algorithm.
//
//   1. Initial duals (the paper's cheap start): u_i = min_j c_ij (row minimum), then
//      v_j = min_i (c_ij − u_i) (column minimum of what is left); both keep r ≥ 0.
//      Greedy matching on the tight edges (r = 0): each column takes a free row on a tight
//      edge. Then augmenting paths made of tight edges only, found by depth-first searches
//      with lookahead in phases (each phase O(nnz), as in Pothen & Fan's MC21 variant);
//      such a path has length 0, so flipping it changes no dual. This matters for
//      matrices with many equal magnitudes, where Dijkstra would degenerate into one
//      breadth-first search per column.
//      With a start (an earlier matching of a matrix of the same order: a Newton loop's
//      last analysis), its row duals are taken instead, the column duals made feasible
//      by the column minimum, and its pairs that are tight under these duals matched
//      before the greedy pass; the steps below then match only what the start did not.
//   2. For every column still free, a shortest augmenting path in the residual graph:
//      column j → row i along an unmatched edge costs r_ij ≥ 0; row i → its matched column
//      costs r = 0. Dijkstra's algorithm with a binary heap of rows, from the free column
//      j0, stops as soon as the smallest tentative distance in the heap is not below the
//      best distance D found so far to a free row (free rows are never pushed: they end a
//      path). With d_i the distance of a row that was taken out of the heap ("finalized",
//      d_i ≤ D), the duals are updated by
//
//          u_i ← u_i + (d_i − D),  v_{m(i)} ← v_{m(i)} + (D − d_i)  (m(i): column matched
//          to row i), and v_{j0} ← v_{j0} + D,
//
//      which keeps r ≥ 0 on every edge (by the shortest-path inequalities d_i ≤ dist(j) +
//      r_ij) and makes every edge of the shortest path tight; the path is then flipped and
//      the matching grows by one. When it is perfect it is optimal by weak duality: any
//      perfect matching costs Σ c ≥ Σ u + Σ v, which ours attains.
//      If no free row is reachable, column j0 stays free for good: a vertex with no
//      augmenting path never gets one after later augmentations (Berge), so the final
//      matching has maximum cardinality. The rows that failed search reached can never be
//      on an augmenting path again either; they are retired so that later searches do not
//      walk them again (see retire_dead_set; this keeps singular inputs cheap).
//   3. The reduced cost of each matched edge is made exactly zero (v_j recomputed from
//      c_ij − u_i, a rounding-level change), unmatched columns are placed on unmatched rows
//      in increasing order, and the scaling is formed.
//
// Cost: each search is O(nnz log n) in the worst case, so O(n·nnz·log n) in all; in
// practice the greedy start matches most columns and the searches stop early. Measured
// (Release, one core): n = 1e5 with 1.1e6 random entries spread over 8 decades (a hard
// case: ~19% of columns need a search) ~3.5–4 s; a row-permuted 3D 7-point pattern with
// n = 97k, nnz = 670k and random magnitudes ~1 s; all magnitudes equal ~0.2 s.
// The scaling factors are exp of dual variables. Their exponents are clamped to ±700
// (factors in about [1e-304, 1e304]) so that they are always finite and nonzero: a column
// whose largest magnitude is subnormal (below 1/DBL_MAX ≈ 5.6e-309) would otherwise get
// the factor 1/a_j = inf, and entries spanning more than ~600 decades a factor that
// overflows. Such a matrix is then not fully equilibrated, which costs accuracy (reported
// through perturbed pivots and the backward error), never a NaN.
#include "ordering/matching.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "base/default_init.hpp"
#include "base/parallel_ranges.hpp"
#include "sparse/canonical.hpp"
#include "strata/errors.hpp"

namespace strata::ordering {
namespace {

constexpr index_t kNone = -1;
constexpr double kInf = std::numeric_limits<double>::infinity();
// Largest |log| of a scaling factor (see the header comment): exp(±700) ≈ 1e±304.
constexpr double kMaxLogScale = 700.0;

// The bipartite graph of the nonzeros of A in compressed-column form, with the costs c_ij.
// Without explicit zeros its columns are A's own (colptr and rowind point into A's
// arrays); otherwise they are copies without the zeros.
struct CostGraph {
  index_t n = 0;
  const index_t* colptr = nullptr;  // n+1
  const index_t* rowind = nullptr;  // row of each edge
  UninitVector<double> cost;        // c_ij of each edge
  std::vector<double> log_colmax;   // log a_j (0 for unmatchable columns)
  std::vector<char> matchable;      // a_j > 0
  std::vector<index_t> own_colptr;  // the copies, when A has explicit zeros
  UninitVector<index_t> own_rowind;
};

// Three passes in ranges of columns over the calling arena's threads (each column writes
// only its own entries), the same graph for any thread count: the edges per column; the
// magnitudes of the edges (copied without the explicit zeros when there are any) turned
// into their logarithms in place; per column log a_j = the largest of its logarithms
// (std::log is monotone, so this is log of the largest magnitude, bit for bit) and c_ij =
// log a_j − log|a_ij|. No array but the costs (and the copies) is made: on a large matrix
// the fresh memory's first touch costs as much as the arithmetic. The logarithm is libm's
// scalar one on purpose: the Newton matrices hold many entries of equal or related
// magnitudes, so optimal matchings tie, and a logarithm rounded differently (glibc's
// vector one, within 2 units in the last place) picks another of them, which on
// tracked:1000 left pivots the fixed order could not take.
CostGraph build_cost_graph(const SparseMatrix& full) {
  CostGraph g;
  const index_t n = full.n_cols;
  const index_t* co = full.offsets.data();
  const bool vals = !full.values.empty();
  const double* a = full.values.data();
  g.n = n;
  g.log_colmax.assign(n, 0.0);
  g.matchable.assign(n, 0);
  std::vector<index_t>& edges_before = g.own_colptr;  // per column first, then summed
  edges_before.assign(n + 1, 0);
  detail::parallel_ranges(n, 512, [&](index_t j0, index_t j1) {
    for (index_t j = j0; j < j1; ++j) {
      index_t edges = co[j + 1] - co[j];
      if (vals)
        for (index_t p = co[j]; p < co[j + 1]; ++p) edges -= a[p] == 0.0;
      edges_before[j + 1] = edges;
    }
  });
  for (index_t j = 0; j < n; ++j) edges_before[j + 1] += edges_before[j];
  const bool zeros = edges_before[n] != co[n];
  g.cost.resize(edges_before[n]);
  double* cost = g.cost.data();
  if (zeros) {
    g.own_rowind.resize(edges_before[n]);
    g.colptr = g.own_colptr.data();
    g.rowind = g.own_rowind.data();
  } else {
    g.own_colptr = {};
    g.colptr = co;
    g.rowind = full.indices.data();
  }
  detail::parallel_ranges(n, 512, [&](index_t j0, index_t j1) {
    const index_t e0 = g.colptr[j0], e1 = g.colptr[j1];
    if (!vals) {
      std::fill(cost + e0, cost + e1, 0.0);  // every magnitude 1
      return;
    }
    if (zeros) {
      index_t out = e0;
      for (index_t p = co[j0]; p < co[j1]; ++p) {
        if (a[p] == 0.0) continue;
        g.own_rowind[out] = full.indices[p];
        cost[out++] = a[p];
      }
    }
    const double* from = zeros ? cost : a;
    for (index_t p = e0; p < e1; ++p) cost[p] = std::log(std::abs(from[p]));
  });
  detail::parallel_ranges(n, 512, [&](index_t j0, index_t j1) {
    for (index_t j = j0; j < j1; ++j) {
      const index_t e0 = g.colptr[j], e1 = g.colptr[j + 1];
      if (e0 == e1) continue;  // no entry, or only explicit zeros: a_j = 0
      const double lmax = *std::max_element(cost + e0, cost + e1);
      g.log_colmax[j] = lmax;
      g.matchable[j] = 1;
      for (index_t p = e0; p < e1; ++p) cost[p] = std::max(0.0, lmax - cost[p]);
    }
  });
  return g;
}

// Per-row state touched on every edge relaxation, packed so that a relaxation costs one
// cache line. `slot` is the row's position in the Dijkstra heap (>= 0) or one of kOut,
// kFinalized (taken out of the heap in the current search), kDead (see retire_dead_set).
constexpr index_t kOut = -1, kFinalized = -2, kDead = -3;
struct RowState {
  double u = 0.0;       // dual variable (for a dead row: stored, see dead_shift_)
  double dist = kInf;   // Dijkstra: tentative distance in the current search
  index_t col = kNone;  // matched column, or kNone
  index_t slot = kOut;  // heap position or state
};

// Binary min-heap of (distance, row), with decrease-key through RowState::slot.
class RowHeap {
 public:
  explicit RowHeap(std::vector<RowState>& rows) : rows_(rows) {}
  bool empty() const { return heap_.empty(); }
  double top_key() const { return heap_.front().key; }

  // Inserts row i with key d, or lowers its key to d. Out of line: the searches' scans of
  // edges, which call it, keep their own variables in registers.
  [[gnu::noinline]] void push_or_decrease(index_t i, double d) {
    index_t at = rows_[i].slot;
    if (at < 0) {
      at = static_cast<index_t>(heap_.size());
      heap_.push_back({d, i});
    }
    sift_up(at, {d, i});
  }

  // Removes the row of smallest key; its slot is set to kOut.
  index_t pop() {
    const index_t i = heap_.front().row;
    rows_[i].slot = kOut;
    const Item last = heap_.back();
    heap_.pop_back();
    if (!heap_.empty()) sift_down(0, last);
    return i;
  }

  void clear() {
    for (const Item& it : heap_) rows_[it.row].slot = kOut;
    heap_.clear();
  }

 private:
  struct Item {
    double key;
    index_t row;
  };
  void place(index_t at, Item it) {
    heap_[at] = it;
    rows_[it.row].slot = at;
  }
  void sift_up(index_t at, Item it) {
    while (at > 0) {
      const index_t parent = (at - 1) / 2;
      if (heap_[parent].key <= it.key) break;
      place(at, heap_[parent]);
      at = parent;
    }
    place(at, it);
  }
  void sift_down(index_t at, Item it) {
    const index_t size = static_cast<index_t>(heap_.size());
    for (;;) {
      index_t child = 2 * at + 1;
      if (child >= size) break;
      if (child + 1 < size && heap_[child + 1].key < heap_[child].key) ++child;
      if (heap_[child].key >= it.key) break;
      place(at, heap_[child]);
      at = child;
    }
    place(at, it);
  }

  std::vector<Item> heap_;
  std::vector<RowState>& rows_;
};

class Matcher {
 public:
  explicit Matcher(const CostGraph& g)
      : g_(g),
        rows_(g.n),
        v_(g.n, 0.0),
        row_of_col_(g.n, kNone),
        edge_of_col_(g.n, kNone),
        col_dead_(g.n, 0),
        via_col_(g.n, kNone),
        via_edge_(g.n, kNone),
        heap_(rows_) {}

  void run(const Matching* start) {
    if (start)
      start_from(*start);
    else
      initial_duals();
    greedy_tight_matching();
    tight_augmentations();
    for (index_t j = 0; j < g_.n; ++j)
      if (g_.matchable[j] && row_of_col_[j] == kNone) shortest_augmenting_path(j);
    finish_duals();
  }

  Matching result() const {
    const index_t n = g_.n;
    Matching m;
    m.column_permutation.assign(n, kNone);
    m.row_scaling.resize(n);
    m.column_scaling.resize(n);
    for (index_t i = 0; i < n; ++i) {
      m.column_permutation[i] = rows_[i].col;
      if (rows_[i].col != kNone)
        ++m.n_matched;
      else if (m.first_unmatched_row < 0)
        m.first_unmatched_row = i;
      m.row_scaling[i] = std::exp(std::clamp(rows_[i].u, -kMaxLogScale, kMaxLogScale));
    }
    for (index_t j = 0; j < n; ++j)
      m.column_scaling[j] =
          g_.matchable[j]
              ? std::exp(std::clamp(v_[j] - g_.log_colmax[j], -kMaxLogScale, kMaxLogScale))
              : 1.0;
    m.structurally_singular = m.n_matched < n;
    if (m.structurally_singular) {
      // Complete into a permutation: unmatched columns, in increasing order, onto the
      // unmatched rows, in increasing order.
      index_t next_col = 0;
      for (index_t i = 0; i < n; ++i) {
        if (m.column_permutation[i] != kNone) continue;
        while (row_of_col_[next_col] != kNone) ++next_col;
        m.column_permutation[i] = next_col++;
      }
    }
    return m;
  }

 private:
  // r_ij of edge p = (i, j) given u_i, always evaluated in this order so that the value
  // that defined a minimum gives exactly zero.
  double reduced(index_t p, double ui, index_t j) const { return (g_.cost[p] - ui) - v_[j]; }

  void match(index_t i, index_t j, index_t p) {
    rows_[i].col = j;
    row_of_col_[j] = i;
    edge_of_col_[j] = p;
  }

  // u_i = min_j c_ij; v_j = min_i (c_ij − u_i). Rows without an edge keep u_i = 0.
  void initial_duals() {
    std::vector<double> rowmin(g_.n, kInf);
    for (index_t p = 0; p < g_.colptr[g_.n]; ++p)
      rowmin[g_.rowind[p]] = std::min(rowmin[g_.rowind[p]], g_.cost[p]);
    for (index_t i = 0; i < g_.n; ++i) rows_[i].u = rowmin[i] < kInf ? rowmin[i] : 0.0;
    for (index_t j = 0; j < g_.n; ++j) {
      double vmin = kInf;
      for (index_t p = g_.colptr[j]; p < g_.colptr[j + 1]; ++p)
        vmin = std::min(vmin, g_.cost[p] - rows_[g_.rowind[p]].u);
      v_[j] = vmin < kInf ? vmin : 0.0;
    }
  }

  // A start from an earlier matching: its row duals u_i = log(row scaling), the column
  // duals v_j = min_i (c_ij − u_i) (so r ≥ 0 on every edge, and r = 0 on the edge that
  // defined the minimum), and each of its pairs (i, j) that is an edge, tight, and whose
  // column is still free, matched. Rows without an edge are left free.
  void start_from(const Matching& m) {
    for (index_t i = 0; i < g_.n; ++i) rows_[i].u = std::log(m.row_scaling[i]);
    for (index_t j = 0; j < g_.n; ++j) {
      double vmin = kInf;
      for (index_t p = g_.colptr[j]; p < g_.colptr[j + 1]; ++p)
        vmin = std::min(vmin, g_.cost[p] - rows_[g_.rowind[p]].u);
      v_[j] = vmin < kInf ? vmin : 0.0;
    }
    for (index_t i = 0; i < g_.n; ++i) {
      const index_t j = m.column_permutation[i];
      if (!g_.matchable[j] || row_of_col_[j] != kNone) continue;
      const index_t* b = g_.rowind + g_.colptr[j];
      const index_t* e = g_.rowind + g_.colptr[j + 1];
      const index_t* f = std::lower_bound(b, e, i);  // a canonical column: rows sorted
      if (f == e || *f != i) continue;
      const index_t p = f - g_.rowind;
      if (reduced(p, rows_[i].u, j) <= 0.0) match(i, j, p);
    }
  }

  // A free tight row for each column still free, in turn (the paper's cheap initial
  // matching).
  void greedy_tight_matching() {
    for (index_t j = 0; j < g_.n; ++j)
      if (row_of_col_[j] == kNone)
        for (index_t p = g_.colptr[j]; p < g_.colptr[j + 1]; ++p) {
          const index_t i = g_.rowind[p];
          if (rows_[i].col == kNone && reduced(p, rows_[i].u, j) <= 0.0) {
            match(i, j, p);
            break;
          }
        }
  }

  // Grows the matching by augmenting paths made of tight edges (r = 0) only: depth-first
  // searches with lookahead, in phases in which each row is visited at most once, so that
  // a phase costs O(nnz) (Pothen & Fan's MC21-with-lookahead scheme). A path of tight
  // edges is a shortest augmenting path of length 0, so flipping it keeps the duals
  // optimal and changes none of them. Phases are repeated until one finds no path.
  // Rows never become free here and the duals do not move, so each column's lookahead
  // pointer (scanning for a free tight row) only moves forward over all phases.
  void tight_augmentations() {
    const index_t n = g_.n;
    std::vector<index_t> look(g_.colptr, g_.colptr + n);
    std::vector<index_t> iter(n), visited(n, -1);
    std::vector<index_t> stack, edge_in;  // columns; edge_in[k]: edge from stack[k-1]
    for (index_t phase = 0;; ++phase) {
      std::copy(g_.colptr, g_.colptr + n, iter.begin());
      index_t augmented = 0;
      for (index_t j0 = 0; j0 < n; ++j0) {
        if (!g_.matchable[j0] || row_of_col_[j0] != kNone) continue;
        stack.assign(1, j0);
        edge_in.assign(1, kNone);
        while (!stack.empty()) {
          const index_t c = stack.back();
          const index_t end = g_.colptr[c + 1];
          index_t q = look[c];
          while (q < end &&
                 !(rows_[g_.rowind[q]].col == kNone && reduced(q, rows_[g_.rowind[q]].u, c) <= 0.0))
            ++q;
          look[c] = q;
          if (q < end) {  // free tight row: flip the path held by the stack
            look[c] = q + 1;
            for (index_t k = static_cast<index_t>(stack.size()) - 1; k >= 0; --k) {
              const index_t next = edge_in[k];  // into the row stack[k] held before
              match(g_.rowind[q], stack[k], q);
              q = next;
            }
            ++augmented;
            break;
          }
          index_t& p = iter[c];
          while (p < end) {
            const index_t i = g_.rowind[p];
            if (visited[i] != phase && reduced(p, rows_[i].u, c) <= 0.0) break;
            ++p;
          }
          if (p == end) {
            stack.pop_back();
            edge_in.pop_back();
            continue;
          }
          const index_t i = g_.rowind[p];
          visited[i] = phase;  // i is matched: its free tight edges were taken by look
          stack.push_back(rows_[i].col);
          edge_in.push_back(p);
          ++p;
        }
      }
      if (augmented == 0) break;
    }
  }

  // Dijkstra from the free column j0 (see the header comment); augments and updates the
  // duals when a free row is reachable, retires the rows it reached when none is.
  void shortest_augmenting_path(index_t j0) {
    double best = kInf;  // D: shortest distance found so far to a free row
    index_t best_row = kNone;
    double dead_min = kInf;  // shortest distance found to a dead row (see retire_dead_set)
    index_t j = j0;
    double dj = 0.0;
    // the arrays the scans read, in locals: the heap's updates (out of line) would otherwise
    // make the compiler reload them, and the loop's own variables, at every edge
    const index_t* const colptr = g_.colptr;
    const index_t* const rowind = g_.rowind;
    const double* const cost = g_.cost.data();
    RowState* const rows = rows_.data();
    index_t* const via_col = via_col_.data();
    index_t* const via_edge = via_edge_.data();
    const double shift = dead_shift_;
    for (;;) {
      const double vj = v_[j];  // r_ij = (c_ij − u_i) − v_j, as reduced() evaluates it
      const index_t end = colptr[j + 1];
      for (index_t p = colptr[j]; p < end; ++p) {
        const index_t i = rowind[p];
        RowState& r = rows[i];
        const index_t slot = r.slot;
        if (slot == kFinalized) continue;
        if (slot == kDead) {
          dead_min = std::min(dead_min, dj + ((cost[p] - (r.u - shift)) - vj));
          continue;
        }
        const double nd = dj + std::max(0.0, (cost[p] - r.u) - vj);
        if (nd >= best || nd >= r.dist) continue;
        if (r.dist == kInf) touched_.push_back(i);
        r.dist = nd;
        via_col[i] = j;
        via_edge[i] = p;
        if (r.col == kNone) {
          best = nd;
          best_row = i;
        } else {
          heap_.push_or_decrease(i, nd);
        }
      }
      if (heap_.empty() || heap_.top_key() >= best) break;
      const index_t i = heap_.pop();
      rows_[i].slot = kFinalized;
      done_.push_back(i);
      j = rows_[i].col;
      dj = rows_[i].dist;
    }
    heap_.clear();

    if (best_row == kNone) {
      retire_dead_set(j0);
    } else {
      // Dual update, before the path is flipped (it needs the old matched columns).
      // Every finalized row has d_i <= D.
      for (index_t i : done_) {
        rows_[i].u += rows_[i].dist - best;
        v_[rows_[i].col] += best - rows_[i].dist;
      }
      v_[j0] += best;
      // The live columns scanned had their v_j raised by at most D - (their distance); an
      // edge from such a column into a dead row keeps r >= 0 if the dead set moves away
      // by D - dead_min.
      if (dead_min < best) dead_shift_ += best - dead_min;
      // Flip the path: each row on it takes the column it was reached from.
      for (index_t i = best_row;;) {
        const index_t jc = via_col_[i];
        const index_t next = row_of_col_[jc];
        match(i, jc, via_edge_[i]);
        if (jc == j0) break;
        i = next;
      }
    }
    for (index_t i : touched_) {
      rows_[i].dist = kInf;
      if (rows_[i].slot == kFinalized) rows_[i].slot = kOut;
    }
    touched_.clear();
    done_.clear();
  }

  // A search from j0 that found no free row reached the rows R = done_ (all matched) and
  // the columns C = {j0} ∪ m(R); every edge of a column of C ends in R or in an earlier
  // dead set. No augmenting path can ever enter R (from R it could only go on to C and back
  // to R, all matched), so these rows and columns are retired for good: later searches do
  // not expand them. To keep the duals feasible on edges from live columns into dead rows,
  // the whole dead set is moved by one global shift Δ (dead_shift_): the true duals are
  // u_i − Δ for dead rows and v_j + Δ for dead columns, which leaves r unchanged inside the
  // dead set (its columns have no edge to live rows) and only increases r on edges from
  // live columns. Values stored now are offset so the true duals do not change.
  void retire_dead_set(index_t j0) {
    for (index_t i : done_) {
      rows_[i].slot = kDead;
      rows_[i].u += dead_shift_;
      v_[rows_[i].col] -= dead_shift_;
      col_dead_[rows_[i].col] = 1;
    }
    v_[j0] -= dead_shift_;
    col_dead_[j0] = 1;
  }

  // Converts the dead set to true duals, then removes the rounding drift of the dual
  // updates on the matched edges: r_ij = 0 exactly.
  void finish_duals() {
    for (index_t i = 0; i < g_.n; ++i)
      if (rows_[i].slot == kDead) rows_[i].u -= dead_shift_;
    for (index_t j = 0; j < g_.n; ++j)
      if (col_dead_[j]) v_[j] += dead_shift_;
    for (index_t j = 0; j < g_.n; ++j) {
      const index_t p = edge_of_col_[j];
      if (p != kNone) v_[j] = g_.cost[p] - rows_[row_of_col_[j]].u;
    }
  }

  const CostGraph& g_;
  std::vector<RowState> rows_;
  std::vector<double> v_;                // column duals (for a dead column: stored)
  std::vector<index_t> row_of_col_;      // matched row of each column, or kNone
  std::vector<index_t> edge_of_col_;     // edge of the matched pair, by column
  std::vector<char> col_dead_;           // column retired by a failed search
  double dead_shift_ = 0.0;              // Δ, see retire_dead_set
  std::vector<index_t> via_col_;         // Dijkstra: column a row was reached from
  std::vector<index_t> via_edge_;        // Dijkstra: and by which edge
  std::vector<index_t> touched_, done_;  // rows to reset; finalized rows
  RowHeap heap_;
};

}  // namespace

Matching maximum_product_matching(const SparseMatrix& a) {
  if (a.n_rows != a.n_cols)
    throw InvalidInput("maximum_product_matching: matrix is " + std::to_string(a.n_rows) + "x" +
                       std::to_string(a.n_cols) + ", not square");
  // canonical CSC, both triangles: the input itself when it is so already
  const bool as_is = detail::is_canonical_full(a);
  SparseMatrix expanded;
  if (!as_is) expanded = expand_symmetric(a);
  return maximum_product_matching_canonical(as_is ? a : expanded);
}

Matching maximum_product_matching_canonical(const SparseMatrix& a, const Matching* start) {
  const CostGraph g = build_cost_graph(a);
  Matcher matcher(g);
  matcher.run(start);
  return matcher.result();
}

}  // namespace strata::ordering
