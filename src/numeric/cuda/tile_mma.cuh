// strata — the 64×64 tile product of strata's batched panel kernels (kernels_panel.cu for
// Cholesky, kernels_lu_panel.cu for LU), on the FP64 tensor cores.
//
// C = A·Bᵀ for a 64 × w block A and a 64 × w block B (w the inner dimension, any size), the
// operands staged through shared memory kChunk inner columns at a time, the products by
// WMMA m8n8k4 in FP64 (sm_80 and later): 256 threads, 8 warps, a 32×16 part of C each (or
// 512 threads, 16 warps, a 16×16 part each, for a kernel of that many).
// Two layouts of B in global memory:
//   kBRows: B(c, t) = b[t·ldb + c] — B's columns are the inner dimension (the panel's own
//           columns, as in A·Lᵀ);
//   kBCols: B(c, t) = b[c·ldb + t] — the inner dimension runs down B's columns, i.e. the
//           product is A·M for the w × 64 column-major block M = b (as in L·U).
// In both, consecutive threads read consecutive addresses and write consecutive shared
// words (kBCols keeps B c-major in shared memory and loads its fragments column-major, so
// no transpose goes through shared-memory banks).
#pragma once

#include <mma.h>

#include <cstdint>
#include <type_traits>

namespace strata::cuda::tile {

constexpr int kEdge = 64;      ///< tile edge (rows and columns of C)
constexpr int kChunk = 32;     ///< inner columns staged in shared memory at a time
constexpr int kThreads = 256;  ///< threads of a block that calls product()
/// Doubles of the shared buffer product() needs (the two staged operands, then C).
constexpr int kSharedDoubles = 2 * kChunk * kEdge;

enum class BLayout { kBRows, kBCols };

/// The 64×64 tile C = A·Bᵀ with A(r, t) = a[t·lda + r] for r < a_rows (zero beyond) and
/// B(c, t) as `L` says for c < b_rows (zero beyond), t < w; with kBCols and a row map
/// `brow` (w entries, shared or global memory), B(c, t) = b[c·ldb + brow[t]] instead (the
/// rows of a column block read in another order). `sm`: kSharedDoubles of shared memory,
/// 32-byte aligned, owned by the calling kernel. Returns C in `sm`, C(r, c) at [c·64 + r],
/// valid until the next call. Every thread of the block (`Threads`: 256, or 512 for a
/// kernel of that many) must call it; each warp forms a 32×16 (256) or 16×16 (512) part of
/// C, every entry summed over t in the same order either way, so both give the same bits.
template <BLayout L, int Threads = kThreads>
__device__ const double* product(const double* a, std::int64_t lda, int a_rows, const double* b,
                                 std::int64_t ldb, int b_rows, int w, double* sm,
                                 const int* brow = nullptr) {
  static_assert(Threads == 256 || Threads == 512, "tile::product: 256 or 512 threads");
  using namespace nvcuda;
  constexpr int kRowWarps = Threads / 128;      // warps along C's rows: 2 or 4
  constexpr int kWarpRows = kEdge / kRowWarps;  // C's rows per warp: 32 or 16
  constexpr int kFragRows = kWarpRows / 8;      // 8×8 fragments along them: 4 or 2
  double* As = sm;                              // A(r, t) at [t·64 + r]: column-major, ld 64
  double* Bs = sm + kChunk * kEdge;  // kBRows: B(c, t) at [t·64 + c]; kBCols: at [c·32 + t]
  const int tid = threadIdx.x, warp = tid >> 5;
  const int wr = (warp % kRowWarps) * kWarpRows, wc = (warp / kRowWarps) * 16;  // its part of C
  using BMajor = std::conditional_t<L == BLayout::kBRows, wmma::row_major, wmma::col_major>;
  wmma::fragment<wmma::accumulator, 8, 8, 4, double> acc[kFragRows][2];
  for (auto& row : acc)
    for (auto& f : row) wmma::fill_fragment(f, 0.0);
  // a thread's entries of a chunk, x = tid + Threads·u: every load issued before the first
  // store to shared memory, so that they are in flight together (the compiler cannot tell
  // that the stores do not alias the operands, and would otherwise wait for each load)
  constexpr int kPer = kChunk * kEdge / Threads;
  for (int t0 = 0; t0 < w; t0 += kChunk) {
    double va[kPer], vb[kPer];
#pragma unroll
    for (int u = 0; u < kPer; ++u) {
      const int x = tid + u * Threads;
      const int tt = x >> 6, r = x & 63;
      const bool in = t0 + tt < w;
      va[u] = in && r < a_rows ? a[static_cast<std::int64_t>(t0 + tt) * lda + r] : 0.0;
      if constexpr (L == BLayout::kBRows) {
        vb[u] = in && r < b_rows ? b[static_cast<std::int64_t>(t0 + tt) * ldb + r] : 0.0;
      } else {
        const int t = x & (kChunk - 1), c = x >> 5;
        const int row = brow ? (t0 + t < w ? brow[t0 + t] : 0) : t0 + t;
        vb[u] = t0 + t < w && c < b_rows ? b[static_cast<std::int64_t>(c) * ldb + row] : 0.0;
      }
    }
#pragma unroll
    for (int u = 0; u < kPer; ++u) {
      As[tid + u * Threads] = va[u];
      Bs[tid + u * Threads] = vb[u];
    }
    __syncthreads();
    const int steps = min(kChunk, w - t0);
    for (int tt = 0; tt < steps; tt += 4) {
      wmma::fragment<wmma::matrix_a, 8, 8, 4, double, wmma::col_major> fa[kFragRows];
      wmma::fragment<wmma::matrix_b, 8, 8, 4, double, BMajor> fb[2];
#pragma unroll
      for (int i = 0; i < kFragRows; ++i)
        wmma::load_matrix_sync(fa[i], As + tt * kEdge + wr + 8 * i, kEdge);
#pragma unroll
      for (int j = 0; j < 2; ++j) {
        if constexpr (L == BLayout::kBRows)
          wmma::load_matrix_sync(fb[j], Bs + tt * kEdge + wc + 8 * j, kEdge);
        else
          wmma::load_matrix_sync(fb[j], Bs + (wc + 8 * j) * kChunk + tt, kChunk);
      }
#pragma unroll
      for (int i = 0; i < kFragRows; ++i)
#pragma unroll
        for (int j = 0; j < 2; ++j) wmma::mma_sync(acc[i][j], fa[i], fb[j], acc[i][j]);
    }
    __syncthreads();
  }
#pragma unroll
  for (int i = 0; i < kFragRows; ++i)
#pragma unroll
    for (int j = 0; j < 2; ++j)
      wmma::store_matrix_sync(sm + (wc + 8 * j) * kEdge + wr + 8 * i, acc[i][j], kEdge,
                              wmma::mem_col_major);
  __syncthreads();
  return sm;
}

}  // namespace strata::cuda::tile
