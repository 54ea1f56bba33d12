// strata — symmetric matching-based scaling and 2×2 pairing (see pairing.hpp).
//
// Why. LDLᵀ with Bunch–Kaufman pivoting restricted to a front's fully summed block cannot
// use a 2×2 pivot whose two columns sit in different fronts. In a KKT matrix
// [[H, Bᵀ], [B, 0]] a constraint unknown has a zero diagonal: when the ordering eliminates
// it alone, or first in a front with none of its coupled unknowns, its pivot is (near)
// zero and static pivoting has to replace it by ±ε‖A‖, which costs accuracy (and makes
// the inertia wrong). Duff & Pralet's remedy: find, from a maximum product matching of
// the whole matrix, pairs of unknowns (i, j) with a large a_ij to serve as 2×2 pivots,
// and make the ordering and the symbolic phase keep each useful pair together, so that
// Bunch–Kaufman finds the 2×2 pivot inside one fully summed block.
//
// Source. I. S. Duff and S. Pralet, "Strategies for scaling and pivoting for sparse
// symmetric indefinite problems", SIAM J. Matrix Anal. Appl. 27(2):313–340, 2005 (the
// symmetric scaling from the unsymmetric maximum product matching, the decomposition of
// the matching into cycles and pairs, and the compressed-graph ordering); the same
// strategy is MUMPS's ICNTL(12) and PARDISO's IPARM(13). Written from the paper's
// description, not from either code.
//
// 1. Scaling. maximum_product_matching (MC64 job 5, matching.cpp) gives a column
//    permutation σ (row i is matched to column σ(i)) and Dr, Dc with |(Dr A Dc)_ij| ≤ 1,
//    = 1 on the matched entries. For symmetric A the symmetric scaling D = sqrt(Dr·Dc)
//    keeps both properties: |d_i a_ij d_j| = sqrt(|(DrADc)_ij|·|(DrADc)_ji|) ≤ 1, and for
//    a perfect matching the matched entries stay exactly 1 — writing e_i = log of the
//    second factor at the matched entry (i, σ(i)), each e_i ≤ 0 and Σ e_i = Σ log|a_iσ(i)|
//    + Σ log dr_i + Σ log dc_i = 0 (the matched entries of DrADc are 1), so every e_i = 0.
//
// 2. Cycles and pairs. σ decomposes into cycles. A 1-cycle (i) is a singleton (a_ii is
//    matched: a good 1×1 pivot). A 2-cycle (i, j) is a pair. A cycle (c_0 → c_1 → … →
//    c_{k−1} → c_0) of length k ≥ 3 is split into ⌊k/2⌋ pairs of consecutive members plus,
//    for odd k, one singleton: an even cycle has two splittings, an odd one k (one per
//    choice of the singleton). The paper keeps the splitting with the largest product of
//    the pairs' off-diagonal magnitudes; we compare the products of the SCALED entries.
//    With an optimal matching and its scaling every cycle edge has magnitude 1, so the
//    products tie up to rounding (an even cycle's two splittings are two halves of an
//    optimal matching); ties (relative 1e-8 in the log) are broken by the number of useful
//    pairs (below), then, for odd cycles, by the larger |diagonal| of the singleton (a 1×1
//    pivot should be large), then by the first candidate. Members of a pair must be
//    coupled by an entry: a cycle through the arbitrary completion of a structurally
//    singular matching may contain non-entries; splittings with fewer such pairs are
//    preferred and such pairs are dropped.
//
// 2b. Odd cycles kept whole (our addition; the paper leaves an odd cycle's singleton
//    alone). When even the best singleton of an odd cycle has a small scaled diagonal, it
//    is exactly the unknown static pivoting would have to perturb if it were eliminated
//    on its own, and joining it to one neighbouring pair does not help in general: with
//    zero diagonals, any 3 consecutive members of a longer cycle form the singular block
//    [[0 a 0]; [a 0 b]; [0 b 0]]. The whole cycle does: the weighted adjacency matrix of
//    an odd cycle has determinant 2·Π(edges) ≠ 0 (the two rotations are the only
//    permutations along its edges), so a zero-diagonal odd cycle is a nonsingular block.
//    Such a cycle of length k ≤ kMaxCycleGroup (a 3-cycle [[0 a b]; [a 0 c]; [b c 0]]
//    above all) is therefore kept as one group, listed in cycle order from the singleton
//    on, so that each member is coupled to the next by a matched entry (which the
//    symbolic phase needs); Bunch–Kaufman then pivots within it in one front. Longer ones
//    are split as above (a group is a dense block of one front, and such cycles were not
//    seen in practice).
//
// 3. Useful pairs only. A pair whose two scaled diagonal entries are both large gives two
//    good 1×1 pivots on its own, and constraining the ordering for it only costs fill, so
//    a pair is kept only when min(|d_i a_ii d_i|, |d_j a_jj d_j|) < threshold
//    (Options::pairing_threshold, default 0.01; a structurally zero diagonal counts as 0).
//    The paper uses the same kind of test on the scaled diagonal; 0.01 is our choice: the
//    matched off-diagonal of a pair has magnitude 1 after scaling, so a 1×1 pivot below
//    0.01 would grow entries by more than 100, which Bunch–Kaufman (α ≈ 0.64) would refuse
//    in favour of the 2×2 pivot anyway.
//
// 4. Order inside a pair: the member with the smaller scaled |diagonal| first (ties: the
//    smaller index). In the postordered elimination the first member i is then a child of
//    the second (a_{i+1,i} ≠ 0 makes i+1 the etree parent of i), and Bunch–Kaufman meets
//    the small diagonal first, with its partner still in the fully summed block: it takes
//    the 2×2 pivot, or interchanges and takes the partner's large diagonal as a 1×1 pivot,
//    after which the small one is updated to −b²/a (scaled |b| = 1 ≥ |a|, so not small).
//    The other order would also be safe inside one front; this one never leaves the small
//    diagonal as the pivot BK is forced to take last.
#include "ordering/pairing.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "ordering/matching.hpp"
#include "strata/errors.hpp"

