// strata — backend selection. The CUDA executor is not part of this version: asking for
// it is a clear NotSupported error, in builds with and without CUDA alike.
#include "numeric/factor.hpp"
#include "strata/errors.hpp"

namespace strata::numeric {

bool cuda_available() { return false; }

std::unique_ptr<Executor> make_cuda_executor(const Options&) {
#ifdef STRATA_HAVE_CUDA
  throw NotSupported("the CUDA backend is not implemented in this version of strata yet");
#else
  throw NotSupported("this build of strata has no CUDA backend (nvcc was not found at build time)");
#endif
}

}  // namespace strata::numeric
