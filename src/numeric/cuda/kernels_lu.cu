// strata — CUDA kernels around the library LU of a large front (see kernels_lu.cuh).
//
// A large LU front with more than Options::gpu_lu_strip_pivots pivots (and
// any front whose elimination without interchanges was rejected) is factored by
// whole-block library calls (lu_fronts.cu, lu_large_fronts; the others by the batched
// kernels of kernels_lu_panel.cu): cuSOLVER GETRF on the k×k fully summed block A11 —
// pivoting over the fully summed rows only, as the CPU kernel's restricted pivoting — then
// the row interchanges applied to A12, two TRSMs and one GEMM. GETRF runs first without
// pivoting (several times faster at the large fronts' k: partial pivoting's search and
// swaps are what make GETRF slow there), and that factor is kept only when the CPU's
// threshold partial pivoting (u = Options::pivot_threshold) would have chosen the same
// pivots, i.e. every multiplier |L(i,j)| is at most 1/u (the diagonal within the
// threshold); otherwise the front is assembled again and, for u = 1, GETRF runs with
// partial pivoting — the CPU's rule then, largest magnitude, first on ties. GETRF does no
// static pivoting, so the pivots it chose are checked afterwards: when one is below the
// static-pivot threshold (or GETRF met an exact zero, or anything is not finite), or when
// u < 1 (GETRF's rule is not the CPU's then), the front is assembled again and refactored
// by the blocked path with our panel kernel, which applies the threshold and perturbs tiny
// pivots as the CPU does. So the result is the CPU's within rounding either way.
//
// The two TRSMs (L₂₁ = A₂₁U₁₁⁻¹, U₁₂ = L₁₁⁻¹A₁₂) run far below the device's rate on
// separator-front shapes and are a large share of an unsymmetric factorization's GPU time
// (bench/history.md). Splitting them by recursion into 64-wide
// cuBLAS TRSMs and DGEMMs gave the same rates (cuBLAS already does that); base cases of our
// own (one thread per row of B, the triangle in shared memory) took twice cuBLAS's kernel
// time there, too few rows per call to fill the device, and no wall-clock gain (2026-11-23);
// so they stay cuBLAS calls.
// The kernels here are the glue: the pivot checks (after the unpivoted GETRF also the
// multipliers'), the conversion of GETRF's interchange
// list (LAPACK's ipiv, 1-based) into the row permutation the factor records, the
// interchanges on A12 (one thread per column, in order), and the gather of the pivots'
// diagonal entries that the host bookkeeping reads when the panels stay on the device.
#include <algorithm>
#include <cfloat>

#include "numeric/cuda/cuda_check.hpp"
#include "numeric/cuda/kernels.cuh"

