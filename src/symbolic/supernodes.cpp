// strata — the assembly tree: fundamental supernodes, relaxed amalgamation, separator
// blocking and the row structures of the fronts; analyze_pattern drives the whole
// symbolic phase (see symbolic.hpp).
//
// Sources:
//  * Fundamental supernodes: Liu, Ng & Peyton, "On finding supernodes for sparse matrix
//    computations", SIAM J. Matrix Anal. Appl. 14(1), 1993. In a postordered etree,
//    column j+1 continues the supernode of column j when j is the only child of j+1 and
//    colcount[j] = colcount[j+1] + 1.
//  * Relaxed amalgamation: Ashcraft & Grimes, "The influence of relaxed supernode
//    partitions on the multifrontal method", ACM TOMS 15(4), 1989, with the rule CHOLMOD
//    uses (Chen, Davis, Hager & Rajamanickam, ACM TOMS 35(3), 2008, the nrelax/zrelax
//    parameters): supernodes are visited from the last to the first; supernode s is
//    merged into its current parent only when that parent starts at s+1 (s is its last
//    child), which keeps the pivot columns of every front contiguous in the postorder.
//    The merged front has ns pivots and is stored as a lower trapezoid of
//    ns(ns+1)/2 + ns·(rows below the pivots) entries; merging adds to each of s's columns
//    the rows of the parent it does not have. They merge when ns <= relax_small, or when
//    the fraction z of explicit zeros in the merged trapezoid is below relax_zeros_1 if
//    ns <= relax_size_1, below relax_zeros_2 if ns <= relax_size_2, below relax_zeros_3
//    otherwise (with decreasing thresholds, as the defaults are, this is CHOLMOD's
//    rule). Two details follow CHOLMOD (cholmod_super_symbolic) exactly: a merge that
//    adds no explicit zeros is always made, and the zeros added by a merge accepted for
//    its size alone (ns <= relax_small) are not counted in the zero fractions of later
//    merges. With the same parameters the fronts are then exactly CHOLMOD's relaxed
//    supernodes (the tests check this). relax_small <= 1 with zero thresholds gives
//    fronts without amalgamation zeros: the fundamental supernodes, plus last children
//    that fit their parent exactly.
//  * Separator blocking (Jung & Bae 2018, "separators divided into smaller blocks"): a
//    front with more than max_block_size pivots becomes a chain of fronts: pieces of
//    exactly max_block_size pivots from the bottom up, the remainder on top; each piece's
//    parent is the next piece, the top piece keeps the front's parent.
//  * Kept pairs (AmalgamationOptions::keep_with_next, for the 2×2 pivots of symmetric
//    indefinite matrices; Duff & Pralet 2005): a flagged column j of the postordered tree
//    has j+1 as its etree parent (checked), so it is the last column of some supernode s
//    and j+1 the first of s+1, s is the last child of s+1, and merging s into s+1 is an
//    ordinary relaxed amalgamation (s+1's rows are added to s's columns as explicit
//    zeros). Relaxed amalgamation makes that merge unconditionally (its zeros count in
//    the fractions of later merges), and separator blocking moves a piece boundary that
//    would fall between j and j+1 down below the chain of flagged columns it cuts (up
//    past it, making a piece longer than max_block_size, when that would leave the piece
//    empty).
//  * Row structures: the rows of a front are its pivots, then every row i beyond them
//    whose row subtree passes through the front. They are found by walking, for every
//    original entry A(i, j), j < i, from the front of j up the assembly tree to the front
//    of i, stopping at a front already marked for row i (the row-subtree traversal of
//    Liu 1990 / Davis 2006 §4.2 on the contracted tree). Rows are visited in increasing
//    order (in consecutive ranges side by side, each range's rows placed after the
//    previous range's), so every front's list comes out sorted, and the work is
//    O(nnz(A) + Σ rows): linear in the input plus the output. This is exactly the symbolic union of
//    the children's contribution-block rows and the front's original entries.
//  * analyze_permuted_graph runs the same phase on P A Pᵀ gathered column by column from
//    the ordering's graph, its rows left unsorted (no bucket sort): none of the passes
//    needs a column's rows in order (symbolic/pattern_view.hpp).
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cstdint>
#include <string>

#include "base/default_init.hpp"
#include "base/serial_scope.hpp"
#include "strata/errors.hpp"
#include "symbolic/pattern_view.hpp"
#include "symbolic/symbolic.hpp"

