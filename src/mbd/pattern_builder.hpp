// strata::mbd — a CSC pattern from (row, column) pairs, built over the host's threads.
//
// What: PatternBuilder collects the (row, column) pairs of a matrix's entries, one at a
// time or in blocks that several threads fill, and finishes them into a canonical CSC
// pattern (each column's rows sorted, duplicates dropped); entry_position() then gives an
// entry's position in it. group_by_target lists, for an array of targets (entry positions,
// say), the indices that share each target, in increasing order. from_triplets sums
// triplets into a CSC matrix with these.
//
// Why: the Newton matrix of a large model (a flexible body of 10⁶ coordinates has about
// 4.5·10⁸ pairs for 2·10⁸ entries) has its pattern built at set-up and again whenever its
// contact set or partition changes; sorting and searching that many pairs on one thread
// is most of such a model's set-up.
//
// How: finish() distributes the pairs into columns by the stable bucket sort of
// sparse/bucket_entries.hpp (blocks of pairs as its lines), then sorts and deduplicates
// the columns, many at once. group_by_target buckets the indices by target the same way
// (by coarse buckets of 2^s consecutive targets when the targets are too many for the
// bucket sort's count tables, each bucket then ordered by a stable counting sort on the
// targets' low s bits). Both run on the threads of the calling TBB arena and give the
// same result for every thread count; inside a SerialScope (base/serial_scope.hpp) they
// run on the calling thread. Their large arrays are not zeroed when allocated (FillLater):
// the threads that fill them are the first to write, and so to map, their pages (huge
// pages for the large ones, advise_huge_pages).
#pragma once

#include <tbb/task_arena.h>

#include <cstddef>
#include <memory>
#include <new>
#include <span>
#include <utility>
#include <vector>

#include "strata/sparse_matrix.hpp"

namespace strata::mbd {

/// Asks the kernel for transparent huge pages on the whole 2 MiB pages of [p, p + bytes)
/// when that is at least 8 MiB (madvise MADV_HUGEPAGE; nothing where it is not supported):
/// arrays of this size are written once each, and 4 KiB pages would cost a page fault
/// every 4 KiB of them.
void advise_huge_pages(void* p, std::size_t bytes) noexcept;

/// std::allocator whose value construction leaves a scalar uninitialized (resize() does not
/// zero), for arrays that are filled right after, in parallel; large ones on huge pages.
template <class T>
struct UninitializedAllocator : std::allocator<T> {
  template <class U>
  struct rebind {
    using other = UninitializedAllocator<U>;
  };
  UninitializedAllocator() = default;
  template <class U>
  UninitializedAllocator(const UninitializedAllocator<U>&) noexcept {}
  template <class U>
  void construct(U* p) noexcept {
    ::new (static_cast<void*>(p)) U;
  }
  template <class U, class... Args>
  void construct(U* p, Args&&... args) {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
  T* allocate(std::size_t n) {
    T* p = std::allocator<T>::allocate(n);
    advise_huge_pages(p, n * sizeof(T));
    return p;
  }
};
/// A vector whose new elements are uninitialized until written (see UninitializedAllocator).
template <class T>
using FillLater = std::vector<T, UninitializedAllocator<T>>;

/// Builds a canonical CSC pattern (0-based; rows sorted within each column, no
/// duplicates) from (row, column) pairs; entry_position finds entries in it.
class PatternBuilder {
 public:
  /// Throws InvalidInput for more than 2^32 rows or 2^31 columns (a pair is kept in 64
  /// bits: its column above its row).
  PatternBuilder(index_t n_rows, index_t n_cols);
  /// Adds the pair (r, c): 0 ≤ r < n_rows, 0 ≤ c < n_cols (not checked).
  void add(index_t r, index_t c) { keys_.push_back(key(r, c)); }
  /// Makes room for `count` more pairs and returns the index of the first of them; set()
  /// then writes each, from any thread (different indices).
  std::size_t grow(std::size_t count);
  void set(std::size_t k, index_t r, index_t c) { keys_[k] = key(r, c); }
  /// The pairs sorted into the pattern (values zero), on the calling arena's threads (see
  /// the file comment). The pairs are released.
  SparseMatrix finish();

 private:
  static unsigned long long key(index_t r, index_t c) {
    return static_cast<unsigned long long>(c) << 32 | static_cast<unsigned long long>(r);
  }
  index_t rows_, cols_;
  FillLater<unsigned long long> keys_;
};

/// Position of entry (r, c) in the values of `a` (canonical CSC: rows sorted within each
/// column). Throws std::logic_error when (r, c) is not in the pattern (an internal error
/// of the caller).
index_t entry_position(const SparseMatrix& a, index_t r, index_t c);

/// For target_of[k] in [0, targets) (k = 0 … K−1): the targets that occur, in increasing
/// order (target), and for target[t] the indices k with target_of[k] = target[t] in
/// increasing order, slot[first[t]] … slot[first[t + 1] − 1] (first has target.size() + 1
/// entries, first[0] = 0). A stable counting sort of the indices by target.
struct TargetGroups {
  std::vector<index_t> target;
  std::vector<std::size_t> first;
  FillLater<std::size_t> slot;
};

/// TargetGroups of `target_of` on the calling arena's threads (see the file comment).
TargetGroups group_by_target(std::span<const index_t> target_of, index_t targets);

/// A CSC matrix (n_rows × n_cols, 0-based) from triplets (rows[k], cols[k], vals[k]),
/// duplicates summed in the order of k (so the values are the same for any thread
/// count). On the threads of `arena`; null: on the calling thread.
SparseMatrix from_triplets(index_t n_rows, index_t n_cols, const std::vector<index_t>& rows,
                           const std::vector<index_t>& cols, const std::vector<double>& vals,
                           tbb::task_arena* arena = nullptr);

}  // namespace strata::mbd
