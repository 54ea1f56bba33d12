// strata — the residuals and steps of iterative refinement on the device, for a factor
// resident there (core/solve_phase.cpp runs solve/refinement.hpp's steps over them).
//
// What: r = b − A·x for nrhs columns, with A's own values (not the scaled ones the
// factorization read) in the canonical entry order of the analysis's pattern, and per
// column the three maxima of the normwise backward error ‖r‖∞ / (‖A‖∞‖x‖∞ + ‖b‖∞)
// (Rigal and Gaches; Higham, "Accuracy and Stability of Numerical Algorithms", 2nd ed.,
// §7.1); and a step x += d that keeps x first, or puts the kept x back.
//
// How: one warp per row and column of right-hand sides, through the value pass's
// row-wise map of the pattern (value_pass.cu: per row its entries' positions and
// columns); for symmetric storage (the lower triangle) a row of the full matrix is its
// stored row plus the column of the same index below the diagonal (the column-wise
// map). The warp's sum is a fixed shuffle tree, so a residual is the same on every run.
// The maxima are taken as the bits of non-negative doubles, which order as the numbers do
// (a NaN's magnitude above +inf, so that the host sees a column that is not finite),
// by one atomicMax per block and column. A's values come from the copy the last
// factorization kept on the device (keep_device_input: values given from GPU or
// page-locked memory, or copied by the value pass for checked solves), else from the host
// once per factorization (MatrixValues::id).
//
// Why: a checked solve with the residual on the host copied x back, read A and b there,
// and sent each correction's right-hand side up again: on the multibody Newton matrices
// that took several times the solve itself (bench/history.md); here only 3·nrhs numbers
// per residual come back.
#include <algorithm>
#include <cstring>

#include "numeric/cuda/cuda_executor.hpp"

namespace strata::cuda {
namespace {

constexpr int kWarp = 32;
constexpr int kThreads = 256;  // 8 warps: 8 rows per block
constexpr int kMaxGridY = 65535;

__device__ unsigned long long magnitude_bits(double v) {
  return static_cast<unsigned long long>(__double_as_longlong(fabs(v)));
}

// r = b − A x for row i (blockIdx.x's warps) of column c (blockIdx.y + c0), and the block's
// maxima of |r|, |x| and |b| over its rows into maxima[3c .. 3c+2] (atomicMax on the bits).
__global__ void residual_kernel(std::int64_t n, const std::int64_t* row_ptr, const int* row_pos,
                                const int* row_col, const std::int64_t* col_ptr, const int* col_row,
                                bool symmetric, const double* a, const double* b, const double* x,
                                double* r, std::int64_t c0, unsigned long long* maxima) {
  __shared__ unsigned long long s_max[kThreads / kWarp][3];
  const int warp = threadIdx.x / kWarp, lane = threadIdx.x % kWarp;
  const std::int64_t i = static_cast<std::int64_t>(blockIdx.x) * (kThreads / kWarp) + warp;
  const std::int64_t c = c0 + blockIdx.y;
  const double* xc = x + c * n;
  unsigned long long mr = 0, mx = 0, mb = 0;
  if (i < n) {  // whole warps: a row each
    double s = 0;
    for (std::int64_t q = row_ptr[i] + lane; q < row_ptr[i + 1]; q += kWarp)
      s += a[row_pos[q]] * xc[row_col[q]];
    if (symmetric)
      for (std::int64_t p = col_ptr[i] + lane; p < col_ptr[i + 1]; p += kWarp) {
        const int k = col_row[p];
        if (k != i) s += a[p] * xc[k];
      }
    for (int off = kWarp / 2; off > 0; off /= 2) s += __shfl_xor_sync(0xffffffffu, s, off);
    if (lane == 0) {
      const double bi = b[c * n + i], ri = bi - s;
      r[c * n + i] = ri;
      mr = magnitude_bits(ri);
      mx = magnitude_bits(xc[i]);
      mb = magnitude_bits(bi);
    }
  }
  if (lane == 0) {
    s_max[warp][0] = mr;
    s_max[warp][1] = mx;
    s_max[warp][2] = mb;
  }
  __syncthreads();
  if (threadIdx.x < 3) {
    unsigned long long m = 0;
    for (int w = 0; w < kThreads / kWarp; ++w) m = max(m, s_max[w][threadIdx.x]);
    atomicMax(maxima + 3 * c + threadIdx.x, m);
  }
}

// kept = x, x += d (step) or x = kept (undo), n entries.
__global__ void step_kernel(std::int64_t n, double* x, const double* d, double* kept, bool undo) {
  const std::int64_t i = static_cast<std::int64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i >= n) return;
  if (undo) {
    x[i] = kept[i];
  } else {
    kept[i] = x[i];
    x[i] += d[i];
  }
}

}  // namespace

