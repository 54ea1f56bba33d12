// strata — power-of-two Ruiz equilibration of a refactorization's values (see rescale.hpp).
#include "core/rescale.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>

namespace strata {
namespace {

// The power of two nearest to 1/√x (x > 0): an exact scale factor.
double inverse_sqrt_pow2(double x) {
  int e = 0;
  std::frexp(x, &e);  // x = f·2^e, f in [1/2, 1)
  return std::ldexp(1.0, -((e - 1) / 2));
}

// Entries from which the passes run in column blocks on the arena's threads, and the
// number of blocks (fixed, so that the work array's size does not depend on the threads).
constexpr index_t kParallelEntries = 1 << 16;
constexpr int kBlocks = 8;

}  // namespace

bool within_factor_two(std::span<const double> maxima) {
  for (double v : maxima)
    if (v != 0 && (v < 0.5 || v > 2)) return false;
  return true;
}

std::uint64_t next_rescaling_id() {
  static std::atomic<std::uint64_t> last{0};
  return ++last;
}

Rescaling rescale_values(const SparseMatrix& c, bool symmetric, std::vector<double>& values,
                         int max_sweeps, tbb::task_arena* arena, std::vector<double>* work,
                         std::span<const double> row_max, std::span<const double> col_max) {
  const index_t n = c.n_cols;
  const std::size_t rows = static_cast<std::size_t>(c.n_rows);
  Rescaling out;
  std::vector<double> rmax(rows), cmax(n);
  // Column blocks: each takes the maxima of its columns and, in a row array of its own,
  // of its rows; the row arrays are then reduced by max, so the result does not depend
  // on the threads (max is exact and commutative).
  const bool parallel =
      arena && work && c.nnz() >= kParallelEntries && rows == static_cast<std::size_t>(n);
  const int blocks = parallel ? kBlocks : 1;
  if (parallel && work->size() < blocks * rows) work->resize(blocks * rows);
  auto block_range = [&](int b) {
    return static_cast<index_t>(static_cast<std::int64_t>(n) * b / blocks);
  };
  // the maxima of |B| of column block b (row maxima into r), after scaling B by
  // diag(rs)·B·diag(cs) when rs is given (a sweep's scaling and the next sweep's maxima in
  // one pass over the values)
  auto block_maxima = [&](int b, double* r, const double* rs, const double* cs) {
    std::fill(r, r + rows, 0.0);
    for (index_t j = block_range(b); j < block_range(b + 1); ++j) {
      double cm = 0;
      for (index_t p = c.offsets[j]; p < c.offsets[j + 1]; ++p) {
        const index_t i = c.indices[p];
        if (rs) values[p] *= rs[i] * cs[j];
        const double v = std::abs(values[p]);
        r[i] = std::max(r[i], v);
        cm = std::max(cm, v);
        if (symmetric) r[j] = std::max(r[j], v);  // the mirrored entry (j, i): row j
      }
      cmax[j] = cm;
    }
  };
  auto maxima = [&](const double* rs, const double* cs) {
    if (!parallel) {
      block_maxima(0, rmax.data(), rs, cs);
    } else {
      arena->execute([&] {
        tbb::parallel_for(0, blocks,
                          [&](int b) { block_maxima(b, work->data() + b * rows, rs, cs); });
        tbb::parallel_for(tbb::blocked_range<std::size_t>(0, rows, 8192),
                          [&](const tbb::blocked_range<std::size_t>& r) {
                            for (std::size_t i = r.begin(); i < r.end(); ++i) {
                              double m = 0;
                              for (int b = 0; b < blocks; ++b)
                                m = std::max(m, (*work)[b * rows + i]);
                              rmax[i] = m;
                            }
                          });
      });
    }
    if (symmetric)  // the mirrored entries: column i's maximum is row i's
      for (index_t j = 0; j < n; ++j) cmax[j] = rmax[j] = std::max(rmax[j], cmax[j]);
  };
  if (row_max.size() == rows && (symmetric || col_max.size() == static_cast<std::size_t>(n))) {
    std::copy(row_max.begin(), row_max.end(), rmax.begin());
    if (symmetric)
      std::copy(row_max.begin(), row_max.end(), cmax.begin());
    else
      std::copy(col_max.begin(), col_max.end(), cmax.begin());
  } else {
    maxima(nullptr, nullptr);
  }
  if (within_factor_two(rmax) && within_factor_two(cmax)) return out;
  out.row.assign(c.n_rows, 1.0);
  out.col.assign(n, 1.0);
  std::vector<double> r(c.n_rows), s(n);
  while (out.sweeps < max_sweeps) {
    for (index_t i = 0; i < c.n_rows; ++i) r[i] = rmax[i] > 0 ? inverse_sqrt_pow2(rmax[i]) : 1.0;
    for (index_t j = 0; j < n; ++j) s[j] = cmax[j] > 0 ? inverse_sqrt_pow2(cmax[j]) : 1.0;
    for (index_t i = 0; i < c.n_rows; ++i) out.row[i] *= r[i];
    for (index_t j = 0; j < n; ++j) out.col[j] *= s[j];
    ++out.sweeps;
    // symmetric: the maxima are mirrored, so r == s and D·B·D stays symmetric
    if (out.sweeps == max_sweeps) {  // the last sweep: its scaling alone
      auto scale = [&](index_t j0, index_t j1) {
        for (index_t j = j0; j < j1; ++j)
          for (index_t p = c.offsets[j]; p < c.offsets[j + 1]; ++p)
            values[p] *= r[c.indices[p]] * s[j];
      };
      if (!parallel)
        scale(0, n);
      else
        arena->execute([&] {
          tbb::parallel_for(0, blocks, [&](int b) { scale(block_range(b), block_range(b + 1)); });
        });
      break;
    }
    maxima(r.data(), s.data());
    if (within_factor_two(rmax) && within_factor_two(cmax)) break;
  }
  return out;
}

void apply_rescaling(const SparseMatrix& c, const Rescaling& r, std::vector<double>& values,
                     tbb::task_arena* arena) {
  if (r.row.empty()) return;
  const index_t n = c.n_cols;
  auto scale = [&](index_t j0, index_t j1) {
    for (index_t j = j0; j < j1; ++j)
      for (index_t p = c.offsets[j]; p < c.offsets[j + 1]; ++p)
        values[p] *= r.row[c.indices[p]] * r.col[j];
  };
  if (!arena || c.nnz() < kParallelEntries) {
    scale(0, n);
    return;
  }
  arena->execute([&] {
    tbb::parallel_for(0, kBlocks, [&](int b) {
      scale(static_cast<index_t>(static_cast<std::int64_t>(n) * b / kBlocks),
            static_cast<index_t>(static_cast<std::int64_t>(n) * (b + 1) / kBlocks));
    });
  });
}

}  // namespace strata
