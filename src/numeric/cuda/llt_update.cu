// strata — the contribution-block update of one large Cholesky front on the GPU,
// C −= L₂₁L₂₁ᵀ (lower triangle), by one cuBLAS call chosen by shape.
//
// cuBLAS DSYRK has two kinds of kernel on Hopper: a tensor-core one (`sm90_xmma_syrk…`)
// and a generic one (`syherk_kernel_core`). Which one runs depends on the shape, and the
// generic one stays slow whatever the size: below about n·k = 240,000 (C of order n below
// a panel of k columns) one DGEMM of the whole n × n square — twice the flops, on the
// tensor cores — takes less time, except where the square is small. The rule below takes
// the GEMM inside the region where it was measured faster (bench/history.md, "DSYRK
// against DGEMM"): n·k < 240,000 and either n ≥ 1,000 with k ≥ 48, or n ≥ 400 with
// k ≥ 192.
//
// The GEMM also writes C's strict upper triangle. Nothing reads it: the contribution
// block is stored from its lower triangle (store_cb_kernel), the factor panels are the
// pivot columns only, and every front is assembled into zeros.
#include <string>

#include "numeric/cuda/cuda_executor.hpp"
#include "numeric/cuda_testing.hpp"
#include "numeric/factor.hpp"
#include "strata/errors.hpp"

namespace strata::cuda {

bool llt_update_by_gemm(std::int64_t n, std::int64_t k) {
  if (n * k >= 240000) return false;
  return (n >= 1000 && k >= 48) || (n >= 400 && k >= 192);
}

void llt_update(cublasHandle_t blas, std::int64_t n, std::int64_t k, const double* L,
                std::int64_t ld, double* C, std::int64_t ldc) {
  if (n <= 0 || k <= 0) return;
  const double one = 1.0, minus_one = -1.0;
  const int ni = static_cast<int>(n), ki = static_cast<int>(k);
  if (llt_update_by_gemm(n, k))
    STRATA_CUBLAS(cublasDgemm(blas, CUBLAS_OP_N, CUBLAS_OP_T, ni, ni, ki, &minus_one, L,
                              static_cast<int>(ld), L, static_cast<int>(ld), &one, C,
                              static_cast<int>(ldc)));
  else
    STRATA_CUBLAS(cublasDsyrk(blas, CUBLAS_FILL_MODE_LOWER, CUBLAS_OP_N, ni, ki, &minus_one, L,
                              static_cast<int>(ld), &one, C, static_cast<int>(ldc)));
}

}  // namespace strata::cuda

namespace strata::numeric {

bool cuda_llt_update(double* c, const double* l, index_t n, index_t k) {
  if (n < 1 || k < 1)
    throw InvalidInput("cuda_llt_update: needs n >= 1 and k >= 1 (n = " + std::to_string(n) +
                       ", k = " + std::to_string(k) + ")");
  STRATA_CUDA(cudaSetDevice(0));
  const std::size_t cn = static_cast<std::size_t>(n) * static_cast<std::size_t>(n);
  const std::size_t ln = static_cast<std::size_t>(n) * static_cast<std::size_t>(k);
  cuda::DeviceBuffer<double> C(cn), L(ln);
  cublasHandle_t blas = nullptr;
  STRATA_CUBLAS(cublasCreate(&blas));
  struct Handle {
    cublasHandle_t b;
    ~Handle() { cublasDestroy(b); }
  } owned{blas};
  STRATA_CUDA(cudaMemcpy(C.data(), c, cn * sizeof(double), cudaMemcpyHostToDevice));
  STRATA_CUDA(cudaMemcpy(L.data(), l, ln * sizeof(double), cudaMemcpyHostToDevice));
  cuda::llt_update(blas, n, k, L.data(), n, C.data(), n);
  STRATA_CUDA(cudaMemcpy(c, C.data(), cn * sizeof(double), cudaMemcpyDeviceToHost));
  return cuda::llt_update_by_gemm(n, k);
}

}  // namespace strata::numeric
