// strata — an LU front larger than the device budget, factored slab by slab (issue 5's
// "any device memory"; a Cholesky front goes through tiled_llt.cu instead).
//
// The front F (m×m, column-major) is assembled into pinned host memory by the host's
// threads (tiled_host.cpp; the device kernel did it over the bus, slower). It is then
// factored right-looking by slabs of w columns, w chosen so that
// a slab and two column blocks of the trailing matrix fit the device pool (3·m·w
// doubles):
//   for each slab p0 .. p0+w of the k pivot columns:
//     upload the slab (rows p0..m) and factor it on the device with our panel kernel,
//     pivot candidates the fully summed rows [j, k) as in-core, row swaps applied to
//     the slab on the device and then to the front's other columns on the host, so the
//     pivot sequence is the in-core one;
//     download it; then for each column block jb of the trailing matrix: upload it,
//     TRSM of its w rows by L11 (they become U12), GEMM below, and download it — the
//     blocks alternate between two lanes (streams) with a buffer each, so that one
//     block's transfers run while the other's update computes.
// The contribution block F[k:m, k:m] is then copied where the device plan keeps it (by
// the host's threads when that is the host arena: a 2-D cudaMemcpy between host buffers
// runs on one thread and dominated the factorization under a small budget), and the
// panels into the host factor (and the resident device factor, if any).
// Traffic is about k·m²/w doubles each way: this is the slow, always-possible path; the
// memory plan makes it the exception (a front whose working set alone exceeds the budget).
// The left-looking, tiled scheme of tiled_llt.cu would move less here too; what LU adds
// is the row interchanges of each slab, applied to the whole front.
//
// Source: the right-looking blocked algorithm of Golub & Van Loan, "Matrix
// Computations", 4th ed., §3.2.11, with the panel as the unit of transfer
// (out-of-core dense factorization as in Toledo, "A survey of out-of-core algorithms in
// numerical linear algebra", 1999).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>

#include "base/host_copy.hpp"
#include "numeric/cuda/cuda_executor.hpp"

