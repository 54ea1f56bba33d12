// strata — the patterns the analysis derives from its input (see patterns.hpp).
//
// What: (1) the graph of B + Bᵀ (its pattern without the diagonal, which neither the
// ordering nor the symbolic phase looks at) that the ordering and the symbolic phase work
// on, and (2) the assembly map, which sorts the input's entries by the front they are
// added to and gives each its place in that front.
//
// How: every pass is linear in the entries and runs over the threads of the calling TBB
// arena with the same result for every thread count. The transposes and the sorting by
// front are stable bucket sorts (sparse/bucket_entries.hpp: Gustavson's bucket transpose,
// split into chunks of lines); the other passes are independent per column or per front
// (a union of two sorted lists, the positions of a front's entries through a row → local
// index map kept per thread). Why in parallel: these passes touch every entry, as the
// ordering does, but unlike the nested dissection (METIS, sequential) they split over a
// host's cores. A small matrix's analysis runs them on the calling thread alone
// (base/serial_scope.hpp).
//
// B + Bᵀ: column j is the union of B(:, j) and row j of B, both sorted (a canonical
// column, and the transpose's rows listed in increasing column order), so a merge gives
// the sorted union without a sort; B itself is never formed. General: B(:, j) =
// A(:, q_j). Symmetric: B(:, j) is column j of the lower triangle and row j of it the
// entries above the diagonal. Each range of columns is merged once, side by side into the
// room for both lists of its columns, and then moved down to its place (the union is
// known only once merged).
#include "analysis/patterns.hpp"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <utility>

#include "base/parallel_ranges.hpp"
#include "base/serial_scope.hpp"
#include "ordering/ordering.hpp"
#include "sparse/bucket_entries.hpp"