namespace strata::symbolic {
namespace {

/// Supernodes as contiguous column ranges of the postordered tree.
struct Partition {
  std::vector<index_t> first;   ///< first column of each supernode, plus n at the end
  std::vector<index_t> parent;  ///< parent supernode, -1 for a root
};

index_t count(const Partition& p) { return static_cast<index_t>(p.first.size()) - 1; }

/// Maps each column to the supernode of `p` holding it.
std::vector<index_t> owner_of_columns(const Partition& p, index_t n) {
  std::vector<index_t> owner(n);
  for (index_t s = 0; s < count(p); ++s)
    for (index_t j = p.first[s]; j < p.first[s + 1]; ++j) owner[j] = s;
  return owner;
}

/// Fundamental supernodes of a postordered etree `parent` (parent[j] > j) with column
/// counts `cc`.
Partition fundamental_supernodes(const std::vector<index_t>& parent,
                                 const std::vector<index_t>& cc) {
  const index_t n = static_cast<index_t>(parent.size());
  std::vector<index_t> nchild(n, 0);
  for (index_t j = 0; j < n; ++j)
    if (parent[j] != -1) ++nchild[parent[j]];
  Partition p;
  for (index_t j = 0; j < n; ++j) {
    const bool continues = j > 0 && parent[j - 1] == j && nchild[j] == 1 && cc[j - 1] == cc[j] + 1;
    if (!continues) p.first.push_back(j);
  }
  p.first.push_back(n);
  const std::vector<index_t> owner = owner_of_columns(p, n);
  p.parent.resize(count(p));
  for (index_t s = 0; s < count(p); ++s) {
    const index_t top = p.first[s + 1] - 1;
    p.parent[s] = parent[top] == -1 ? -1 : owner[parent[top]];
  }
  return p;
}

/// Relaxed amalgamation of the supernodes `fs` (see the file header). `cc` are the
/// column counts of the postordered tree.
Partition relaxed_amalgamation(const Partition& fs, const std::vector<index_t>& cc,
                               const AmalgamationOptions& o, const std::vector<char>& keep,
                               index_t n) {
  const index_t ns_count = count(fs);
  std::vector<index_t> ncols(ns_count), nrows(ns_count), merged(ns_count, -1);
  std::vector<double> zeros(ns_count, 0.0);
  for (index_t s = 0; s < ns_count; ++s) {
    ncols[s] = fs.first[s + 1] - fs.first[s];
    nrows[s] = cc[fs.first[s]];  // rows of the leading column
  }
  // merged[x] = y: supernode x was absorbed into the group named y (y < x, the lowest
  // supernode of the group). Visited from the top, so a group grows downwards.
  for (index_t s = ns_count - 2; s >= 0; --s) {
    if (fs.parent[s] == -1) continue;
    index_t cur = fs.parent[s];
    while (merged[cur] != -1) cur = merged[cur];
    for (index_t t = fs.parent[s]; merged[t] != -1;) {  // path compression
      const index_t up = merged[t];
      merged[t] = cur;
      t = up;
    }
    if (cur != s + 1) continue;  // s is not the last child of its current parent

    const index_t ns = ncols[s] + ncols[s + 1];
    const double per_col_new = static_cast<double>(nrows[s + 1] + ncols[s] - nrows[s]);
    const double total_zeros = zeros[s + 1] + static_cast<double>(ncols[s]) * per_col_new;
    // Small merges are made unconditionally and, as in CHOLMOD, their zeros are not
    // counted in later fractions; a merge that adds no explicit zeros is always made.
    const bool small = ns <= o.relax_small;
    // a kept pair across the boundary (keep[top of s]) forces the merge
    const bool forced = !keep.empty() && keep[fs.first[s + 1] - 1];
    bool merge = small || per_col_new == 0 || forced;
    if (!merge) {
      const double xns = static_cast<double>(ns);
      const double size =
          xns * (xns + 1) / 2 + xns * static_cast<double>(nrows[s + 1] - ncols[s + 1]);
      const double z = total_zeros / size;
      const double limit = ns <= o.relax_size_1   ? o.relax_zeros_1
                           : ns <= o.relax_size_2 ? o.relax_zeros_2
                                                  : o.relax_zeros_3;
      merge = z < limit;
    }
    if (merge) {
      zeros[s] = small ? zeros[s + 1] : total_zeros;
      merged[s + 1] = s;
      nrows[s] = ncols[s] + nrows[s + 1];
      ncols[s] += ncols[s + 1];
    }
  }
  Partition r;
  for (index_t s = 0; s < ns_count; ++s)
    if (merged[s] == -1) r.first.push_back(fs.first[s]);
  r.first.push_back(n);
  return r;  // parents are filled in by the caller, from the etree
}

/// Splits every range of more than `max_block` columns into a chain (see the header).
/// Returns the new ranges; chain_next[f] is true when front f's parent is front f+1.
/// A piece never ends at a column flagged in `keep` (empty: no flags).
Partition block_separators(const Partition& p, index_t max_block, const std::vector<char>& keep,
                           std::vector<char>& chain_next) {
  Partition r;
  chain_next.clear();
  auto kept = [&](index_t j) { return !keep.empty() && keep[j]; };
  for (index_t s = 0; s < count(p); ++s) {
    const index_t b = p.first[s], e = p.first[s + 1];
    index_t start = b;
    if (max_block > 0)
      while (e - start > max_block) {
        index_t next = start + max_block;
        // move the boundary down past kept pairs; up when that would empty the piece
        while (next > start && kept(next - 1)) --next;
        if (next == start) {
          next = start + max_block;
          while (next < e && kept(next - 1)) ++next;
          if (next == e) break;  // the rest is one chain of pairs: one piece
        }
        r.first.push_back(start);
        chain_next.push_back(1);
        start = next;
      }
    r.first.push_back(start);
    chain_next.push_back(0);
  }
  r.first.push_back(p.first.back());
  return r;
}

/// Throws InvalidInput unless the canonical (sorted) CSC pattern `a` is symmetric. One
/// sweep: columns are visited in increasing order, so the entries (j, i), j < i, of
/// column i are met in the order they are stored; each entry A(i, j), i > j, must be the
/// next unmatched one above the diagonal of column i. O(nnz), O(n) memory.
// Ranges of rows for the row-structure walks (analyze_pattern): one per thread of the
// calling arena, none under 4096 rows, and their count tables (one entry per front each)
// together at most 2^25 entries; 1 inside a SerialScope.
index_t row_ranges(index_t n, index_t fronts) {
  if (detail::serial_passes()) return 1;
  const auto threads = static_cast<std::int64_t>(tbb::this_task_arena::max_concurrency());
  const std::int64_t by_rows = n / 4096,
                     by_memory = (std::int64_t{1} << 25) / std::max<index_t>(fronts, 1);
  return static_cast<index_t>(std::max<std::int64_t>(1, std::min({threads, by_rows, by_memory})));
}

void require_symmetric_pattern(const SparseMatrix& a) {
  auto fail = [](index_t r, index_t c) {
    throw InvalidInput("analyze_pattern: the pattern is not symmetric (or not sorted): entry (" +
                       std::to_string(r) + ", " + std::to_string(c) + ") has no mirror entry");
  };
  const index_t n = a.n_cols;
  std::vector<index_t> next(a.offsets.begin(), a.offsets.end() - 1);
  for (index_t j = 0; j < n; ++j)
    for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p) {
      const index_t i = a.indices[p];
      if (i < 0 || i >= n) throw InvalidInput("analyze_pattern: row index out of range");
      if (i <= j) continue;
      if (next[i] >= a.offsets[i + 1] || a.indices[next[i]] != j) fail(i, j);
      ++next[i];
    }
  for (index_t i = 0; i < n; ++i)
    if (next[i] < a.offsets[i + 1] && a.indices[next[i]] < i) fail(a.indices[next[i]], i);
}

}  // namespace