namespace strata::cuda {

void copy_host_block(cudaStream_t s, double* d, const double* h, std::int64_t ldh, std::int64_t r0,
                     std::int64_t c0, std::int64_t rows, std::int64_t cols, bool to_device) {
  if (rows == 0 || cols == 0) return;
  const double* src = h + c0 * ldh + r0;
  if (to_device)
    STRATA_CUDA(cudaMemcpy2DAsync(d, sizeof(double) * rows, src, sizeof(double) * ldh,
                                  sizeof(double) * rows, cols, cudaMemcpyHostToDevice, s));
  else
    STRATA_CUDA(cudaMemcpy2DAsync(const_cast<double*>(src), sizeof(double) * ldh, d,
                                  sizeof(double) * rows, sizeof(double) * rows, cols,
                                  cudaMemcpyDeviceToHost, s));
}

std::int64_t CudaExecutor::slab_width(std::int64_t m, std::int64_t k) const {
  return std::max<std::int64_t>(
      1, std::min<std::int64_t>(std::max<std::int64_t>(k, 1),
                                static_cast<std::int64_t>(plan_.pool) / (3 * m)));
}

void CudaExecutor::factor_tiled(const numeric::FactorContext& ctx, index_t pos) {
  const auto wall_start = std::chrono::steady_clock::now();
  const Analysis& an = *ctx.analysis;
  const auto& t = an.tree;
  const index_t f = ctx.part->schedule->fronts[pos];
  const bool lu = ctx.type == MatrixType::general;
  const std::int64_t m = t.n_rows(f), k = t.n_pivots(f);
  if (ctx.type == MatrixType::symmetric_indefinite)
    throw NotSupported("a front of " + std::to_string(m) +
                       " rows is over the device memory budget, and slab-by-slab LDLᵀ is not "
                       "implemented on the CUDA backend: raise device_memory_limit or use the "
                       "CPU backend");
  if (!lu) {
    factor_tiled_llt(ctx, pos);  // tiled_llt.cu
    return;
  }
  ++tiled_.count;
  ++chunks_;
  tiled_.front.resize(static_cast<std::size_t>(m) * m);
  double* H = tiled_.front.data();
  assemble_on_host(ctx, f, H, false);  // tiled_host.cpp
  const auto slabs_start = std::chrono::steady_clock::now();
  phases_.tiled_assembly += std::chrono::duration<double>(slabs_start - wall_start).count();

  const std::int64_t w_max = slab_width(m, k);
  double* S = pool_.data();
  double* const Cbuf[2] = {pool_.data() + static_cast<std::size_t>(m) * w_max,
                           pool_.data() + 2 * static_cast<std::size_t>(m) * w_max};
  std::vector<std::unique_ptr<Lane>>& lane = lanes();  // lanes 1 and 2: the column blocks
  const double one = 1.0, minus_one = -1.0;
  std::vector<std::int64_t> fperm(k), sperm(k);
  for (std::int64_t i = 0; i < k; ++i) fperm[i] = i;
  std::int64_t npert = 0;
  perm_.resize(static_cast<std::size_t>(k) + 1);
  perturbed_.resize(1);
  STRATA_CUDA(cudaMemsetAsync(perturbed_.data(), 0, sizeof(std::int64_t), stream_));
  for (std::int64_t p0 = 0; p0 < k; p0 += w_max) {
    const std::int64_t w = std::min(w_max, k - p0), r = m - p0;
    copy_host_block(stream_, S, H, m, p0, p0, r, w, true);
    bytes_h2d_ += sizeof(double) * r * w;
    {
      const std::int64_t kk = k - p0;
      if (static_cast<std::int64_t>(iota_.size()) < kk) {
        iota_.resize(kk);
        for (std::int64_t i = 0; i < kk; ++i) iota_[i] = i;
      }
      STRATA_CUDA(cudaMemcpyAsync(perm_.data(), iota_.data(), sizeof(std::int64_t) * kk,
                                  cudaMemcpyHostToDevice, stream_));
      launch_lu_slab(S, r, w, kk, ctx.static_pivot, ctx.diagonal_pivot_threshold, perm_.data(),
                     perturbed_.data(), stream_);
      STRATA_CUDA(cudaMemcpyAsync(sperm.data(), perm_.data(), sizeof(std::int64_t) * kk,
                                  cudaMemcpyDeviceToHost, stream_));
      STRATA_CUDA(cudaStreamSynchronize(stream_));
      // the slab's row swaps on the front's other columns (rows p0..k), and in the
      // front's pivot order
      std::vector<double> tmp(kk);  // one buffer for all m columns
      for (std::int64_t c = 0; c < m; ++c) {
        if (c >= p0 && c < p0 + w) continue;
        double* colc = H + c * m + p0;
        std::copy(colc, colc + kk, tmp.begin());
        for (std::int64_t i = 0; i < kk; ++i) colc[i] = tmp[sperm[i]];
      }
      std::vector<std::int64_t> old(fperm.begin() + p0, fperm.end());
      for (std::int64_t i = 0; i < kk; ++i) fperm[p0 + i] = old[sperm[i]];
    }
    // the lanes start when the slab is factored; its download overlaps their work
    STRATA_CUDA(cudaEventRecord(lane[0]->done, stream_));
    for (int l = 1; l <= 2; ++l)
      STRATA_CUDA(cudaStreamWaitEvent(lane[l]->stream, lane[0]->done, 0));
    copy_host_block(stream_, S, H, m, p0, p0, r, w, false);
    bytes_d2h_ += sizeof(double) * r * w;
    // the trailing matrix, one column block at a time, on lanes 1 and 2 alternately
    std::int64_t block = 0;
    for (std::int64_t jb = p0 + w; jb < m; jb += w_max, ++block) {
      const std::int64_t wb = std::min(w_max, m - jb);
      Lane& ln = *lane[1 + block % 2];
      const cudaStream_t cs = ln.stream;
      const cublasHandle_t cb = ln.blas;
      double* const C = Cbuf[block % 2];
      copy_host_block(cs, C, H, m, p0, jb, r, wb, true);
      STRATA_CUBLAS(cublasDtrsm(cb, CUBLAS_SIDE_LEFT, CUBLAS_FILL_MODE_LOWER, CUBLAS_OP_N,
                                CUBLAS_DIAG_UNIT, static_cast<int>(w), static_cast<int>(wb), &one,
                                S, static_cast<int>(r), C, static_cast<int>(r)));
      if (r > w)
        STRATA_CUBLAS(cublasDgemm(cb, CUBLAS_OP_N, CUBLAS_OP_N, static_cast<int>(r - w),
                                  static_cast<int>(wb), static_cast<int>(w), &minus_one, S + w,
                                  static_cast<int>(r), C, static_cast<int>(r), &one, C + w,
                                  static_cast<int>(r)));
      copy_host_block(cs, C, H, m, p0, jb, r, wb, false);
      bytes_h2d_ += sizeof(double) * r * wb;
      bytes_d2h_ += sizeof(double) * r * wb;
    }
    for (int l = 1; l <= 2; ++l) {  // the next slab reads what the lanes wrote to H
      STRATA_CUDA(cudaEventRecord(lane[l]->done, lane[l]->stream));
      STRATA_CUDA(cudaStreamWaitEvent(stream_, lane[l]->done, 0));
    }
    STRATA_CUDA(cudaStreamSynchronize(stream_));
  }
  STRATA_CUDA(cudaMemcpyAsync(&npert, perturbed_.data(), sizeof(std::int64_t),
                              cudaMemcpyDeviceToHost, stream_));
  STRATA_CUDA(cudaStreamSynchronize(stream_));

  const auto store_start = std::chrono::steady_clock::now();
  phases_.tiled_slabs += std::chrono::duration<double>(store_start - slabs_start).count();
  // contribution block to where the plan keeps it; panels to the host factor
  const std::int64_t mc = m - k;
  if (mc > 0 && t.parent[f] >= 0) {
    double* const dst = cur_->cb_ptr_host[f];
    if (in_host_arena(dst))
      parallel_copy_2d(dst, mc, H + k * m + k, m, mc, mc);
    else
      STRATA_CUDA(cudaMemcpy2DAsync(dst, sizeof(double) * mc, H + k * m + k, sizeof(double) * m,
                                    sizeof(double) * mc, mc, cudaMemcpyHostToDevice, stream_));
  }
  double* panel = ctx.factor->panels.data() + an.factor_layout.panel_offset[f];
  parallel_copy(panel, H, static_cast<std::size_t>(m) * k);
  parallel_copy_2d(panel + m * k, k, H + k * m, m, k, mc);  // U12, k × mc
  if (keep_resident()) {
    const std::size_t sz = panel_size(t, f, true);
    STRATA_CUDA(cudaMemcpyAsync(panels_.data() + an.factor_layout.panel_offset[f], panel,
                                sizeof(double) * sz, cudaMemcpyHostToDevice, stream_));
    bytes_h2d_ += sizeof(double) * sz;
  }
  STRATA_CUDA(cudaStreamSynchronize(stream_));
  std::vector<double> diag(k);
  for (std::int64_t i = 0; i < k; ++i) diag[i] = panel[i * m + i];
  finish_front(ctx, f, -1, npert, fperm.data(), diag.data());
  const auto end = std::chrono::steady_clock::now();
  phases_.tiled_store += std::chrono::duration<double>(end - store_start).count();
  phases_.tiled_fronts += std::chrono::duration<double>(end - wall_start).count();
}

}  // namespace strata::cuda
