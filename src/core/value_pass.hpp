// strata — the host passes over a factorization's values (internal to the Solver).
//
// What: the checks and norms of the values a factorization is given (every value finite,
// no row or column magnitude sum past the largest double), their scaling by the analysis's
// matching scaling (B = Dr·A(:,Q)·Dc, stored in A's entry order) and whether B still needs
// equilibrating (rescale.hpp), in one parallel pass for a refactorization with the
// analyzed pattern (refactor_values); the pattern test and the
// parallel copies that decide and serve that path; ‖B‖₁ after a rescaling (rescale.hpp).
//
// Why: on the GPU these passes run on the host before the device's factorization, and
// for the multibody Newton matrices (millions of entries, a few ms of device work) they
// are of the order of the device's work, so each pass over the entries counts. Sums that
// scatter go to per-range vectors added in range order: the same result for every number
// of threads.
#pragma once

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <functional>
#include <span>
#include <vector>

#include "analysis/analysis.hpp"
#include "base/alloc.hpp"
#include "strata/sparse_matrix.hpp"

namespace strata::detail {

/// ‖A‖∞ (max row sum) of a canonical matrix, symmetric storage expanded.
double norm_inf(const SparseMatrix& c);

/// Refuses a matrix whose row or column magnitude sums overflow: ‖A‖∞ and ‖A‖₁ set the
/// static pivot threshold and the backward error, and an infinite norm would make every
/// pivot "tiny" and every backward error 0. Throws InvalidInput naming the first row, then
/// column, whose magnitude sum (row[i], col[j]) is not finite.
void throw_if_norm_overflows(std::span<const double> row, std::span<const double> col);

/// throw_if_norm_overflows for the row and column sums of canonical c (with `values` in
/// place of c.values: c.indices.size() of them).
void check_norms(const SparseMatrix& c);
void check_norms(const SparseMatrix& c, const double* values);

/// Throws InvalidInput naming the first of `values` (a.indices.size() of them, in a's
/// entry order) that is not finite: its position, row and column; the last value when
/// all are finite (call it when one is not).
[[noreturn]] void throw_first_not_finite(const SparseMatrix& a, const double* values);

/// True when `a` is stored exactly as the analysis's canonical pattern (CSC, sorted, no
/// duplicates; the lower triangle when symmetric): its values can be used as they are.
/// Large arrays are compared in parallel chunks on `arena`.
bool has_analyzed_pattern(const Analysis& an, const SparseMatrix& a, tbb::task_arena& arena);

/// Where each entry of `a` (the matrix given to the analysis `an`, in its own layout,
/// storage and order) lands in the analysis's canonical pattern: position q of
/// an.pattern_indices, or −1 for an entry the analysis does not keep (the strict upper
/// triangle of a symmetric matrix given in full storage). Duplicates land on the same q.
/// Throws InternalError for an entry outside the pattern (a was not the analyzed matrix).
std::vector<index_t> input_entry_map(const Analysis& an, const SparseMatrix& a);

/// to = from (parallel chunks on `arena` for large arrays of equal size).
void copy_values(std::vector<double>& to, std::span<const double> from, tbb::task_arena& arena);

/// to[0, n) = from[0, n) (parallel chunks on `arena` when n is large).
void copy_range(double* to, const double* from, std::size_t n, tbb::task_arena& arena);

/// to[0, n) = from[0, n) in pieces of 1 MiB copied side by side on `arena`'s threads, each
/// piece [b, e) reported to done(b, e) by the thread that copied it as soon as it is in
/// place (a small n: one piece, on this thread). One parallel loop for the whole range:
/// entering the arena once per piece cost about 0.2 ms each on a 16-core host.
void stage_range(double* to, const double* from, std::size_t n, tbb::task_arena& arena,
                 const std::function<void(std::size_t, std::size_t)>& done);

// The per-refactorization passes over the values run over kValueBlocks fixed column
// ranges in parallel; sums that scatter (row sums, the mirrored half of a symmetric
// matrix) go to one vector per range, added in range order: the same result whatever the
// number of threads. On a large matrix these host passes, one thread each, took a third of
// a GPU refactorization.
constexpr int kValueBlocks = 8;
// Entries below which one thread does the pass: a pass over ~10⁵ entries is already a
// sizeable share of a small matrix's refactorization on a GPU, so the threshold sits well
// below that (bench/history.md has the measurements).
constexpr index_t kParallelValues = 32768;

// Runs range(blk) for the kValueBlocks column ranges of a pass over `nnz` entries, then
// reduce(i0, i1) over the rows [0, n) in pieces: on one thread below kParallelValues
// entries (a Newton step of a small model), else on `arena`'s.
template <class Range, class Reduce>
void for_value_ranges(std::size_t nnz, std::size_t n, tbb::task_arena& arena, Range&& range,
                      Reduce&& reduce) {
  if (nnz < static_cast<std::size_t>(kParallelValues)) {
    for (int blk = 0; blk < kValueBlocks; ++blk) range(blk);
    reduce(std::size_t{0}, n);
    return;
  }
  arena.execute([&] {
    tbb::parallel_for(0, kValueBlocks, range);
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(0, n, 16384),
        [&](const tbb::blocked_range<std::size_t>& r) { reduce(r.begin(), r.end()); });
  });
}

