// strata — what the CUDA build offers: whether a GPU is visible and how many
// (base/device.hpp), page-locking host memory for transfers, and the CUDA executor's
// factory (numeric/factor.hpp). A build without CUDA has numeric/backends.cpp instead.
#include <algorithm>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "numeric/cuda/cuda_executor.hpp"
#include "numeric/cuda/cuda_libraries.hpp"
#include "numeric/cuda_testing.hpp"

namespace strata::cuda {
namespace {

bool device_present() {
  int count = 0;
  if (cudaGetDeviceCount(&count) != cudaSuccess) {
    (void)cudaGetLastError();
    return false;
  }
  return count > 0;
}

}  // namespace
}  // namespace strata::cuda

namespace strata::numeric {

bool cuda_available() { return cuda::device_present(); }

int cuda_device_count() {
  int count = 0;
  if (cudaGetDeviceCount(&count) != cudaSuccess) {
    (void)cudaGetLastError();
    return 0;
  }
  return count;
}

void start_device_context(int device) {
  // the thread is kept in a static object whose destructor joins it: a program that ends
  // while the driver is still creating the context waits for it rather than tearing the
  // runtime down under it
  struct Starter {
    std::thread thread;
    ~Starter() {
      if (thread.joinable()) thread.join();
    }
  };
  static Starter starter;
  static std::once_flag once;
  std::call_once(once, [device] {
    if (device < 0 || device >= cuda_device_count()) return;
    starter.thread = std::thread([device] {
      if (cudaSetDevice(device) != cudaSuccess || cudaFree(nullptr) != cudaSuccess)
        (void)cudaGetLastError();  // left to the code that uses the GPU
      // cuBLAS and cuSOLVER too (cuda_libraries.cpp); any failure is left to the
      // executor's factory, which loads them again and throws (nothing may escape a
      // thread's function)
      try {
        cuda::load_libraries();
      } catch (...) {
      }
    });
  });
}

namespace {
class CudaPinnedRange final : public PinnedHostRange {
 public:
  using PinnedHostRange::PinnedHostRange;
  ~CudaPinnedRange() override { cudaHostUnregister(const_cast<void*>(data())); }
};
}  // namespace

std::unique_ptr<PinnedHostRange> pin_host_memory(void* p, std::size_t bytes) {
  if (!p || bytes == 0 || !cuda::device_present()) return nullptr;
  if (cudaHostRegister(p, bytes, cudaHostRegisterPortable) != cudaSuccess) {
    (void)cudaGetLastError();
    return nullptr;
  }
  return std::make_unique<CudaPinnedRange>(p, bytes);
}

bool page_locked(const void* p, std::size_t bytes) {
  if (!p || bytes == 0 || !cuda::device_present()) return false;
  const auto host = [](const void* q) {
    cudaPointerAttributes a{};
    if (cudaPointerGetAttributes(&a, q) != cudaSuccess) {
      (void)cudaGetLastError();
      return false;
    }
    return a.type == cudaMemoryTypeHost;
  };
  return host(p) && host(static_cast<const char*>(p) + (bytes - 1));
}

int device_memory_of(const void* p) {
  if (!p || !cuda::device_present()) return -1;
  cudaPointerAttributes a{};
  if (cudaPointerGetAttributes(&a, p) != cudaSuccess) {
    (void)cudaGetLastError();
    return -1;
  }
  return a.type == cudaMemoryTypeDevice ? a.device : -1;
}

void copy_from_device(double* host, const double* device, std::size_t n) {
  if (n > 0) STRATA_CUDA(cudaMemcpy(host, device, n * sizeof(double), cudaMemcpyDefault));
}

void copy_to_device(double* device, const double* host, std::size_t n) {
  if (n > 0) STRATA_CUDA(cudaMemcpy(device, host, n * sizeof(double), cudaMemcpyDefault));
}

std::shared_ptr<double> cuda_device_copy(const std::vector<double>& host) {
  if (!cuda::device_present()) throw NotSupported(cuda_unavailable_reason());
  STRATA_CUDA(cudaSetDevice(0));
  double* p = nullptr;
  STRATA_CUDA(cudaMalloc(&p, std::max<std::size_t>(host.size(), 1) * sizeof(double)));
  std::shared_ptr<double> owned(p, [](double* q) { cudaFree(q); });
  if (!host.empty())
    STRATA_CUDA(cudaMemcpy(p, host.data(), host.size() * sizeof(double), cudaMemcpyHostToDevice));
  return owned;
}

std::string cuda_unavailable_reason() {
  return cuda::device_present() ? "" : "the CUDA backend was asked for, but no CUDA GPU is visible";
}

std::unique_ptr<Executor> make_cuda_executor(const Options& opts, int device) {
  if (!cuda::device_present()) throw NotSupported(cuda_unavailable_reason());
  cuda::load_libraries();  // NotSupported, naming the library, before any handle is made
  const int count = cuda_device_count();
  if (device < 0 || device >= count)
    throw NotSupported("CUDA device " + std::to_string(device) + " was asked for, " +
                       std::to_string(count) + " are visible");
  return std::make_unique<cuda::CudaExecutor>(opts, device);
}

}  // namespace strata::numeric
