// strata — the pivot block and panel of one large Cholesky front, by recursion on the
// pivot columns.
//
// A front F (m × m, column-major, lower triangle) with k pivots needs L₁₁ = chol(F₁₁) and
// L₂₁ = F₂₁ L₁₁⁻ᵀ before the update of its contribution block. cuSOLVER POTRF and cuBLAS
// TRSM do that at a fraction of the device's rate at the shapes of separator fronts: on
// an H100, POTRF of order 1,000 took 0.42 ms whatever m (0.8 TFLOP/s), the TRSM of
// 3,000 × 1,000 ran at 5.6 TFLOP/s, and the pair took four times the SYRK of the same
// front's update (bench/REPORT.md, "Dense kernels at the shapes of large fronts"). Cutting
// the k columns into blocks and calling POTRF and TRSM per block did not help
// (llt_blocked.cu): those calls cost about as much per block as for all k.
//
// Here the m × k panel P is factored by the recursive Cholesky of Gustavson & Jonsson
// ("Minimal-storage high-performance Cholesky factorization via blocking and recursion",
// IBM J. Res. Dev. 44(6), 2000), applied to the panel as Toledo did for LU ("Locality of
// reference in LU decomposition with partial pivoting", SIAM J. Matrix Anal. Appl. 18(4),
// 1997):
//   panel(P, rows, k):  if k ≤ 64: base case, else with k₁ = ⌈k/2⌉ rounded up to 64,
//     panel(P[:, 0:k₁]);
//     P[k₁:rows, k₁:k] −= L[k₁:rows, 0:k₁]·L[k₁:k, 0:k₁]ᵀ   (one cuBLAS GEMM)
//     panel(P[k₁:rows, k₁:k]).
// The (m−k)·k² + k³/3 flops of POTRF + TRSM become GEMM flops with inner dimensions k/2,
// k/4, …, 64, and what stays serial is one 64-column base case per 64 pivots. The GEMM
// also writes the strict upper triangle of the pivot block's diagonal part (one GEMM is
// faster than a SYRK and a GEMM, and nothing reads that triangle): the last launch sets
// it to zero, as the executor's fronts (and the CPU's packed panels) have it.
// The base case is one launch of 256-thread blocks: every block factors the same w×w
// diagonal block (unblocked right-looking Cholesky, the same operations in the same order
// in every block, so every block gets the same bits) together with its own 64 rows below
// it, which that elimination turns into rows of L₂₁. Doing the diagonal block in every
// block trades 64³/3 redundant flops per block for a second launch and a grid-wide wait. Because
// the blocks read the diagonal block while another would be writing L_jj over it, block 0 writes
// L_jj to a workspace slot instead, and the last launch copies every slot into place (nothing in
// between reads a factored diagonal block: the updates read only the rows below it). The result is
// the factor that POTRF + TRSM give, in another order of summation (elimination, not an explicit
// inverse, so the error bound is Cholesky's and TRSM's: Higham, "Accuracy and Stability of
// Numerical Algorithms", 2nd ed., §8.1 and §10.1). A non-positive (or NaN) pivot at column j sets
// info = j + 1 (POTRF's convention, the order of the first leading minor that is not positive
// definite), and every later base case of the front leaves it alone.
#include <algorithm>
#include <string>

#include "numeric/cuda/cuda_executor.hpp"
#include "strata/errors.hpp"