// Flop convention: a pivot column with c entries (diagonal included) costs c² — about
// c²/2 multiply-adds of its rank-one update of the trailing c−1 rows, counted as 2 flops
// each, which dominates the c−1 divisions and the square root. Σ_j c_j² is the usual
// Cholesky count (George & Liu 1981); CHOLMOD's Common->fl is the same sum over the
// columns of L (the tests check both). LU on the same fronts costs about twice as much.
double front_flops(const AssemblyTree& t, index_t f) {
  const index_t np = t.n_pivots(f), nr = t.n_rows(f);
  double flops = 0;
  for (index_t k = 0; k < np; ++k) {
    const double c = static_cast<double>(nr - k);
    flops += c * c;
  }
  return flops;
}

namespace {

// The symbolic phase once sf.parent, sf.post, sf.colcount and sf.nnz_l are known: `cols`
// gives the pattern's columns in the postordered numbering (column k is input column
// post[k], with postordered indices), `par` and `cc` the etree and the column counts in
// that numbering.
template <class Columns>
void build_assembly_tree(SymbolicFactorization& sf, const Columns& cols,
                         const std::vector<index_t>& par, const std::vector<index_t>& cc,
                         const AmalgamationOptions& opts) {
  const index_t n = cols.n;
  // Kept pairs in the postordered numbering (see the file header).
  std::vector<char> keep;
  if (!opts.keep_with_next.empty()) {
    if (static_cast<index_t>(opts.keep_with_next.size()) != n)
      throw InvalidInput("analyze_pattern: keep_with_next has " +
                         std::to_string(opts.keep_with_next.size()) + " entries for " +
                         std::to_string(n) + " columns");
    keep.assign(n, 0);
    for (index_t k = 0; k < n; ++k) {
      const index_t j = sf.post[k];
      if (!opts.keep_with_next[j]) continue;
      if (j + 1 >= n || sf.parent[j] != j + 1)
        throw InvalidInput("analyze_pattern: keep_with_next[" + std::to_string(j) +
                           "] is set but column " + std::to_string(j + 1) +
                           " is not the etree parent of column " + std::to_string(j) +
                           " (is (j+1, j) an entry of the pattern?)");
      // j+1's children are all below j+1, so j is its last child: the postorder visits
      // j's subtree last among them, ending with j, and then j+1.
      if (k + 1 >= n || sf.post[k + 1] != j + 1)
        throw InvalidInput(
            "analyze_pattern: internal error: a kept pair is not consecutive "
            "in the postorder");
      keep[k] = 1;
    }
  }

  const Partition fundamental = fundamental_supernodes(par, cc);
  const Partition relaxed = relaxed_amalgamation(fundamental, cc, opts, keep, n);
  std::vector<char> chain_next;
  const Partition fronts = block_separators(relaxed, opts.max_block_size, keep, chain_next);

  AssemblyTree& t = sf.tree;
  t.n = n;
  t.first_pivot = fronts.first;
  const index_t nf = count(fronts);
  t.front_of_column = owner_of_columns(fronts, n);
  for (index_t k = 0; k < n; ++k)
    if (!keep.empty() && keep[k] && t.front_of_column[k] != t.front_of_column[k + 1])
      throw InternalError("analyze_pattern: a kept pair was split across fronts");
  t.parent.assign(nf, -1);
  for (index_t f = 0; f < nf; ++f) {
    if (chain_next[f]) {
      t.parent[f] = f + 1;
    } else {
      const index_t up = par[t.first_pivot[f + 1] - 1];
      t.parent[f] = up == -1 ? -1 : t.front_of_column[up];
    }
  }

  // Children, in increasing order (counting sort by parent).
  t.child_offsets.assign(nf + 1, 0);
  for (index_t f = 0; f < nf; ++f)
    if (t.parent[f] != -1) ++t.child_offsets[t.parent[f] + 1];
  for (index_t f = 0; f < nf; ++f) t.child_offsets[f + 1] += t.child_offsets[f];
  t.children.resize(t.child_offsets[nf]);
  {
    std::vector<index_t> next(t.child_offsets.begin(), t.child_offsets.end() - 1);
    for (index_t f = 0; f < nf; ++f)
      if (t.parent[f] != -1) t.children[next[t.parent[f]]++] = f;
  }

  // Row structures by row-subtree walks on the assembly tree, two passes (count, fill).
  // Row i of the tree is column post[i] of the input; its entries left of the diagonal
  // are the entries of input column post[i] whose postordered index is below i. The rows
  // are cut into consecutive ranges walked side by side over the calling arena's threads,
  // each with its own marks and counts per front; a range's rows go to the slots after
  // those of the ranges before it, so every list is in increasing row order and the
  // structure is the same for any number of ranges.
  const index_t ranges = row_ranges(n, nf);
  auto range_begin = [&](index_t r) { return static_cast<index_t>(std::int64_t{n} * r / ranges); };
  std::vector<std::vector<index_t>> count(ranges, std::vector<index_t>(nf, 0));
  auto walk = [&](index_t r, auto&& visit) {
    std::vector<index_t> mark(nf, -1);
    for (index_t i = range_begin(r); i < range_begin(r + 1); ++i) {
      const index_t fi = t.front_of_column[i];
      cols.for_each(i, [&](index_t j) {
        if (j >= i) return;
        for (index_t f = t.front_of_column[j]; f != fi; f = t.parent[f]) {
          // Only an unsymmetric pattern can leave the tree before reaching row i's front.
          if (f == -1) throw InvalidInput("analyze_pattern: the pattern is not symmetric");
          if (mark[f] == i) break;  // the rest of the path is already marked
          mark[f] = i;
          visit(f, i);
        }
      });
    }
  };
  auto over_ranges = [&](auto&& body) {
    if (ranges == 1) {
      body(index_t{0});
      return;
    }
    tbb::parallel_for(index_t{0}, ranges, [&](index_t r) { body(r); });
  };
  over_ranges([&](index_t r) { walk(r, [&](index_t f, index_t) { ++count[r][f]; }); });
  t.row_offsets.assign(nf + 1, 0);
  for (index_t f = 0; f < nf; ++f) {
    index_t extra = 0;
    for (index_t r = 0; r < ranges; ++r) extra += count[r][f];
    t.row_offsets[f + 1] = t.row_offsets[f] + t.n_pivots(f) + extra;
  }
  t.rows.resize(t.row_offsets[nf]);
  for (index_t f = 0; f < nf; ++f) {  // count[r][f] becomes range r's first slot in f
    index_t w = t.row_offsets[f];
    for (index_t j = t.first_pivot[f]; j < t.first_pivot[f + 1]; ++j) t.rows[w++] = j;
    for (index_t r = 0; r < ranges; ++r) {
      const index_t c = count[r][f];
      count[r][f] = w;
      w += c;
    }
  }
  over_ranges(
      [&](index_t r) { walk(r, [&](index_t f, index_t i) { t.rows[count[r][f]++] = i; }); });
}

// The whole symbolic phase on the pattern given by `cols` (columns in any row order).
template <class Columns>
SymbolicFactorization analyze_columns(const Columns& cols, const AmalgamationOptions& opts) {
  const index_t n = cols.n;
  SymbolicFactorization sf;
  sf.parent = elimination_tree_of(cols);
  sf.post = postorder(sf.parent);
  sf.colcount = column_counts_of(cols, sf.parent, sf.post);
  sf.nnz_l = 0;
  for (index_t c : sf.colcount) sf.nnz_l += c;

  // The etree and counts in the postordered numbering: parent[k] > k.
  std::vector<index_t> ipost(n), par(n), cc(n);
  for (index_t k = 0; k < n; ++k) ipost[sf.post[k]] = k;
  for (index_t k = 0; k < n; ++k) {
    const index_t p = sf.parent[sf.post[k]];
    par[k] = p == -1 ? -1 : ipost[p];
    cc[k] = sf.colcount[sf.post[k]];
  }
  const RelabeledColumns postordered{cols.offsets, cols.indices, sf.post.data(), ipost.data(), n};
  build_assembly_tree(sf, postordered, par, cc, opts);
  return sf;
}

}  // namespace