// Calls visit(j, p, acc) for every stored entry p of column j, acc[k] (k < sums) being the
// n-vector of sum k for the entry's column range; returns the sums over the ranges, added
// in range order. `work` keeps the per-range vectors from one call to the next (sizing
// and zero-filling 8 fresh n-vectors per pass cost more than the pass on a large matrix).
// `lower`: `a` holds a lower triangle and visit writes only rows i ≥ j, so the range
// [j0, j1) leaves rows below j0 alone — neither zeroed nor added (they would be zeros).
constexpr int kMaxSums = 2;
inline index_t range_begin(std::size_t n, int blk) {
  return static_cast<index_t>(static_cast<std::int64_t>(n) * blk / kValueBlocks);
}
template <class Visit>
std::vector<std::vector<double>> blocked_sums(const SparseMatrix& a, int sums, bool lower,
                                              tbb::task_arena& arena, std::vector<double>& work,
                                              Visit&& visit) {
  const std::size_t n = static_cast<std::size_t>(a.n_cols);
  const std::size_t per = static_cast<std::size_t>(sums) * n;
  if (work.size() < kValueBlocks * per)
    sized_resize(work, kValueBlocks * per, "factorize: value sums");
  auto range = [&](int blk) {
    double* base = work.data() + blk * per;
    const index_t j0 = range_begin(n, blk), j1 = range_begin(n, blk + 1);
    double* acc[kMaxSums] = {};
    for (int k = 0; k < sums; ++k) {
      acc[k] = base + k * n;
      std::fill(acc[k] + (lower ? j0 : 0), acc[k] + n, 0.0);
    }
    for (index_t j = j0; j < j1; ++j)
      for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p) visit(j, p, acc);
  };
  std::vector<std::vector<double>> total(sums, std::vector<double>(n));
  std::size_t first_row[kValueBlocks];  // rows below it are not the range's (lower)
  for (int blk = 0; blk < kValueBlocks; ++blk)
    first_row[blk] = lower ? static_cast<std::size_t>(range_begin(n, blk)) : 0;
  auto reduce = [&](std::size_t i0, std::size_t i1) {
    for (int k = 0; k < sums; ++k)
      for (std::size_t i = i0; i < i1; ++i) {
        double t = 0;
        for (int blk = 0; blk < kValueBlocks; ++blk)
          if (first_row[blk] <= i) t += work[blk * per + k * n + i];
        total[k][i] = t;
      }
  };
  for_value_ranges(static_cast<std::size_t>(a.nnz()), n, arena, range, reduce);
  return total;
}

/// A refactorization's one pass over `a`, which has the analyzed pattern (symmetric: its
/// lower triangle): every value finite, no row or column magnitude sum past the largest
/// double (InvalidInput as validate and check_norms), the values as assembled written to
/// `scaled` (Dr·A·Dc with the analysis' scaling). Returns ‖A‖∞ and the ‖·‖₁ of the scaled
/// matrix (symmetric storage expanded). The checks, the norms and the scaling share the
/// pass: each would otherwise read every entry again.
struct ValueNorms {
  double norm_inf = 0;
  double scaled_norm1 = 0;
  /// With the analysis's scaling: every nonzero row and column maximum of |B| is within
  /// [1/2, 2], so rescale_values would leave B as it is (always false without a scaling).
  bool equilibrated = false;
  /// With the analysis's scaling and not `equilibrated`: the row and column maxima of |B|
  /// (n each; symmetric: row_max of the full rows and col_max empty), which rescale_values
  /// takes instead of a first pass of its own. Empty otherwise.
  std::vector<double> row_max, col_max;
};

/// See ValueNorms: the pass over `values` (a.indices.size() of them, in the entry order
/// of a, whose pattern is the analyzed one; a.values is not read) into `scaled`. `work`:
/// the pass's per-range row arrays (refactor_work_size doubles, kept from one call to the
/// next). The sums are added as blocked_sums adds them (each column range in entry order,
/// the ranges in order), so the norms do not depend on the number of threads.
ValueNorms refactor_values(const Analysis& an, const SparseMatrix& a, const double* values,
                           tbb::task_arena& arena, std::vector<double>& work,
                           std::vector<double>& scaled);

/// The doubles of refactor_values' `work` for a matrix of analysis `an`.
std::size_t refactor_work_size(const Analysis& an);

/// Whether the analysis's matching scaling hit its clamp (ordering/matching.cpp: factors
/// within e^±700) for some row or column.
bool scaling_clamped(const Analysis& an);

/// ‖B‖₁ of the scaled values (entry order of the canonical `c`; symmetric: lower storage,
/// mirrored), by blocked_sums on the arena (work: its scratch).
double scaled_norm1(const SparseMatrix& c, bool symmetric, const std::vector<double>& scaled,
                    tbb::task_arena& arena, std::vector<double>& work);

}  // namespace strata::detail
