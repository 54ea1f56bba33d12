// strata — the pivot block and panel of one large Cholesky front, by recursion on the
// pivot columns.
//
// A front F (m × m, column-major, lower triangle) with k pivots needs L₁₁ = chol(F₁₁) and
// L₂₁ = F₂₁ L₁₁⁻ᵀ before the update of its contribution block. cuSOLVER POTRF and cuBLAS
// TRSM do that at a fraction of the device's rate at the shapes of separator fronts, the
// pair slower than the SYRK of the same front's update (bench/REPORT.md, "Dense kernels at
// the shapes of large fronts"). Cutting the k columns into blocks and calling POTRF and
// TRSM per block does not help (llt_blocked.cu): those calls cost about as much per block
// as for all k.
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
// The base case is one launch of 128-thread blocks: every block factors the same w×w
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
#include "numeric/cuda_testing.hpp"
#include "strata/errors.hpp"

namespace strata::cuda {
namespace {

constexpr int kBase = 64;            // columns of a base case, and panel rows per block
constexpr int kThreads = 2 * kBase;  // one row each: the diagonal block's, then the panel's

// One base case: P points at the diagonal entry of the sub-panel (leading dimension ld),
// `rows` rows from there down, w ≤ 64 columns; col0 is P's first column within the front
// (for info). Block b factors the diagonal block together with rows w + 64b … of the
// sub-panel below it; block 0 also writes L_jj (lower triangle, column-major 64×64) to
// `slot`.
// The block runs the right-looking Cholesky of the 128 × w matrix [A_jj; A_b] (the
// diagonal block over its 64 panel rows): the panel rows come out as A_b·L_jj⁻ᵀ, the
// forward substitution, with the same operations as the diagonal block's rows below the
// diagonal. Thread t holds row t of that matrix in registers (threads 0–63 the diagonal
// block's rows, 64–127 the panel rows); every loop is unrolled, so the register indices
// are compile-time. Column j (one barrier per column): the diagonal block's threads publish
// their entries of column j, not yet scaled, in column j of U (shared memory); after the
// barrier every thread reads d = U(j, j), scales its own entry, l(t, j) = a(t, j)/√d, and
// updates its entries right of j, a(t, c) −= l(t, j)·U(c, j)/√d; the diagonal block's
// threads then publish column j + 1 into U's next column (no column is written twice, so
// one barrier per column is enough).
// The limit of this kernel is issue latency, not the FP64 pipe (Nsight Compute); the
// variants measured against it (a 16 × 16 grid of register tiles, rows in shared memory
// with rolled loops, 32 columns per base case) are in bench/history.md.
__global__ void __launch_bounds__(kThreads)
    llt_base_kernel(double* P, std::int64_t ld, std::int64_t rows, int w, double* slot, int* info,
                    std::int64_t col0) {
  __shared__ double U[kBase * kBase];  // column j: the diagonal block's column j, unscaled
  if (col0 > 0 && *info != 0) return;  // an earlier base case of this front failed
  const int t = threadIdx.x;
  const bool diag = t < kBase;
  const std::int64_t pr = w + static_cast<std::int64_t>(blockIdx.x) * kBase + (t - kBase);
  double a[kBase];
  if (diag) {
#pragma unroll
    for (int c = 0; c < kBase; ++c) a[c] = c <= t && t < w ? P[c * ld + t] : 0.0;
  } else {
#pragma unroll
    for (int c = 0; c < kBase; ++c) a[c] = pr < rows && c < w ? P[c * ld + pr] : 0.0;
  }
  if (diag) U[t] = a[0];
  __syncthreads();
  int fail = -1;  // the same in every thread (every thread reads the same d)
#pragma unroll
  for (int j = 0; j < kBase; ++j) {
    if (j >= w) break;
    const double d = U[j * kBase + j];
    if (!(d > 0.0)) {
      fail = j;
      break;
    }
    const double rs = rsqrt(d);
    // the diagonal block's rows above j: zero (their entries right of the diagonal are
    // never read, and the zero keeps them from growing)
    const double l = diag ? (t > j ? a[j] * rs : (t == j ? d * rs : 0.0)) : a[j] * rs;
    a[j] = l;
    const double f = l * rs;
#pragma unroll
    for (int c = j + 1; c < kBase; ++c) a[c] -= f * U[j * kBase + c];
    if (j + 1 < w) {
      if (diag) U[(j + 1) * kBase + t] = a[j + 1];
      __syncthreads();
    }
  }
  if (fail >= 0) {
    if (blockIdx.x == 0 && t == 0) *info = static_cast<int>(col0) + fail + 1;
    return;
  }
  if (blockIdx.x == 0 && t == 0 && col0 == 0) *info = 0;
  if (diag) {
    if (blockIdx.x == 0) {
#pragma unroll
      for (int c = 0; c < kBase; ++c) slot[c * kBase + t] = c <= t && t < w ? a[c] : 0.0;
    }
  } else if (pr < rows) {
#pragma unroll
    for (int c = 0; c < kBase; ++c)
      if (c < w) P[c * ld + pr] = a[c];
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

void llt_pivot_block_and_panel_recursive(Lane& ln, double* P, std::int64_t ld, std::int64_t rows,
                                         std::int64_t k, int* info) {
  if (k <= 0) return;
  ln.diag_work.resize(llt_recursive_work_size(k));
  recurse(ln, P, ld, rows, k, 0, ln.diag_work.data(), info);
  const unsigned blocks = static_cast<unsigned>((k + kBase - 1) / kBase);
  llt_place_diagonal_kernel<<<dim3(blocks, blocks), kThreads, 0, ln.stream>>>(
      P, ld, k, ln.diag_work.data(), info);
  STRATA_CUDA_LAUNCH();
}

void llt_pivot_block_and_panel_recursive(Lane& ln, double* F, std::int64_t m, std::int64_t k,
                                         int* info) {
  llt_pivot_block_and_panel_recursive(ln, F, m, m, k, info);
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
