// strata — gathering and scattering values by position on the GPU (see value_positions.hpp).
// One thread per position, grid-strided; the positions come increasing (the entries of a
// rank's subtrees' fronts), so neighbouring threads mostly touch neighbouring entries.
#include <string>
#include <vector>

#include "numeric/cuda/cuda_check.hpp"
#include "numeric/cuda/device_buffer.hpp"
#include "numeric/cuda/value_positions.hpp"
#include "numeric/cuda_testing.hpp"

namespace strata::cuda {
namespace {

constexpr int kThreads = 256;

__global__ void gather_kernel(const double* in, const index_t* pos, std::int64_t count,
                              double* out) {
  for (std::int64_t k = blockIdx.x * static_cast<std::int64_t>(blockDim.x) + threadIdx.x; k < count;
       k += static_cast<std::int64_t>(gridDim.x) * blockDim.x)
    out[k] = in[pos[k]];
}

__global__ void scatter_kernel(const double* in, const index_t* pos, std::int64_t count,
                               double* out) {
  for (std::int64_t k = blockIdx.x * static_cast<std::int64_t>(blockDim.x) + threadIdx.x; k < count;
       k += static_cast<std::int64_t>(gridDim.x) * blockDim.x)
    out[pos[k]] = in[k];
}

unsigned blocks_for(std::int64_t count) {
  const std::int64_t b = (count + kThreads - 1) / kThreads;
  return static_cast<unsigned>(b < 65536 ? b : 65536);
}

}  // namespace

void gather_positions(const double* in, const index_t* pos, std::int64_t count, double* out,
                      cudaStream_t stream) {
  if (count <= 0) return;
  gather_kernel<<<blocks_for(count), kThreads, 0, stream>>>(in, pos, count, out);
  STRATA_CUDA(cudaGetLastError());
}

void scatter_positions(const double* in, const index_t* pos, std::int64_t count, double* out,
                       cudaStream_t stream) {
  if (count <= 0) return;
  scatter_kernel<<<blocks_for(count), kThreads, 0, stream>>>(in, pos, count, out);
  STRATA_CUDA(cudaGetLastError());
}

}  // namespace strata::cuda

namespace strata::numeric {

std::vector<double> cuda_gather_and_scatter_positions(const std::vector<double>& values,
                                                      const std::vector<index_t>& pos,
                                                      std::vector<double>& scattered) {
  for (const index_t p : pos)
    if (p < 0 || static_cast<std::size_t>(p) >= values.size())
      throw InvalidInput("cuda_gather_and_scatter_positions: position " + std::to_string(p) +
                         " outside " + std::to_string(values.size()) + " values");
  STRATA_CUDA(cudaSetDevice(0));
  const std::size_t n = values.size(), k = pos.size();
  cuda::DeviceBuffer<double> V(n ? n : 1), G(k ? k : 1), S(n ? n : 1);
  cuda::DeviceBuffer<index_t> P(k ? k : 1);
  STRATA_CUDA(cudaMemcpy(V.data(), values.data(), n * sizeof(double), cudaMemcpyHostToDevice));
  STRATA_CUDA(cudaMemcpy(P.data(), pos.data(), k * sizeof(index_t), cudaMemcpyHostToDevice));
  STRATA_CUDA(cudaMemset(S.data(), 0, (n ? n : 1) * sizeof(double)));
  cuda::gather_positions(V.data(), P.data(), static_cast<std::int64_t>(k), G.data(), nullptr);
  cuda::scatter_positions(G.data(), P.data(), static_cast<std::int64_t>(k), S.data(), nullptr);
  std::vector<double> gathered(k);
  scattered.assign(n, 0.0);
  STRATA_CUDA(cudaMemcpy(gathered.data(), G.data(), k * sizeof(double), cudaMemcpyDeviceToHost));
  STRATA_CUDA(cudaMemcpy(scattered.data(), S.data(), n * sizeof(double), cudaMemcpyDeviceToHost));
  return gathered;
}

}  // namespace strata::numeric
