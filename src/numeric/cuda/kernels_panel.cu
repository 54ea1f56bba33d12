// strata — the pivot block and the panel of large Cholesky fronts with few pivots, for all
// such fronts of a chunk in two launches (see kernels.cuh, launch_llt_panel_small_k).
//
// Why: a front with many rows but few pivots (k ≤ 64; about 2,300 of the 3,100 fronts
// over 256 rows in lap3d 100³) went through cuSOLVER POTRF on its k×k block and cuBLAS
// TRSM on the (m−k)×k panel, two library calls of a few MFLOP each. Measured on the H100
// (bench_gpu_memory --parts kernels, REPORT §4): POTRF reaches 0.0–0.2 TFLOP/s below
// k = 500 and TRSM about 1 TFLOP/s at k = 250; 32 fronts of 1000 rows × 100 pivots, POTRF +
// TRSM + SYRK each, reach 2 TFLOP/s in aggregate however many streams run them (it
// saturates at 4–8). Here two launches do the POTRF and the TRSM of every such front of
// the chunk; only the contribution-block update (SYRK, where the flops are) stays a library
// call per front.
//
// How: two launches. First one block per front loads its k×k pivot block into shared
// memory, factors it there (unblocked right-looking Cholesky; k ≤ 64) and writes L11 back
// (lower triangle; the strict upper one is left as it was, as POTRF leaves it) and the
// info. (One launch in which every panel block factored its own copy raced: the block
// writing L11 back could precede another block's load of A11 — lap3d 100³ then failed
// with a NaN pivot on the H100.) Then block (i, y) reads L11 and rows k + 128·y … of front
// i's panel; each thread owns one row a and solves x·L11ᵀ = a by forward substitution (x_j = (a_j −
// Σ_{l<j} L11(j,l)·x_l) / L11(j,j)), the row kept in shared memory transposed so the 128 threads
// touch 128 banks. A non-positive pivot j sets info = j + 1 (cuSOLVER's convention) and the panel
// is left alone, the front then failing on the host as before. Source: the right-looking Cholesky
// and the forward substitution of Golub & Van Loan, "Matrix Computations", 4th ed., §4.2.5 and
// §3.1.
#include <algorithm>

#include "numeric/cuda/cuda_check.hpp"
#include "numeric/cuda/kernels.cuh"

namespace strata::cuda {
namespace {

constexpr int kRows = 128;  // panel rows per block, one per thread
constexpr std::size_t kSmem =
    sizeof(double) * (kPanelMaxPivots * kPanelMaxPivots + kPanelMaxPivots * kRows);

// Launch 1: one block per front factors its k×k pivot block in shared memory and writes
// L11 back (lower triangle) and the info.
__global__ void pivot_block_kernel(DeviceTree t, const std::int64_t* items, double* pool,
                                   int* info) {
  extern __shared__ double L[];  // k × k, leading dimension k
  __shared__ int sfail;
  const std::int64_t pos = items[2 * blockIdx.x], slot = items[2 * blockIdx.x + 1];
  const std::int64_t f = t.fronts[pos];
  const std::int64_t m = t.n_rows[f], k = t.n_pivots[f];
  double* F = pool + t.pos_offset[pos];
  const int tid = threadIdx.x;
  if (tid == 0) sfail = 0;
  for (std::int64_t x = tid; x < k * k; x += blockDim.x) {
    const std::int64_t i = x % k, j = x / k;
    L[x] = i >= j ? F[j * m + i] : 0.0;
  }
  __syncthreads();
  for (std::int64_t j = 0; j < k; ++j) {
    if (tid == 0) {
      const double d = L[j * k + j];
      if (!(d > 0.0))
        sfail = static_cast<int>(j) + 1;
      else
        L[j * k + j] = sqrt(d);
    }
    __syncthreads();
    if (sfail) break;
    const double inv = 1.0 / L[j * k + j];
    for (std::int64_t i = j + 1 + tid; i < k; i += blockDim.x) L[j * k + i] *= inv;
    __syncthreads();
    const std::int64_t rem = k - j - 1;  // trailing lower triangle: i >= c > j
    for (std::int64_t x = tid; x < rem * rem; x += blockDim.x) {
      const std::int64_t i = j + 1 + x % rem, c = j + 1 + x / rem;
      if (i >= c) L[c * k + i] -= L[j * k + i] * L[j * k + c];
    }
    __syncthreads();
  }
  if (tid == 0) info[slot] = sfail;
  if (sfail) return;
  for (std::int64_t x = tid; x < k * k; x += blockDim.x) {
    const std::int64_t i = x % k, j = x / k;
    if (i >= j) F[j * m + i] = L[x];
  }
}

// Launch 2: block (i, y) solves rows k + kRows·y … of front i's panel against its L11
// (read back from the front), one row per thread; a front whose pivot block failed is
// left alone.
__global__ void panel_rows_kernel(DeviceTree t, const std::int64_t* items, double* pool,
                                  const int* info) {
  extern __shared__ double smem[];
  const std::int64_t pos = items[2 * blockIdx.x], slot = items[2 * blockIdx.x + 1];
  const std::int64_t f = t.fronts[pos];
  const std::int64_t m = t.n_rows[f], k = t.n_pivots[f];
  const std::int64_t r0 = k + static_cast<std::int64_t>(blockIdx.y) * kRows;
  if (r0 >= m || info[slot] != 0) return;  // the whole block leaves together
  double* F = pool + t.pos_offset[pos];
  double* L = smem;                                      // k × k, leading dimension k
  double* B = smem + kPanelMaxPivots * kPanelMaxPivots;  // kRows × k, transposed
  const int tid = threadIdx.x;
  for (std::int64_t x = tid; x < k * k; x += blockDim.x) {
    const std::int64_t i = x % k, j = x / k;
    L[x] = i >= j ? F[j * m + i] : 0.0;
  }
  __syncthreads();
  const std::int64_t row = r0 + tid;
  if (row >= m) return;
  for (std::int64_t j = 0; j < k; ++j) B[j * kRows + tid] = F[j * m + row];  // coalesced
  for (std::int64_t j = 0; j < k; ++j) {
    double x = B[j * kRows + tid];
    for (std::int64_t l = 0; l < j; ++l) x -= B[l * kRows + tid] * L[l * k + j];
    x /= L[j * k + j];
    B[j * kRows + tid] = x;
    F[j * m + row] = x;
  }
}

}  // namespace

void launch_llt_panel_small_k(const DeviceTree& t, const std::int64_t* items, std::int64_t count,
                              std::int64_t max_rows, double* pool, int* info, cudaStream_t s) {
  if (count == 0) return;
  constexpr std::size_t l_bytes = sizeof(double) * kPanelMaxPivots * kPanelMaxPivots;
  // over the 48 KiB default; the attribute belongs to the current device, so it is set
  // at every launch (several GPUs run this in one process)
  STRATA_CUDA(cudaFuncSetAttribute(panel_rows_kernel, cudaFuncAttributeMaxDynamicSharedMemorySize,
                                   static_cast<int>(kSmem)));
  pivot_block_kernel<<<static_cast<unsigned>(count), kRows, l_bytes, s>>>(t, items, pool, info);
  STRATA_CUDA_LAUNCH();
  const dim3 grid(static_cast<unsigned>(count),
                  static_cast<unsigned>(std::max<std::int64_t>(1, (max_rows + kRows - 1) / kRows)));
  panel_rows_kernel<<<grid, kRows, kSmem, s>>>(t, items, pool, info);
  STRATA_CUDA_LAUNCH();
}

}  // namespace strata::cuda
