// strata — the stable bucket (counting) sort of a pattern's entries, over the host's threads.
//
// What: the entries of n_lines lines (the columns of a CSC pattern, say) are distributed
// into n_buckets buckets by a key of each entry; within a bucket they keep the order of a
// sequential pass over the lines in increasing order and over each line's entries in
// order. This is the bucket transpose of Gustavson ("Two fast algorithms for sparse
// matrices: multiplication and permuted transposition", ACM TOMS 4(3), 1978) — with the
// row index as the key it lists each row's columns in increasing order — and the analysis
// uses it for the transpose of B, the symmetric permutation of a pattern and the sorting
// of the input's entries by front.
//
// How: the lines are cut into chunks of about equal numbers of entries, one per thread of
// the calling TBB arena (at most as many as keep the chunks' count tables under 2^25
// entries). Each chunk counts its entries per bucket; a bucket's slots are then handed to
// the chunks in chunk order, and each chunk fills its own slots. Every entry lands in the
// slot the sequential pass gives it, so the result is the same for every thread count.
// Work O(nnz + chunks · n_buckets), memory one count table per chunk.
#pragma once

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <vector>

#include "base/serial_scope.hpp"
#include "strata/types.hpp"

namespace strata::detail {

/// Distributes the entries of lines 0..n_lines-1 into buckets 0..n_buckets-1 (stable, see
/// the file comment) on the threads of the calling arena.
///
/// - `range(j)` gives line j's entries as a half-open pair {begin, end} of entry indices p
///   (indices into the caller's arrays; the lines need not be contiguous or in order);
/// - `key(j, p)` the bucket of entry p of line j, in [0, n_buckets) (called twice per entry);
/// - `emit(slot, j, p)` is called once per entry with its position slot in the sorted
///   order (0-based, in [0, nnz)); calls for different entries may run concurrently, so
///   emit writes only what belongs to that slot.
///
/// Returns the bucket offsets (n_buckets + 1 entries, offsets[0] = 0): bucket b holds the
/// slots [offsets[b], offsets[b + 1]). A chunk of fewer than `min_chunk_entries` entries
/// is not split off, so a small pattern is sorted on the calling thread, as every pattern is
/// inside a SerialScope (base/serial_scope.hpp).
template <class Range, class Key, class Emit>
std::vector<index_t> bucket_entries(index_t n_lines, index_t n_buckets, Range range, Key key,
                                    Emit emit, index_t min_chunk_entries = index_t{1} << 15) {
  // entries before each line, for chunks of equal work
  std::vector<index_t> before(static_cast<std::size_t>(n_lines) + 1, 0);
  for (index_t j = 0; j < n_lines; ++j) {
    const auto [b, e] = range(j);
    before[j + 1] = before[j] + (e - b);
  }
  const index_t nnz = before[n_lines];
  const index_t table_cap = index_t{1} << 25;
  index_t chunks = std::max<index_t>(1, nnz / std::max<index_t>(1, min_chunk_entries));
  if (chunks > 1)  // inside a SerialScope: one chunk, TBB not entered
    chunks =
        serial_passes() ? 1 : std::min<index_t>(chunks, tbb::this_task_arena::max_concurrency());
  chunks = std::min(chunks, std::max<index_t>(1, table_cap / (n_buckets + 1)));
  chunks = std::min(chunks, std::max<index_t>(1, n_lines));
  // chunk c covers the lines [first[c], first[c + 1])
  std::vector<index_t> first(chunks + 1, n_lines);
  first[0] = 0;
  for (index_t c = 1; c < chunks; ++c)
    first[c] = static_cast<index_t>(
        std::lower_bound(before.begin(), before.end(), nnz / chunks * c) - before.begin());
  for (index_t c = 1; c < chunks; ++c) first[c] = std::clamp(first[c], first[c - 1], n_lines);

  // count[c][b]: entries of chunk c in bucket b; then the first slot of chunk c in bucket b
  std::vector<std::vector<index_t>> count(chunks);
  auto count_chunk = [&](index_t c) {
    count[c].assign(static_cast<std::size_t>(n_buckets), 0);
    index_t* cnt = count[c].data();
    for (index_t j = first[c]; j < first[c + 1]; ++j) {
      const auto [b, e] = range(j);
      for (index_t p = b; p < e; ++p) ++cnt[key(j, p)];
    }
  };
  if (chunks == 1)
    count_chunk(0);
  else
    tbb::parallel_for(index_t{0}, chunks, count_chunk);
  std::vector<index_t> offsets(static_cast<std::size_t>(n_buckets) + 1, 0);
  for (index_t b = 0; b < n_buckets; ++b) {
    index_t at = offsets[b];
    for (index_t c = 0; c < chunks; ++c) {
      const index_t k = count[c][b];
      count[c][b] = at;
      at += k;
    }
    offsets[b + 1] = at;
  }
  auto fill_chunk = [&](index_t c) {
    index_t* next = count[c].data();
    for (index_t j = first[c]; j < first[c + 1]; ++j) {
      const auto [b, e] = range(j);
      for (index_t p = b; p < e; ++p) emit(next[key(j, p)]++, j, p);
    }
  };
  if (chunks == 1)
    fill_chunk(0);
  else
    tbb::parallel_for(index_t{0}, chunks, fill_chunk);
  return offsets;
}

}  // namespace strata::detail
