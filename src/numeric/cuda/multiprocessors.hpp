// strata — the streaming multiprocessors of a GPU, which size the device's grids and plans.
#pragma once

#include <cuda_runtime.h>

#include "numeric/cuda/cuda_check.hpp"

namespace strata::cuda {

/// The number of streaming multiprocessors of GPU `device` (the current one when −1).
/// Throws DeviceError when the runtime refuses.
inline int multiprocessor_count(int device = -1) {
  if (device < 0) STRATA_CUDA(cudaGetDevice(&device));
  int sms = 0;
  STRATA_CUDA(cudaDeviceGetAttribute(&sms, cudaDevAttrMultiProcessorCount, device));
  return sms;
}

}  // namespace strata::cuda
