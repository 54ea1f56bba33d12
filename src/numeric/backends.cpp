// strata — backend selection in a build without CUDA: asking for the GPU backend is a
// clear NotSupported error. (A CUDA build compiles numeric/cuda/cuda_executor.cu, which
// defines these two functions instead.)
#ifndef STRATA_HAVE_CUDA
#include "numeric/factor.hpp"
#include "strata/errors.hpp"

namespace strata::numeric {

bool cuda_available() { return false; }

int cuda_device_count() { return 0; }

std::unique_ptr<Executor> make_cuda_executor(const Options&, int) {
  throw NotSupported("this build of strata has no CUDA backend (nvcc was not found at build time)");
}

}  // namespace strata::numeric
#endif
