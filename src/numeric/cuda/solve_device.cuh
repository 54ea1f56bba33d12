// strata — the device code of the triangular solves (solve_kernels.cu), in a header of its
// own so that the CPU tests can also compile it for the host and run it with one OS thread
// per CUDA thread (tests/unit/test_solve_kernel_emulation.cpp checks the index arithmetic,
// the barrier placement and the warp exchanges in CI against the CPU solve). Only
// solve_kernels.cu and that test include this file. It uses nothing from CUDA but
// threadIdx/blockDim, __syncthreads, __shfl_sync, __shfl_down_sync, __device__ and
// __shared__ (the tile a warp solves), and one cache hint, a PTX prefetch compiled for the
// device only (prefetch_lines).
//
// Per front (m rows, k pivots; panel L column-major m×k, leading dimension m; W the
// front's block of the scratch, m×nrhs with leading dimension m, at row_offsets[f]·nrhs):
//   gather (forward)   W(i) = x at the pivot row as factored (i < k; 0 below) + the
//                      children's update entries at that row (SolvePlan::inv_*);
//   sweep (forward)    W[0:k] ← L11⁻¹ W[0:k], W[k:m] −= L21 W[0:k] — by tiles of 32 pivot
//                      columns: one warp solves a tile's triangle per right-hand side from
//                      the tile's copy in shared memory (register shuffles between its
//                      steps), then the threads update the rows below the tile with
//                      32-wide dot products (a row's columns split over the threads
//                      that fewer rows than threads leave idle: sliced_products) while
//                      the block copies the next tile; two or three barriers per tile
//                      instead of one or two per pivot;
//   scatter (forward)  W[0:k] → x (LU: at the column positions), W[k:m] → the front's
//                      update vector;
//   gather (backward)  W = x at the front's rows (col(i): LU pivots at their column
//                      positions, otherwise the rows as factored);
//   tall fronts        (more than kChunkRows rows, gathered and scattered by chunks of
//                      rows, one block each): the sweeps do the pivot rows only; the
//                      forward scatter's chunks subtract L21's rows times W[0:k] as they
//                      write the update vector, and the backward gather's chunks write
//                      partial products L21ᵀ W[k:m] or U12 W[k:m] of their rows
//                      (backward_partials), which the backward sweep subtracts from W[0:k]
//                      in chunk order — the products, most of a tall front's bytes, spread
//                      over as many blocks as it has chunks;
//   sweep (backward)   LLᵀ/LDLᵀ left-looking by tiles from the last: the tile's columns
//                      take the dot products of L(solved rows, j) with W (one warp per
//                      column and right-hand side — coalesced reads of L's columns, L21ᵀ
//                      included), then a warp solves the tile's L11ᵀ triangle; LU right-
//                      looking: W[0:k] −= U12 W[k:m] (threads down U12's columns,
//                      coalesced, each row's columns sliced over the idle threads), then
//                      per tile from the last a warp solves U11's triangle and every thread
//                      updates the rows above;
//   scatter (backward) W[0:k] → x;
//   diagonal (LDLᵀ)    x ← D⁻¹ x, 1×1 and 2×2 blocks by pivot position.
// front_forward / front_backward chain a front's three steps in one block (the fronts the
// block path solves, alone or a whole subtree one after another in postorder).
// Every thread of a block reaches every __syncthreads() (loop trip counts depend only on
// m, k, nrhs); every lane of a warp reaches every shuffle (the loops around them are
// uniform within a warp). blockDim.x must be a multiple of 32 and at most kChunkRows.
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

// s[0] + … + s[N−1] summed pairwise (N a power of two).
template <int N>
__device__ double pair_sum(const double* s) {
  if constexpr (N == 1)
    return s[0];
  else
    return pair_sum<N / 2>(s) + pair_sum<N / 2>(s + N / 2);
}

