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
// threshold partial pivoting (u = Options::diagonal_pivot_threshold) would have chosen the same
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
// A front rejected with u < 1 is factored again by the blocked path: per panel of up to 64
// pivot columns (as many as shared memory holds for its k − p0 rows), lu_tall_panel_kernel
// factors the panel's fully summed rows [p0, k) with
// the CPU's threshold partial pivoting and static pivoting in shared memory (one block;
// each pivot step a search by shuffles and a rank-1 update of at most k − p0 rows by 64
// columns, four barriers), writes it back and moves the rest of the interchanged rows
// (their other columns, one thread per column, in order); the caller then forms the panel's
// rows [k, m) by a TRSM with its U block and updates the rest (lu_fronts.cu). Panels too
// tall for 8 columns in shared memory take lu_columns (kernels.cu), in global memory.
//
// The kernels here are the glue: the pivot checks (after the unpivoted GETRF also the
// multipliers'), the conversion of GETRF's interchange
// list (LAPACK's ipiv, 1-based) into the row permutation the factor records, the
// interchanges on A12 (one thread per column, in order), and the gather of the pivots'
// diagonal entries that the host bookkeeping reads when the panels stay on the device.
#include <algorithm>
#include <atomic>
#include <cfloat>
#include <string>

#include "numeric/cuda/cuda_check.hpp"
#include "numeric/cuda/kernels.cuh"
#include "numeric/cuda/warp_argmax.cuh"
#include "numeric/static_pivot.hpp"

