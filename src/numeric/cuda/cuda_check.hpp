// strata — checked CUDA, cuBLAS and cuSOLVER calls: every failure becomes a
// strata::DeviceError naming the call, its file and line, and the library's message
// (an allocation failure becomes strata::OutOfMemory with the bytes asked for).
#pragma once

#include <cublas_v2.h>
#include <cuda_runtime.h>
#include <cusolverDn.h>

#include <string>

#include "strata/errors.hpp"

namespace strata::cuda {

[[noreturn]] void throw_cuda(cudaError_t e, const char* call, const char* file, int line);
[[noreturn]] void throw_cublas(cublasStatus_t s, const char* call, const char* file, int line);
[[noreturn]] void throw_cusolver(cusolverStatus_t s, const char* call, const char* file, int line);

}  // namespace strata::cuda

#define STRATA_CUDA(call)                                               \
  do {                                                                  \
    cudaError_t strata_e_ = (call);                                     \
    if (strata_e_ != cudaSuccess)                                       \
      ::strata::cuda::throw_cuda(strata_e_, #call, __FILE__, __LINE__); \
  } while (0)
#define STRATA_CUBLAS(call)                                               \
  do {                                                                    \
    cublasStatus_t strata_s_ = (call);                                    \
    if (strata_s_ != CUBLAS_STATUS_SUCCESS)                               \
      ::strata::cuda::throw_cublas(strata_s_, #call, __FILE__, __LINE__); \
  } while (0)
#define STRATA_CUSOLVER(call)                                               \
  do {                                                                      \
    cusolverStatus_t strata_s_ = (call);                                    \
    if (strata_s_ != CUSOLVER_STATUS_SUCCESS)                               \
      ::strata::cuda::throw_cusolver(strata_s_, #call, __FILE__, __LINE__); \
  } while (0)
/// Checks the last kernel launch.
#define STRATA_CUDA_LAUNCH() STRATA_CUDA(cudaGetLastError())
