// strata — the assembly of a front that is factored slab by slab (tiled_front.cu), on the
// host's threads.
//
// Why on the host: such a front does not fit the device budget, so it is assembled into
// pinned host memory. The device kernel did that over the bus — zeroing m² doubles, then
// a read-modify-write across PCIe for every original entry and every entry of each
// child's contribution block (themselves mostly spilled to the host arena): 2.3 s of a
// 12.8 s factorization of lap3d 100³ under 1/20 of its factor on the H100 (commit
// 4c2899b, bench/results/gpu-memory-phases-20261122T024659Z.json). On the host the same
// additions run at memory bandwidth; a child block that stayed on the device comes over in
// one DMA copy. The order of the additions is the kernel's (entries, then children one
// after another, each destination written once per child), so the front is bitwise the
// same.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>

#include "numeric/cuda/cuda_executor.hpp"

namespace strata::cuda {

void CudaExecutor::assemble_on_host(const numeric::FactorContext& ctx, index_t f, double* H,
                                    bool symmetric) {
  const Analysis& an = *ctx.analysis;
  const auto& t = an.tree;
  const std::int64_t m = t.n_rows(f);
  // the children's blocks were stored by kernels on stream_: they must have landed
  STRATA_CUDA(cudaStreamSynchronize(stream_));
  tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, m, 64),
                    [&](const auto& r) { std::fill(H + r.begin() * m, H + r.end() * m, 0.0); });
  const auto& am = an.assembly;
  for (index_t e = am.entry_offsets[f]; e < am.entry_offsets[f + 1]; ++e)
    H[am.entry_dst[e]] += ctx.values[am.entry_src[e]];  // distinct destinations
  const double* arena_begin = host_arena_.data();
  const double* arena_end = arena_begin + host_arena_.size();
  for (index_t q = t.child_offsets[f]; q < t.child_offsets[f + 1]; ++q) {
    const index_t c = t.children[q];
    const std::int64_t mc = t.cb_size(c);
    if (mc == 0) continue;
    const double* cb = cur_->cb_ptr_host[c];
    if (cb < arena_begin || cb >= arena_end) {  // on the device: one copy over
      host_staging_.resize(static_cast<std::size_t>(mc) * mc);
      STRATA_CUDA(cudaMemcpyAsync(host_staging_.data(), cb, sizeof(double) * mc * mc,
                                  cudaMemcpyDeviceToHost, stream_));
      STRATA_CUDA(cudaStreamSynchronize(stream_));
      bytes_d2h_ += sizeof(double) * mc * mc;
      cb = host_staging_.data();
    }
    const std::int64_t* rel = rel_host_.data() + rel_offsets_host_[c];
    // the child's columns go to distinct front columns: no two tasks write one entry
    tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, mc, 16), [&](const auto& r) {
      for (std::int64_t jj = r.begin(); jj < r.end(); ++jj) {
        double* fcol = H + rel[jj] * m;
        const double* src = cb + jj * mc;
        for (std::int64_t ii = symmetric ? jj : 0; ii < mc; ++ii) fcol[rel[ii]] += src[ii];
      }
    });
  }
}

}  // namespace strata::cuda