// s = Σ_{j<w} A[j·lda]·x[j] with Batch (4 or 16) independent sums, the loads of a batch of
// columns issued before the first multiply waits for one. A thread's loads in flight are
// what keeps the memory busy where few blocks run (a tall front's triangle and products,
// a level's few fronts near the top: 16); launches of many blocks keep 4 (fewer
// registers, more blocks per SM). The last w mod Batch columns go Tail at a time (their
// loads together, added into s[0] in column order): 4 where the registers allow it (a
// tall front's scatter chunks), 1 in the kernels at their register limit.
template <int Batch, int Tail = 1>
__device__ double tile_dot(const double* a, std::int64_t lda, const double* x, std::int64_t w) {
  double s[Batch];
#ifdef __CUDA_ARCH__
#pragma unroll
#endif
  for (int q = 0; q < Batch; ++q) s[q] = 0.0;
  std::int64_t j = 0;
  for (; j + Batch <= w; j += Batch) {
    double av[Batch], xv[Batch];
#ifdef __CUDA_ARCH__
#pragma unroll
#endif
    for (int q = 0; q < Batch; ++q) {
      av[q] = a[(j + q) * lda];
      xv[q] = x[j + q];
    }
#ifdef __CUDA_ARCH__
#pragma unroll
#endif
    for (int q = 0; q < Batch; ++q) s[q] += av[q] * xv[q];
  }
  for (; j < w; j += Tail) {
    double av[Tail], xv[Tail];
#ifdef __CUDA_ARCH__
#pragma unroll
#endif
    for (int q = 0; q < Tail; ++q) {
      av[q] = j + q < w ? a[(j + q) * lda] : 0.0;
      xv[q] = j + q < w ? x[j + q] : 0.0;
    }
#ifdef __CUDA_ARCH__
#pragma unroll
#endif
    for (int q = 0; q < Tail; ++q)
      if (j + q < w) s[0] += av[q] * xv[q];
  }
  return pair_sum<Batch>(s);  // (s0 + s1) + (s2 + s3) for Batch 4
}

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
    // the children's entries four at a time: their indices' loads together, then their
    // values' (two rounds of latency per four entries instead of two per entry), added in
    // child order
    const std::int64_t s0 = t.inv_offsets[ro + p], s1 = t.inv_offsets[ro + p + 1];
    for (std::int64_t s = s0; s < s1; s += 4) {
      std::int64_t src[4];
      double uv[4];
#ifdef __CUDA_ARCH__
#pragma unroll
#endif
      for (int q = 0; q < 4; ++q) src[q] = s + q < s1 ? t.inv_src[s + q] : 0;
#ifdef __CUDA_ARCH__
#pragma unroll
#endif
      for (int q = 0; q < 4; ++q) uv[q] = s + q < s1 ? u[src[q] + r * t.u_total] : 0.0;
#ifdef __CUDA_ARCH__
#pragma unroll
#endif
      for (int q = 0; q < 4; ++q)
        if (s + q < s1) v += uv[q];
    }
    W[i + r * m] = v;
  }
}

/// Forward scatter of rows [i0, i1) of front f: pivots to x, the rest to u_f. Batch: the
/// dot products' (tile_dot). MayBeTall: f may be a tall front (the scatter chunks' kernel;
/// the fronts a block solves whole never are, and their kernels leave the products out).
template <int Batch, bool MayBeTall = true>
__device__ void scatter_forward(const SolveTree& t, std::int64_t f, std::int64_t i0,
                                std::int64_t i1, double* x, double* u, const double* scratch,
                                std::int64_t nrhs, bool lu) {
  const std::int64_t m = t.n_rows[f], k = t.n_pivots[f], fp = t.first_pivot[f];
  const std::int64_t ro = t.row_offsets[f];
  const std::int64_t* prow = t.rows + ro;
  const double* W = scratch + ro * nrhs;
  const double* L = t.panels + t.panel_offset[f];
  const bool tall = t.part_offset[f] >= 0;  // L21's product is this chunk's (see the plan)
  const std::int64_t len = i1 - i0;
  for (std::int64_t e = threadIdx.x; e < len * nrhs; e += blockDim.x) {
    const std::int64_t i = i0 + e % len, r = e / len;
    double v = W[i + r * m];
    if (i < k) {
      x[(lu ? fp + i : prow[i]) + r * t.n] = v;
    } else {
      if constexpr (MayBeTall)
        if (tall) v -= tile_dot<Batch, 4>(L + i, m, W + r * m, k);
      u[t.u_offset[f] + i - k + r * t.u_total] = v;
    }
  }
}

// Where row i of front f lives in x during the backward sweep.
__device__ std::int64_t backward_col(const std::int64_t* prow, std::int64_t fp, std::int64_t k,
                                     std::int64_t i, bool lu) {
  return lu && i < k ? fp + i : prow[i];
}

