// strata — the assembly of a front that is factored slab by slab (tiled_front.cu), on the
// host's threads.
//
// Why on the host: such a front does not fit the device budget, so it is assembled into
// pinned host memory. The device kernel did that over the bus — zeroing m² doubles, then
// a read-modify-write across PCIe for every original entry and every entry of each
// child's contribution block (themselves mostly spilled to the host arena), a large share
// of an out-of-core factorization (bench/history.md). On the host the same
// additions run at memory bandwidth; a child block that stayed on the device comes over in
// one DMA copy. The front is built by blocks of columns, in parallel, each block zeroed and
// then given its entries and each child's columns that land in it (the device kernel's
// slices, on the host; no faster than whole-front passes — host memory bandwidth bounds
// both — but one front's work spreads over the threads). The
// additions themselves are numeric/assembly.hpp's, the CPU executor's. The order of the additions
// is the kernel's (entries, then children one after another, each destination written once per
// child), so the front is bitwise the same.
//
// A Cholesky front is assembled split (assemble_llt_split): its k pivot columns in place in
// the panel buffer (the front's own layout), its contribution block's lower triangle
// straight into its destination (mc × mc, leading dimension mc: the host arena, where the
// plan spilled it), so that the tiled factorization (tiled_llt.cu) never holds — or copies
// — the m × m front. The memory plan never places a block over its children's blocks
// (schedule/memory_plan.hpp), so writing it while they are read is safe.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <vector>

#include "numeric/assembly.hpp"
#include "numeric/cuda/cuda_executor.hpp"

namespace strata::cuda {

std::vector<const double*> CudaExecutor::children_blocks_on_host(const numeric::FactorContext& ctx,
                                                                 index_t f) {
  const auto& t = ctx.analysis->tree;
  // the children's blocks were stored by kernels on stream_: they must have landed
  STRATA_CUDA(cudaStreamSynchronize(stream_));
  // each child's block: in the host arena, or copied from the device into host_staging_
  // (all such blocks one after another, one wait)
  const index_t q0 = t.child_offsets[f], q1 = t.child_offsets[f + 1];
  std::vector<const double*> block(q1 - q0, nullptr);
  std::size_t staged = 0;
  for (index_t q = q0; q < q1; ++q) {
    const double* cb = cur_->cb_ptr_host[t.children[q]];
    const std::size_t mc = static_cast<std::size_t>(t.cb_size(t.children[q]));
    if (mc > 0 && !in_host_arena(cb)) staged += mc * mc;
  }
  if (staged > 0) host_staging_.resize(staged);
  staged = 0;
  for (index_t q = q0; q < q1; ++q) {
    const index_t c = t.children[q];
    const std::size_t mc = static_cast<std::size_t>(t.cb_size(c));
    const double* cb = cur_->cb_ptr_host[c];
    if (mc == 0) continue;
    if (!in_host_arena(cb)) {  // on the device: copied over
      STRATA_CUDA(cudaMemcpyAsync(host_staging_.data() + staged, cb, sizeof(double) * mc * mc,
                                  cudaMemcpyDeviceToHost, stream_));
      bytes_d2h_ += sizeof(double) * mc * mc;
      cb = host_staging_.data() + staged;
      staged += mc * mc;
    }
    block[q - q0] = cb;
  }
  if (staged > 0) STRATA_CUDA(cudaStreamSynchronize(stream_));
  return block;
}

namespace {

constexpr std::int64_t kCols = 32;  // columns per block of the host assembly

// Columns [c0, c1) of front f (m rows) assembled into W (leading dimension m, W's column 0
// the front's column c0): zeroed, the original entries, then each child's columns that
// land there, in child order — the block stays in cache through all of its additions, and
// every entry sees the device kernel's order of additions.
void assemble_columns(const Analysis& an, const double* values, index_t f,
                      const std::vector<const double*>& block, const std::int64_t* rel_all,
                      const std::int64_t* rel_offsets, bool symmetric, std::int64_t c0,
                      std::int64_t c1, double* W) {
  const auto& t = an.tree;
  const auto& am = an.assembly;
  const std::int64_t m = t.n_rows(f);
  std::fill(W, W + (c1 - c0) * m, 0.0);
  numeric::add_entries(W, am.entry_dst.data(), am.entry_src.data(), values, am.entry_offsets[f],
                       am.entry_offsets[f + 1], c0 * m, c1 * m);
  const index_t q0 = t.child_offsets[f], q1 = t.child_offsets[f + 1];
  for (index_t q = q0; q < q1; ++q) {
    const double* cb = block[q - q0];
    if (!cb) continue;
    const index_t c = t.children[q];
    const std::int64_t mc = t.cb_size(c);
    const std::int64_t* rel = rel_all + rel_offsets[c];
    // rel is increasing: the child's columns that land in [c0, c1)
    const std::int64_t j0 = std::lower_bound(rel, rel + mc, c0) - rel;
    const std::int64_t j1 = std::lower_bound(rel, rel + mc, c1) - rel;
    numeric::extend_add(W, m, cb, mc, rel, j0, j1, symmetric, c0);
  }
}

}  // namespace

void CudaExecutor::assemble_on_host(const numeric::FactorContext& ctx, index_t f, double* H,
                                    bool symmetric) {
  const Analysis& an = *ctx.analysis;
  const std::int64_t m = an.tree.n_rows(f);
  const std::vector<const double*> block = children_blocks_on_host(ctx, f);
  const std::int64_t blocks = (m + kCols - 1) / kCols;
  tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, blocks), [&](const auto& r) {
    for (std::int64_t b = r.begin(); b < r.end(); ++b) {
      const std::int64_t c0 = b * kCols, c1 = std::min(m, c0 + kCols);
      assemble_columns(an, ctx.values, f, block, an.child_rows.rel.data(),
                       an.child_rows.offsets.data(), symmetric, c0, c1, H + c0 * m);
    }
  });
}

