// strata — NVIDIA cuBLAS and cuSOLVER loaded on first use (see cuda_libraries.hpp).
//
// Why. Linked as usual, libcublas.so and libcusolver.so are loaded and initialised when
// any program that links strata starts, whether it ever touches a GPU or not, and
// cuBLASLt, which cuBLAS loads, initialises itself by touching over a hundred megabytes
// of its own pages: a start-up cost for the command line, the Python module and every
// test, on the CPU backend too (bench/history.md, "cuBLAS and cuSOLVER opened on first
// use", has the figures).
//
// How. strata's library does not link them. This file defines the cuBLAS and cuSOLVER
// entry points that strata calls, with the signatures of the toolkit's own headers (the
// compiler checks them against those declarations); each forwards to the library's own
// function, found with dlsym in the library opened by dlopen on the first call of any of
// them (POSIX dlopen/dlsym; the loader resolves the libraries' own dependencies, e.g.
// cuSOLVER's on cuBLAS, from their RUNPATH). A program that links cuBLAS itself as well
// (the benchmarks) calls these forwarders too, which reach the same, already loaded,
// library. A library that cannot be loaded makes the call throw NotSupported with the
// loader's message, which the CUDA executor's factory turns into the backend's refusal
// before any handle is created (device_query.cu calls load_libraries first).
#include "numeric/cuda/cuda_libraries.hpp"

#include <cublas_v2.h>
#include <cusolverDn.h>
#include <dlfcn.h>

#include <string>

#include "strata/errors.hpp"

#define STRATA_STR2(x) #x
#define STRATA_STR(x) STRATA_STR2(x)

namespace strata::cuda {
namespace {

constexpr const char* kCublasFile = "libcublas.so." STRATA_STR(CUBLAS_VER_MAJOR);
constexpr const char* kCusolverFile = "libcusolver.so." STRATA_STR(CUSOLVER_VER_MAJOR);

struct Libraries {
  void* cublas;
  void* cusolver;
};

// Opened once; a failure leaves the static uninitialised, so that a later call retries.
const Libraries& libraries() {
  static const Libraries libs{open_library(kCublasFile, "NVIDIA cuBLAS"),
                              open_library(kCusolverFile, "NVIDIA cuSOLVER")};
  return libs;
}

template <class F>
F symbol(void* library, const char* file, const char* name) {
  void* p = dlsym(library, name);
  if (!p)
    throw NotSupported(std::string("the CUDA backend needs ") + name + " from " + file +
                       ", which it does not export: is the CUDA toolkit's library of the "
                       "version strata was built with installed?");
  return reinterpret_cast<F>(p);
}

}  // namespace

void* open_library(const char* file, const char* what) {
  if (void* h = dlopen(file, RTLD_NOW | RTLD_LOCAL)) return h;
  const std::string searched = dlerror();
  const std::string in_toolkit = std::string(STRATA_CUDA_LIBRARY_DIR) + "/" + file;
  if (void* h = dlopen(in_toolkit.c_str(), RTLD_NOW | RTLD_LOCAL)) return h;
  throw NotSupported(std::string("the CUDA backend needs ") + what + " (" + file +
                     "), which could not be loaded: " + searched + "; nor from " + in_toolkit +
                     ": " + dlerror());
}

void load_libraries() { (void)libraries(); }

}  // namespace strata::cuda

