// strata — the host passes over a factorization's values (see value_pass.hpp).
#include "core/value_pass.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>

#include "base/host_copy.hpp"
#include "core/rescale.hpp"
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

}  // namespace

void throw_first_not_finite(const SparseMatrix& a, const double* values) {
  const std::size_t nnz = a.indices.size();
  std::size_t p = 0;
  while (p + 1 < nnz && std::isfinite(values[p])) ++p;
  const index_t j = static_cast<index_t>(
      std::upper_bound(a.offsets.begin(), a.offsets.end(), static_cast<index_t>(p)) -
      a.offsets.begin() - 1);
  throw InvalidInput("values[" + std::to_string(p) + "] is not finite (row " +
                     std::to_string(a.indices[p]) + ", column " + std::to_string(j) + ")");
}

namespace {

// One column range [j0, j1) of refactor_values' pass (Sym: `a` holds a lower triangle,
// each off-diagonal entry also counted in its mirrored row; Scale: B = Dr·A·Dc, else B =
// A). Per range: row sums of |a| in rx, of |b| in ry (Sym && Scale), row maxima of |b| in
// rm (Scale), all zero-filled here from row `first` on (rows below it are not written);
// per column (unsymmetric): its sums of |a| and |b| and its maximum of |b|. Returns
// whether some value is not finite. The loops keep every pointer and flag in registers:
// the pass is a large share of a multibody refactorization on the GPU.
template <bool Sym, bool Scale>
bool value_range(const SparseMatrix& a, const double* val, const double* rs, const double* cs,
                 index_t j0, index_t j1, std::size_t first, double* scaled, double* rx, double* ry,
                 double* rm, double* cx, double* cy, double* cm) {
  const auto n = static_cast<std::size_t>(a.n_cols);
  std::fill(rx + first, rx + n, 0.0);
  if (Sym && Scale) std::fill(ry + first, ry + n, 0.0);
  if (Scale) std::fill(rm + first, rm + n, 0.0);
  const index_t* off = a.offsets.data();
  const index_t* idx = a.indices.data();
  bool bad = false;
  for (index_t j = j0; j < j1; ++j) {
    const double cj = Scale ? cs[j] : 1.0;
    double sx = 0, sy = 0, my = 0;  // column j's |a| and |b| sums, its |b| maximum
    for (index_t p = off[j]; p < off[j + 1]; ++p) {
      const index_t i = idx[p];
      const double x = val[p];
      const double v = std::abs(x);
      bad |= !(v <= std::numeric_limits<double>::max());  // NaN or ±inf
      const double y = Scale ? x * rs[i] * cj : x;
      scaled[p] = y;
      const double w = std::abs(y);
      rx[i] += v;
      if (Scale) rm[i] = std::max(rm[i], w);
      if (Sym) {                 // added entry by entry, in the order of blocked_sums' passes
        if (i != j) rx[j] += v;  // the mirrored entry (j, i)
        if (Scale) {
          ry[j] += w;
          if (i != j) {
            ry[i] += w;
            rm[j] = std::max(rm[j], w);
          }
        }
      } else {
        sx += v;
        sy += w;
        if (Scale) my = std::max(my, w);
      }
    }
    if (!Sym) {
      cx[j] = sx;
      cy[j] = sy;
      if (Scale) cm[j] = my;
    }
  }
  return bad;
}

template <bool Sym, bool Scale>
ValueNorms refactor_pass(const Analysis& an, const SparseMatrix& a, const double* values,
                         tbb::task_arena& arena, std::vector<double>& work,
                         std::vector<double>& scaled) {
  const std::size_t n = static_cast<std::size_t>(a.n_cols);
  constexpr int kArrays = 1 + (Sym && Scale) + Scale;  // rx, ry, rm per range
  if (work.size() < kValueBlocks * kArrays * n)
    sized_resize(work, kValueBlocks * kArrays * n, "factorize: value sums");
  std::vector<double> cx(Sym ? 0 : n), cy(Sym ? 0 : n), cm(Sym || !Scale ? 0 : n);
  const double* rs = Scale ? an.row_scaling.data() : nullptr;
  const double* cs = Scale ? an.col_scaling.data() : nullptr;
  std::size_t first[kValueBlocks];  // Sym: rows below it are not the range's
  bool bad[kValueBlocks] = {};
  for (int blk = 0; blk < kValueBlocks; ++blk)
    first[blk] = Sym ? static_cast<std::size_t>(range_begin(n, blk)) : 0;
  auto array = [&](int blk, int k) { return work.data() + (blk * kArrays + k) * n; };
  auto range = [&](int blk) {
    double* rx = array(blk, 0);
    double* ry = Sym && Scale ? array(blk, 1) : nullptr;
    double* rm = Scale ? array(blk, kArrays - 1) : nullptr;
    bad[blk] = value_range<Sym, Scale>(a, values, rs, cs, range_begin(n, blk),
                                       range_begin(n, blk + 1), first[blk], scaled.data(), rx, ry,
                                       rm, cx.data(), cy.data(), cm.data());
  };
  // the ranges' rows added (maxima: taken) in range order, into range 0's arrays
  auto reduce = [&](std::size_t i0, std::size_t i1) {
    for (int k = 0; k < kArrays; ++k) {
      const bool max = Scale && k == kArrays - 1;
      for (std::size_t i = i0; i < i1; ++i) {
        double t = array(0, k)[i];
        for (int blk = 1; blk < kValueBlocks; ++blk)
          if (first[blk] <= i) t = max ? std::max(t, array(blk, k)[i]) : t + array(blk, k)[i];
        array(0, k)[i] = t;
      }
    }
  };
  for_value_ranges(static_cast<std::size_t>(a.nnz()), n, arena, range, reduce);
  if (std::any_of(bad, bad + kValueBlocks, [](bool b) { return b; }))
    throw_first_not_finite(a, values);
  const double* rx = array(0, 0);
  throw_if_norm_overflows({rx, n}, cx);
  ValueNorms r;
  for (std::size_t i = 0; i < n; ++i) r.norm_inf = std::max(r.norm_inf, rx[i]);
  if (!Scale) {
    r.scaled_norm1 = r.norm_inf;  // symmetric: ‖A‖₁ = ‖A‖∞
    if (!Sym) r.scaled_norm1 = *std::max_element(cx.begin(), cx.end());
    return r;
  }
  const double* ry = Sym ? array(0, 1) : cy.data();
  for (std::size_t j = 0; j < n; ++j) r.scaled_norm1 = std::max(r.scaled_norm1, ry[j]);
  r.equilibrated = within_factor_two({array(0, kArrays - 1), n}) && (Sym || within_factor_two(cm));
  if (!r.equilibrated) {  // for rescale_values, which would otherwise take them again
    r.row_max.assign(array(0, kArrays - 1), array(0, kArrays - 1) + n);
    if (!Sym) r.col_max = std::move(cm);
  }
  return r;
}

}  // namespace

