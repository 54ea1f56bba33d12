// strata::mbd — a CSC pattern from (row, column) pairs (see pattern_builder.hpp).
#include "mbd/pattern_builder.hpp"

#include <sys/mman.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <utility>

#include "base/serial_scope.hpp"
#include "sparse/bucket_entries.hpp"
#include "strata/errors.hpp"

namespace strata::mbd {
namespace {

// The pairs (or indices) are handed to the bucket sort as lines of this many entries.
constexpr std::size_t kBlock = 4096;

// f(begin, end) over [0, n) in pieces of at least `grain` on the calling arena's threads;
// on the calling thread inside a SerialScope or when n ≤ grain.
template <class F>
void for_pieces(std::size_t n, std::size_t grain, F&& f) {
  if (n <= grain || detail::serial_passes()) {
    f(std::size_t{0}, n);
    return;
  }
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, grain),
                    [&](const tbb::blocked_range<std::size_t>& r) { f(r.begin(), r.end()); });
}

// The entries [j·kBlock, min(size, (j + 1)·kBlock)) as bucket_entries' line j.
std::pair<index_t, index_t> block(index_t j, std::size_t size) {
  const auto b = static_cast<std::size_t>(j) * kBlock;
  return {static_cast<index_t>(b), static_cast<index_t>(std::min(size, b + kBlock))};
}

index_t blocks_of(std::size_t size) { return static_cast<index_t>((size + kBlock - 1) / kBlock); }

}  // namespace

void advise_huge_pages(void* p, std::size_t bytes) noexcept {
#ifdef MADV_HUGEPAGE
  constexpr std::uintptr_t kHuge = std::uintptr_t{1} << 21;
  if (bytes < 4 * kHuge) return;
  const auto begin = (reinterpret_cast<std::uintptr_t>(p) + kHuge - 1) & ~(kHuge - 1);
  const auto end = (reinterpret_cast<std::uintptr_t>(p) + bytes) & ~(kHuge - 1);
  if (end > begin) madvise(reinterpret_cast<void*>(begin), end - begin, MADV_HUGEPAGE);
#else
  (void)p;
  (void)bytes;
#endif
}

PatternBuilder::PatternBuilder(index_t n_rows, index_t n_cols) : rows_(n_rows), cols_(n_cols) {
  if (n_rows < 0 || n_cols < 0 || n_rows > (index_t{1} << 32) || n_cols > (index_t{1} << 31))
    throw InvalidInput("PatternBuilder: a matrix of " + std::to_string(n_rows) + " x " +
                       std::to_string(n_cols) + " is outside 0..2^32 rows and 0..2^31 columns");
}

std::size_t PatternBuilder::grow(std::size_t count) {
  const std::size_t at = keys_.size();
  keys_.resize(at + count);
  return at;
}

SparseMatrix PatternBuilder::finish() {
  SparseMatrix a;
  a.n_rows = rows_;
  a.n_cols = cols_;
  const std::size_t size = keys_.size();
  FillLater<index_t> rows(size);
  // the pairs by column (stable), then each column's rows sorted and made unique
  const std::vector<index_t> start = detail::bucket_entries(
      blocks_of(size), cols_, [&](index_t j) { return block(j, size); },
      [&](index_t, index_t p) { return static_cast<index_t>(keys_[p] >> 32); },
      [&](index_t slot, index_t, index_t p) {
        rows[slot] = static_cast<index_t>(keys_[p] & 0xffffffffULL);
      });
  FillLater<unsigned long long>().swap(keys_);
  const auto cols = static_cast<std::size_t>(cols_);
  std::vector<index_t> length(cols);
  for_pieces(cols, 512, [&](std::size_t c0, std::size_t c1) {
    for (std::size_t c = c0; c < c1; ++c) {
      const auto b = rows.begin() + start[c], e = rows.begin() + start[c + 1];
      std::sort(b, e);
      length[c] = std::unique(b, e) - b;
    }
  });
  a.offsets.assign(cols + 1, 0);
  for (std::size_t c = 0; c < cols; ++c) a.offsets[c + 1] = a.offsets[c] + length[c];
  a.indices.resize(a.offsets[cols]);
  for_pieces(cols, 512, [&](std::size_t c0, std::size_t c1) {
    for (std::size_t c = c0; c < c1; ++c)
      std::copy_n(rows.begin() + start[c], length[c], a.indices.begin() + a.offsets[c]);
  });
  a.values.assign(a.indices.size(), 0.0);
  return a;
}

index_t entry_position(const SparseMatrix& a, index_t r, index_t c) {
  const auto b = a.indices.begin() + a.offsets[c], e = a.indices.begin() + a.offsets[c + 1];
  const auto it = std::lower_bound(b, e, r);
  if (it == e || *it != r) throw std::logic_error("entry_position: entry not in the pattern");
  return it - a.indices.begin();
}