/// Backward gather of rows [i0, i1) of front f (of a tall front only its pivot rows: the
/// rest enter through backward_partials, which reads them from x).
__device__ void gather_backward(const SolveTree& t, std::int64_t f, std::int64_t i0,
                                std::int64_t i1, const double* x, double* scratch,
                                std::int64_t nrhs, bool lu) {
  const std::int64_t m = t.n_rows[f], k = t.n_pivots[f], fp = t.first_pivot[f];
  const std::int64_t ro = t.row_offsets[f];
  const std::int64_t* prow = t.rows + ro;
  double* W = scratch + ro * nrhs;
  const std::int64_t end = t.part_offset[f] >= 0 ? min64(i1, k) : i1;
  const std::int64_t len = end > i0 ? end - i0 : 0;
  for (std::int64_t e = threadIdx.x; e < len * nrhs; e += blockDim.x) {
    const std::int64_t i = i0 + e % len, r = e / len;
    W[i + r * m] = x[backward_col(prow, fp, k, i, lu) + r * t.n];
  }
}

/// A tall front's partial product of rows [i0, i1) ∩ [k, m) for the backward sweep:
/// P(j) = Σ_i A(j, i) x(i), j < k, with A = L21ᵀ (LLᵀ, LDLᵀ; a warp per j and right-hand
/// side, coalesced down L's columns) or U12 (LU; threads along U12's columns, coalesced),
/// read from x (not W, which other threads of the block are writing), into the chunk's
/// k × nrhs slot of t.part. Nothing for a front that is not tall or a chunk of pivot rows
/// only (uniform across the block: the LU path has barriers). blockDim.x ≤ kChunkRows.
__device__ void backward_partials(const SolveTree& t, std::int64_t f, std::int64_t i0,
                                  std::int64_t i1, const double* x, std::int64_t nrhs, bool lu) {
  const std::int64_t m = t.n_rows[f], k = t.n_pivots[f];
  if (t.part_offset[f] < 0 || i1 <= k || k == 0) return;  // uniform across the block
  const std::int64_t* prow = t.rows + t.row_offsets[f];
  const double* L = t.panels + t.panel_offset[f];
  const std::int64_t lo = i0 > k ? i0 : k;
  double* P = t.part + (t.part_offset[f] + (i0 / kChunkRows - k / kChunkRows) * k) * nrhs;
  if (lu) {
    // the chunk's x entries in shared memory; thread e takes column j = e % k of U12 over
    // the rows of slice e / k (every nsl-th row), and the slices are summed in order, so
    // that a front with few pivots still has every thread of the block reading
    const double* U12 = L + m * k;  // k × (m − k), leading dimension k
    const std::int64_t len = i1 - lo;
    __shared__ double xs[kChunkRows];
    __shared__ double sums[kChunkRows];  // blockDim.x ≤ kChunkRows
    const std::int64_t nsl = k < static_cast<std::int64_t>(blockDim.x) ? blockDim.x / k : 1;
    for (std::int64_t r = 0; r < nrhs; ++r) {
      const double* xr = x + r * t.n;
      for (std::int64_t i = threadIdx.x; i < len; i += blockDim.x) xs[i] = xr[prow[lo + i]];
      __syncthreads();
      for (std::int64_t e = threadIdx.x; e < (nsl > 1 ? nsl * k : k); e += blockDim.x) {
        const std::int64_t j = e % k, sl = e / k;
        const double* u = U12 + j + (lo - k) * k;                  // u[i·k]: U12(j, lo − k + i)
        double acc[8] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0};  // 8 loads in flight
        std::int64_t i = sl;
        for (; i + 7 * nsl < len; i += 8 * nsl)
#ifdef __CUDA_ARCH__
#pragma unroll
#endif
          for (int q = 0; q < 8; ++q) acc[q] += u[(i + q * nsl) * k] * xs[i + q * nsl];
        for (; i < len; i += 4 * nsl) {  // the rest: each four's loads issued together
          double uv[4];
#ifdef __CUDA_ARCH__
#pragma unroll
#endif
          for (int q = 0; q < 4; ++q) uv[q] = i + q * nsl < len ? u[(i + q * nsl) * k] : 0.0;
#ifdef __CUDA_ARCH__
#pragma unroll
#endif
          for (int q = 0; q < 4; ++q)
            if (i + q * nsl < len) acc[0] += uv[q] * xs[i + q * nsl];
        }
        const double sum = pair_sum<8>(acc);
        if (nsl > 1)
          sums[e] = sum;
        else
          P[j + r * k] = sum;
      }
      __syncthreads();
      if (nsl > 1)
        for (std::int64_t j = threadIdx.x; j < k; j += blockDim.x) {
          double v = 0.0;
          for (std::int64_t sl = 0; sl < nsl; ++sl) v += sums[sl * k + j];
          P[j + r * k] = v;
        }
      __syncthreads();  // xs and sums are reused by the next right-hand side
    }
  } else {
    // lane l takes rows lo + l + 32u (u < kChunkRows / 32); their x entries are read once
    // per right-hand side, and a column's loads are all issued before the first is used
    constexpr int kPerLane = static_cast<int>(kChunkRows / kWarp);
    const int lane = threadIdx.x % kWarp;
    const std::int64_t warp = threadIdx.x / kWarp, nwarps = blockDim.x / kWarp;
    for (std::int64_t r = 0; r < nrhs; ++r) {
      const double* xr = x + r * t.n;
      double xv[kPerLane];
      for (int u = 0; u < kPerLane; ++u) {
        const std::int64_t i = lo + lane + u * kWarp;
        xv[u] = i < i1 ? xr[prow[i]] : 0.0;
      }
      for (std::int64_t j = warp; j < k; j += nwarps) {  // uniform across the warp
        const double* Lj = L + j * m;
        double s = 0.0;
        for (int u = 0; u < kPerLane; ++u) {
          const std::int64_t i = lo + lane + u * kWarp;
          s += (i < i1 ? Lj[i] : 0.0) * xv[u];
        }
        for (int off = kWarp / 2; off > 0; off /= 2) s += __shfl_down_sync(kFullMask, s, off);
        if (lane == 0) P[j + r * k] = s;
      }
    }
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

constexpr int kTileLd = kWarp + 1;  // leading dimension of a tile in shared memory

// The block copies the w×w triangle T (leading dimension m) to `tile` (kWarp × kWarp,
// leading dimension kTileLd, zero outside w×w), transposed if asked (tile(i, j) = T(j, i)),
// so that the warp that solves it reads shared memory, not global memory, in each of its
// dependent steps. A thread's entries (four for a block of 256) are all loaded before the
// first is stored, so that their latencies overlap rather than follow one another. A
// barrier must follow before the tile is read.
__device__ void load_tile(const double* T, std::int64_t m, std::int64_t w, double* tile,
                          bool transposed) {
  constexpr int kPer = 4;
  const int step = static_cast<int>(blockDim.x);
  for (int e0 = threadIdx.x; e0 < kWarp * kWarp; e0 += kPer * step) {
    double v[kPer];
#ifdef __CUDA_ARCH__
#pragma unroll
#endif
    for (int q = 0; q < kPer; ++q) {
      const int e = e0 + q * step, i = e % kWarp, j = e / kWarp;
      v[q] = e < kWarp * kWarp && i < w && j < w ? (transposed ? T[j + i * m] : T[i + j * m]) : 0.0;
    }
#ifdef __CUDA_ARCH__
#pragma unroll
#endif
    for (int q = 0; q < kPer; ++q) {
      const int e = e0 + q * step;
      if (e < kWarp * kWarp) tile[e % kWarp + e / kWarp * kTileLd] = v[q];
    }
  }
}

// Products y(q) = Σ_{c<len} a_q[c·lda]·x_q[c] for items q < items, given to done(q, y(q)),
// with the block's idle threads put to work: when items < blockDim.x, the columns of each
// item are split into nsl = blockDim.x / items slices (column c in slice c mod nsl), thread
// e taking item e mod items in slice e / items, and the slices' sums are added in slice
// order after a barrier. Consecutive threads take consecutive items, so the loads of a
// column-major A (a_q = A + row of q) are coalesced; each thread keeps four loads in
// flight, and its last one to three columns' loads go out together. A front's product of
// a few dozen rows by a tile of 32 columns is then one or two rounds of memory latency
// instead of eight. `sums`: shared memory of at least blockDim.x doubles. Every thread of
// the block must call it (the barrier, when nsl > 1, is uniform: nsl depends on items and
// blockDim.x only); done(q, ·) is called once per q, by one thread.
template <class AOf, class XOf, class Done>
__device__ void sliced_products(std::int64_t items, std::int64_t len, std::int64_t lda, AOf a_of,
                                XOf x_of, Done done, double* sums) {
  const std::int64_t threads = blockDim.x;
  const std::int64_t nsl = items > 0 && items < threads ? threads / items : 1;
  for (std::int64_t e = threadIdx.x; e < nsl * items; e += threads) {
    const std::int64_t q = e % items, sl = e / items;
    const double* a = a_of(q);
    const double* x = x_of(q);
    double acc[4] = {0.0, 0.0, 0.0, 0.0};
    std::int64_t c = sl;
    for (; c + 3 * nsl < len; c += 4 * nsl) {
      double av[4], xv[4];
#ifdef __CUDA_ARCH__
#pragma unroll
#endif
      for (int u = 0; u < 4; ++u) {
        av[u] = a[(c + u * nsl) * lda];
        xv[u] = x[c + u * nsl];
      }
#ifdef __CUDA_ARCH__
#pragma unroll
#endif
      for (int u = 0; u < 4; ++u) acc[u] += av[u] * xv[u];
    }
    // at most three columns are left (c + 3·nsl ≥ len): their loads in flight together,
    // then added into acc[0] in column order
    {
      double av[3], xv[3];
#ifdef __CUDA_ARCH__
#pragma unroll
#endif
      for (int u = 0; u < 3; ++u) {
        const std::int64_t cu = c + u * nsl;
        av[u] = cu < len ? a[cu * lda] : 0.0;
        xv[u] = cu < len ? x[cu] : 0.0;
      }
#ifdef __CUDA_ARCH__
#pragma unroll
#endif
      for (int u = 0; u < 3; ++u)
        if (c + u * nsl < len) acc[0] += av[u] * xv[u];
    }
    const double y = pair_sum<4>(acc);
    if (nsl > 1)
      sums[e] = y;
    else
      done(q, y);
  }
  if (nsl > 1) {  // uniform across the block
    __syncthreads();
    for (std::int64_t q = threadIdx.x; q < items; q += threads) {
      double y = 0.0;
      for (std::int64_t sl = 0; sl < nsl; ++sl) y += sums[sl * items + q];
      done(q, y);
    }
  }
}

// One warp solves the w×w triangle of `tile` (load_tile) for right-hand sides r = warp,
// warp + nwarps, ... of W0 (leading dimension m): lower (forward; tile(i, j) below the
// diagonal) or upper (tile(i, j) above it: U11, or L11ᵀ loaded transposed). Lane t holds
// W(j0 + t). `unit`: the diagonal is 1 and not read; otherwise each lane multiplies by its
// pivot's reciprocal, computed before the w dependent steps (a division in each step
// would lengthen the chain). w ≤ kWarp is uniform across the warp, so every lane reaches
// every shuffle.
__device__ void warp_triangle(const double* tile, std::int64_t m, std::int64_t w, double* W0,
                              std::int64_t nrhs, bool lower, bool unit) {
  const int lane = threadIdx.x % kWarp;
  const std::int64_t warp = threadIdx.x / kWarp, nwarps = blockDim.x / kWarp;
  if (warp >= nrhs) return;         // uniform across the warp
  const double* row = tile + lane;  // row[j · kTileLd] = tile(lane, j)
  const double inv = unit || lane >= w ? 1.0 : 1.0 / row[lane * kTileLd];
  for (std::int64_t r = warp; r < nrhs; r += nwarps) {
    double* Wr = W0 + r * m;
    double v = lane < w ? Wr[lane] : 0.0;
    if (lower) {
      for (int j = 0; j < w; ++j) {
        if (lane == j) v *= inv;
        const double vj = __shfl_sync(kFullMask, v, j);
        if (lane > j) v -= row[j * kTileLd] * vj;  // 0 for lanes ≥ w
      }
    } else {
      for (int j = static_cast<int>(w) - 1; j >= 0; --j) {
        if (lane == j) v *= inv;
        const double vj = __shfl_sync(kFullMask, v, j);
        if (lane < j) v -= row[j * kTileLd] * vj;
      }
    }
    if (lane < w) Wr[lane] = v;
  }
}

// Batch ≥ 16: this thread's first item of update_tile_rows (row row0 + threadIdx.x %
// count, when threadIdx.x < count·nrhs) has the tile's w entries of its row of A (A the
// panel's columns of the tile, leading dimension m) loaded into lv (zero past w), so that
// their latency passes during the warp's triangle. Nothing for Batch < 16.
template <int Batch>
__device__ void prefetch_tile_row(const double* A, std::int64_t m, std::int64_t row0,
                                  std::int64_t count, std::int64_t nrhs, std::int64_t w,
                                  double* lv) {
  if constexpr (Batch >= 16) {
    if (threadIdx.x < count * nrhs) {
      const double* a = A + row0 + threadIdx.x % count;
#ifdef __CUDA_ARCH__
#pragma unroll
#endif
      for (int q = 0; q < kTile; ++q) lv[q] = q < w ? a[q * m] : 0.0;
    }
  }
}

// W(i) −= A(i, tile)·W(j0 : j0 + w) for rows i in [row0, row0 + count) and every
// right-hand side: Batch ≥ 16 (launches of few blocks), one thread per (row, right-hand
// side), the thread's first one from lv (prefetch_tile_row); otherwise by
// sliced_products (a barrier inside when the items leave threads idle; every thread of
// the block must call it).
template <int Batch>
__device__ void update_tile_rows(const double* A, std::int64_t m, std::int64_t row0,
                                 std::int64_t count, std::int64_t j0, std::int64_t w, double* W,
                                 std::int64_t nrhs, const double* lv, double* sums) {
  if constexpr (Batch < 16) {
    sliced_products(
        count * nrhs, w, m, [&](std::int64_t q) { return A + row0 + q % count; },
        [&](std::int64_t q) { return W + q / count * m + j0; },
        [&](std::int64_t q, double y) { W[row0 + q % count + q / count * m] -= y; }, sums);
  } else {
    for (std::int64_t e = threadIdx.x; e < count * nrhs; e += blockDim.x) {
      const std::int64_t i = row0 + e % count, r = e / count;
      const double* x = W + r * m + j0;
      if (e == threadIdx.x) {  // the prefetched row (lv is zero past w)
        double s4[4] = {0.0, 0.0, 0.0, 0.0};
#ifdef __CUDA_ARCH__
#pragma unroll
#endif
        for (int q = 0; q < kTile; ++q) s4[q % 4] += lv[q] * (q < w ? x[q] : 0.0);
        W[i + r * m] -= (s4[0] + s4[1]) + (s4[2] + s4[3]);
        continue;
      }
      W[i + r * m] -= tile_dot<Batch>(A + i, m, x, w);
    }
  }
}

/// Forward sweep of one front (W gathered). `unit`: L11 has a unit diagonal.
template <int Batch>
__device__ void sweep_forward(const SolveTree& t, std::int64_t f, double* scratch,
                              std::int64_t nrhs, bool unit) {
  const std::int64_t m = t.n_rows[f], k = t.n_pivots[f];
  // a tall front's rows below its pivots are its scatter chunks' (scatter_forward)
  const std::int64_t row_end = t.part_offset[f] >= 0 ? k : m;
  const double* L = t.panels + t.panel_offset[f];
  double* W = scratch + t.row_offsets[f] * nrhs;
  __shared__ double tile[kWarp * kTileLd];
  __shared__ double sums[kChunkRows];  // update_tile_rows' (blockDim.x ≤ kChunkRows)
  if (k > 0) load_tile(L, m, min64(kTile, k), tile, false);
  __syncthreads();
  for (std::int64_t j0 = 0; j0 < k; j0 += kTile) {
    const std::int64_t w = min64(kTile, k - j0);
    const std::int64_t i0 = j0 + w, below = row_end - i0;
    // Batch ≥ 16 (a tall front, few blocks): the thread's first row below the tile has its
    // L(i, tile) loaded before the triangle, whose dependent steps hide the latency
    double lv[kTile];
    prefetch_tile_row<Batch>(L + j0 * m, m, i0, below, nrhs, w, lv);
    warp_triangle(tile, m, w, W + j0, nrhs, true, unit);
    __syncthreads();
    // the next tile into shared memory (its loads in flight with the products below), and
    // the rows below the tile: W(i) −= L(i, tile)·W(tile)
    if (i0 < k) load_tile(L + i0 * m + i0, m, min64(kTile, k - i0), tile, false);
    update_tile_rows<Batch>(L + j0 * m, m, i0, below, j0, w, W, nrhs, lv, sums);
    __syncthreads();
  }
}

/// Backward sweep of one front (W gathered): L11ᵀ (LLᵀ, LDLᵀ) or U11 (LU).
template <int Batch>
__device__ void sweep_backward(const SolveTree& t, std::int64_t f, double* scratch,
                               std::int64_t nrhs, bool lu, bool unit) {
  const std::int64_t m = t.n_rows[f], k = t.n_pivots[f];
  if (k == 0) return;  // uniform across the block
  const double* L = t.panels + t.panel_offset[f];
  double* W = scratch + t.row_offsets[f] * nrhs;
  const int lane = threadIdx.x % kWarp;
  const std::int64_t warp = threadIdx.x / kWarp, nwarps = blockDim.x / kWarp;
  const bool tall = t.part_offset[f] >= 0;
  __shared__ double sums[kChunkRows];  // sliced_products' (blockDim.x ≤ kChunkRows)
  // a tall front: W[0:k] −= the partial products of its chunks (backward_partials), in
  // chunk order; its rows below the pivots take no further part
  const std::int64_t row_end = tall ? k : m;
  if (tall) {
    // product_chunks: none when m = k (its chunks write no partial product)
    const std::int64_t np = m > k ? (m + kChunkRows - 1) / kChunkRows - k / kChunkRows : 0;
    const double* P = t.part + t.part_offset[f] * nrhs;
    for (std::int64_t e = threadIdx.x; e < k * nrhs; e += blockDim.x) {
      double s = 0.0;
      for (std::int64_t c = 0; c < np; c += 4) {  // each four chunks' loads together
        double pv[4];
#ifdef __CUDA_ARCH__
#pragma unroll
#endif
        for (int q = 0; q < 4; ++q) pv[q] = c + q < np ? P[(c + q) * k * nrhs + e] : 0.0;
#ifdef __CUDA_ARCH__
#pragma unroll
#endif
        for (int q = 0; q < 4; ++q)
          if (c + q < np) s += pv[q];
      }
      W[e % k + e / k * m] -= s;
    }
    __syncthreads();
  } else if (lu) {
    // W[0:k] −= U12 W[k:m]; U12 is k×(m−k) with leading dimension k: consecutive threads
    // down U12's columns, the columns sliced over the threads the k rows leave idle
    const double* U12 = L + m * k;
    sliced_products(
        k * nrhs, m - k, k, [&](std::int64_t q) { return U12 + q % k; },
        [&](std::int64_t q) { return W + q / k * m + k; },
        [&](std::int64_t q, double y) { W[q % k + q / k * m] -= y; }, sums);
    __syncthreads();
  }
  __shared__ double tile[kWarp * kTileLd];
  const std::int64_t last = (k - 1) / kTile * kTile;
  if (lu) load_tile(L + last * m + last, m, k - last, tile, false);
  __syncthreads();
  for (std::int64_t j0 = last; j0 >= 0; j0 -= kTile) {
    const std::int64_t w = min64(kTile, k - j0);
    if (lu) {
      // Batch ≥ 16: the thread's first row above the tile has its U(i, tile) loaded before
      // the triangle (as in sweep_forward)
      double lv[kTile];
      prefetch_tile_row<Batch>(L + j0 * m, m, 0, j0, nrhs, w, lv);
      warp_triangle(tile, m, w, W + j0, nrhs, false, false);
      __syncthreads();
      // the tile before into shared memory, and the rows above the tile: W(i) −= U(i, tile)
      // ·W(tile)
      if (j0 > 0) load_tile(L + (j0 - kTile) * m + (j0 - kTile), m, kTile, tile, false);
      update_tile_rows<Batch>(L + j0 * m, m, 0, j0, j0, w, W, nrhs, lv, sums);
      __syncthreads();
    } else {
      // the tile's L11ᵀ into shared memory, and the tile's columns: W(j) −= L(i0:m, j)·
      // W(i0:m), rows i0 = j0 + w on are solved
      const std::int64_t i0 = j0 + w;
      load_tile(L + j0 * m + j0, m, w, tile, true);  // its loads in flight with the dots
      for (std::int64_t q = warp; q < w * nrhs; q += nwarps) {
        const std::int64_t j = j0 + q % w, r = q / w;
        const double* Lj = L + j * m;
        double* Wr = W + r * m;
        double s = 0.0;
        std::int64_t i = i0 + lane;
        if constexpr (Batch >= 16) {  // loads of four rows per lane in flight
          double s4[4] = {0.0, 0.0, 0.0, 0.0};
          for (; i + 3 * kWarp < row_end; i += 4 * kWarp)
            for (int u = 0; u < 4; ++u) s4[u] += Lj[i + u * kWarp] * Wr[i + u * kWarp];
          s = (s4[0] + s4[1]) + (s4[2] + s4[3]);
        }
        // the rest (all of it for Batch < 16) four rows a lane at a time, each four's loads
        // issued together, added into s in row order
        for (; i < row_end; i += 4 * kWarp) {
          double lv4[4], wv4[4];
#ifdef __CUDA_ARCH__
#pragma unroll
#endif
          for (int u = 0; u < 4; ++u) {
            const std::int64_t iu = i + u * kWarp;
            lv4[u] = iu < row_end ? Lj[iu] : 0.0;
            wv4[u] = iu < row_end ? Wr[iu] : 0.0;
          }
#ifdef __CUDA_ARCH__
#pragma unroll
#endif
          for (int u = 0; u < 4; ++u)
            if (i + u * kWarp < row_end) s += lv4[u] * wv4[u];
        }
        for (int off = kWarp / 2; off > 0; off /= 2) s += __shfl_down_sync(kFullMask, s, off);
        if (lane == 0) Wr[j] -= s;
      }
      __syncthreads();
      warp_triangle(tile, m, w, W + j0, nrhs, false, unit);
      __syncthreads();
    }
  }
}

// Asks the SM's L1 cache for the 128-byte lines of [begin, end), the block's threads taking
// one line each in turn (a hint: no register waits for it; nothing on the host).
__device__ void prefetch_lines(const void* begin, const void* end) {
#ifdef __CUDA_ARCH__
  constexpr std::uintptr_t kLine = 128;
  const std::uintptr_t b = reinterpret_cast<std::uintptr_t>(begin) & ~(kLine - 1);
  const std::uintptr_t e = reinterpret_cast<std::uintptr_t>(end);
  for (std::uintptr_t p = b + threadIdx.x * kLine; p < e; p += blockDim.x * kLine)
    asm volatile("prefetch.global.L1 [%0];" ::"l"(p));
#else
  (void)begin;
  (void)end;
#endif
}

/// What the forward (or backward) step of front f reads that no block writes during the
/// solve — its rows, the children's update positions adding into them (forward) and its
/// panel (L, and U12 for LU) — asked into the L1 cache of the block's SM, for a block
/// about to wait for other blocks (the chain's level fronts): the step's index and panel
/// loads after the wait then find them there, and only the loads of x and of the update
/// vectors, which the awaited blocks write, go to memory. Every thread calls it; it has no
/// barrier and writes nothing.
__device__ void prefetch_front(const SolveTree& t, std::int64_t f, bool forward, bool lu) {
  const std::int64_t m = t.n_rows[f], k = t.n_pivots[f], ro = t.row_offsets[f];
  prefetch_lines(t.first_pivot + f, t.first_pivot + f + 1);
  prefetch_lines(t.u_offset + f, t.u_offset + f + 1);
  prefetch_lines(t.part_offset + f, t.part_offset + f + 1);
  prefetch_lines(t.rows + ro, t.rows + ro + m);
  if (forward) {
    prefetch_lines(t.inv_offsets + ro, t.inv_offsets + ro + m + 1);
    prefetch_lines(t.inv_src + t.inv_offsets[ro], t.inv_src + t.inv_offsets[ro + m]);
  }
  const double* L = t.panels + t.panel_offset[f];
  prefetch_lines(L, L + (lu ? k * (2 * m - k) : m * k));  // L (m × k), then U12 (k × (m − k))
}

/// The whole forward step of front f by one block: gather, sweep and scatter, with a
/// barrier after each, the last so that the next front the block solves (a parent in the
/// same subtree) reads the update vector this one wrote. Batch: the sweep's (tile_dot).
template <int Batch>
__device__ void front_forward(const SolveTree& t, std::int64_t f, double* x, double* u,
                              double* scratch, std::int64_t nrhs, bool unit, bool lu) {
  const std::int64_t m = t.n_rows[f];
  gather_forward(t, f, 0, m, x, u, scratch, nrhs);
  __syncthreads();
  sweep_forward<Batch>(t, f, scratch, nrhs, unit);
  __syncthreads();
  scatter_forward<Batch, false>(t, f, 0, m, x, u, scratch, nrhs, lu);
  __syncthreads();
}

/// The whole backward step of front f by one block (gather, sweep, scatter; barriers as
/// in front_forward: the next front of the block, a child, reads the pivots written here).
template <int Batch>
__device__ void front_backward(const SolveTree& t, std::int64_t f, double* x, double* scratch,
                               std::int64_t nrhs, bool lu, bool unit) {
  const std::int64_t m = t.n_rows[f];
  gather_backward(t, f, 0, m, x, scratch, nrhs, lu);
  __syncthreads();
  sweep_backward<Batch>(t, f, scratch, nrhs, lu, unit);
  __syncthreads();
  scatter_backward(t, f, 0, m, x, scratch, nrhs, lu);
  __syncthreads();
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
