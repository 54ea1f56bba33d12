// strata — CUDA kernels of the triangular solves (see solve_kernels.cuh).
//
// Per front (m rows, k pivots, panel L column-major with leading dimension m):
//   forward  W = [x at the pivot rows as factored; 0] + Σ children's u (extend-add at
//            their rows' positions, a pivot row's position being where the factorization
//            moved it), then column sweeps j = 0..k−1: W[j] /= L(j,j) (non-unit only),
//            W[i] −= L(i,j)·W[j] for i > j — which also forms u_f = W[k:m];
//   backward W = x at the front's rows, W[0:k] −= L21ᵀ·W[k:m] (LU: U12·W[k:m]), then a
//            column sweep with L11ᵀ (LU: U11) from j = k−1 down.
// The sweeps synchronize the block once per pivot: fine for the many small fronts of a
// level; the few large fronts near the root are the solve's critical path.
#include "numeric/cuda/cuda_check.hpp"
#include "numeric/cuda/solve_kernels.cuh"

namespace strata::cuda {
namespace {

constexpr int kThreads = 256;

__global__ void forward_kernel(SolveTree t, std::int64_t begin, double* x, double* u,
                               double* scratch, std::int64_t nrhs, bool lu, bool unit) {
  const std::int64_t f = t.fronts[begin + blockIdx.x];
  const std::int64_t m = t.n_rows[f], k = t.n_pivots[f], fp = t.first_pivot[f];
  const std::int64_t* prow = t.rows + t.row_offsets[f];
  const double* L = t.panels + t.panel_offset[f];
  double* W = scratch + t.row_offsets[f];
  for (std::int64_t r = 0; r < nrhs; ++r) {
    double* xr = x + r * t.n;
    double* ur = u + r * t.u_total;
    for (std::int64_t i = threadIdx.x; i < m; i += blockDim.x) W[i] = i < k ? xr[prow[i]] : 0.0;
    __syncthreads();
    for (std::int64_t q = t.child_offsets[f]; q < t.child_offsets[f + 1]; ++q) {
      const std::int64_t c = t.children[q];
      const std::int64_t mc = t.n_rows[c] - t.n_pivots[c];
      const std::int64_t* rel = t.rel + t.rel_offsets[c];
      const double* uc = ur + t.u_offset[c];
      for (std::int64_t e = threadIdx.x; e < mc; e += blockDim.x) {
        const std::int64_t p = rel[e];
        W[p < k ? t.pivot_pos[fp + p] : p] += uc[e];
      }
      __syncthreads();
    }
    for (std::int64_t j = 0; j < k; ++j) {
      if (!unit) {
        if (threadIdx.x == 0) W[j] /= L[j * m + j];
        __syncthreads();
      }
      const double wj = W[j];
      for (std::int64_t i = j + 1 + threadIdx.x; i < m; i += blockDim.x) W[i] -= L[j * m + i] * wj;
      __syncthreads();
    }
    for (std::int64_t i = threadIdx.x; i < m; i += blockDim.x) {
      if (i < k)
        xr[lu ? fp + i : prow[i]] = W[i];
      else
        ur[t.u_offset[f] + i - k] = W[i];
    }
    __syncthreads();
  }
}

__global__ void diagonal_kernel(SolveTree t, const double* d_diag, const double* d_off,
                                const int* pivot_size, double* x, std::int64_t nrhs) {
  const std::int64_t p = blockIdx.x * static_cast<std::int64_t>(blockDim.x) + threadIdx.x;
  if (p >= t.n) return;
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

__global__ void backward_kernel(SolveTree t, std::int64_t begin, double* x, double* scratch,
                                std::int64_t nrhs, bool lu, bool unit) {
  const std::int64_t f = t.fronts[begin + blockIdx.x];
  const std::int64_t m = t.n_rows[f], k = t.n_pivots[f], fp = t.first_pivot[f];
  const std::int64_t* prow = t.rows + t.row_offsets[f];
  const double* L = t.panels + t.panel_offset[f];
  double* W = scratch + t.row_offsets[f];
  auto col = [&](std::int64_t i) { return lu && i < k ? fp + i : prow[i]; };
  for (std::int64_t r = 0; r < nrhs; ++r) {
    double* xr = x + r * t.n;
    for (std::int64_t i = threadIdx.x; i < m; i += blockDim.x) W[i] = xr[col(i)];
    __syncthreads();
    for (std::int64_t i = threadIdx.x; i < k; i += blockDim.x) {
      double s = 0.0;
      if (lu) {
        const double* U12 = L + m * k;  // k×(m−k), leading dimension k
        for (std::int64_t j = k; j < m; ++j) s += U12[(j - k) * k + i] * W[j];
      } else {
        for (std::int64_t j = k; j < m; ++j) s += L[i * m + j] * W[j];
      }
      W[i] -= s;
    }
    __syncthreads();
    for (std::int64_t j = k - 1; j >= 0; --j) {
      if (lu || !unit) {
        if (threadIdx.x == 0) W[j] /= L[j * m + j];
        __syncthreads();
      }
      const double wj = W[j];
      for (std::int64_t i = threadIdx.x; i < j; i += blockDim.x)
        W[i] -= (lu ? L[j * m + i] : L[i * m + j]) * wj;
      __syncthreads();
    }
    for (std::int64_t i = threadIdx.x; i < k; i += blockDim.x) xr[col(i)] = W[i];
    __syncthreads();
  }
}

}  // namespace

void launch_solve_forward(const SolveTree& t, std::int64_t begin, std::int64_t count, double* x,
                          double* u, double* scratch, std::int64_t nrhs, bool lu, bool unit,
                          cudaStream_t s) {
  if (count == 0) return;
  forward_kernel<<<static_cast<unsigned>(count), kThreads, 0, s>>>(t, begin, x, u, scratch, nrhs,
                                                                   lu, unit);
  STRATA_CUDA_LAUNCH();
}

void launch_solve_diagonal(const SolveTree& t, const double* d_diag, const double* d_off,
                           const int* pivot_size, double* x, std::int64_t nrhs, cudaStream_t s) {
  if (t.n == 0) return;
  const unsigned blocks = static_cast<unsigned>((t.n + kThreads - 1) / kThreads);
  diagonal_kernel<<<blocks, kThreads, 0, s>>>(t, d_diag, d_off, pivot_size, x, nrhs);
  STRATA_CUDA_LAUNCH();
}

void launch_solve_backward(const SolveTree& t, std::int64_t begin, std::int64_t count, double* x,
                           double* scratch, std::int64_t nrhs, bool lu, bool unit, cudaStream_t s) {
  if (count == 0) return;
  backward_kernel<<<static_cast<unsigned>(count), kThreads, 0, s>>>(t, begin, x, scratch, nrhs, lu,
                                                                    unit);
  STRATA_CUDA_LAUNCH();
}

}  // namespace strata::cuda