TargetGroups group_by_target(std::span<const index_t> target_of, index_t targets) {
  const std::size_t size = target_of.size();
  // coarse buckets of 2^shift targets: at most 2^21 of them, so that the bucket sort's
  // count tables leave room for 16 chunks
  int shift = 0;
  while ((targets >> shift) >= (index_t{1} << 21)) ++shift;
  const index_t buckets = (targets >> shift) + 1;
  TargetGroups g;
  g.slot.resize(size);
  const std::vector<index_t> start = detail::bucket_entries(
      blocks_of(size), buckets, [&](index_t j) { return block(j, size); },
      [&](index_t, index_t k) { return target_of[k] >> shift; },
      [&](index_t at, index_t, index_t k) { g.slot[at] = static_cast<std::size_t>(k); });
  const auto nb = static_cast<std::size_t>(buckets);
  // a coarse bucket holds its indices in increasing order; a stable counting sort on the
  // target's low `shift` bits keeps that order among the indices of one target
  if (shift > 0) {
    const index_t low = (index_t{1} << shift) - 1;
    for_pieces(nb, 256, [&](std::size_t b0, std::size_t b1) {
      std::vector<index_t> count(static_cast<std::size_t>(low) + 2);
      std::vector<std::size_t> sorted;
      for (std::size_t b = b0; b < b1; ++b) {
        const auto first = static_cast<std::size_t>(start[b]);
        const auto last = static_cast<std::size_t>(start[b + 1]);
        if (last - first < 2) continue;
        std::fill(count.begin(), count.end(), 0);
        for (std::size_t p = first; p < last; ++p) ++count[(target_of[g.slot[p]] & low) + 1];
        for (std::size_t v = 1; v < count.size(); ++v) count[v] += count[v - 1];
        sorted.resize(last - first);
        for (std::size_t p = first; p < last; ++p)
          sorted[count[target_of[g.slot[p]] & low]++] = g.slot[p];
        std::copy(sorted.begin(), sorted.end(), g.slot.begin() + first);
      }
    });
  }
  if (shift == 0) {  // a bucket per target: its slots are its group
    for (std::size_t b = 0; b < nb; ++b)
      if (start[b + 1] > start[b]) {
        g.target.push_back(static_cast<index_t>(b));
        g.first.push_back(static_cast<std::size_t>(start[b]));
      }
    g.first.push_back(size);
    return g;
  }
  // the distinct targets of each bucket, then where each bucket's groups start
  auto is_new = [&](std::size_t b, index_t p) {
    return p == start[b] || target_of[g.slot[p]] != target_of[g.slot[p - 1]];
  };
  std::vector<std::size_t> groups(nb + 1, 0);
  for_pieces(nb, 1024, [&](std::size_t b0, std::size_t b1) {
    for (std::size_t b = b0; b < b1; ++b)
      for (index_t p = start[b]; p < start[b + 1]; ++p) groups[b + 1] += is_new(b, p);
  });
  for (std::size_t b = 0; b < nb; ++b) groups[b + 1] += groups[b];
  g.target.resize(groups[nb]);
  g.first.resize(groups[nb] + 1);
  g.first[groups[nb]] = size;
  for_pieces(nb, 1024, [&](std::size_t b0, std::size_t b1) {
    for (std::size_t b = b0; b < b1; ++b) {
      std::size_t t = groups[b];
      for (index_t p = start[b]; p < start[b + 1]; ++p)
        if (is_new(b, p)) {
          g.target[t] = target_of[g.slot[p]];
          g.first[t++] = static_cast<std::size_t>(p);
        }
    }
  });
  return g;
}

SparseMatrix from_triplets(index_t n_rows, index_t n_cols, const std::vector<index_t>& rows,
                           const std::vector<index_t>& cols, const std::vector<double>& vals,
                           tbb::task_arena* arena) {
  SparseMatrix a;
  auto build = [&] {
    const std::size_t size = rows.size();
    PatternBuilder pb(n_rows, n_cols);
    pb.grow(size);
    for_pieces(size, 16384, [&](std::size_t k0, std::size_t k1) {
      for (std::size_t k = k0; k < k1; ++k) pb.set(k, rows[k], cols[k]);
    });
    a = pb.finish();
    FillLater<index_t> position(size);
    for_pieces(size, 16384, [&](std::size_t k0, std::size_t k1) {
      for (std::size_t k = k0; k < k1; ++k) position[k] = entry_position(a, rows[k], cols[k]);
    });
    // each entry the sum of its triplets in the order of k
    const TargetGroups g = group_by_target(position, a.nnz());
    for_pieces(g.target.size(), 4096, [&](std::size_t t0, std::size_t t1) {
      for (std::size_t t = t0; t < t1; ++t) {
        double s = 0;
        for (std::size_t i = g.first[t]; i < g.first[t + 1]; ++i) s += vals[g.slot[i]];
        a.values[g.target[t]] = s;
      }
    });
  };
  if (arena) {
    arena->execute(build);
  } else {
    detail::SerialScope serial(true);
    build();
  }
  return a;
}

}  // namespace strata::mbd