namespace strata::cuda {
namespace {

constexpr int kBase = 64;      // columns of a base case, and panel rows per block
constexpr int kThreads = 256;  // a 16 × 16 grid of threads, 4 × 4 entries each

// One base case: P points at the diagonal entry of the sub-panel (leading dimension ld),
// `rows` rows from there down, w ≤ 64 columns; col0 is P's first column within the front
// (for info). Block b factors the diagonal block together with rows w + 64b … of the
// sub-panel below it; block 0 also writes L_jj (lower triangle, column-major 64×64) to
// `slot`.
// The block runs the right-looking Cholesky of the 128 × w matrix [A_jj; A_b] (the
// diagonal block over its 64 panel rows): the panel rows come out as A_b·L_jj⁻ᵀ, the
// forward substitution, with the same operations as the diagonal block's rows below the
// diagonal. Thread (ti, tj) = (t mod 16, t / 16) holds, in registers, rows ti + 16r of
// the diagonal block and of the panel tile (r < 4 each) in columns tj + 16c (c < 4): the
// register indices are compile-time (the column loop runs over c in an unrolled outer
// loop and tj in a runtime inner one), and every thread has work at every step.
// Column j (one barrier per column): the 16 threads holding column j (one half-warp) take
// the diagonal entry d by a warp shuffle, finish the column (L(r, j) = a(r, j)/√d, its
// panel rows too) and publish it into one of two buffers; after the barrier every thread
// updates its entries right of j, a(r, c) −= L(r, j)·L(c, j). The other buffer takes
// column j + 1, so no second barrier is needed before it is written. Doing the square
// root before the barrier keeps it off the other threads' path.
// Earlier versions, per base case of a 4,000-row sub-panel under Nsight Compute on the
// H100: rows in registers with every loop unrolled, 255 registers and spills, 114 µs;
// the diagonal block and the panel in shared memory, 75 µs; these register tiles with
// the column published unscaled (the square root after the barrier) and the panel solved
// in a second loop of 64 barriers, 47 µs; with the square root before the barrier, 43 µs.
// (This version was measured by the kernel table, not Nsight: 4,000 × 1,000 at 5.4
// TFLOP/s against 4.7 for the 43 µs one.)
__global__ void __launch_bounds__(kThreads)
    llt_base_kernel(double* P, std::int64_t ld, std::int64_t rows, int w, double* slot, int* info,
                    std::int64_t col0) {
  __shared__ double col[2][2 * kBase];  // the published column: diagonal block, panel rows
  __shared__ double dpub[2];            // the diagonal entry before its square root
  __shared__ int sfail;
  if (col0 > 0 && *info != 0) return;  // an earlier base case of this front failed
  const int ti = threadIdx.x & 15, tj = threadIdx.x >> 4;
  const std::int64_t r0 = w + static_cast<std::int64_t>(blockIdx.x) * kBase;
  const std::int64_t nr = rows - r0 < kBase ? rows - r0 : kBase;  // ≤ 0: no panel rows
  double a[8][4];  // rows 0–3: the diagonal block's; rows 4–7: the panel tile's
#pragma unroll
  for (int r = 0; r < 4; ++r)
#pragma unroll
    for (int c = 0; c < 4; ++c) {
      const int i = ti + 16 * r, k = tj + 16 * c;
      a[r][c] = k <= i && i < w ? P[k * ld + i] : 0.0;
      a[r + 4][c] = i < nr && k < w ? P[k * ld + r0 + i] : 0.0;
    }
  if (threadIdx.x == 0) sfail = 0;
  int j = 0;
  bool failed = false;  // the same in every thread (every thread reads the same d)
#pragma unroll
  for (int c = 0; c < 4; ++c) {
    for (int jj = 0; jj < 16; ++jj, ++j) {
      if (j >= w || failed) break;
      double* const buf = col[j & 1];
      // the diagonal entry (j, j) is a[c][c] of thread (jj, jj), in the owners' warp
      const double d = __shfl_sync(0xffffffffu, a[c][c], (17 * jj) & 31);
      if (tj == jj) {  // the owners finish column j and publish it
        const double rs = rsqrt(d);
#pragma unroll
        for (int r = 0; r < 4; ++r) {
          const int i = ti + 16 * r;
          if (i > j)
            a[r][c] *= rs;
          else if (i == j)
            a[r][c] = d * rs;
          buf[i] = a[r][c];
          a[r + 4][c] *= rs;
          buf[kBase + i] = a[r + 4][c];
        }
        if (ti == jj) dpub[j & 1] = d;
      }
      __syncthreads();
      if (!(dpub[j & 1] > 0.0)) {
        if (threadIdx.x == 0) sfail = static_cast<int>(col0) + j + 1;
        failed = true;
        break;
      }
      double lr[8], lc[4];
#pragma unroll
      for (int r = 0; r < 4; ++r) {
        lr[r] = buf[ti + 16 * r];
        lr[r + 4] = buf[kBase + ti + 16 * r];
      }
#pragma unroll
      for (int cc = 0; cc < 4; ++cc) lc[cc] = buf[tj + 16 * cc];
#pragma unroll
      for (int cc = 0; cc < 4; ++cc) {
        const int k = tj + 16 * cc;
        if (k <= j) continue;
#pragma unroll
        for (int r = 0; r < 4; ++r) {
          if (ti + 16 * r >= k) a[r][cc] -= lr[r] * lc[cc];
          a[r + 4][cc] -= lr[r + 4] * lc[cc];
        }
      }
    }
  }
  __syncthreads();
  if (sfail) {
    if (blockIdx.x == 0 && threadIdx.x == 0) *info = sfail;
    return;
  }
  if (blockIdx.x == 0 && threadIdx.x == 0 && col0 == 0) *info = 0;
#pragma unroll
  for (int r = 0; r < 4; ++r)
#pragma unroll
    for (int c = 0; c < 4; ++c) {
      const int i = ti + 16 * r, k = tj + 16 * c;
      if (blockIdx.x == 0) slot[k * kBase + i] = k <= i && i < w ? a[r][c] : 0.0;
      if (i < nr && k < w) P[k * ld + r0 + i] = a[r + 4][c];
    }
}

// Block (b, y), y ≤ b, is the 64 × 64 tile of the k × k pivot block at rows 64y, columns
// 64b: above the diagonal (y < b) it is set to zero; on it (y = b) slot b (L of that
// diagonal block, lower triangle) is copied into place with zeros above the diagonal.
__global__ void llt_place_diagonal_kernel(double* P, std::int64_t ld, std::int64_t k,
                                          const double* slots, const int* info) {
  if (*info != 0 || blockIdx.y > blockIdx.x) return;  // a failed front: its factor is unused
  const std::int64_t j0 = static_cast<std::int64_t>(blockIdx.x) * kBase;
  const std::int64_t i0 = static_cast<std::int64_t>(blockIdx.y) * kBase;
  const bool diagonal = blockIdx.x == blockIdx.y;
  const double* s = slots + static_cast<std::int64_t>(blockIdx.x) * kBase * kBase;
  for (int x = threadIdx.x; x < kBase * kBase; x += blockDim.x) {
    const int i = x & (kBase - 1), c = x >> 6;
    if (j0 + c >= k) break;  // x grows with c
    if (i0 + i < k) P[(j0 + c) * ld + i0 + i] = diagonal ? s[x] : 0.0;
  }
}

void recurse(const Lane& ln, double* P, std::int64_t ld, std::int64_t rows, std::int64_t k,
             std::int64_t col0, double* slots, int* info) {
  if (k <= kBase) {
    const std::int64_t below = rows - k;
    const unsigned grid =
        static_cast<unsigned>(std::max<std::int64_t>(1, (below + kBase - 1) / kBase));
    llt_base_kernel<<<grid, kThreads, 0, ln.stream>>>(
        P, ld, rows, static_cast<int>(k), slots + (col0 / kBase) * kBase * kBase, info, col0);
    STRATA_CUDA_LAUNCH();
    return;
  }
  const std::int64_t k1 = (k / 2 + kBase - 1) / kBase * kBase;  // < k since k > 64
  const std::int64_t k2 = k - k1;
  recurse(ln, P, ld, rows, k1, col0, slots, info);
  const double one = 1.0, minus_one = -1.0;
  const double* L = P + k1;  // rows k1 … of the left columns
  double* T = P + k1 * ld + k1;
  STRATA_CUBLAS(cublasDgemm(ln.blas, CUBLAS_OP_N, CUBLAS_OP_T, static_cast<int>(rows - k1),
                            static_cast<int>(k2), static_cast<int>(k1), &minus_one, L,
                            static_cast<int>(ld), L, static_cast<int>(ld), &one, T,
                            static_cast<int>(ld)));
  recurse(ln, T, ld, rows - k1, k2, col0 + k1, slots, info);
}

}  // namespace

std::size_t llt_recursive_work_size(std::int64_t k) {
  return static_cast<std::size_t>(std::max<std::int64_t>(1, (k + kBase - 1) / kBase)) * kBase *
         kBase;
}

void llt_pivot_block_and_panel_recursive(Lane& ln, double* F, std::int64_t m, std::int64_t k,
                                         int* info) {
  if (k <= 0) return;
  ln.diag_work.resize(llt_recursive_work_size(k));
  recurse(ln, F, m, m, k, 0, ln.diag_work.data(), info);
  const unsigned blocks = static_cast<unsigned>((k + kBase - 1) / kBase);
  llt_place_diagonal_kernel<<<dim3(blocks, blocks), kThreads, 0, ln.stream>>>(
      F, m, k, ln.diag_work.data(), info);
  STRATA_CUDA_LAUNCH();
}

}  // namespace strata::cuda