namespace strata::detail {
namespace {

// Turns per-line counts (counts[j + 1] for line j, counts[0] = 0) into offsets.
void prefix_sum(std::vector<index_t>& counts) {
  for (std::size_t j = 1; j < counts.size(); ++j) counts[j] += counts[j - 1];
}

// The transpose of the n_lines lines given by range(j) = {begin, end} of `indices`, whose
// entries lie in [0, n_buckets): for each bucket i, the lines j holding i, in increasing j.
struct Transposed {
  std::vector<index_t> offsets, lines;
};
template <class Range>
Transposed transpose_lines(index_t n_lines, index_t n_buckets, const index_t* indices,
                           Range range) {
  Transposed t;
  index_t nnz = 0;
  for (index_t j = 0; j < n_lines; ++j) nnz += range(j).second - range(j).first;
  t.lines.resize(nnz);
  index_t* out = t.lines.data();
  t.offsets = bucket_entries(
      n_lines, n_buckets, range, [&](index_t, index_t p) { return indices[p]; },
      [&](index_t slot, index_t j, index_t) { out[slot] = j; });
  return t;
}

// Column j of the graph from its two sorted halves: the union of the sorted lists
// [a, ae) and [b, be) without j, written to out; returns its length. Branch-free merge.
index_t union_without(index_t j, const index_t* a, const index_t* ae, const index_t* b,
                      const index_t* be, index_t* out) {
  index_t w = 0;
  while (a < ae && b < be) {
    const index_t ia = *a, ib = *b, i = ia < ib ? ia : ib;
    out[w] = i;
    w += i != j;
    a += ia == i;
    b += ib == i;
  }
  for (; a < ae; ++a) {
    out[w] = *a;
    w += *a != j;
  }
  for (; b < be; ++b) {
    out[w] = *b;
    w += *b != j;
  }
  return w;
}

}  // namespace

ordering::Graph symmetric_graph(const SparseMatrix& c, bool symmetric,
                                const std::vector<index_t>& q, index_t* diagonal_entries) {
  const index_t n = c.n_cols;
  const index_t* ci = c.indices.data();
  const index_t* co = c.offsets.data();
  // column k of B: column q[k] of A (general), column k of the lower triangle (symmetric)
  auto column_of_b = [&](index_t k) {
    const index_t j = symmetric || q.empty() ? k : q[k];
    return std::pair<index_t, index_t>{co[j], co[j + 1]};
  };
  // row j of B, the columns holding row j in increasing order: for a symmetric matrix the
  // part of column j of B + Bᵀ above the diagonal
  const Transposed t = transpose_lines(n, n, ci, column_of_b);
  // Each column merged once into room for both halves, then moved down to its place (in
  // place already when one range holds all the columns).
  ordering::Graph g;
  g.n = n;
  g.xadj.assign(n + 1, 0);
  std::vector<index_t> room(n + 1, 0);
  for (index_t j = 0; j < n; ++j) {
    const auto [b0, b1] = column_of_b(j);
    room[j + 1] = room[j] + (b1 - b0) + (t.offsets[j + 1] - t.offsets[j]);
  }
  g.adjncy.resize(room[n]);
  index_t* adj = g.adjncy.data();
  const index_t* tl = t.lines.data();
  // a range of columns is merged side by side from the room of its first column on;
  // room[j] becomes where column j was written
  detail::parallel_ranges(n, 256, [&](index_t j0, index_t j1) {
    index_t at = room[j0];
    for (index_t j = j0; j < j1; ++j) {
      const auto [b0, b1] = column_of_b(j);
      room[j] = at;
      g.xadj[j + 1] =
          union_without(j, ci + b0, ci + b1, tl + t.offsets[j], tl + t.offsets[j + 1], adj + at);
      at += g.xadj[j + 1];
    }
  });
  if (diagonal_entries) {  // B(j, j) in its sorted column
    *diagonal_entries = 0;
    for (index_t j = 0; j < n; ++j) {
      const auto [b0, b1] = column_of_b(j);
      *diagonal_entries += std::binary_search(ci + b0, ci + b1, j);
    }
  }
  for (index_t j = 0; j < n; ++j) {  // in place: each column moves down, never up
    const index_t len = g.xadj[j + 1];
    g.xadj[j + 1] = g.xadj[j] + len;
    if (g.xadj[j] != room[j]) std::copy(adj + room[j], adj + room[j] + len, adj + g.xadj[j]);
  }
  g.adjncy.resize(g.xadj[n]);
  return g;
}

AssemblyMap build_assembly_map(const SparseMatrix& c, const Analysis& an) {
  const auto& t = an.tree;
  const index_t nf = t.n_fronts();
  const index_t nnz = c.nnz();
  const bool symmetric = an.symmetric;
  const index_t* ci = c.indices.data();
  const index_t* co = c.offsets.data();
  // Line k of the bucket pass: general, the input column that becomes pivot column k (pj =
  // k), column perm[k] of B, which is column q[perm[k]] of A; symmetric, column k of the
  // lower triangle (pj = iperm[k]).
  auto input_column = [&](index_t k) {
    if (symmetric) return k;
    const index_t b = an.perm[k];
    return an.matching_perm.empty() ? b : an.matching_perm[b];
  };
  auto pivot_of_line = [&](index_t k) { return symmetric ? an.iperm[k] : k; };
  // the entries sorted by front (the front of the smaller permuted index), in the order of
  // the lines and then of each column's entries (symmetric: the input's order)
  AssemblyMap map;
  map.entry_src.resize(nnz);
  map.entry_dst.resize(nnz);
  // Until place() writes the positions, entry_dst holds each entry's permuted pair packed
  // as (pi << bits) | pj, so that place() reads it in order instead of going back to the
  // input's rows; an order too large for that (2·bits > 62) keeps each entry's pj.
  int bits = 1;
  while (bits < 62 && (index_t{1} << bits) < an.n) ++bits;
  const bool packed = 2 * bits <= 62;
  const index_t low_mask = (index_t{1} << bits) - 1;
  std::vector<index_t> column_of(packed ? 0 : nnz);
  map.entry_offsets = bucket_entries(
      an.n, nf,
      [&](index_t k) {
        const index_t j = input_column(k);
        return std::pair<index_t, index_t>{co[j], co[j + 1]};
      },
      [&](index_t k, index_t p) {
        return t.front_of_column[std::min(an.iperm[ci[p]], pivot_of_line(k))];
      },
      [&](index_t slot, index_t k, index_t p) {
        map.entry_src[slot] = p;
        if (packed)
          map.entry_dst[slot] = (an.iperm[ci[p]] << bits) | pivot_of_line(k);
        else
          column_of[slot] = pivot_of_line(k);
      });
  // Each entry's place: its column in the front is the local index of max(pi, pj) for the
  // part above the diagonal (general) and of min(pi, pj) otherwise, found through a
  // row → local index map set per front (linear in the fronts' rows plus the entries, no
  // search). A front's entries must be ordered by that column, stably (a part of the
  // front's columns receives a contiguous range of its entries, which the GPU's assembly
  // of a front cut into column slices finds by a search). General: they are already, as
  // the column is the local index of pj (lower part: pj = min(pi, pj) is a pivot of the
  // front, at pj − first pivot; upper part: pj = max(pi, pj) is a row of the front), the
  // local index increases with the row (a front's rows are sorted) and the lines came in
  // increasing pj, each column's entries in the input's order. Symmetric: the column is
  // that of min(pi, pj), which no order of the lines gives, so a counting sort over the
  // front's m columns orders them, stably from the input's order. One scratch per thread.
  struct Scratch {
    std::vector<index_t> local, count, col, src, dst;
  };
  auto place = [&](index_t f0, index_t f1, Scratch& s) {
    std::vector<index_t>& local = s.local;
    for (index_t f = f0; f < f1; ++f) {
      const index_t* rows = t.rows_of(f);
      const index_t m = t.n_rows(f);
      const index_t e0 = map.entry_offsets[f], e1 = map.entry_offsets[f + 1];
      const std::size_t ne = static_cast<std::size_t>(e1 - e0);
      for (index_t i = 0; i < m; ++i) local[rows[i]] = i;
      auto pair_of = [&](index_t k) {
        return packed ? std::pair<index_t, index_t>{map.entry_dst[k] >> bits,
                                                    map.entry_dst[k] & low_mask}
                      : std::pair<index_t, index_t>{an.iperm[ci[map.entry_src[k]]], column_of[k]};
      };
      if (!symmetric) {
        for (index_t k = e0; k < e1; ++k) {
          const auto [pi, pj] = pair_of(k);
          // lower part (pi ≥ pj): row pi, column pj; upper part: row pi, column pj of the
          // front's U block, both as local indices
          map.entry_dst[k] = local[pj] * m + local[pi];
        }
      } else {
        s.count.assign(static_cast<std::size_t>(m) + 1, 0);
        s.col.resize(ne);
        s.src.resize(ne);
        s.dst.resize(ne);
        for (std::size_t x = 0; x < ne; ++x) {
          const index_t k = e0 + static_cast<index_t>(x);
          const auto [pi, pj] = pair_of(k);
          // the lower triangle: row max(pi, pj), column min(pi, pj)
          const index_t col = local[std::min(pi, pj)];
          s.col[x] = col;
          s.src[x] = map.entry_src[k];
          s.dst[x] = col * m + local[std::max(pi, pj)];
          ++s.count[col + 1];
        }
        prefix_sum(s.count);
        for (std::size_t x = 0; x < ne; ++x) {
          const index_t at = e0 + s.count[s.col[x]]++;
          map.entry_src[at] = s.src[x];
          map.entry_dst[at] = s.dst[x];
        }
      }
      for (index_t i = 0; i < m; ++i) local[rows[i]] = -1;
    }
  };
  if (serial_passes()) {
    Scratch s{std::vector<index_t>(an.n, -1), {}, {}, {}, {}};
    place(0, nf, s);
    return map;
  }
  tbb::enumerable_thread_specific<Scratch> scratch([&] {
    return Scratch{std::vector<index_t>(an.n, -1), {}, {}, {}, {}};
  });
  tbb::parallel_for(tbb::blocked_range<index_t>(0, nf, 16),
                    [&](const auto& r) { place(r.begin(), r.end(), scratch.local()); });
  return map;
}

}  // namespace strata::detail
