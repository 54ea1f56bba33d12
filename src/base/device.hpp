// strata — what the build and the machine offer in GPUs, for every layer that chooses a
// backend (the analysis sizes fronts for it, the solvers and the engine pick executors).
// Defined by the CUDA backend (numeric/cuda/device_query.cu) or, in a build without CUDA,
// by numeric/backends.cpp, which answers "none".
#pragma once

#include <string>

#include "strata/options.hpp"

namespace strata::numeric {

/// True when this build has the CUDA backend and a GPU is visible.
bool cuda_available();

/// Number of visible CUDA devices (0 in a build without CUDA or when the driver fails).
int cuda_device_count();

/// Why the CUDA backend cannot run here, or "" when it can: the message of the
/// NotSupported error that asking for it gives (no CUDA backend in this build, or no GPU
/// visible).
std::string cuda_unavailable_reason();

/// Starts creating the CUDA context of `device` (its primary context) on a thread of its
/// own and returns at once, so that a program that will use the GPU later overlaps the
/// context's creation (a few hundred milliseconds) with its host work; a CUDA call of
/// another thread in the meantime waits for it. Once per process (later calls do
/// nothing); the thread is joined at exit. Nothing in a build without CUDA or on a machine
/// without a GPU; an error is left to the first CUDA call of the code that uses the GPU.
void start_device_context(int device = 0);

/// Whether `backend` resolves to the CUDA executor on this machine: Backend::cuda, or
/// Backend::automatic with a GPU visible.
inline bool uses_cuda(Backend backend) {
  return backend == Backend::cuda || (backend == Backend::automatic && cuda_available());
}

}  // namespace strata::numeric
