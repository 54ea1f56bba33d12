// strata — the patterns the analysis derives from its input (see patterns.hpp).
//
// What: (1) the symmetric pattern of B + Bᵀ that the ordering and the symbolic phase work
// on, and (2) the assembly map, which sorts the input's entries by the front they are
// added to and gives each its place in that front.
//
// How: every pass is linear in the entries and runs over the threads of the calling TBB
// arena with the same result for every thread count. The transposes and the sorting by
// front are stable bucket sorts (sparse/bucket_entries.hpp: Gustavson's bucket transpose,
// split into chunks of lines); the other passes are independent per column or per front
// (a union of two sorted lists, the copy of a column, the positions of a front's entries
// through a row → local index map kept per thread). Why in parallel: these passes touch
// every entry, as the ordering does, but unlike the nested dissection (METIS, sequential)
// they split over a host's cores. A small matrix's analysis runs them on the calling
// thread alone (base/serial_scope.hpp).
//
// B + Bᵀ, general: column j is the union of B(:, j) = A(:, q_j) and row j of B, both sorted
// (a canonical column, and the transpose's rows listed in increasing column order), so a
// merge gives the canonical union without a sort; B itself is never formed. Symmetric:
// column j of the expansion of the lower triangle is row j of it without the diagonal
// (the entries above the diagonal, in increasing column order) followed by column j.
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

// Runs body(j) for j in [0, n) over the calling arena's threads, in ranges of 256 or more
// (on the calling thread alone inside a SerialScope: base/parallel_ranges.hpp).
template <class Body>
void for_each_index(index_t n, Body body) {
  detail::parallel_ranges(n, 256, [&](index_t j0, index_t j1) {
    for (index_t j = j0; j < j1; ++j) body(j);
  });
}

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

SparseMatrix full_csc(index_t n) {
  SparseMatrix f;
  f.n_rows = f.n_cols = n;
  f.layout = Layout::csc;
  f.storage = Storage::full;
  return f;
}

}  // namespace

SparseMatrix symmetric_pattern(const SparseMatrix& c, bool symmetric,
                               const std::vector<index_t>& q) {
  const index_t n = c.n_cols;
  SparseMatrix u = full_csc(n);
  const index_t* ci = c.indices.data();
  const index_t* co = c.offsets.data();
  if (symmetric) {
    // row j of the lower triangle: the columns k ≤ j holding row j, increasing (the
    // diagonal, when stored, is the last one)
    const Transposed t = transpose_lines(n, n, ci, [&](index_t k) {
      return std::pair<index_t, index_t>{co[k], co[k + 1]};
    });
    auto upper_end = [&](index_t j) {  // row j's entries left of the diagonal
      index_t e = t.offsets[j + 1];
      return e > t.offsets[j] && t.lines[e - 1] == j ? e - 1 : e;
    };
    u.offsets.assign(n + 1, 0);
    for_each_index(n, [&](index_t j) {
      u.offsets[j + 1] = (upper_end(j) - t.offsets[j]) + (co[j + 1] - co[j]);
    });
    prefix_sum(u.offsets);
    u.indices.resize(u.offsets[n]);
    for_each_index(n, [&](index_t j) {
      index_t* out = u.indices.data() + u.offsets[j];
      out = std::copy(t.lines.begin() + t.offsets[j], t.lines.begin() + upper_end(j), out);
      std::copy(ci + co[j], ci + co[j + 1], out);
    });
    return u;
  }
  // column k of B is column q[k] of A
  auto column_of_b = [&](index_t k) {
    const index_t j = q.empty() ? k : q[k];
    return std::pair<index_t, index_t>{co[j], co[j + 1]};
  };
  const Transposed t = transpose_lines(n, n, ci, column_of_b);
  // the union of B(:, j) and row j of B: sizes first, then the merge
  auto merge = [&](index_t j, index_t* out) {
    auto [a, ae] = column_of_b(j);
    index_t b = t.offsets[j], be = t.offsets[j + 1], w = 0;
    while (a < ae || b < be) {
      const index_t ia = a < ae ? ci[a] : n, ib = b < be ? t.lines[b] : n;
      const index_t i = std::min(ia, ib);
      a += ia == i;
      b += ib == i;
      if (out) out[w] = i;
      ++w;
    }
    return w;
  };
  u.offsets.assign(n + 1, 0);
  for_each_index(n, [&](index_t j) { u.offsets[j + 1] = merge(j, nullptr); });
  prefix_sum(u.offsets);
  u.indices.resize(u.offsets[n]);
  for_each_index(n, [&](index_t j) { merge(j, u.indices.data() + u.offsets[j]); });
  return u;
}