void CudaExecutor::assemble_llt_split(const numeric::FactorContext& ctx, index_t f, double* P,
                                      double* C) {
  assemble_llt_split_from(*ctx.analysis, ctx.values, f, P, C, children_blocks_on_host(ctx, f));
}

void CudaExecutor::assemble_llt_split_from(const Analysis& an, const double* values, index_t f,
                                           double* P, double* C,
                                           const std::vector<const double*>& block) {
  const auto& t = an.tree;
  const std::int64_t m = t.n_rows(f), k = t.n_pivots(f), mc = m - k;
  // blocks of the pivot columns, then (when C is wanted) of the contribution block's
  const std::int64_t pb = (k + kCols - 1) / kCols;
  const std::int64_t blocks = pb + (C ? (mc + kCols - 1) / kCols : 0);
  const std::int64_t* rel = an.child_rows.rel.data();
  const std::int64_t* rel_off = an.child_rows.offsets.data();
  tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, blocks), [&](const auto& r) {
    std::vector<double> W;  // a block of the contribution block's columns, whole
    for (std::int64_t b = r.begin(); b < r.end(); ++b) {
      if (b < pb) {  // the panel has the front's layout: assembled in place
        const std::int64_t c0 = b * kCols, c1 = std::min(k, c0 + kCols);
        assemble_columns(an, values, f, block, rel, rel_off, true, c0, c1, P + c0 * m);
        continue;
      }
      const std::int64_t c0 = k + (b - pb) * kCols, c1 = std::min(m, c0 + kCols);
      W.resize(static_cast<std::size_t>((c1 - c0) * m));
      assemble_columns(an, values, f, block, rel, rel_off, true, c0, c1, W.data());
      for (std::int64_t c = c0; c < c1; ++c)  // its lower triangle: rows c..m
        std::copy(W.data() + (c - c0) * m + c, W.data() + (c - c0 + 1) * m,
                  C + (c - k) * mc + (c - k));
    }
  });
}

}  // namespace strata::cuda