SymbolicFactorization analyze_pattern(const SparseMatrix& a, const AmalgamationOptions& opts,
                                      PatternCheck check) {
  if (a.layout != Layout::csc || a.n_rows != a.n_cols)
    throw InvalidInput("analyze_pattern needs a square CSC pattern, got " +
                       std::to_string(a.n_rows) + "x" + std::to_string(a.n_cols));
  if (static_cast<index_t>(a.offsets.size()) != a.n_cols + 1)
    throw InvalidInput("analyze_pattern: offsets has the wrong length");
  if (check == PatternCheck::full) require_symmetric_pattern(a);
  return analyze_columns(CscColumns{a.offsets.data(), a.indices.data(), a.n_cols}, opts);
}

SymbolicFactorization analyze_permuted_graph(index_t n, const std::vector<index_t>& offsets,
                                             const index_t* indices,
                                             const std::vector<index_t>& perm,
                                             const AmalgamationOptions& opts) {
  const std::vector<index_t> iperm =
      checked_inverse(n, offsets.size(), perm, "analyze_permuted_graph");
  // P A Pᵀ gathered column by column, its rows left in the graph's order (unsorted)
  std::vector<index_t> permuted_offsets(n + 1);
  permuted_offsets[0] = 0;
  for (index_t k = 0; k < n; ++k)
    permuted_offsets[k + 1] = permuted_offsets[k] + (offsets[perm[k] + 1] - offsets[perm[k]]);
  UninitVector<index_t> permuted_indices(static_cast<std::size_t>(permuted_offsets[n]));
  for (index_t k = 0; k < n; ++k) {
    index_t* out = permuted_indices.data() + permuted_offsets[k];
    for (index_t p = offsets[perm[k]]; p < offsets[perm[k] + 1]; ++p) *out++ = iperm[indices[p]];
  }
  return analyze_columns(CscColumns{permuted_offsets.data(), permuted_indices.data(), n}, opts);
}

}  // namespace strata::symbolic
