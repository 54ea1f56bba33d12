// strata — the host passes over a factorization's values (see value_pass.hpp).
#include "core/value_pass.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <string>

#include "base/host_copy.hpp"
#include "strata/errors.hpp"

namespace strata::detail {
namespace {

// Large arrays are compared and copied in parallel chunks: one thread did a few ms of each
// per refactorization of a matrix with millions of entries.
constexpr std::size_t kParallelChunk = std::size_t{1} << 18;  // elements per task

// Runs f(b, e) over [0, size) in chunks of kParallelChunk elements, in parallel in `arena`.
template <class F>
void for_chunks(tbb::task_arena& arena, std::size_t size, F&& f) {
  arena.execute([&] {
    tbb::parallel_for(std::size_t{0}, (size + kParallelChunk - 1) / kParallelChunk,
                      [&](std::size_t c) {
                        const std::size_t b = c * kParallelChunk;
                        f(b, std::min(size, b + kParallelChunk));
                      });
  });
}

template <class T>
bool equal_arrays(const std::vector<T>& x, const std::vector<T>& y, tbb::task_arena& arena) {
  if (x.size() != y.size()) return false;
  if (x.size() < 2 * kParallelChunk) return x == y;
  std::atomic<bool> same{true};
  for_chunks(arena, x.size(), [&](std::size_t b, std::size_t e) {
    if (same.load(std::memory_order_relaxed) &&
        std::memcmp(x.data() + b, y.data() + b, sizeof(T) * (e - b)) != 0)
      same.store(false, std::memory_order_relaxed);
  });
  return same;
}

// Throws InvalidInput naming the first value of `a` that is not finite (there is one).
[[noreturn]] void throw_first_not_finite(const SparseMatrix& a) {
  const std::size_t nnz = a.values.size();
  std::size_t p = 0;
  while (p + 1 < nnz && std::isfinite(a.values[p])) ++p;
  const index_t j = static_cast<index_t>(
      std::upper_bound(a.offsets.begin(), a.offsets.end(), static_cast<index_t>(p)) -
      a.offsets.begin() - 1);
  throw InvalidInput("values[" + std::to_string(p) + "] is not finite (row " +
                     std::to_string(a.indices[p]) + ", column " + std::to_string(j) + ")");
}

}  // namespace

ValueNorms refactor_values(const Analysis& an, const SparseMatrix& a, tbb::task_arena& arena,
                           std::vector<double>& work, std::vector<double>& scaled) {
  const bool sym = an.symmetric, scale = !an.row_scaling.empty();
  const index_t n = a.n_cols;
  sized_resize(scaled, a.values.size(), "factorize: scaled values");
  std::atomic<bool> not_finite{false};
  // unsymmetric: column sums, each column within one range (no per-range vectors)
  std::vector<double> col(sym ? 0 : n, 0.0), scol(sym ? 0 : n, 0.0);
  // symmetric and unscaled: the scaled matrix is A, its ‖·‖₁ is ‖A‖∞ (one sum)
  const int nsums = sym && scale ? 2 : 1;
  const auto sums =
      blocked_sums(a, nsums, sym, arena, work, [&](index_t j, index_t p, double* const* acc) {
        const index_t i = a.indices[p];
        const double x = a.values[p];
        if (!std::isfinite(x)) not_finite.store(true, std::memory_order_relaxed);
        const double v = std::abs(x);
        const double y = scale ? x * an.row_scaling[i] * an.col_scaling[j] : x;
        scaled[p] = y;
        acc[0][i] += v;
        if (sym) {
          if (i != j) acc[0][j] += v;
          if (scale) {
            acc[1][j] += std::abs(y);
            if (i != j) acc[1][i] += std::abs(y);
          }
        } else {
          col[j] += v;
          scol[j] += std::abs(y);
        }
      });
  if (not_finite) throw_first_not_finite(a);
  throw_if_norm_overflows(sums[0], col);
  ValueNorms r;
  for (double x : sums[0]) r.norm_inf = std::max(r.norm_inf, x);
  if (sym && !scale)
    r.scaled_norm1 = r.norm_inf;
  else
    for (double x : sym ? sums[1] : scol) r.scaled_norm1 = std::max(r.scaled_norm1, x);
  return r;
}

// ‖A‖∞ (max row sum) of a canonical matrix with symmetric storage expanded.
double norm_inf(const SparseMatrix& c) {
  std::vector<double> row(c.n_rows, 0.0);
  for (index_t j = 0; j < c.n_cols; ++j)
    for (index_t p = c.offsets[j]; p < c.offsets[j + 1]; ++p) {
      const double v = std::abs(c.values[p]);
      row[c.indices[p]] += v;
      if (c.storage != Storage::full && c.indices[p] != j) row[j] += v;
    }
  double m = 0;
  for (double r : row) m = std::max(m, r);
  return m;
}

// Refuses a matrix whose row or column magnitude sums overflow: ‖A‖∞ and ‖A‖₁ set the
// static pivot threshold and the backward error, and an infinite norm would make every
// pivot "tiny" and every backward error 0. (Each value is finite — validate checked —
// but a few values near DBL_MAX can sum past it.)
// Throws InvalidInput naming the first row, then column, whose magnitude sum is not finite.
void throw_if_norm_overflows(const std::vector<double>& row, const std::vector<double>& col) {
  for (std::size_t k = 0; k < row.size() + col.size(); ++k) {
    const bool is_row = k < row.size();
    const double sum = is_row ? row[k] : col[k - row.size()];
    if (!std::isfinite(sum))
      throw InvalidInput("the matrix norm overflows: the magnitudes in " +
                         std::string(is_row ? "row " : "column ") +
                         std::to_string(is_row ? k : k - row.size()) +
                         " (0-based) sum past the largest double (1.8e308); scale the matrix");
  }
}

void check_norms(const SparseMatrix& c) {
  std::vector<double> row(c.n_rows, 0.0), col(c.n_cols, 0.0);
  for (index_t j = 0; j < c.n_cols; ++j)
    for (index_t p = c.offsets[j]; p < c.offsets[j + 1]; ++p) {
      const double v = std::abs(c.values[p]);
      row[c.indices[p]] += v;
      col[j] += v;
      if (c.storage != Storage::full && c.indices[p] != j) {
        row[j] += v;
        col[c.indices[p]] += v;
      }
    }
  throw_if_norm_overflows(row, col);
}

void copy_values(std::vector<double>& to, const std::vector<double>& from, tbb::task_arena& arena) {
  if (to.size() != from.size() || from.size() < 2 * kParallelChunk) {
    to = from;
    return;
  }
  arena.execute([&] { parallel_copy(to.data(), from.data(), from.size()); });
}

bool has_analyzed_pattern(const Analysis& an, const SparseMatrix& a, tbb::task_arena& arena) {
  return a.n_rows == an.n && a.n_cols == an.n && a.layout == Layout::csc &&
         a.storage != Storage::upper && a.values.size() == a.indices.size() &&
         equal_arrays(a.offsets, an.pattern_offsets, arena) &&
         equal_arrays(a.indices, an.pattern_indices, arena);
}

// Whether the analysis's matching scaling hit its clamp (ordering/matching.cpp: factors
// within e^±700) for some row or column.
bool scaling_clamped(const Analysis& an) {
  constexpr double kNearClamp = 1e300;
  for (const auto* v : {&an.row_scaling, &an.col_scaling})
    for (double d : *v)
      if (d > kNearClamp || d < 1 / kNearClamp) return true;
  return false;
}

// ‖B‖₁ of the scaled values (entry order of the canonical `c`; symmetric: lower storage,
// mirrored), by blocked_sums on the arena (work: its scratch).
double scaled_norm1(const SparseMatrix& c, bool symmetric, const std::vector<double>& scaled,
                    tbb::task_arena& arena, std::vector<double>& work) {
  const auto col =
      blocked_sums(c, 1, symmetric, arena, work, [&](index_t j, index_t p, double* const* sum) {
        const double v = std::abs(scaled[p]);
        sum[0][j] += v;
        if (symmetric && c.indices[p] != j) sum[0][c.indices[p]] += v;
      });
  double m = 0;
  for (double v : col[0]) m = std::max(m, v);
  return m;
}

}  // namespace strata::detail