namespace strata::ordering {
namespace {

// Longest odd cycle kept whole when its best singleton has a small diagonal (step 2b).
constexpr std::size_t kMaxCycleGroup = 64;

// |a_ij| from a full canonical CSC (sorted rows): binary search in column j; 0 if absent.
double abs_entry(const SparseMatrix& full, index_t i, index_t j) {
  const index_t* b = full.indices.data() + full.offsets[j];
  const index_t* e = full.indices.data() + full.offsets[j + 1];
  const index_t* it = std::lower_bound(b, e, i);
  if (it == e || *it != i) return 0.0;
  return std::abs(full.values[it - full.indices.data()]);
}

// Score of one way of splitting a cycle into pairs (and a singleton).
struct Score {
  index_t missing = 0;     // pairs not coupled by an entry
  double log_product = 0;  // Σ log (scaled |a_ij|) over the coupled pairs
  index_t useful = 0;      // coupled pairs with a small diagonal
  double singleton_diag = std::numeric_limits<double>::infinity();  // odd cycles
};

// True when split a is strictly better than b (see the file header, step 2).
bool better(const Score& a, const Score& b, std::size_t k) {
  if (a.missing != b.missing) return a.missing < b.missing;
  const double tol = 1e-8 * static_cast<double>(k);
  if (std::abs(a.log_product - b.log_product) > tol) return a.log_product > b.log_product;
  if (a.useful != b.useful) return a.useful > b.useful;
  return a.singleton_diag > b.singleton_diag;
}

// Sums over every other edge of a cycle, in O(1) per query after O(k) set-up, so that
// choosing among the k splittings of an odd cycle costs O(k), not O(k²). Edge t joins
// members t and t+1 (mod k); the edges are laid out twice (t < 2k) so that a run of
// alternate edges never wraps, and S[t] = value[t] + S[t−2].
class AlternateSums {
 public:
  template <class Value>
  AlternateSums(std::size_t k, const Value& value) : s_(2 * k) {
    for (std::size_t t = 0; t < 2 * k; ++t) s_[t] = value(t % k) + (t >= 2 ? s_[t - 2] : 0.0);
  }
  // value[a] + value[a+2] + ... (m terms), a + 2(m−1) < 2k.
  double sum(std::size_t a, std::size_t m) const {
    if (m == 0) return 0.0;
    return s_[a + 2 * (m - 1)] - (a >= 2 ? s_[a - 2] : 0.0);
  }