// One forwarder per entry point strata calls: the library's function, looked up once.
#define STRATA_FORWARD(library, file, ret, name, params, args)             \
  extern "C" ret name params {                                             \
    static const auto fn = ::strata::cuda::symbol<decltype(&name)>(        \
        ::strata::cuda::libraries().library, ::strata::cuda::file, #name); \
    return fn args;                                                        \
  }
#define STRATA_CUBLAS_FORWARD(ret, name, params, args) \
  STRATA_FORWARD(cublas, kCublasFile, ret CUBLASWINAPI, name, params, args)
#define STRATA_CUSOLVER_FORWARD(name, params, args) \
  STRATA_FORWARD(cusolver, kCusolverFile, cusolverStatus_t CUSOLVERAPI, name, params, args)

STRATA_CUBLAS_FORWARD(cublasStatus_t, cublasCreate_v2, (cublasHandle_t * handle), (handle))
STRATA_CUBLAS_FORWARD(cublasStatus_t, cublasDestroy_v2, (cublasHandle_t handle), (handle))
STRATA_CUBLAS_FORWARD(cublasStatus_t, cublasSetStream_v2,
                      (cublasHandle_t handle, cudaStream_t streamId), (handle, streamId))
STRATA_CUBLAS_FORWARD(cublasStatus_t, cublasGetStream_v2,
                      (cublasHandle_t handle, cudaStream_t* streamId), (handle, streamId))
STRATA_CUBLAS_FORWARD(const char*, cublasGetStatusString, (cublasStatus_t status), (status))
STRATA_CUBLAS_FORWARD(const char*, cublasGetStatusName, (cublasStatus_t status), (status))
STRATA_CUBLAS_FORWARD(cublasStatus_t, cublasDgemm_v2,
                      (cublasHandle_t handle, cublasOperation_t transa, cublasOperation_t transb,
                       int m, int n, int k, const double* alpha, const double* A, int lda,
                       const double* B, int ldb, const double* beta, double* C, int ldc),
                      (handle, transa, transb, m, n, k, alpha, A, lda, B, ldb, beta, C, ldc))
STRATA_CUBLAS_FORWARD(cublasStatus_t, cublasDtrsm_v2,
                      (cublasHandle_t handle, cublasSideMode_t side, cublasFillMode_t uplo,
                       cublasOperation_t trans, cublasDiagType_t diag, int m, int n,
                       const double* alpha, const double* A, int lda, double* B, int ldb),
                      (handle, side, uplo, trans, diag, m, n, alpha, A, lda, B, ldb))
STRATA_CUBLAS_FORWARD(cublasStatus_t, cublasDsyrk_v2,
                      (cublasHandle_t handle, cublasFillMode_t uplo, cublasOperation_t trans, int n,
                       int k, const double* alpha, const double* A, int lda, const double* beta,
                       double* C, int ldc),
                      (handle, uplo, trans, n, k, alpha, A, lda, beta, C, ldc))
STRATA_CUBLAS_FORWARD(cublasStatus_t, cublasDsyrkx,
                      (cublasHandle_t handle, cublasFillMode_t uplo, cublasOperation_t trans, int n,
                       int k, const double* alpha, const double* A, int lda, const double* B,
                       int ldb, const double* beta, double* C, int ldc),
                      (handle, uplo, trans, n, k, alpha, A, lda, B, ldb, beta, C, ldc))
STRATA_CUBLAS_FORWARD(cublasStatus_t, cublasDtrsv_v2,
                      (cublasHandle_t handle, cublasFillMode_t uplo, cublasOperation_t trans,
                       cublasDiagType_t diag, int n, const double* A, int lda, double* x, int incx),
                      (handle, uplo, trans, diag, n, A, lda, x, incx))
STRATA_CUBLAS_FORWARD(cublasStatus_t, cublasDgemv_v2,
                      (cublasHandle_t handle, cublasOperation_t trans, int m, int n,
                       const double* alpha, const double* A, int lda, const double* x, int incx,
                       const double* beta, double* y, int incy),
                      (handle, trans, m, n, alpha, A, lda, x, incx, beta, y, incy))

STRATA_CUSOLVER_FORWARD(cusolverDnCreate, (cusolverDnHandle_t * handle), (handle))
STRATA_CUSOLVER_FORWARD(cusolverDnDestroy, (cusolverDnHandle_t handle), (handle))
STRATA_CUSOLVER_FORWARD(cusolverDnSetStream, (cusolverDnHandle_t handle, cudaStream_t streamId),
                        (handle, streamId))
STRATA_CUSOLVER_FORWARD(cusolverDnDpotrf_bufferSize,
                        (cusolverDnHandle_t handle, cublasFillMode_t uplo, int n, double* A,
                         int lda, int* Lwork),
                        (handle, uplo, n, A, lda, Lwork))
STRATA_CUSOLVER_FORWARD(cusolverDnDpotrf,
                        (cusolverDnHandle_t handle, cublasFillMode_t uplo, int n, double* A,
                         int lda, double* Workspace, int Lwork, int* devInfo),
                        (handle, uplo, n, A, lda, Workspace, Lwork, devInfo))
STRATA_CUSOLVER_FORWARD(cusolverDnDgetrf_bufferSize,
                        (cusolverDnHandle_t handle, int m, int n, double* A, int lda, int* Lwork),
                        (handle, m, n, A, lda, Lwork))
STRATA_CUSOLVER_FORWARD(cusolverDnDgetrf,
                        (cusolverDnHandle_t handle, int m, int n, double* A, int lda,
                         double* Workspace, int* devIpiv, int* devInfo),
                        (handle, m, n, A, lda, Workspace, devIpiv, devInfo))