namespace strata::cuda {
namespace {

constexpr int kThreads = 256;

__global__ void lu_check_kernel(const double* a, std::int64_t ld, std::int64_t k,
                                double static_pivot, const int* getrf_info, int* bad) {
  __shared__ int sbad;
  if (threadIdx.x == 0) sbad = *getrf_info != 0;
  __syncthreads();
  for (std::int64_t j = threadIdx.x; j < k; j += blockDim.x) {
    const double d = a[j * ld + j];
    // !(|d| >= sp) also catches NaN; an infinite pivot means growth we do not accept
    if (!(fabs(d) >= static_pivot) || !(fabs(d) <= DBL_MAX)) sbad = 1;
  }
  __syncthreads();
  if (threadIdx.x == 0) *bad = sbad;
}

// One block per column (grid-stride): the column's pivot and its multipliers. Every
// violation writes the same 1, so plain stores suffice; *bad was zeroed before.
__global__ void lu_unpivoted_check_kernel(const double* a, std::int64_t ld, std::int64_t k,
                                          double static_pivot, double threshold,
                                          const int* getrf_info, int* ipiv, int* bad) {
  if (blockIdx.x == 0 && threadIdx.x == 0 && *getrf_info != 0) *bad = 1;
  for (std::int64_t j = blockIdx.x; j < k; j += gridDim.x) {
    const double* col = a + j * ld;
    if (threadIdx.x == 0) {
      ipiv[j] = static_cast<int>(j + 1);
      const double d = col[j];
      if (!(fabs(d) >= static_pivot) || !(fabs(d) <= DBL_MAX)) *bad = 1;
    }
    for (std::int64_t i = j + 1 + threadIdx.x; i < k; i += blockDim.x)
      if (!(threshold * fabs(col[i]) <= 1.0)) *bad = 1;
  }
}

__global__ void ipiv_to_perm_kernel(const int* ipiv, std::int64_t k, std::int64_t* perm) {
  if (threadIdx.x != 0) return;
  for (std::int64_t j = 0; j < k; ++j) perm[j] = j;
  for (std::int64_t j = 0; j < k; ++j) {
    const std::int64_t r = ipiv[j] - 1;
    if (r != j) {
      const std::int64_t t = perm[j];
      perm[j] = perm[r];
      perm[r] = t;
    }
  }
}

__global__ void identity_perm_kernel(std::int64_t k, std::int64_t* perm) {
  const std::int64_t j = blockIdx.x * static_cast<std::int64_t>(blockDim.x) + threadIdx.x;
  if (j < k) perm[j] = j;
}

// Block b copies segment b: dst[seg[3b] + j] = src[seg[3b + 2] + j] for j < seg[3b + 1].
__global__ void scatter_segments_kernel(const std::int64_t* seg, const std::int64_t* src,
                                        std::int64_t* dst) {
  const std::int64_t* s = seg + 3 * static_cast<std::int64_t>(blockIdx.x);
  for (std::int64_t j = threadIdx.x; j < s[1]; j += blockDim.x) dst[s[0] + j] = src[s[2] + j];
}

// Block b fills the segment [offset[b], offset[b + 1]) of perm with 0, 1, ….
__global__ void identity_perms_kernel(const std::int64_t* offset, std::int64_t* perm) {
  const std::int64_t o = offset[blockIdx.x], k = offset[blockIdx.x + 1] - o;
  for (std::int64_t j = threadIdx.x; j < k; j += blockDim.x) perm[o + j] = j;
}

__global__ void laswp_kernel(double* a, std::int64_t ld, std::int64_t ncols, const int* ipiv,
                             std::int64_t k) {
  const std::int64_t c = blockIdx.x * static_cast<std::int64_t>(blockDim.x) + threadIdx.x;
  if (c >= ncols) return;
  double* col = a + c * ld;
  for (std::int64_t j = 0; j < k; ++j) {
    const std::int64_t r = ipiv[j] - 1;
    if (r != j) {
      const double t = col[j];
      col[j] = col[r];
      col[r] = t;
    }
  }
}

__global__ void gather_diagonals_kernel(DeviceTree t, std::int64_t begin,
                                        const std::int64_t* panel_offset, const double* panels,
                                        const std::int64_t* diag_offset, double* diag) {
  const std::int64_t pos = begin + blockIdx.x;
  const std::int64_t f = t.fronts[pos];
  const std::int64_t m = t.n_rows[f], k = t.n_pivots[f];
  const double* p = panels + panel_offset[blockIdx.x];
  double* d = diag + diag_offset[blockIdx.x];
  for (std::int64_t i = threadIdx.x; i < k; i += blockDim.x) d[i] = p[i * m + i];
}

}  // namespace

void launch_lu_check(const double* a, std::int64_t ld, std::int64_t k, double static_pivot,
                     const int* getrf_info, int* bad, cudaStream_t s) {
  lu_check_kernel<<<1, kThreads, 0, s>>>(a, ld, k, static_pivot, getrf_info, bad);
  STRATA_CUDA_LAUNCH();
}

void launch_lu_unpivoted_check(const double* a, std::int64_t ld, std::int64_t k,
                               double static_pivot, double threshold, const int* getrf_info,
                               int* ipiv, int* bad, cudaStream_t s) {
  STRATA_CUDA(cudaMemsetAsync(bad, 0, sizeof(int), s));
  const std::int64_t blocks = std::max<std::int64_t>(1, std::min<std::int64_t>(k, 1024));
  lu_unpivoted_check_kernel<<<static_cast<unsigned>(blocks), kThreads, 0, s>>>(
      a, ld, k, static_pivot, threshold, getrf_info, ipiv, bad);
  STRATA_CUDA_LAUNCH();
}

void launch_ipiv_to_perm(const int* ipiv, std::int64_t k, std::int64_t* perm, cudaStream_t s) {
  if (k == 0) return;
  ipiv_to_perm_kernel<<<1, 32, 0, s>>>(ipiv, k, perm);
  STRATA_CUDA_LAUNCH();
}

void launch_identity_perm(std::int64_t k, std::int64_t* perm, cudaStream_t s) {
  if (k == 0) return;
  identity_perm_kernel<<<static_cast<unsigned>((k + kThreads - 1) / kThreads), kThreads, 0, s>>>(
      k, perm);
  STRATA_CUDA_LAUNCH();
}

void launch_scatter_segments(const std::int64_t* seg, std::int64_t count, const std::int64_t* src,
                             std::int64_t* dst, cudaStream_t s) {
  if (count == 0) return;
  scatter_segments_kernel<<<static_cast<unsigned>(count), 64, 0, s>>>(seg, src, dst);
  STRATA_CUDA_LAUNCH();
}

void launch_identity_perms(const std::int64_t* offset, std::int64_t count, std::int64_t* perm,
                           cudaStream_t s) {
  if (count == 0) return;
  identity_perms_kernel<<<static_cast<unsigned>(count), kThreads, 0, s>>>(offset, perm);
  STRATA_CUDA_LAUNCH();
}

void launch_laswp(double* a, std::int64_t ld, std::int64_t ncols, const int* ipiv, std::int64_t k,
                  cudaStream_t s) {
  if (ncols == 0 || k == 0) return;
  const std::int64_t blocks = (ncols + kThreads - 1) / kThreads;
  laswp_kernel<<<static_cast<unsigned>(blocks), kThreads, 0, s>>>(a, ld, ncols, ipiv, k);
  STRATA_CUDA_LAUNCH();
}

void launch_gather_diagonals(const DeviceTree& t, std::int64_t begin, std::int64_t count,
                             const std::int64_t* panel_offset, const double* panels,
                             const std::int64_t* diag_offset, double* diag, cudaStream_t s) {
  if (count == 0) return;
  gather_diagonals_kernel<<<static_cast<unsigned>(count), kThreads, 0, s>>>(
      t, begin, panel_offset, panels, diag_offset, diag);
  STRATA_CUDA_LAUNCH();
}

}  // namespace strata::cuda
