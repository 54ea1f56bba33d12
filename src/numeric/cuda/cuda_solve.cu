// strata — the triangular solves on the device, when the factor stayed resident after
// the factorization (CudaExecutor::plan_device_memory decides; FactorStats::
// factor_resident says). The right-hand sides go up once, the level-parallel forward
// and backward sweeps of solve_kernels.cu run, the solutions come back once; iterative
// refinement calls this again per step, so each step moves only 2·n·nrhs doubles.
// When the factor is not resident the executor declines and the host solve runs.
#include <algorithm>

#include "numeric/cuda/cuda_executor.hpp"
#include "numeric/cuda/solve_kernels.cuh"

namespace strata::cuda {

bool CudaExecutor::solve(const Analysis& an, const numeric::NumericFactor& fac, double* x,
                         index_t nrhs) {
  if (!keep_resident() || resident_for_ != &fac || resident_analysis_ != an.id || !fac.valid ||
      an.id != analysis_id_)
    return false;
  if (an.n == 0 || nrhs == 0) return true;
  STRATA_CUDA(cudaSetDevice(device_));
  const auto& t = an.tree;
  const auto& s = an.schedule;
  const bool lu = fac.type == MatrixType::general;
  const bool ldlt = fac.type == MatrixType::symmetric_indefinite;
  const std::size_t nx = static_cast<std::size_t>(an.n) * nrhs;
  s_x_.upload(x, nx, stream_);
  const std::int64_t u_total = u_offset_host_.back();
  s_u_.resize(std::max<std::size_t>(static_cast<std::size_t>(u_total) * nrhs, 1));
  s_scratch_.resize(std::max<std::size_t>(t.rows.size(), 1));
  DeviceBuffer<std::int64_t>& u_off = s_u_offset_;
  SolveTree st{fronts_.data(),
               n_rows_.data(),
               n_pivots_.data(),
               s_row_offsets_.data(),
               s_first_pivot_.data(),
               s_rows_.data(),
               child_offsets_.data(),
               children_.data(),
               rel_offsets_.data(),
               rel_.data(),
               s_pivot_pos_.data(),
               s_pivot_row_.data(),
               u_off.data(),
               s_panel_offset_.data(),
               panels_.data(),
               an.n,
               u_total};
  const bool unit = lu || ldlt;
  for (index_t l = 0; l < s.n_levels(); ++l)
    launch_solve_forward(st, s.level_offsets[l], s.level_offsets[l + 1] - s.level_offsets[l],
                         s_x_.data(), s_u_.data(), s_scratch_.data(), nrhs, lu, unit, stream_);
  if (ldlt)
    launch_solve_diagonal(st, s_d_diag_.data(), s_d_off_.data(), s_pivot_size_.data(), s_x_.data(),
                          nrhs, stream_);
  for (index_t l = s.n_levels() - 1; l >= 0; --l)
    launch_solve_backward(st, s.level_offsets[l], s.level_offsets[l + 1] - s.level_offsets[l],
                          s_x_.data(), s_scratch_.data(), nrhs, lu, unit, stream_);
  STRATA_CUDA(
      cudaMemcpyAsync(x, s_x_.data(), sizeof(double) * nx, cudaMemcpyDeviceToHost, stream_));
  STRATA_CUDA(cudaStreamSynchronize(stream_));
  return true;
}

}  // namespace strata::cuda