std::size_t refactor_work_size(const Analysis& an) {
  const bool scale = !an.row_scaling.empty();
  const std::size_t arrays = 1 + (an.symmetric && scale) + scale;
  return kValueBlocks * arrays * static_cast<std::size_t>(an.n);
}

ValueNorms refactor_values(const Analysis& an, const SparseMatrix& a, const double* values,
                           tbb::task_arena& arena, std::vector<double>& work,
                           std::vector<double>& scaled) {
  sized_resize(scaled, a.indices.size(), "factorize: scaled values");
  if (a.indices.empty()) return {};
  const bool scale = !an.row_scaling.empty();
  if (an.symmetric)
    return scale ? refactor_pass<true, true>(an, a, values, arena, work, scaled)
                 : refactor_pass<true, false>(an, a, values, arena, work, scaled);
  return scale ? refactor_pass<false, true>(an, a, values, arena, work, scaled)
               : refactor_pass<false, false>(an, a, values, arena, work, scaled);
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
void throw_if_norm_overflows(std::span<const double> row, std::span<const double> col) {
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

void check_norms(const SparseMatrix& c) { check_norms(c, c.values.data()); }

void check_norms(const SparseMatrix& c, const double* values) {
  std::vector<double> row(c.n_rows, 0.0), col(c.n_cols, 0.0);
  for (index_t j = 0; j < c.n_cols; ++j)
    for (index_t p = c.offsets[j]; p < c.offsets[j + 1]; ++p) {
      const double v = std::abs(values[p]);
      row[c.indices[p]] += v;
      col[j] += v;
      if (c.storage != Storage::full && c.indices[p] != j) {
        row[j] += v;
        col[c.indices[p]] += v;
      }
    }
  throw_if_norm_overflows(row, col);
}

void copy_values(std::vector<double>& to, std::span<const double> from, tbb::task_arena& arena) {
  if (to.size() != from.size()) {
    to.assign(from.begin(), from.end());
    return;
  }
  copy_range(to.data(), from.data(), from.size(), arena);
}

std::vector<index_t> input_entry_map(const Analysis& an, const SparseMatrix& a) {
  std::vector<index_t> map(a.indices.size(), -1);
  const bool csc = a.layout == Layout::csc;
  const index_t outer = csc ? a.n_cols : a.n_rows;
  for (index_t o = 0; o < outer; ++o)
    for (index_t p = a.offsets[o]; p < a.offsets[o + 1]; ++p) {
      index_t r = csc ? a.indices[p] : o, c = csc ? o : a.indices[p];
      if (an.symmetric) {
        if (a.storage == Storage::upper) std::swap(r, c);
        if (r < c) continue;  // full storage: the lower triangle is the one kept
      }
      const auto begin = an.pattern_indices.begin() + an.pattern_offsets[c];
      const auto end = an.pattern_indices.begin() + an.pattern_offsets[c + 1];
      const auto at = std::lower_bound(begin, end, r);
      if (at == end || *at != r)
        throw InternalError("input_entry_map: entry (" + std::to_string(r) + ", " +
                            std::to_string(c) + ") is not in the analyzed pattern");
      map[p] = static_cast<index_t>(at - an.pattern_indices.begin());
    }
  return map;
}

void copy_range(double* to, const double* from, std::size_t n, tbb::task_arena& arena) {
  if (n < 2 * kParallelChunk) {
    std::copy(from, from + n, to);
    return;
  }
  arena.execute([&] { parallel_copy(to, from, n); });
}

void stage_range(double* to, const double* from, std::size_t n, tbb::task_arena& arena,
                 const std::function<void(std::size_t, std::size_t)>& done) {
  constexpr std::size_t kPiece = std::size_t{1} << 17;  // doubles: 1 MiB
  if (n < 2 * kPiece) {
    std::copy(from, from + n, to);
    done(0, n);
    return;
  }
  arena.execute([&] {
    tbb::parallel_for(std::size_t{0}, (n + kPiece - 1) / kPiece, [&](std::size_t c) {
      const std::size_t b = c * kPiece, e = std::min(n, b + kPiece);
      std::copy(from + b, from + e, to + b);
      done(b, e);
    });
  });
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
