// strata — the plan of the triangular solves on the device (cuda_solve.cu), host-only
// code with no CUDA in it, so that the CPU tests can run it
// (tests/unit/test_solve_kernel_emulation.cpp).
//
// What: for each level of the schedule, which fronts are solved by one thread block each
// (solve_device.cuh) and which by cuBLAS calls, one front after another on the stream
// (large_front_forward/backward below); the blocks of the level-wide gather and scatter
// kernels; and, for every front row, the children's update-vector entries that add into it.
//
// Why: a thread block streams a panel at a small fraction of the device's bandwidth, so a
// level whose work sits in a few large fronts (the top of a nested-dissection tree) is
// limited by one SM per front; cuBLAS spreads one front over the whole device but costs a
// few microseconds of launch per call, which a level of thousands of small fronts cannot
// afford. The planner picks, per level, the split that minimizes a simple time model
// (see kBlockBytesPerSecond etc.): the largest fronts go to the library as long as that
// shortens the level. Gathering by parent row (the inverse of the children's relative
// positions) lets every thread build its row alone — no ordering between children, no
// atomics, the same summation order as the CPU solve's child-by-child extend-add.
//
// Source: the multifrontal solve of Liu (SIAM Review 34, 1992, §6) on the level schedule
// of the factorization (DESIGN.md §1, §2).
#pragma once

#include <algorithm>
#include <cstdint>
#include <numeric>
#include <vector>

#include "symbolic/symbolic.hpp"