 private:
  std::vector<double> s_;
};

}  // namespace

SymmetricPairing symmetric_matching_pairing(const SparseMatrix& a, double threshold) {
  if (a.n_rows != a.n_cols)
    throw InvalidInput("symmetric_matching_pairing: matrix is " + std::to_string(a.n_rows) + "x" +
                       std::to_string(a.n_cols) + ", not square");
  const index_t n = a.n_cols;
  const SparseMatrix full = expand_symmetric(a);  // canonical CSC, both triangles
  if (full.values.empty() && full.nnz() > 0)
    throw InvalidInput("symmetric_matching_pairing: the matrix has no values");
  SymmetricPairing r;
  const Matching m = maximum_product_matching_canonical(full);
  r.structurally_singular = m.structurally_singular;
  r.first_unmatched_row = m.first_unmatched_row;
  r.matching = m.column_permutation;
  r.scaling.resize(n);
  for (index_t i = 0; i < n; ++i) {
    const double d = std::sqrt(m.row_scaling[i] * m.column_scaling[i]);
    r.scaling[i] = (std::isfinite(d) && d > 0) ? d : 1.0;  // overflow guard (see matching.cpp)
  }
  auto scaled = [&](index_t i, index_t j) {
    return abs_entry(full, i, j) * r.scaling[i] * r.scaling[j];
  };
  r.scaled_diagonal.resize(n);
  for (index_t i = 0; i < n; ++i) r.scaled_diagonal[i] = scaled(i, i);
  const std::vector<double>& sd = r.scaled_diagonal;
  auto small = [&](index_t i) { return sd[i] < threshold; };
  auto add_pair = [&](index_t u, index_t v) {  // the smaller diagonal first (step 4)
    if (!(sd[u] < sd[v] || (sd[u] == sd[v] && u < v))) std::swap(u, v);
    r.groups.members.push_back(u);
    r.groups.members.push_back(v);
    r.groups.ptr.push_back(static_cast<index_t>(r.groups.members.size()));
  };

  std::vector<char> seen(n, 0);
  std::vector<index_t> cycle;
  std::vector<double> w;  // w[t]: scaled |a| of edge t, joining cycle[t] and cycle[t+1]
  for (index_t i0 = 0; i0 < n; ++i0) {
    if (seen[i0]) continue;
    cycle.clear();
    for (index_t i = i0; !seen[i]; i = r.matching[i]) {
      seen[i] = 1;
      cycle.push_back(i);
    }
    const std::size_t k = cycle.size();
    if (k < 2) continue;
    if (k == 2) {  // a 2-cycle: matched both ways, so coupled
      if (small(cycle[0]) || small(cycle[1])) add_pair(cycle[0], cycle[1]);
      continue;
    }
    w.resize(k);
    for (std::size_t t = 0; t < k; ++t) w[t] = scaled(cycle[t], cycle[(t + 1) % k]);
    const AlternateSums missing(k, [&](std::size_t t) { return w[t] == 0.0 ? 1.0 : 0.0; });
    const AlternateSums logw(k, [&](std::size_t t) { return w[t] > 0.0 ? std::log(w[t]) : 0.0; });
    const AlternateSums useful(k, [&](std::size_t t) {
      return w[t] > 0.0 && (small(cycle[t]) || small(cycle[(t + 1) % k])) ? 1.0 : 0.0;
    });
    // Splitting at offset s: for odd k, cycle[s] is the singleton and the pairs are the
    // edges s+1, s+3, ..., s+k−2; for even k the pairs are the edges s, s+2, ..., s+k−2.
    const bool odd = k % 2 == 1;
    const std::size_t npairs = k / 2;
    auto score = [&](std::size_t s) {
      const std::size_t first_edge = odd ? s + 1 : s;
      Score sc;
      sc.missing = static_cast<index_t>(std::lround(missing.sum(first_edge, npairs)));
      sc.log_product = logw.sum(first_edge, npairs);
      sc.useful = static_cast<index_t>(std::lround(useful.sum(first_edge, npairs)));
      if (odd) sc.singleton_diag = sd[cycle[s]];
      return sc;
    };
    std::size_t best = 0;
    Score best_score = score(0);
    for (std::size_t s = 1; s < (odd ? k : 2); ++s) {
      const Score sc = score(s);
      if (better(sc, best_score, k)) best = s, best_score = sc;
    }
    // An odd cycle whose best singleton is small is kept whole (step 2b).
    if (odd && small(cycle[best]) && k <= kMaxCycleGroup &&
        std::find(w.begin(), w.end(), 0.0) == w.end()) {
      for (std::size_t t = 0; t < k; ++t) r.groups.members.push_back(cycle[(best + t) % k]);
      r.groups.ptr.push_back(static_cast<index_t>(r.groups.members.size()));
      continue;
    }
    for (std::size_t p = 0; p < npairs; ++p) {
      const std::size_t t = ((odd ? best + 1 : best) + 2 * p) % k;  // the pair's edge
      const index_t u = cycle[t], v = cycle[(t + 1) % k];
      if (w[t] == 0.0) continue;             // not coupled: no pair
      if (!small(u) && !small(v)) continue;  // two good 1×1 pivots: not worth a constraint
      add_pair(u, v);
    }
  }
  return r;
}

VertexGroups complete_groups(index_t n, const VertexGroups& multi) {
  std::vector<index_t> group_of(n, -1);
  for (index_t g = 0; g < multi.n_groups(); ++g)
    for (index_t p = multi.ptr[g]; p < multi.ptr[g + 1]; ++p) {
      const index_t v = multi.members[p];
      if (v < 0 || v >= n || group_of[v] != -1)
        throw InvalidInput("complete_groups: a vertex is out of range or in two groups");
      group_of[v] = g;
    }
  VertexGroups out;
  out.members.reserve(n);
  out.ptr.reserve(n + 1);
  std::vector<char> done(multi.n_groups(), 0);
  for (index_t v = 0; v < n; ++v) {
    const index_t g = group_of[v];
    if (g == -1) {
      out.members.push_back(v);
    } else {
      if (done[g]) continue;  // made at its smallest member
      done[g] = 1;
      for (index_t p = multi.ptr[g]; p < multi.ptr[g + 1]; ++p)
        out.members.push_back(multi.members[p]);
    }
    out.ptr.push_back(static_cast<index_t>(out.members.size()));
  }
  return out;
}

Graph quotient_graph(const Graph& g, const VertexGroups& groups) {
  const index_t ng = groups.n_groups();
  std::vector<index_t> group_of(g.n, -1);
  for (index_t q = 0; q < ng; ++q)
    for (index_t p = groups.ptr[q]; p < groups.ptr[q + 1]; ++p) group_of[groups.members[p]] = q;
  Graph out;
  out.n = ng;
  out.xadj.assign(ng + 1, 0);
  std::vector<index_t> mark(ng, -1);
  for (index_t q = 0; q < ng; ++q) {
    mark[q] = q;
    const std::size_t begin = out.adjncy.size();
    for (index_t p = groups.ptr[q]; p < groups.ptr[q + 1]; ++p) {
      const index_t v = groups.members[p];
      for (index_t e = g.xadj[v]; e < g.xadj[v + 1]; ++e) {
        const index_t h = group_of[g.adjncy[e]];
        if (mark[h] == q) continue;
        mark[h] = q;
        out.adjncy.push_back(h);
      }
    }
    std::sort(out.adjncy.begin() + static_cast<std::ptrdiff_t>(begin), out.adjncy.end());
    out.xadj[q + 1] = static_cast<index_t>(out.adjncy.size());
  }
  return out;
}

OrderingResult compute_grouped_ordering(const Graph& g, const VertexGroups& groups,
                                        const Options& opts, int workers) {
  if (groups.ptr.back() != g.n)
    throw InvalidInput("compute_grouped_ordering: the groups hold " +
                       std::to_string(groups.ptr.back()) + " vertices, the graph has " +
                       std::to_string(g.n));
  if (opts.ordering == OrderingMethod::natural || opts.ordering == OrderingMethod::user)
    return compute_ordering(g, opts, workers);
  const Graph q = quotient_graph(g, groups);
  OrderingResult r;
  r.method = opts.ordering;
  std::vector<index_t> qperm;
  if (opts.ordering == OrderingMethod::automatic && workers == 1) {
    // CHOLMOD's rule (amd_is_good_enough) on the graph of the groups
    AmdCounts counts;
    qperm = amd_ordering(q, &counts);
    r.method =
        amd_is_good_enough(counts, q) ? OrderingMethod::amd : OrderingMethod::nested_dissection;
  }
  // nested dissection asked for, chosen by the rule, or automatic with several workers
  // (their split needs the separator tree)
  if (r.method == OrderingMethod::nested_dissection || r.method == OrderingMethod::automatic)
    return nested_dissection(q, nd_options(opts, workers), groups);
  if (opts.ordering == OrderingMethod::metis) {
    std::vector<index_t> w(q.n);
    for (index_t v = 0; v < q.n; ++v) w[v] = groups.size(v);
    qperm = metis_ordering(q, w);
  } else if (qperm.empty()) {
    qperm = amd_ordering(q);
  }
  r.perm.reserve(g.n);
  for (const index_t v : qperm)
    for (index_t p = groups.ptr[v]; p < groups.ptr[v + 1]; ++p) r.perm.push_back(groups.members[p]);
  return r;
}

}  // namespace strata::ordering
