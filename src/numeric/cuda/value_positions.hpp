// strata — values gathered from and scattered to positions of an array on the GPU (the
// scaled values that distributed ranks send one another: distributed/nccl_transport.cpp
// gathers each rank's share of rank 0's values on rank 0's GPU and scatters it into the
// receiving rank's array on its GPU, so that neither side packs them on the host).
#pragma once

#include <cuda_runtime.h>

#include <cstdint>

#include "strata/types.hpp"

namespace strata::cuda {

/// out[k] = in[pos[k]] for k = 0 … count − 1 (all three in device memory; pos 0-based,
/// each within `in`). Enqueued on `stream`; throws DeviceError when the launch fails.
void gather_positions(const double* in, const index_t* pos, std::int64_t count, double* out,
                      cudaStream_t stream);

/// out[pos[k]] = in[k] for k = 0 … count − 1 (device memory; pos 0-based and distinct, each
/// within `out`; the other entries of `out` are left as they are). Enqueued on `stream`;
/// throws DeviceError when the launch fails.
void scatter_positions(const double* in, const index_t* pos, std::int64_t count, double* out,
                       cudaStream_t stream);

}  // namespace strata::cuda