double* CudaExecutor::refinement_workspace(std::size_t count) {
  STRATA_CUDA(cudaSetDevice(device_));
  try {
    refine_.work.resize(std::max<std::size_t>(count, 1));
  } catch (const OutOfMemory&) {
    return nullptr;
  }
  return refine_.work.data();
}

bool CudaExecutor::residual(const Analysis& an, const numeric::MatrixValues& a, const double* b,
                            const double* x, double* r, index_t nrhs, double* maxima) {
  if (an.id != analysis_id_) return false;
  STRATA_CUDA(cudaSetDevice(device_));
  if (value_pass_.analysis != an.id) prepare_value_pass(an);
  const ValuePass& v = value_pass_;
  if (v.analysis != an.id) return false;
  const std::size_t nnz = an.pattern_indices.size();
  const double* values = nullptr;
  if (!a.host) {
    if (input_analysis_ != an.id || input_.size() < nnz) return false;
    values = input_.data();
  } else {
    if (refine_.values_analysis != an.id || refine_.values_id != a.id || a.id == 0 ||
        refine_.values.size() < nnz) {
      refine_.values_analysis = 0;
      try {
        refine_.values.resize(std::max<std::size_t>(nnz, 1));
      } catch (const OutOfMemory&) {
        return false;
      }
      if (nnz > 0)
        STRATA_CUDA(cudaMemcpyAsync(refine_.values.data(), a.host, nnz * sizeof(double),
                                    cudaMemcpyHostToDevice, stream_));
      refine_.values_analysis = an.id;
      refine_.values_id = a.id;
    }
    values = refine_.values.data();
  }
  const std::size_t m = 3 * static_cast<std::size_t>(std::max<index_t>(nrhs, 1));
  refine_.maxima.resize(m);
  refine_.maxima_host.resize(m);
  STRATA_CUDA(cudaMemsetAsync(refine_.maxima.data(), 0, m * sizeof(unsigned long long), stream_));
  const auto n = static_cast<std::int64_t>(an.n);
  if (n > 0)
    for (std::int64_t c0 = 0; c0 < nrhs; c0 += kMaxGridY) {
      const dim3 grid(static_cast<unsigned>((n + kThreads / kWarp - 1) / (kThreads / kWarp)),
                      static_cast<unsigned>(std::min<std::int64_t>(nrhs - c0, kMaxGridY)));
      residual_kernel<<<grid, kThreads, 0, stream_>>>(
          n, v.row_ptr.data(), v.row_pos.data(), v.row_col.data(), v.col_ptr.data(),
          v.col_row.data(), an.symmetric, values, b, x, r, c0, refine_.maxima.data());
      STRATA_CUDA_LAUNCH();
    }
  STRATA_CUDA(cudaMemcpyAsync(refine_.maxima_host.data(), refine_.maxima.data(),
                              m * sizeof(unsigned long long), cudaMemcpyDeviceToHost, stream_));
  STRATA_CUDA(cudaStreamSynchronize(stream_));
  for (std::size_t k = 0; k < 3 * static_cast<std::size_t>(nrhs); ++k)
    std::memcpy(maxima + k, refine_.maxima_host.data() + k, sizeof(double));
  return true;
}

void CudaExecutor::refinement_step(double* x, const double* d, double* kept, index_t n, bool undo) {
  if (n <= 0) return;
  STRATA_CUDA(cudaSetDevice(device_));
  constexpr int kBlock = 256;
  step_kernel<<<static_cast<unsigned>((n + kBlock - 1) / kBlock), kBlock, 0, stream_>>>(n, x, d,
                                                                                        kept, undo);
  STRATA_CUDA_LAUNCH();
}

}  // namespace strata::cuda
