// strata — RAII device buffers (cudaMalloc/cudaFree) and pinned host buffers.
#pragma once

#include <cstddef>
#include <utility>

#include "numeric/cuda/cuda_check.hpp"
#include "numeric/device_cap.hpp"

namespace strata::cuda {

/// Device array of T. Allocation failure (or the test-only cap of numeric/device_cap.hpp)
/// throws OutOfMemory naming the bytes; the buffer is then empty.
template <class T>
class DeviceBuffer {
 public:
  DeviceBuffer() = default;
  explicit DeviceBuffer(std::size_t n) { resize(n); }
  ~DeviceBuffer() { release(); }
  DeviceBuffer(DeviceBuffer&& o) noexcept
      : p_(std::exchange(o.p_, nullptr)), n_(std::exchange(o.n_, 0)), device_(o.device_) {}
  DeviceBuffer& operator=(DeviceBuffer&& o) noexcept {
    if (this != &o) {
      release();
      p_ = std::exchange(o.p_, nullptr);
      n_ = std::exchange(o.n_, 0);
      device_ = o.device_;
    }
    return *this;
  }
  DeviceBuffer(const DeviceBuffer&) = delete;
  DeviceBuffer& operator=(const DeviceBuffer&) = delete;

  /// Makes room for n elements; keeps the allocation when it is already large enough
  /// (contents are not preserved on growth). Growth first waits for the device that holds
  /// the old allocation: kernels and copies enqueued earlier, on any of its streams, may
  /// still use it, and cudaFree need not wait for them. Throws DeviceError when that wait
  /// reports an earlier asynchronous failure.
  void resize(std::size_t n) {
    if (n <= n_) return;
    if (p_) wait_for_owner();
    release();
    if (n == 0) return;
    // the test-only allocation cap (numeric/device_cap.hpp) fails here like cudaMalloc
    numeric::charge_device_allocation(n * sizeof(T), "cudaMalloc (device memory)");
    STRATA_CUDA(cudaGetDevice(&device_));
    cudaError_t e = cudaMalloc(reinterpret_cast<void**>(&p_), n * sizeof(T));
    if (e != cudaSuccess) {
      p_ = nullptr;
      (void)cudaGetLastError();
      throw OutOfMemory(n * sizeof(T), "cudaMalloc (device memory)");
    }
    n_ = n;
  }
  void upload(const T* host, std::size_t n, cudaStream_t s) {
    resize(n);
    if (n) STRATA_CUDA(cudaMemcpyAsync(p_, host, n * sizeof(T), cudaMemcpyHostToDevice, s));
  }
  T* data() { return p_; }
  const T* data() const { return p_; }
  std::size_t size() const { return n_; }
  /// Frees the allocation (size becomes 0).
  void clear() { release(); }

 private:
  void release() {
    if (p_) cudaFree(p_);
    p_ = nullptr;
    n_ = 0;
  }
  // Synchronizes device_ (the current device is left as it was).
  void wait_for_owner() const {
    int current = 0;
    STRATA_CUDA(cudaGetDevice(&current));
    if (current != device_) STRATA_CUDA(cudaSetDevice(device_));
    const cudaError_t e = cudaDeviceSynchronize();
    if (current != device_) STRATA_CUDA(cudaSetDevice(current));
    STRATA_CUDA(e);
  }
  T* p_ = nullptr;
  std::size_t n_ = 0;
  int device_ = 0;  ///< the device current at the allocation
};

/// Page-locked host array of T (cudaMallocHost), so device-to-host copies run at full
/// bandwidth and asynchronously. Grows only; contents are not preserved on growth.
template <class T>
class PinnedBuffer {
 public:
  PinnedBuffer() = default;
  ~PinnedBuffer() { release(); }
  PinnedBuffer(const PinnedBuffer&) = delete;
  PinnedBuffer& operator=(const PinnedBuffer&) = delete;
  void resize(std::size_t n) {
    if (n <= n_) return;
    release();
    if (cudaMallocHost(reinterpret_cast<void**>(&p_), n * sizeof(T)) != cudaSuccess) {
      p_ = nullptr;
      (void)cudaGetLastError();
      throw OutOfMemory(n * sizeof(T), "cudaMallocHost (pinned host memory)");
    }
    n_ = n;
  }
  T* data() { return p_; }
  const T* data() const { return p_; }
  std::size_t size() const { return n_; }
  /// Frees the allocation (size becomes 0).
  void clear() { release(); }
  /// Exchanges the two allocations.
  void swap(PinnedBuffer& o) noexcept {
    std::swap(p_, o.p_);
    std::swap(n_, o.n_);
  }

 private:
  void release() {
    if (p_) cudaFreeHost(p_);
    p_ = nullptr;
    n_ = 0;
  }
  T* p_ = nullptr;
  std::size_t n_ = 0;
};

}  // namespace strata::cuda
