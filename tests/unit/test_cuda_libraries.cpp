// strata — cuBLAS and cuSOLVER opened on first use (numeric/cuda/cuda_libraries.cpp), on
// any host, GPU or not: a process that links strata has neither library loaded until it
// calls one of their functions; the call reaches the library's own function (cuBLAS's
// status names need no GPU); and a library that cannot be opened is NotSupported naming
// it, the file and the dynamic loader's message. A build without the CUDA backend skips.
#include <gtest/gtest.h>

#include <string>

#include "strata/errors.hpp"

#if STRATA_HAVE_CUDA
#include <cublas_v2.h>
#include <cusolverDn.h>
#include <dlfcn.h>

#include "numeric/cuda/cuda_libraries.hpp"

#define STRATA_STR2(x) #x
#define STRATA_STR(x) STRATA_STR2(x)

namespace strata {
namespace {

bool loaded(const char* file) { return dlopen(file, RTLD_NOLOAD | RTLD_NOW) != nullptr; }

const char* const kCublas = "libcublas.so." STRATA_STR(CUBLAS_VER_MAJOR);
const char* const kCusolver = "libcusolver.so." STRATA_STR(CUSOLVER_VER_MAJOR);

// One test, so that "not loaded before" holds whatever order a runner picks.
TEST(CudaLibraries, OpenedOnFirstCallAndReached) {
  ASSERT_FALSE(loaded(kCublas)) << kCublas << " is loaded before any cuBLAS call";
  ASSERT_FALSE(loaded(kCusolver)) << kCusolver << " is loaded before any cuSOLVER call";
  // the library's own answer, which needs no GPU
  EXPECT_EQ(std::string(cublasGetStatusName(CUBLAS_STATUS_SUCCESS)), "CUBLAS_STATUS_SUCCESS");
  EXPECT_EQ(std::string(cublasGetStatusName(CUBLAS_STATUS_INVALID_VALUE)),
            "CUBLAS_STATUS_INVALID_VALUE");
  EXPECT_TRUE(loaded(kCublas));
  EXPECT_TRUE(loaded(kCusolver));  // both are opened together
  // a cuSOLVER handle: created with a GPU, refused by the library without one
  cusolverDnHandle_t h = nullptr;
  const cusolverStatus_t s = cusolverDnCreate(&h);
  if (s == CUSOLVER_STATUS_SUCCESS)
    EXPECT_EQ(cusolverDnDestroy(h), CUSOLVER_STATUS_SUCCESS);
  else
    EXPECT_EQ(s, CUSOLVER_STATUS_NOT_INITIALIZED);
  EXPECT_NO_THROW(cuda::load_libraries());  // already open: returns at once
}

TEST(CudaLibraries, MissingLibraryIsNotSupportedNamingIt) {
  try {
    cuda::open_library("libstrata-absent-test.so.7", "a library the test names");
    FAIL() << "opened a library that does not exist";
  } catch (const NotSupported& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("a library the test names"), std::string::npos) << m;
    EXPECT_NE(m.find("libstrata-absent-test.so.7"), std::string::npos) << m;
    EXPECT_NE(m.find("could not be loaded"), std::string::npos) << m;
  }
}

}  // namespace
}  // namespace strata
#else
TEST(CudaLibraries, NotInThisBuild) { GTEST_SKIP() << "this build has no CUDA backend"; }
#endif