namespace strata::numeric {

index_t cuda_llt_pivot_block_and_panel(double* f, index_t m, index_t k) {
  if (m < 1 || k < 0 || k > m)
    throw InvalidInput("cuda_llt_pivot_block_and_panel: needs 0 <= k <= m and m >= 1 (m = " +
                       std::to_string(m) + ", k = " + std::to_string(k) + ")");
  STRATA_CUDA(cudaSetDevice(0));
  const std::size_t n = static_cast<std::size_t>(m) * static_cast<std::size_t>(m);
  cuda::DeviceBuffer<double> F(n);
  cuda::DeviceBuffer<int> info(1);
  cuda::Lane ln;  // the legacy default stream, with handles of its own
  STRATA_CUBLAS(cublasCreate(&ln.blas));
  struct Handles {
    cublasHandle_t b;
    ~Handles() { cublasDestroy(b); }
  } owned{ln.blas};
  STRATA_CUDA(cudaMemcpy(F.data(), f, n * sizeof(double), cudaMemcpyHostToDevice));
  STRATA_CUDA(cudaMemset(info.data(), 0, sizeof(int)));
  cuda::llt_pivot_block_and_panel_recursive(ln, F.data(), m, k, info.data());
  int status = 0;
  STRATA_CUDA(cudaMemcpy(&status, info.data(), sizeof(int), cudaMemcpyDeviceToHost));
  // all of F back, so that a caller can check what should be untouched
  STRATA_CUDA(cudaMemcpy(f, F.data(), n * sizeof(double), cudaMemcpyDeviceToHost));
  return status > 0 ? status - 1 : -1;
}

}  // namespace strata::numeric