namespace strata::cuda {

/// Device view of what the solve reads (int64, tree numbering, 0-based). Pointers are
/// device pointers on the GPU, host pointers in the emulation test.
struct SolveTree {
  const std::int64_t* n_rows;        ///< per front
  const std::int64_t* n_pivots;      ///< per front
  const std::int64_t* row_offsets;   ///< per front: into rows, inv_offsets; scratch at ×nrhs
  const std::int64_t* first_pivot;   ///< per front
  const std::int64_t* rows;          ///< NumericFactor::rows (pivot rows as factored)
  const std::int64_t* inv_offsets;   ///< per front row (+1): its entries of inv_src
  const std::int64_t* inv_src;       ///< u-arena index of each child entry adding into a row
  const std::int64_t* u_offset;      ///< per front: its update vector in the u arena
  const std::int64_t* panel_offset;  ///< per front: its panel in `panels`
  const double* panels;              ///< the factor (NumericFactor::panels layout)
  const std::int64_t* pivot_row;     ///< per pivot position: the unknown it eliminated
  std::int64_t n;                    ///< unknowns
  std::int64_t u_total;              ///< doubles of the u arena per right-hand side
};

/// Rows of one front handled by one block of the gather and scatter kernels.
constexpr std::int64_t kChunkRows = 256;

// The time model of the planner (seconds, bytes). Estimates for a Hopper GPU, not
// measured per front; they only need to be right within a factor of a few to pick the
// path.
// One 256-thread block streaming a panel: the device's ~3 TB/s over 132 SMs is ~25 GB/s
// per SM when all are busy.
constexpr double kBlockBytesPerSecond = 20e9;
// Per tile of 32 pivot columns, a block's dependent steps (a warp's triangle, two
// barriers): memory latency, not bandwidth.
constexpr double kBlockTileSeconds = 2e-6;
// cuBLAS over one front: most of the device's bandwidth...
constexpr double kLibraryBytesPerSecond = 2e12;
// ...after two library calls' launch and enqueue cost...
constexpr double kLibraryCallSeconds = 8e-6;
// ...plus the triangular solve's sequential dependence, per pivot column.
constexpr double kLibraryPivotSeconds = 2e-8;

/// Which path the planner may choose (the tests force each one).
enum class SolvePath { model, all_block, all_library };

/// The solve plan of one analysis (see the file header). Per level l (schedule order,
/// deepest first): gather/scatter blocks [chunk_offsets[l], chunk_offsets[l+1]) of
/// chunk_front/chunk_row (front, first row); block-solved fronts
/// small_fronts[small_offsets[l]..]; library-solved fronts large_fronts[large_offsets[l]..].
struct SolvePlan {
  std::uint64_t analysis = 0;             ///< Analysis::id it was made for
  int n_sm = 0;                           ///< streaming multiprocessors it was made for
  std::vector<std::int64_t> u_offset;     ///< per front + 1: prefix sums of cb sizes
  std::vector<std::int64_t> inv_offsets;  ///< per front row + 1
  std::vector<std::int64_t> inv_src;
  std::vector<std::int64_t> chunk_offsets{0}, chunk_front, chunk_row;
  std::vector<std::int64_t> small_offsets{0}, small_fronts;
  std::vector<std::int64_t> large_offsets{0}, large_fronts;
};

/// Builds the plan for tree `t` (with its extend-add map `child_rows`, e.g.
/// Analysis::child_rows) and its level schedule `s` on a device of `n_sm` multiprocessors
/// (≥ 1). `path` forces one path for every front (tests); `model` splits each level by
/// the time model above. Deterministic.
inline SolvePlan make_solve_plan(const symbolic::AssemblyTree& t,
                                 const symbolic::ChildRowMap& child_rows,
                                 const symbolic::LevelSchedule& s, int n_sm,
                                 SolvePath path = SolvePath::model) {
  const index_t nf = t.n_fronts();
  SolvePlan p;
  p.n_sm = std::max(n_sm, 1);
  p.u_offset.assign(child_rows.offsets.begin(), child_rows.offsets.end());  // cb sizes' sums

  // inverse extend-add map: for each parent row, the child entries adding into it, in
  // child order (a child contributes at most once to a row)
  const std::size_t nrows = t.rows.size();
  std::vector<std::int64_t> count(nrows + 1, 0), target(p.u_offset[nf]);
  for (index_t f = 0; f < nf; ++f)
    for (index_t q = t.child_offsets[f]; q < t.child_offsets[f + 1]; ++q) {
      const index_t c = t.children[q];
      const index_t* rel = child_rows.of(c);
      for (index_t e = 0; e < t.cb_size(c); ++e) {
        const std::int64_t row = t.row_offsets[f] + rel[e];
        target[p.u_offset[c] + e] = row;
        ++count[row + 1];
      }
    }
  p.inv_offsets.assign(nrows + 1, 0);
  std::partial_sum(count.begin(), count.end(), p.inv_offsets.begin());
  p.inv_src.assign(p.inv_offsets[nrows], 0);
  std::vector<std::int64_t> fill(p.inv_offsets.begin(), p.inv_offsets.end() - 1);
  for (index_t f = 0; f < nf; ++f)  // children in order, so each row's list is in child order
    for (index_t q = t.child_offsets[f]; q < t.child_offsets[f + 1]; ++q) {
      const index_t c = t.children[q];
      for (index_t e = 0; e < t.cb_size(c); ++e) {
        const std::int64_t u = p.u_offset[c] + e;
        p.inv_src[fill[target[u]]++] = u;
      }
    }

  // per level: gather/scatter chunks, and the split between block and library
  auto bytes = [&](index_t f) {
    return 8.0 * static_cast<double>(t.n_rows(f)) * static_cast<double>(t.n_pivots(f));
  };
  auto t_block = [&](index_t f) {
    return bytes(f) / kBlockBytesPerSecond +
           static_cast<double>((t.n_pivots(f) + 31) / 32) * kBlockTileSeconds;
  };
  auto t_library = [&](index_t f) {
    return kLibraryCallSeconds + bytes(f) / kLibraryBytesPerSecond +
           static_cast<double>(t.n_pivots(f)) * kLibraryPivotSeconds;
  };
  std::vector<index_t> order;
  std::vector<double> tail;  // tail[q]: Σ t_block of order[q..]
  for (index_t l = 0; l < s.n_levels(); ++l) {
    order.assign(s.fronts.begin() + s.level_offsets[l], s.fronts.begin() + s.level_offsets[l + 1]);
    for (const index_t f : order)
      for (index_t i0 = 0; i0 < t.n_rows(f); i0 += kChunkRows) {
        p.chunk_front.push_back(f);
        p.chunk_row.push_back(i0);
      }
    p.chunk_offsets.push_back(static_cast<std::int64_t>(p.chunk_front.size()));
    std::stable_sort(order.begin(), order.end(),
                     [&](index_t a, index_t b) { return bytes(a) > bytes(b); });
    const std::size_t nl = order.size();
    tail.assign(nl + 1, 0.0);
    for (std::size_t q = nl; q-- > 0;) tail[q] = tail[q + 1] + t_block(order[q]);
    // level time with the q largest fronts on the library: those one after another, the
    // rest in one launch (its longest block, or its total spread over the SMs)
    std::size_t best = 0;
    if (path == SolvePath::all_library) {
      best = nl;
    } else if (path == SolvePath::model) {
      double lib = 0.0, best_time = 0.0;
      for (std::size_t q = 0; q <= nl; ++q) {
        const double blocks = q < nl ? std::max(t_block(order[q]), tail[q] / p.n_sm) : 0.0;
        const double time = lib + blocks;
        if (q == 0 || time < best_time) {
          best_time = time;
          best = q;
        }
        if (q < nl) lib += t_library(order[q]);
      }
    }
    std::vector<index_t> large(order.begin(), order.begin() + best),
        small(order.begin() + best, order.end());
    std::sort(large.begin(), large.end());
    std::sort(small.begin(), small.end());
    p.large_fronts.insert(p.large_fronts.end(), large.begin(), large.end());
    p.small_fronts.insert(p.small_fronts.end(), small.begin(), small.end());
    p.large_offsets.push_back(static_cast<std::int64_t>(p.large_fronts.size()));
    p.small_offsets.push_back(static_cast<std::int64_t>(p.small_fronts.size()));
  }
  return p;
}

// --- one large front through a BLAS ----------------------------------------------------
//
// `Ops` is cuBLAS on the device (cuda_solve.cu) or the host BLAS in the emulation test:
//   trsv(upper, trans, unit, n, A, lda, x)                 x ← op(A)⁻¹ x
//   trsm(upper, trans, unit, n, nrhs, A, lda, B, ldb)      B ← op(A)⁻¹ B   (left side)
//   gemv(trans, rows, cols, alpha, A, lda, x, beta, y)     y ← α op(A) x + β y, A rows×cols
//   gemm(trans_a, m, n, k, alpha, A, lda, B, ldb, beta, C, ldc)   C ← α op(A) B + β C
// W is the front's gathered block, m×nrhs with leading dimension m; L its panel (m×k,
// leading dimension m; LU: U11 in its upper triangle and U12 after it, k×(m−k) with
// leading dimension k — NumericFactor::panels).

/// Forward: W[0:k] ← L11⁻¹ W[0:k] (unit: LDLᵀ, LU), W[k:m] −= L21 W[0:k].
template <class Ops>
void large_front_forward(Ops& ops, const double* L, int m, int k, int nrhs, bool unit, double* W) {
  if (k == 0) return;
  const int rest = m - k;
  if (nrhs == 1) {
    ops.trsv(false, false, unit, k, L, m, W);
    if (rest > 0) ops.gemv(false, rest, k, -1.0, L + k, m, W, 1.0, W + k);
  } else {
    ops.trsm(false, false, unit, k, nrhs, L, m, W, m);
    if (rest > 0) ops.gemm(false, rest, nrhs, k, -1.0, L + k, m, W, m, 1.0, W + k, m);
  }
}

/// Backward: LLᵀ/LDLᵀ W[0:k] ← L11⁻ᵀ (W[0:k] − L21ᵀ W[k:m]); LU W[0:k] ← U11⁻¹ (W[0:k] −
/// U12 W[k:m]).
template <class Ops>
void large_front_backward(Ops& ops, const double* L, int m, int k, int nrhs, bool lu, bool unit,
                          double* W) {
  if (k == 0) return;
  const int rest = m - k;
  const double* U12 = L + static_cast<std::size_t>(m) * static_cast<std::size_t>(k);
  if (rest > 0) {
    if (lu) {
      if (nrhs == 1)
        ops.gemv(false, k, rest, -1.0, U12, k, W + k, 1.0, W);
      else
        ops.gemm(false, k, nrhs, rest, -1.0, U12, k, W + k, m, 1.0, W, m);
    } else {
      if (nrhs == 1)
        ops.gemv(true, rest, k, -1.0, L + k, m, W + k, 1.0, W);
      else
        ops.gemm(true, k, nrhs, rest, -1.0, L + k, m, W + k, m, 1.0, W, m);
    }
  }
  // LU: U11 upper, never unit; otherwise L11ᵀ
  if (nrhs == 1)
    ops.trsv(lu, !lu, lu ? false : unit, k, L, m, W);
  else
    ops.trsm(lu, !lu, lu ? false : unit, k, nrhs, L, m, W, m);
}

}  // namespace strata::cuda
