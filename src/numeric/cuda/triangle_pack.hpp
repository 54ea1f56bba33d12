// strata — a symmetric matrix's lower triangle packed for a transfer and unpacked again on
// the GPU (the contribution blocks that symmetric factorizations send between ranks:
// distributed/nccl_transport.cpp), so that half the bytes travel.
#pragma once

#include <cuda_runtime.h>

#include <cstdint>

namespace strata::cuda {

/// Doubles of the packed lower triangle of an m × m matrix, diagonal included: m(m+1)/2.
inline std::int64_t packed_lower_size(std::int64_t m) { return m * (m + 1) / 2; }

/// Packs the lower triangle (diagonal included) of the m × m column-major matrix `full`
/// (device memory, leading dimension m) into `packed` (device memory, packed_lower_size(m)
/// doubles): column j's rows j … m − 1, columns in order (LAPACK's 'L' packed storage,
/// as DPPTRF takes it). Enqueued on `stream`; throws DeviceError when the launch fails.
void pack_lower_triangle(const double* full, std::int64_t m, double* packed, cudaStream_t stream);

/// The inverse for a symmetric matrix: `full` (m × m, column-major) gets both triangles
/// from `packed`, its strict upper triangle mirrored from the lower one. Enqueued on
/// `stream`; throws DeviceError when the launch fails.
void unpack_symmetric(const double* packed, std::int64_t m, double* full, cudaStream_t stream);

}  // namespace strata::cuda
