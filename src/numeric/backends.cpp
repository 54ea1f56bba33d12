// strata — backend selection in a build without CUDA: asking for the GPU backend is a
// clear NotSupported error, and no host memory is pinned. (A CUDA build compiles
// numeric/cuda/device_query.cu, which defines these functions instead.)
#ifndef STRATA_HAVE_CUDA
#include "numeric/cuda_testing.hpp"
#include "numeric/factor.hpp"
#include "strata/errors.hpp"

namespace strata::numeric {

bool cuda_available() { return false; }

int cuda_device_count() { return 0; }

void start_device_context(int) {}

std::string cuda_unavailable_reason() {
  return "this build of strata has no CUDA backend (nvcc was not found at build time)";
}

std::unique_ptr<Executor> make_cuda_executor(const Options&, int) {
  throw NotSupported(cuda_unavailable_reason());
}

std::unique_ptr<PinnedHostRange> pin_host_memory(void*, std::size_t) { return nullptr; }

bool page_locked(const void*, std::size_t) { return false; }

int device_memory_of(const void*) { return -1; }

void copy_from_device(double*, const double*, std::size_t) {
  throw NotSupported("this build of strata has no CUDA backend (nvcc was not found at build time)");
}

void copy_to_device(double*, const double*, std::size_t) {
  throw NotSupported("this build of strata has no CUDA backend (nvcc was not found at build time)");
}

std::shared_ptr<double> cuda_device_copy(const std::vector<double>&) {
  throw NotSupported("this build of strata has no CUDA backend (nvcc was not found at build time)");
}

index_t cuda_llt_pivot_block_and_panel(double*, index_t, index_t) {
  throw NotSupported("this build of strata has no CUDA backend (nvcc was not found at build time)");
}

bool cuda_llt_update(double*, const double*, index_t, index_t) {
  throw NotSupported("this build of strata has no CUDA backend (nvcc was not found at build time)");
}

std::vector<double> cuda_pack_and_unpack_lower(const double*, index_t, std::vector<double>&) {
  throw NotSupported("this build of strata has no CUDA backend (nvcc was not found at build time)");
}

std::vector<double> cuda_gather_and_scatter_positions(const std::vector<double>&,
                                                      const std::vector<index_t>&,
                                                      std::vector<double>&) {
  throw NotSupported("this build of strata has no CUDA backend (nvcc was not found at build time)");
}

std::vector<char> cuda_lu_fronts_batched(std::vector<std::vector<double>>&,
                                         const std::vector<index_t>&, const std::vector<index_t>&,
                                         index_t, double, double,
                                         std::vector<std::vector<index_t>>*, bool) {
  throw NotSupported("this build of strata has no CUDA backend (nvcc was not found at build time)");
}

std::vector<double> cuda_divide_rn(const std::vector<double>&, const std::vector<double>&) {
  throw NotSupported("this build of strata has no CUDA backend (nvcc was not found at build time)");
}

std::vector<double> cuda_pivot_reciprocal(const std::vector<double>&, const std::vector<double>&) {
  throw NotSupported("this build of strata has no CUDA backend (nvcc was not found at build time)");
}

std::vector<double> cuda_gemv_n(index_t, index_t, double, const std::vector<double>&, index_t,
                                const std::vector<double>&, std::vector<double>) {
  throw NotSupported("this build of strata has no CUDA backend (nvcc was not found at build time)");
}

std::vector<double> cuda_trsv_tiles(int, bool, index_t, const std::vector<double>&, index_t,
                                    std::vector<double>) {
  throw NotSupported("this build of strata has no CUDA backend (nvcc was not found at build time)");
}

int cuda_small_front_threads(index_t, index_t, int, bool) {
  throw NotSupported("this build of strata has no CUDA backend (nvcc was not found at build time)");
}

index_t cuda_fused_front_max_rows(bool) {
  throw NotSupported("this build of strata has no CUDA backend (nvcc was not found at build time)");
}

}  // namespace strata::numeric
#endif
