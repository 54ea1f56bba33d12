// strata — the device code of the triangular solves (solve_kernels.cu), in a header of its
// own so that the CPU tests can also compile it for the host and run it with one OS thread
// per CUDA thread (tests/unit/test_solve_kernel_emulation.cpp checks the index arithmetic,
// the barrier placement and the warp exchanges in CI against the CPU solve). Only
// solve_kernels.cu and that test include this file. It uses nothing from CUDA but
// threadIdx/blockDim, __syncthreads, __shfl_sync, __shfl_down_sync and __device__.
//
// Per front (m rows, k pivots; panel L column-major m×k, leading dimension m; W the
// front's block of the scratch, m×nrhs with leading dimension m, at row_offsets[f]·nrhs):
//   gather (forward)   W(i) = x at the pivot row as factored (i < k; 0 below) + the
//                      children's update entries at that row (SolvePlan::inv_*);
//   sweep (forward)    W[0:k] ← L11⁻¹ W[0:k], W[k:m] −= L21 W[0:k] — by tiles of 32 pivot
//                      columns: one warp solves a tile's triangle per right-hand side
//                      (register shuffles, no block barrier), then every thread updates
//                      the rows below the tile with a 32-wide dot product; two barriers
//                      per tile instead of one or two per pivot;
//   scatter (forward)  W[0:k] → x (LU: at the column positions), W[k:m] → the front's
//                      update vector;
//   gather (backward)  W = x at the front's rows (col(i): LU pivots at their column
//                      positions, otherwise the rows as factored);
//   sweep (backward)   LLᵀ/LDLᵀ left-looking by tiles from the last: the tile's columns
//                      take the dot products of L(solved rows, j) with W (one warp per
//                      column and right-hand side — coalesced reads of L's columns, L21ᵀ
//                      included), then a warp solves the tile's L11ᵀ triangle; LU right-
//                      looking: W[0:k] −= U12 W[k:m] (one thread per row, coalesced), then
//                      per tile from the last a warp solves U11's triangle and every thread
//                      updates the rows above;
//   scatter (backward) W[0:k] → x;
//   diagonal (LDLᵀ)    x ← D⁻¹ x, 1×1 and 2×2 blocks by pivot position.
// Every thread of a block reaches every __syncthreads() (loop trip counts depend only on
// m, k, nrhs); every lane of a warp reaches every shuffle (the loops around them are
// uniform within a warp). blockDim.x must be a multiple of 32.
#pragma once

#include <cstdint>

#include "numeric/cuda/solve_plan.hpp"