AssemblyMap build_assembly_map(const SparseMatrix& c, const Analysis& an) {
  const auto& t = an.tree;
  const index_t nf = t.n_fronts();
  const index_t nnz = c.nnz();
  std::vector<index_t> q_inv;
  if (!an.matching_perm.empty()) q_inv = ordering::invert_permutation(an.matching_perm);
  const index_t* ci = c.indices.data();
  const index_t* co = c.offsets.data();
  // the permuted indices of entry p of column j: (pi, pj)
  auto permuted = [&](index_t j, index_t p) {
    return std::pair<index_t, index_t>{an.iperm[ci[p]], an.iperm[q_inv.empty() ? j : q_inv[j]]};
  };
  // the entries sorted by front (the front of the smaller permuted index), each with its
  // column; within a front in the order of the input until place() orders them by the
  // column they land in
  AssemblyMap map;
  map.entry_src.resize(nnz);
  map.entry_dst.resize(nnz);
  std::vector<index_t> column_of(nnz);
  map.entry_offsets = bucket_entries(
      c.n_cols, nf,
      [&](index_t j) {
        return std::pair<index_t, index_t>{co[j], co[j + 1]};
      },
      [&](index_t j, index_t p) {
        const auto [pi, pj] = permuted(j, p);
        return t.front_of_column[std::min(pi, pj)];
      },
      [&](index_t slot, index_t j, index_t p) {
        map.entry_src[slot] = p;
        column_of[slot] = j;
      });
  // local positions through a row → local index map set per front (linear in the fronts'
  // rows plus the entries, no search), then the front's entries ordered by the column of
  // the front they land in, stably (a counting sort over its m columns): a part of the
  // front's columns receives a contiguous range of its entries, which the GPU's assembly
  // of a front cut into column slices finds by a search. One scratch per thread.
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
      s.count.assign(static_cast<std::size_t>(m) + 1, 0);
      s.col.resize(ne);
      s.src.resize(ne);
      s.dst.resize(ne);
      for (index_t i = 0; i < m; ++i) local[rows[i]] = i;
      for (std::size_t x = 0; x < ne; ++x) {
        const index_t k = e0 + static_cast<index_t>(x);
        const auto [pi, pj] = permuted(column_of[k], map.entry_src[k]);
        const index_t lo = std::min(pi, pj), hi = std::max(pi, pj);
        const index_t lc = lo - t.first_pivot[f];  // pivot column of the front
        const index_t lr = local[hi];
        // symmetric: lower triangle (row hi, column lo); general: (pi, pj) as it stands
        const bool lower = an.symmetric || pi >= pj;
        const index_t col = lower ? lc : lr;
        s.col[x] = col;
        s.src[x] = map.entry_src[k];
        s.dst[x] = col * m + (lower ? lr : lc);
        ++s.count[col + 1];
      }
      for (index_t i = 0; i < m; ++i) local[rows[i]] = -1;
      prefix_sum(s.count);
      for (std::size_t x = 0; x < ne; ++x) {
        const index_t at = e0 + s.count[s.col[x]]++;
        map.entry_src[at] = s.src[x];
        map.entry_dst[at] = s.dst[x];
      }
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
