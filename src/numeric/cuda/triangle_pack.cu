// strata — packing a lower triangle for a transfer and unpacking it symmetric (see
// triangle_pack.hpp). One thread per stored entry: blockIdx.y walks the columns (grid-
// strided past 65,535), threads the rows of the column from its diagonal down, so the
// reads and the packed writes are contiguous per column; the mirrored writes of the
// unpacking go across a row (one 32-byte sector each), which the transfer's bytes, not
// these copies, dominate.
#include <string>
#include <vector>

#include "numeric/cuda/cuda_check.hpp"
#include "numeric/cuda/device_buffer.hpp"
#include "numeric/cuda/triangle_pack.hpp"
#include "numeric/cuda_testing.hpp"

namespace strata::cuda {
namespace {

constexpr int kThreads = 256;

__device__ std::int64_t column_offset(std::int64_t j, std::int64_t m) {
  return j * m - j * (j - 1) / 2;  // Σ_{c<j} (m − c)
}

__global__ void pack_lower_kernel(const double* full, std::int64_t m, double* packed) {
  for (std::int64_t j = blockIdx.y; j < m; j += gridDim.y) {
    const std::int64_t off = column_offset(j, m);
    for (std::int64_t i = j + blockIdx.x * blockDim.x + threadIdx.x; i < m;
         i += static_cast<std::int64_t>(gridDim.x) * blockDim.x)
      packed[off + (i - j)] = full[i + j * m];
  }
}

__global__ void unpack_symmetric_kernel(const double* packed, std::int64_t m, double* full) {
  for (std::int64_t j = blockIdx.y; j < m; j += gridDim.y) {
    const std::int64_t off = column_offset(j, m);
    for (std::int64_t i = j + blockIdx.x * blockDim.x + threadIdx.x; i < m;
         i += static_cast<std::int64_t>(gridDim.x) * blockDim.x) {
      const double v = packed[off + (i - j)];
      full[i + j * m] = v;
      full[j + i * m] = v;
    }
  }
}

dim3 grid_for(std::int64_t m) {
  const std::int64_t x = (m + kThreads - 1) / kThreads;
  return dim3(static_cast<unsigned>(x < 64 ? x : 64), static_cast<unsigned>(m < 65535 ? m : 65535));
}

}  // namespace

void pack_lower_triangle(const double* full, std::int64_t m, double* packed, cudaStream_t stream) {
  if (m <= 0) return;
  pack_lower_kernel<<<grid_for(m), kThreads, 0, stream>>>(full, m, packed);
  STRATA_CUDA(cudaGetLastError());
}

void unpack_symmetric(const double* packed, std::int64_t m, double* full, cudaStream_t stream) {
  if (m <= 0) return;
  unpack_symmetric_kernel<<<grid_for(m), kThreads, 0, stream>>>(packed, m, full);
  STRATA_CUDA(cudaGetLastError());
}

}  // namespace strata::cuda

namespace strata::numeric {

std::vector<double> cuda_pack_and_unpack_lower(const double* a, index_t m,
                                               std::vector<double>& full) {
  if (m < 0) throw InvalidInput("cuda_pack_and_unpack_lower: m = " + std::to_string(m));
  STRATA_CUDA(cudaSetDevice(0));
  const std::size_t n = static_cast<std::size_t>(m) * static_cast<std::size_t>(m);
  const std::size_t np = static_cast<std::size_t>(cuda::packed_lower_size(m));
  cuda::DeviceBuffer<double> A(n ? n : 1), P(np ? np : 1), F(n ? n : 1);
  STRATA_CUDA(cudaMemcpy(A.data(), a, n * sizeof(double), cudaMemcpyHostToDevice));
  STRATA_CUDA(
      cudaMemset(F.data(), 0xff, (n ? n : 1) * sizeof(double)));  // NaN: every entry written?
  cuda::pack_lower_triangle(A.data(), m, P.data(), nullptr);
  cuda::unpack_symmetric(P.data(), m, F.data(), nullptr);
  std::vector<double> packed(np);
  full.assign(n, 0.0);
  STRATA_CUDA(cudaMemcpy(packed.data(), P.data(), np * sizeof(double), cudaMemcpyDeviceToHost));
  STRATA_CUDA(cudaMemcpy(full.data(), F.data(), n * sizeof(double), cudaMemcpyDeviceToHost));
  return packed;
}

}  // namespace strata::numeric