// Internal linkage: see ldlt_device.cuh (nvcc's host stubs of __device__ functions).
namespace strata::cuda::solve_device {
namespace {

constexpr int kWarp = 32;
constexpr std::int64_t kTile = 32;  // pivot columns per tile: one warp's triangle
constexpr unsigned kFullMask = 0xffffffffu;

__device__ std::int64_t min64(std::int64_t a, std::int64_t b) { return a < b ? a : b; }

/// Forward gather of rows [i0, i1) of front f, all right-hand sides.
__device__ void gather_forward(const SolveTree& t, std::int64_t f, std::int64_t i0, std::int64_t i1,
                               const double* x, const double* u, double* scratch,
                               std::int64_t nrhs) {
  const std::int64_t m = t.n_rows[f], k = t.n_pivots[f], fp = t.first_pivot[f];
  const std::int64_t ro = t.row_offsets[f];
  const std::int64_t* prow = t.rows + ro;
  double* W = scratch + ro * nrhs;
  const std::int64_t len = i1 - i0;
  for (std::int64_t e = threadIdx.x; e < len * nrhs; e += blockDim.x) {
    const std::int64_t i = i0 + e % len, r = e / len;
    // the row's place in the front's column order: pivot rows were permuted within the
    // pivots (prow[i] is one of fp..fp+k−1), the others stay
    const std::int64_t p = i < k ? prow[i] - fp : i;
    double v = i < k ? x[prow[i] + r * t.n] : 0.0;
    for (std::int64_t s = t.inv_offsets[ro + p]; s < t.inv_offsets[ro + p + 1]; ++s)
      v += u[t.inv_src[s] + r * t.u_total];
    W[i + r * m] = v;
  }
}

/// Forward scatter of rows [i0, i1) of front f: pivots to x, the rest to u_f.
__device__ void scatter_forward(const SolveTree& t, std::int64_t f, std::int64_t i0,
                                std::int64_t i1, double* x, double* u, const double* scratch,
                                std::int64_t nrhs, bool lu) {
  const std::int64_t m = t.n_rows[f], k = t.n_pivots[f], fp = t.first_pivot[f];
  const std::int64_t ro = t.row_offsets[f];
  const std::int64_t* prow = t.rows + ro;
  const double* W = scratch + ro * nrhs;
  const std::int64_t len = i1 - i0;
  for (std::int64_t e = threadIdx.x; e < len * nrhs; e += blockDim.x) {
    const std::int64_t i = i0 + e % len, r = e / len;
    const double v = W[i + r * m];
    if (i < k)
      x[(lu ? fp + i : prow[i]) + r * t.n] = v;
    else
      u[t.u_offset[f] + i - k + r * t.u_total] = v;
  }
}

// Where row i of front f lives in x during the backward sweep.
__device__ std::int64_t backward_col(const std::int64_t* prow, std::int64_t fp, std::int64_t k,
                                     std::int64_t i, bool lu) {
  return lu && i < k ? fp + i : prow[i];
}

/// Backward gather of rows [i0, i1) of front f.
__device__ void gather_backward(const SolveTree& t, std::int64_t f, std::int64_t i0,
                                std::int64_t i1, const double* x, double* scratch,
                                std::int64_t nrhs, bool lu) {
  const std::int64_t m = t.n_rows[f], k = t.n_pivots[f], fp = t.first_pivot[f];
  const std::int64_t ro = t.row_offsets[f];
  const std::int64_t* prow = t.rows + ro;
  double* W = scratch + ro * nrhs;
  const std::int64_t len = i1 - i0;
  for (std::int64_t e = threadIdx.x; e < len * nrhs; e += blockDim.x) {
    const std::int64_t i = i0 + e % len, r = e / len;
    W[i + r * m] = x[backward_col(prow, fp, k, i, lu) + r * t.n];
  }
}

/// Backward scatter of the pivot rows among [i0, i1) of front f.
__device__ void scatter_backward(const SolveTree& t, std::int64_t f, std::int64_t i0,
                                 std::int64_t i1, double* x, const double* scratch,
                                 std::int64_t nrhs, bool lu) {
  const std::int64_t m = t.n_rows[f], k = t.n_pivots[f], fp = t.first_pivot[f];
  const std::int64_t ro = t.row_offsets[f];
  const std::int64_t* prow = t.rows + ro;
  const double* W = scratch + ro * nrhs;
  const std::int64_t end = min64(i1, k);
  const std::int64_t len = end > i0 ? end - i0 : 0;
  for (std::int64_t e = threadIdx.x; e < len * nrhs; e += blockDim.x) {
    const std::int64_t i = i0 + e % len, r = e / len;
    x[backward_col(prow, fp, k, i, lu) + r * t.n] = W[i + r * m];
  }
}

// One warp solves the w×w triangle T (leading dimension m) for right-hand sides
// r = warp, warp + nwarps, ...: lower (forward, T(i,j) below the diagonal), or upper
// stored as the transpose of a lower triangle (transposed: Tᵀ of L11), or upper as
// stored (U11). Lane t holds W(j0 + t).
__device__ void warp_triangle(const double* T, std::int64_t m, std::int64_t w, double* W0,
                              std::int64_t nrhs, bool lower, bool transposed, bool unit) {
  const int lane = threadIdx.x % kWarp;
  const std::int64_t warp = threadIdx.x / kWarp, nwarps = blockDim.x / kWarp;
  for (std::int64_t r = warp; r < nrhs; r += nwarps) {
    double* Wr = W0 + r * m;
    double v = lane < w ? Wr[lane] : 0.0;
    if (lower) {
      for (int j = 0; j < w; ++j) {
        if (!unit && lane == j) v /= T[j + j * m];
        const double vj = __shfl_sync(kFullMask, v, j);
        if (lane > j && lane < w) v -= T[lane + j * m] * vj;
      }
    } else {
      for (int j = static_cast<int>(w) - 1; j >= 0; --j) {
        if (!unit && lane == j) v /= T[j + j * m];
        const double vj = __shfl_sync(kFullMask, v, j);
        // upper entry (lane, j): U11 as stored, or L11(j, lane) for L11ᵀ
        if (lane < j) v -= (transposed ? T[j + lane * m] : T[lane + j * m]) * vj;
      }
    }
    if (lane < w) Wr[lane] = v;
  }
}

/// Forward sweep of one front (W gathered). `unit`: L11 has a unit diagonal.
__device__ void sweep_forward(const SolveTree& t, std::int64_t f, double* scratch,
                              std::int64_t nrhs, bool unit) {
  const std::int64_t m = t.n_rows[f], k = t.n_pivots[f];
  const double* L = t.panels + t.panel_offset[f];
  double* W = scratch + t.row_offsets[f] * nrhs;
  for (std::int64_t j0 = 0; j0 < k; j0 += kTile) {
    const std::int64_t w = min64(kTile, k - j0);
    warp_triangle(L + j0 * m + j0, m, w, W + j0, nrhs, true, false, unit);
    __syncthreads();
    // rows below the tile: W(i) −= L(i, tile)·W(tile)
    const std::int64_t i0 = j0 + w, below = m - i0;
    for (std::int64_t e = threadIdx.x; e < below * nrhs; e += blockDim.x) {
      const std::int64_t i = i0 + e % below, r = e / below;
      const double* Wt = W + r * m + j0;
      const double* Li = L + j0 * m + i;
      double s = 0.0;
      for (std::int64_t j = 0; j < w; ++j) s += Li[j * m] * Wt[j];
      W[i + r * m] -= s;
    }
    __syncthreads();
  }
}

/// Backward sweep of one front (W gathered): L11ᵀ (LLᵀ, LDLᵀ) or U11 (LU).
__device__ void sweep_backward(const SolveTree& t, std::int64_t f, double* scratch,
                               std::int64_t nrhs, bool lu, bool unit) {
  const std::int64_t m = t.n_rows[f], k = t.n_pivots[f];
  if (k == 0) return;  // uniform across the block
  const double* L = t.panels + t.panel_offset[f];
  double* W = scratch + t.row_offsets[f] * nrhs;
  const int lane = threadIdx.x % kWarp;
  const std::int64_t warp = threadIdx.x / kWarp, nwarps = blockDim.x / kWarp;
  if (lu) {
    // W[0:k] −= U12 W[k:m]; U12 is k×(m−k) with leading dimension k
    const double* U12 = L + m * k;
    const std::int64_t rest = m - k;
    for (std::int64_t e = threadIdx.x; e < k * nrhs; e += blockDim.x) {
      const std::int64_t i = e % k, r = e / k;
      const double* Wr = W + r * m + k;
      double s = 0.0;
      for (std::int64_t j = 0; j < rest; ++j) s += U12[i + j * k] * Wr[j];
      W[i + r * m] -= s;
    }
    __syncthreads();
  }
  for (std::int64_t j0 = (k - 1) / kTile * kTile; j0 >= 0; j0 -= kTile) {
    const std::int64_t w = min64(kTile, k - j0);
    if (lu) {
      warp_triangle(L + j0 * m + j0, m, w, W + j0, nrhs, false, false, false);
      __syncthreads();
      // rows above the tile: W(i) −= U(i, tile)·W(tile)
      for (std::int64_t e = threadIdx.x; e < j0 * nrhs; e += blockDim.x) {
        const std::int64_t i = e % j0, r = e / j0;
        const double* Wt = W + r * m + j0;
        const double* Ui = L + j0 * m + i;
        double s = 0.0;
        for (std::int64_t j = 0; j < w; ++j) s += Ui[j * m] * Wt[j];
        W[i + r * m] -= s;
      }
      __syncthreads();
    } else {
      // the tile's columns: W(j) −= L(i0:m, j)·W(i0:m), rows i0 = j0 + w on are solved
      const std::int64_t i0 = j0 + w;
      for (std::int64_t q = warp; q < w * nrhs; q += nwarps) {
        const std::int64_t j = j0 + q % w, r = q / w;
        const double* Lj = L + j * m;
        double* Wr = W + r * m;
        double s = 0.0;
        for (std::int64_t i = i0 + lane; i < m; i += kWarp) s += Lj[i] * Wr[i];
        for (int off = kWarp / 2; off > 0; off /= 2) s += __shfl_down_sync(kFullMask, s, off);
        if (lane == 0) Wr[j] -= s;
      }
      __syncthreads();
      warp_triangle(L + j0 * m + j0, m, w, W + j0, nrhs, false, true, unit);
      __syncthreads();
    }
  }
}

/// LDLᵀ: x ← D⁻¹ x at pivot position p (a 1×1 pivot, or the first of a 2×2 one; the
/// second of a 2×2 has pivot_size 0 and is done with the first).
__device__ void diagonal(const SolveTree& t, std::int64_t p, const double* d_diag,
                         const double* d_off, const int* pivot_size, double* x, std::int64_t nrhs) {
  const int size = pivot_size[p];
  for (std::int64_t r = 0; r < nrhs; ++r) {
    double* xr = x + r * t.n;
    if (size == 1) {
      xr[t.pivot_row[p]] /= d_diag[p];
    } else if (size == 2) {
      const double a = d_diag[p], b = d_off[p], d = d_diag[p + 1];
      const double det = a * d - b * b;
      double& v0 = xr[t.pivot_row[p]];
      double& v1 = xr[t.pivot_row[p + 1]];
      const double y0 = (d * v0 - b * v1) / det, y1 = (a * v1 - b * v0) / det;
      v0 = y0;
      v1 = y1;
    }
  }
}

}  // namespace
}  // namespace strata::cuda::solve_device