namespace strata::cuda {
namespace {

using numeric::needs_static_pivot;
using numeric::static_pivot_value;

constexpr int kThreads = 256;

__global__ void lu_check_kernel(const double* a, std::int64_t ld, std::int64_t k,
                                double static_pivot, const int* getrf_info, int* bad) {
  __shared__ int sbad;
  if (threadIdx.x == 0) sbad = *getrf_info != 0;
  __syncthreads();
  for (std::int64_t j = threadIdx.x; j < k; j += blockDim.x) {
    const double d = a[j * ld + j];
    // !(|d| >= sp) also catches NaN; an infinite pivot means growth we do not accept
    if (!(fabs(d) >= fabs(static_pivot)) || !(fabs(d) <= DBL_MAX)) sbad = 1;
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
      if (!(fabs(d) >= fabs(static_pivot)) || !(fabs(d) <= DBL_MAX)) *bad = 1;
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

constexpr int kTallThreads = 1024;
constexpr int kTallWarps = kTallThreads / 32;
constexpr int kTallCols = 64;

// The largest value and its index over the block (ties: the smaller index); every thread
// gets the result. wv, wi: shared arrays of kTallWarps.
__device__ void tall_argmax(double& v, int& at, double* wv, int* wi) {
  const int lane = threadIdx.x & 31, warp = threadIdx.x >> 5;
  warp_argmax_down(v, at);
  if (lane == 0) {
    wv[warp] = v;
    wi[warp] = at;
  }
  __syncthreads();
  v = wv[0];
  at = wi[0];
  for (int q = 1; q < kTallWarps; ++q)
    if (wv[q] > v || (wv[q] == v && wi[q] < at)) {
      v = wv[q];
      at = wi[q];
    }
  __syncthreads();  // wv, wi free for the next call
}

// Panel [p0, p0 + w) of the m×m front F (leading dimension m, fully summed rows [0, k)),
// its rows [p0, k) in shared memory P (R = k − p0 rows, column-major): threshold partial
// pivoting and static pivoting as lu_columns, the interchanges applied to the whole rows,
// perm (front-local, k entries) and *perturbed updated. Rows [k, m) of the panel are the
// caller's (TRSM with the panel's U block).
__global__ void __launch_bounds__(kTallThreads)
    lu_tall_panel_kernel(double* F, std::int64_t m, std::int64_t k, std::int64_t p0, int w,
                         double static_pivot, double threshold, std::int64_t* perm,
                         std::int64_t* perturbed) {
  extern __shared__ double P[];
  __shared__ double wv[kTallWarps];
  __shared__ int wi[kTallWarps];
  __shared__ int ipiv[kTallCols];
  __shared__ double spiv;
  const int R = static_cast<int>(k - p0), t = threadIdx.x, step = blockDim.x;
  double* A = F + p0 * m + p0;
  for (int e = t; e < R * w; e += step) P[e] = A[static_cast<std::int64_t>(e / R) * m + e % R];
  __syncthreads();
  int npert = 0;  // thread 0's count
  for (int j = 0; j < w; ++j) {
    double* col = P + j * R;
    double v = -1.0;  // a NaN is never chosen
    int at = j;
    for (int i = j + t; i < R; i += step) {
      const double x = fabs(col[i]);
      if (x > v) {
        v = x;
        at = i;
      }
    }
    tall_argmax(v, at, wv, wi);
    // the diagonal within the threshold stays (no candidate at all: row j too)
    const int p = (v < 0 || fabs(col[j]) >= threshold * v) ? j : at;
    if (t == 0) ipiv[j] = p;
    if (p != j && t < w) {
      const double x = P[t * R + j];
      P[t * R + j] = P[t * R + p];
      P[t * R + p] = x;
    }
    __syncthreads();
    if (t == 0) {
      double d = col[j];
      if (needs_static_pivot(d, static_pivot)) {  // static_pivoted (kernels.cu)
        ++npert;
        d = static_pivot_value(d, static_pivot);
        col[j] = d;
      }
      spiv = d;
    }
    __syncthreads();
    const double inv = 1.0 / spiv;
    for (int i = j + 1 + t; i < R; i += step) col[i] *= inv;
    __syncthreads();
    const int rows = R - j - 1, cols = w - j - 1;
    for (int x = t; x < rows * cols; x += step) {
      const int i = j + 1 + x % rows, c = j + 1 + x / rows;
      P[c * R + i] -= col[i] * P[c * R + j];
    }
    __syncthreads();
  }
  for (int e = t; e < R * w; e += step) A[static_cast<std::int64_t>(e / R) * m + e % R] = P[e];
  // the panel's interchanges on the rest of its rows, column by column, in order
  for (std::int64_t c = t; c < m; c += step) {
    if (c >= p0 && c < p0 + w) continue;
    double* fc = F + c * m + p0;
    for (int q = 0; q < w; ++q) {
      const int r = ipiv[q];
      if (r != q) {
        const double x = fc[q];
        fc[q] = fc[r];
        fc[r] = x;
      }
    }
  }
  if (t == 0) {
    for (int q = 0; q < w; ++q)
      if (ipiv[q] != q) {
        const std::int64_t x = perm[p0 + q];
        perm[p0 + q] = perm[p0 + ipiv[q]];
        perm[p0 + ipiv[q]] = x;
      }
    *perturbed += npert;
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

namespace {
// The opt-in shared memory per block left for lu_tall_panel_kernel's panel, in bytes,
// asked (and allowed to the kernel) once per device: devices of one process may differ.
int tall_panel_bytes() {
  constexpr int kDevices = 64;
  static std::atomic<int> room[kDevices];  // 0: not asked yet
  int dev = 0;
  STRATA_CUDA(cudaGetDevice(&dev));
  int bytes_max = dev < kDevices ? room[dev].load(std::memory_order_acquire) : 0;
  if (bytes_max == 0) {
    int optin = 0;
    STRATA_CUDA(cudaDeviceGetAttribute(&optin, cudaDevAttrMaxSharedMemoryPerBlockOptin, dev));
    cudaFuncAttributes attr{};
    STRATA_CUDA(cudaFuncGetAttributes(&attr, lu_tall_panel_kernel));
    bytes_max = std::max(1, optin - static_cast<int>(attr.sharedSizeBytes));
    STRATA_CUDA(cudaFuncSetAttribute(lu_tall_panel_kernel,
                                     cudaFuncAttributeMaxDynamicSharedMemorySize, bytes_max));
    if (dev < kDevices) room[dev].store(bytes_max, std::memory_order_release);
  }
  return bytes_max;
}
}  // namespace

std::int64_t lu_tall_panel_columns(std::int64_t rows) {
  if (rows < 1) return kTallCols;
  return std::min<std::int64_t>(
      kTallCols, tall_panel_bytes() / (rows * static_cast<std::int64_t>(sizeof(double))));
}

bool launch_lu_tall_panel(double* f, std::int64_t m, std::int64_t k, std::int64_t p0,
                          std::int64_t w, double static_pivot, double threshold, std::int64_t* perm,
                          std::int64_t* perturbed, cudaStream_t s) {
  if (w < 1 || w > kTallCols || p0 + w > k || k > m)
    throw InternalError("launch_lu_tall_panel: panel " + std::to_string(p0) + " + " +
                        std::to_string(w) + " of a front with " + std::to_string(k) +
                        " pivots and " + std::to_string(m) + " rows");
  const std::int64_t bytes = (k - p0) * w * static_cast<std::int64_t>(sizeof(double));
  if (bytes > tall_panel_bytes()) return false;
  lu_tall_panel_kernel<<<1, kTallThreads, static_cast<std::size_t>(bytes), s>>>(
      f, m, k, p0, static_cast<int>(w), static_pivot, threshold, perm, perturbed);
  STRATA_CUDA_LAUNCH();
  return true;
}

void launch_gather_diagonals(const DeviceTree& t, std::int64_t begin, std::int64_t count,
                             const std::int64_t* panel_offset, const double* panels,
                             const std::int64_t* diag_offset, double* diag, cudaStream_t s) {
  if (count == 0) return;
  gather_diagonals_kernel<<<static_cast<unsigned>(count), kThreads, 0, s>>>(
      t, begin, panel_offset, panels, diag_offset, diag);
  STRATA_CUDA_LAUNCH();
}

namespace {
__global__ void pack_results_kernel(ResultSegments g, std::int64_t* out) {
  const std::int64_t total = g.end[5];
  const std::int64_t step = static_cast<std::int64_t>(gridDim.x) * blockDim.x;
  for (std::int64_t e = blockIdx.x * static_cast<std::int64_t>(blockDim.x) + threadIdx.x; e < total;
       e += step) {
    int q = 0;
    while (e >= g.end[q]) ++q;
    const std::int64_t i = e - (q > 0 ? g.end[q - 1] : 0);
    std::int64_t v;
    if (g.kind[q] == 0)
      v = static_cast<const std::int64_t*>(g.src[q])[i];
    else if (g.kind[q] == 1)
      v = static_cast<const int*>(g.src[q])[i];
    else
      v = __double_as_longlong(static_cast<const double*>(g.src[q])[i]);
    out[e] = v;
  }
}
}  // namespace

void launch_pack_results(const ResultSegments& seg, std::int64_t* out, cudaStream_t s) {
  const std::int64_t total = seg.end[5];
  if (total <= 0) return;
  const std::int64_t blocks = std::min<std::int64_t>((total + kThreads - 1) / kThreads, 64);
  pack_results_kernel<<<static_cast<unsigned>(blocks), kThreads, 0, s>>>(seg, out);
  STRATA_CUDA_LAUNCH();
}

}  // namespace strata::cuda
