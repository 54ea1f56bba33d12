// strata — the triangular solves on the device, when the factor stayed resident after
// the factorization (CudaExecutor::plan_device_memory decides; FactorStats::
// factor_resident says). The right-hand sides go up once, the level-parallel forward
// and backward sweeps run, the solutions come back once; iterative refinement calls this
// again per step, so each step moves only 2·n·nrhs doubles. When the factor is not
// resident the executor declines and the host solve runs.
// solve_original takes the right-hand sides in the matrix's own numbering and does the
// analysis's permutation and scaling (and the factorization's rescaling) on the device as
// well, two elementwise kernels around the sweeps, instead of the host's loops over every
// entry before and after (on the multibody Newton matrices those loops were a large share
// of a solve: bench/history.md).
//
// The sweeps are a fixed sequence of launches for a given analysis and number of
// right-hand sides (one for the plan's subtrees, or with Options::gpu_solve_chain one for
// the subtrees and the bottom levels together, solve_plan.hpp: plan_chain; one per level
// for the other block-path fronts,
// a gather, a sweep, a scatter and a few library calls per level with tall or library-path
// fronts, a level's library fronts side by side on the executor's lanes; in each sweep);
// with Options::gpu_solve_graph they are recorded once as a CUDA graph and replayed with
// one launch per solve, which removes the host's cost per launch and the
// gaps between them on the device (CUDA C++ Programming Guide, "CUDA Graphs"). The graph
// holds the device pointers of the solve that recorded it: it is replayed only while the
// analysis, nrhs, the factor's type and every buffer it reads are the same
// (solve_graph_key), and recorded again otherwise. The values in those buffers (a new
// factorization's panels, its rows after pivoting) are read when it runs.
//
// solve_kernels.cuh describes the launches; which front takes which path is the plan's
// choice (solve_plan.hpp), made once per analysis for this device's number of SMs.
// Everything runs on the executor's stream
// without a host synchronization until the solution is copied back; the workspaces are
// members, grown when the analysis or nrhs needs more, so a solve allocates nothing after
// the first.
#include <algorithm>
#include <cstring>

#include "numeric/cuda/cuda_executor.hpp"
#include "numeric/cuda/multiprocessors.hpp"
#include "numeric/cuda/solve_kernels.cuh"

namespace strata::cuda {
namespace {

// large_front_forward/backward's BLAS on the device: cuBLAS (host pointer mode: the
// scalars are read before the call returns), but for the non-transposed GEMV with β = 1 —
// a front's L21·x or U12·x — strata's launch_gemv_n on the handle's stream, which spreads
// those few hundred rows over a block per 4 to 32 of them, and for the triangle of one
// right-hand side, when the plan made its tiles' inverses, launch_trsv_tiles
// (trsv_tiles.cuh), which takes 64 unknowns per step where cuBLAS's TRSV takes 32.
struct DeviceOps {
  cublasHandle_t h;
  // the front's tiles' inverses for the forward and the backward triangle
  // (SweepPlanDevice::trsv_*), or null: then cuBLAS's TRSV
  const double* inverse_forward = nullptr;
  const double* inverse_backward = nullptr;
  trsv_tiles::TrsvSync sync{};
  static cublasFillMode_t fill(bool upper) {
    return upper ? CUBLAS_FILL_MODE_UPPER : CUBLAS_FILL_MODE_LOWER;
  }
  static cublasOperation_t op(bool trans) { return trans ? CUBLAS_OP_T : CUBLAS_OP_N; }
  static cublasDiagType_t diag(bool unit) { return unit ? CUBLAS_DIAG_UNIT : CUBLAS_DIAG_NON_UNIT; }
  void trsv(bool upper, bool trans, bool unit, int n, const double* a, int lda, double* x) {
    using trsv_tiles::TrsvForm;
    const bool fwd = !upper && !trans;  // the forward sweep's L11; else U11 or L11ᵀ
    if (const double* inv = fwd ? inverse_forward : inverse_backward) {
      cudaStream_t s = nullptr;
      STRATA_CUBLAS(cublasGetStream(h, &s));
      const TrsvForm form = fwd     ? TrsvForm::lower
                            : upper ? TrsvForm::upper
                                    : TrsvForm::lower_transposed;
      launch_trsv_tiles(form, n, a, lda, x, inv, sync, s);
      return;
    }
    STRATA_CUBLAS(cublasDtrsv(h, fill(upper), op(trans), diag(unit), n, a, lda, x, 1));
  }
  void trsm(bool upper, bool trans, bool unit, int n, int nrhs, const double* a, int lda, double* b,
            int ldb) {
    const double one = 1.0;
    STRATA_CUBLAS(cublasDtrsm(h, CUBLAS_SIDE_LEFT, fill(upper), op(trans), diag(unit), n, nrhs,
                              &one, a, lda, b, ldb));
  }
  void gemv(bool trans, int rows, int cols, double alpha, const double* a, int lda, const double* x,
            double beta, double* y) {
    if (!trans && beta == 1.0) {
      cudaStream_t s = nullptr;
      STRATA_CUBLAS(cublasGetStream(h, &s));
      launch_gemv_n(rows, cols, alpha, a, lda, x, y, s);
      return;
    }
    STRATA_CUBLAS(cublasDgemv(h, op(trans), rows, cols, &alpha, a, lda, x, 1, &beta, y, 1));
  }
  void gemm(bool trans_a, int m, int n, int k, double alpha, const double* a, int lda,
            const double* b, int ldb, double beta, double* c, int ldc) {
    STRATA_CUBLAS(
        cublasDgemm(h, op(trans_a), CUBLAS_OP_N, m, n, k, &alpha, a, lda, b, ldb, &beta, c, ldc));
  }
};

}  // namespace

void CudaExecutor::prepare_solve_inverse(const Analysis& an) {
  if (dsolve_.inverse_analysis == an.id && dsolve_.inverse_analysis != 0) return;
  SolvePlan inverse;
  plan_inverse_extend_add(an.tree, an.child_rows, inverse);
  // not upload(): these bytes belong to no factorization's statistics
  dsolve_.inv_offsets.upload(inverse.inv_offsets.data(), inverse.inv_offsets.size(), stream_);
  dsolve_.inv_src.upload(inverse.inv_src.data(), inverse.inv_src.size(), stream_);
  STRATA_CUDA(cudaStreamSynchronize(stream_));  // the copies read `inverse`
  dsolve_.inverse_analysis = an.id;
}

void CudaExecutor::upload_sweep_plan(SweepPlanDevice& sp) {
  auto up = [&](DeviceBuffer<std::int64_t>& d, const std::vector<std::int64_t>& h) {
    d.upload(h.data(), h.size(), stream_);
  };
  const SolvePlan& p = sp.plan;
  up(sp.panel_offset, sp.panel_offset_host);
  up(sp.chunk_front, p.chunk_front);
  up(sp.chunk_row, p.chunk_row);
  up(sp.small_fronts, p.small_fronts);
  up(sp.tall_fronts, p.tall_fronts);
  up(sp.subtree_first, p.subtree_first);
  up(sp.subtree_last, p.subtree_last);
  up(sp.part_offset, p.part_offset);
  if (p.chain_levels > 0) {
    up(sp.chain_first, p.chain_first);
    up(sp.chain_last, p.chain_last);
    up(sp.chain_wait, p.chain_wait);
    up(sp.chain_parent, p.chain_parent);
    const std::size_t words = 2 * p.chain_wait.size() + 3;
    sp.chain_sync.resize(words);
    STRATA_CUDA(
        cudaMemsetAsync(sp.chain_sync.data(), 0, sizeof(unsigned long long) * words, stream_));
  }
  STRATA_CUDA(cudaStreamSynchronize(stream_));  // the copies read the host vectors
}

// The whole tree's solve plan and its device copy (once per analysis).
void CudaExecutor::prepare_solve_plan(const Analysis& an) {
  prepare_solve_inverse(an);
  SweepPlanDevice& w = dsolve_.whole;
  if (w.plan.analysis == an.id && w.plan.analysis != 0) return;
  const int n_sm = multiprocessor_count(device_);
  w.plan = SolvePlan{};
  plan_sweeps(an.tree, an.schedule, n_sm, SolvePath::model, nullptr, w.plan, nullptr, solve_chain_);
  if (solve_chain_) plan_chain(an.tree, an.schedule, w.plan);
  w.plan.analysis = an.id;
  w.panel_offset_host.assign(an.factor_layout.panel_offset.begin(),
                             an.factor_layout.panel_offset.end());
  upload_sweep_plan(w);
  prepare_trsv_tiles(an, w);
}

void CudaExecutor::prepare_trsv_tiles(const Analysis& an, SweepPlanDevice& sp) {
  using trsv_tiles::kTrsvTile;
  constexpr std::int64_t tile_doubles = std::int64_t{kTrsvTile} * kTrsvTile;
  const auto& t = an.tree;
  sp.trsv_inverse_at.assign(static_cast<std::size_t>(t.n_fronts()), -1);
  sp.trsv_sync_at.assign(static_cast<std::size_t>(t.n_fronts()), -1);
  sp.trsv_jobs_count = 0;
  std::vector<trsv_tiles::TrsvTileJob> jobs;
  std::int64_t flags = 0;
  for (const std::int64_t f : sp.plan.large_fronts) {
    const std::int64_t k = t.n_pivots(f), tiles = (k + kTrsvTile - 1) / kTrsvTile;
    if (k == 0) continue;
    const auto first = static_cast<std::int64_t>(jobs.size());
    sp.trsv_inverse_at[f] = first * tile_doubles;
    sp.trsv_sync_at[f] = flags;
    flags += tiles + 2;  // a flag per tile, the ticket, the counter
    for (std::int64_t q = 0; q < tiles; ++q)
      jobs.push_back({sp.panel_offset_host[f], t.n_rows(f), k, q, (first + q) * tile_doubles});
  }
  static_assert(sizeof(trsv_tiles::TrsvTileJob) == 5 * sizeof(std::int64_t));
  const auto* words = reinterpret_cast<const std::int64_t*>(jobs.data());
  sp.trsv_jobs_host.assign(words, words + 5 * jobs.size());
  sp.trsv_flags = flags;
  sp.trsv_made = 0;
}

void CudaExecutor::allocate_trsv_tiles(SweepPlanDevice& sp) {
  using trsv_tiles::kTrsvTile;
  constexpr std::size_t tile_doubles = std::size_t{kTrsvTile} * kTrsvTile;
  if (sp.trsv_jobs_host.empty()) return;
  const std::vector<std::int64_t> jobs = std::move(sp.trsv_jobs_host);
  sp.trsv_jobs_host.clear();  // tried once per plan
  const std::size_t count = jobs.size() / 5;
  try {
    sp.trsv_jobs.upload(jobs.data(), jobs.size(), stream_);
    sp.trsv_forward.resize(count * tile_doubles);
    sp.trsv_backward.resize(count * tile_doubles);
    sp.trsv_sync.resize(static_cast<std::size_t>(sp.trsv_flags));
    STRATA_CUDA(cudaMemsetAsync(sp.trsv_sync.data(), 0, sizeof(int) * sp.trsv_flags, stream_));
    STRATA_CUDA(cudaStreamSynchronize(stream_));  // the upload reads `jobs`
  } catch (const OutOfMemory&) {                  // no room: those fronts keep cuBLAS's TRSV
    STRATA_CUDA(cudaStreamSynchronize(stream_));
    sp.trsv_forward.resize(0);
    sp.trsv_backward.resize(0);
    std::fill(sp.trsv_inverse_at.begin(), sp.trsv_inverse_at.end(), -1);
    return;
  }
  sp.trsv_jobs_count = static_cast<std::int64_t>(count);
  sp.trsv_made = 0;
}

void CudaExecutor::make_trsv_inverses(SweepPlanDevice& sp, const double* panels, MatrixType type) {
  allocate_trsv_tiles(sp);
  if (sp.trsv_jobs_count == 0 || trsv_current(sp, type)) return;
  const bool lu = type == MatrixType::general,
             unit = lu || type == MatrixType::symmetric_indefinite;
  const auto* jobs = reinterpret_cast<const trsv_tiles::TrsvTileJob*>(sp.trsv_jobs.data());
  launch_trsv_inverses(jobs, sp.trsv_jobs_count, panels, sp.trsv_forward.data(),
                       trsv_tiles::TrsvForm::lower, unit, stream_);
  launch_trsv_inverses(jobs, sp.trsv_jobs_count, panels, sp.trsv_backward.data(),
                       lu ? trsv_tiles::TrsvForm::upper : trsv_tiles::TrsvForm::lower_transposed,
                       lu ? false : unit, stream_);
  sp.trsv_made = factorization_count_;
  sp.trsv_type = type;
}

bool CudaExecutor::solves_resident(const Analysis& an, const numeric::NumericFactor& fac) const {
  return keep_resident() && dsolve_.resident_for == &fac && dsolve_.resident_analysis == an.id &&
         fac.valid && an.id == analysis_id_;
}

void CudaExecutor::enqueue_resident_solve(const Analysis& an, const numeric::NumericFactor& fac,
                                          index_t nrhs) {
  const std::int64_t u_total = dsolve_.u_offset_host.back();
  // the tiles' inverses once per factorization, before (not in) the recorded sweeps
  if (nrhs == 1) make_trsv_inverses(dsolve_.whole, panels_.data(), fac.type);
  dsolve_.u.resize(std::max<std::size_t>(static_cast<std::size_t>(u_total) * nrhs, 1));
  dsolve_.scratch.resize(std::max<std::size_t>(an.tree.rows.size() * nrhs, 1));
  dsolve_.part.resize(
      std::max<std::size_t>(static_cast<std::size_t>(dsolve_.whole.plan.part_total) * nrhs, 1));
  if (!solve_graph_) {
    enqueue_solve_sweeps(an, fac, dsolve_.whole, panels_.data(), nrhs, true, true);
    return;
  }
  std::vector<std::uintptr_t> key = solve_graph_key(an, fac, nrhs);
  if (!dsolve_.graph || key != dsolve_.graph_key) {
    drop_solve_graph();
    // Recorded, not run: the kernels and library calls of the sweeps become the graph's
    // nodes with the pointers and sizes of this solve, which the key lists. Relaxed
    // capture mode: cuBLAS may set up its workspace in its first call. A failure ends the
    // capture before it is reported, so the stream stays usable.
    STRATA_CUDA(cudaStreamBeginCapture(stream_, cudaStreamCaptureModeRelaxed));
    cudaGraph_t g = nullptr;
    try {
      enqueue_solve_sweeps(an, fac, dsolve_.whole, panels_.data(), nrhs, true, true, false);
    } catch (...) {
      if (cudaStreamEndCapture(stream_, &g) == cudaSuccess && g) cudaGraphDestroy(g);
      (void)cudaGetLastError();
      throw;
    }
    STRATA_CUDA(cudaStreamEndCapture(stream_, &g));
    const cudaError_t e = cudaGraphInstantiate(&dsolve_.graph, g, 0);
    cudaGraphDestroy(g);
    if (e != cudaSuccess) {
      dsolve_.graph = nullptr;
      STRATA_CUDA(e);
    }
    dsolve_.graph_key = std::move(key);
  }
  // The subtrees' (or the chain's) launch, the longest of the forward sweep, goes first on its own:
  // the device works on it while the host submits the graph, whose launch costs the host tens of
  // microseconds for the sweeps' nodes, which would otherwise leave the device idle.
  enqueue_forward_subtrees(an, fac, dsolve_.whole, panels_.data(), nrhs);
  STRATA_CUDA(cudaGraphLaunch(dsolve_.graph, stream_));
}

bool CudaExecutor::solve(const Analysis& an, const numeric::NumericFactor& fac, double* x,
                         index_t nrhs) {
  if (!solves_resident(an, fac)) return false;
  if (an.n == 0 || nrhs == 0) return true;
  STRATA_CUDA(cudaSetDevice(device_));
  prepare_solve_plan(an);
  const std::size_t nx = static_cast<std::size_t>(an.n) * nrhs;
  dsolve_.x.upload(x, nx, stream_);
  enqueue_resident_solve(an, fac, nrhs);
  STRATA_CUDA(
      cudaMemcpyAsync(x, dsolve_.x.data(), sizeof(double) * nx, cudaMemcpyDeviceToHost, stream_));
  STRATA_CUDA(cudaStreamSynchronize(stream_));
  return true;
}

void CudaExecutor::prepare_solve_io(const Analysis& an) {
  if (dsolve_.io_analysis == an.id && dsolve_.io_analysis != 0) return;
  const index_t n = an.n;
  const bool scale = !an.row_scaling.empty(), match = !an.matching_perm.empty();
  std::vector<std::int64_t> in(n), out(n);
  std::vector<double> in_scale(n, 1.0), out_scale(n, 1.0);
  for (index_t k = 0; k < n; ++k) {
    in[k] = an.perm[k];
    out[k] = match ? an.matching_perm[an.perm[k]] : an.perm[k];
    if (scale) {
      in_scale[k] = an.row_scaling[in[k]];
      out_scale[k] = an.col_scaling[out[k]];
    }
  }
  // not upload(): these bytes belong to no factorization's statistics
  dsolve_.in_index.upload(in.data(), in.size(), stream_);
  dsolve_.out_index.upload(out.data(), out.size(), stream_);
  dsolve_.in_scale.upload(in_scale.data(), in_scale.size(), stream_);
  dsolve_.out_scale.upload(out_scale.data(), out_scale.size(), stream_);
  STRATA_CUDA(cudaStreamSynchronize(stream_));  // the copies read the host vectors
  dsolve_.io_analysis = an.id;
}

bool CudaExecutor::solve_original(const Analysis& an, const numeric::NumericFactor& fac,
                                  const double* b, double* x, index_t nrhs,
                                  const numeric::RescaleView& rescale, double* stage) {
  if (!solves_resident(an, fac)) return false;
  if (an.n == 0 || nrhs == 0) return true;
  STRATA_CUDA(cudaSetDevice(device_));
  prepare_solve_plan(an);
  prepare_solve_io(an);
  const index_t n = an.n;
  const std::size_t nx = static_cast<std::size_t>(n) * nrhs, bytes = nx * sizeof(double);
  // b up as it is (a copy into the page-locked stage first unless it is page-locked: a
  // copy from pageable memory goes through a driver buffer at a fraction of the rate)
  const double* from = b;
  if (!numeric::page_locked(b, bytes)) {
    std::memcpy(stage, b, bytes);
    from = stage;
  }
  dsolve_.b.upload(from, nx, stream_);
  upload_rescale(an, rescale);
  dsolve_.x.resize(nx);
  launch_permute_in(dsolve_.b.data(), dsolve_.in_index.data(), dsolve_.in_scale.data(),
                    rescale.row ? dsolve_.row_rescale.data() : nullptr, dsolve_.x.data(), n, nrhs,
                    stream_);
  enqueue_resident_solve(an, fac, nrhs);
  launch_permute_out(dsolve_.x.data(), dsolve_.out_index.data(), dsolve_.out_scale.data(),
                     rescale.col ? dsolve_.col_rescale.data() : nullptr, dsolve_.b.data(), n, nrhs,
                     stream_);
  const bool direct = numeric::page_locked(x, bytes);
  STRATA_CUDA(cudaMemcpyAsync(direct ? x : stage, dsolve_.b.data(), bytes, cudaMemcpyDeviceToHost,
                              stream_));
  STRATA_CUDA(cudaStreamSynchronize(stream_));
  if (!direct) std::memcpy(x, stage, bytes);
  return true;
}

// The rescaling once per factorization: the solves and refinement steps after it reuse it.
void CudaExecutor::upload_rescale(const Analysis& an, const numeric::RescaleView& rescale) {
  if (rescale.id != 0 && rescale.id == dsolve_.rescale_id) return;
  const std::size_t n = static_cast<std::size_t>(an.n);
  dsolve_.rescale_id = 0;
  if (rescale.row) dsolve_.row_rescale.upload(rescale.row, n, stream_);
  if (rescale.col) dsolve_.col_rescale.upload(rescale.col, n, stream_);
  dsolve_.rescale_id = rescale.id;
}

// solve_original with b and x in this device's memory: b checked, permuted and scaled
// into the factor's numbering, the sweeps (the same graph), the solutions permuted and
// scaled into x unless b held an entry that is not finite, x checked; only the four check
// words come back to the host (page-locked, read when the host waits: at once, or by
// last_gpu_array_check).
bool CudaExecutor::solve_gpu_arrays(const Analysis& an, const numeric::NumericFactor& fac,
                                    const double* b, double* x, index_t nrhs,
                                    const numeric::RescaleView& rescale,
                                    numeric::GpuArrayCheck* check) {
  if (!solves_resident(an, fac)) return false;
  if (numeric::device_memory_of(b) != device_ || numeric::device_memory_of(x) != device_)
    return false;
  dsolve_.checks_host.resize(4);
  dsolve_.checks_pending = true;
  if (an.n == 0 || nrhs == 0) {
    std::fill_n(dsolve_.checks_host.data(), 4, 0ULL);
    if (check) last_gpu_array_check(*check);
    return true;
  }
  STRATA_CUDA(cudaSetDevice(device_));
  prepare_solve_plan(an);
  prepare_solve_io(an);
  const index_t n = an.n;
  const std::int64_t count = static_cast<std::int64_t>(n) * nrhs;
  upload_rescale(an, rescale);
  dsolve_.x.resize(static_cast<std::size_t>(count));
  dsolve_.checks.resize(4);
  // b's check and x's: the complement of the first entry that is not finite, the
  // largest magnitude's bits (EntryCheck), made by the permutations on the way
  unsigned long long* c = dsolve_.checks.data();
  STRATA_CUDA(cudaMemsetAsync(c, 0, 4 * sizeof(unsigned long long), stream_));
  launch_permute_in(b, dsolve_.in_index.data(), dsolve_.in_scale.data(),
                    rescale.row ? dsolve_.row_rescale.data() : nullptr, dsolve_.x.data(), n, nrhs,
                    stream_, EntryCheck{c, c + 2});
  enqueue_resident_solve(an, fac, nrhs);
  launch_permute_out(dsolve_.x.data(), dsolve_.out_index.data(), dsolve_.out_scale.data(),
                     rescale.col ? dsolve_.col_rescale.data() : nullptr, x, n, nrhs, stream_, c,
                     EntryCheck{c + 1, c + 3});
  STRATA_CUDA(cudaMemcpyAsync(dsolve_.checks_host.data(), c, 4 * sizeof(unsigned long long),
                              cudaMemcpyDeviceToHost, stream_));
  if (check) last_gpu_array_check(*check);
  return true;
}

void CudaExecutor::last_gpu_array_check(numeric::GpuArrayCheck& check) {
  if (!dsolve_.checks_pending || dsolve_.checks_host.size() < 4)
    throw InternalError("last_gpu_array_check: no solve of GPU arrays ran on this executor");
  STRATA_CUDA(cudaSetDevice(device_));
  STRATA_CUDA(cudaStreamSynchronize(stream_));
  const unsigned long long* h = dsolve_.checks_host.data();
  auto index = [](unsigned long long v) {
    return v == 0 ? std::int64_t{-1} : static_cast<std::int64_t>(~v);
  };
  auto magnitude = [](unsigned long long v) {
    double d = 0;
    std::memcpy(&d, &v, sizeof d);
    return d;
  };
  check.b_not_finite = index(h[0]);
  check.x_not_finite = check.b_not_finite >= 0 ? -1 : index(h[1]);
  check.b_max = magnitude(h[2]);
  check.x_max = check.b_not_finite >= 0 ? 0.0 : magnitude(h[3]);
}

std::vector<std::uintptr_t> CudaExecutor::solve_graph_key(const Analysis& an,
                                                          const numeric::NumericFactor& fac,
                                                          index_t nrhs) const {
  auto ptr = [](const void* p) { return reinterpret_cast<std::uintptr_t>(p); };
  return {static_cast<std::uintptr_t>(an.id),
          static_cast<std::uintptr_t>(nrhs),
          static_cast<std::uintptr_t>(fac.type),
          ptr(n_rows_.data()),
          ptr(n_pivots_.data()),
          ptr(panels_.data()),
          ptr(dsolve_.row_offsets.data()),
          ptr(dsolve_.first_pivot.data()),
          ptr(dsolve_.rows.data()),
          ptr(dsolve_.pivot_row.data()),
          ptr(dsolve_.whole.panel_offset.data()),
          ptr(dsolve_.pivot_size.data()),
          ptr(dsolve_.d_diag.data()),
          ptr(dsolve_.d_off.data()),
          ptr(dsolve_.x.data()),
          ptr(dsolve_.u.data()),
          ptr(dsolve_.scratch.data()),
          ptr(dsolve_.u_offset.data()),
          ptr(dsolve_.inv_offsets.data()),
          ptr(dsolve_.inv_src.data()),
          ptr(dsolve_.whole.chunk_front.data()),
          ptr(dsolve_.whole.chunk_row.data()),
          ptr(dsolve_.whole.small_fronts.data()),
          ptr(dsolve_.whole.tall_fronts.data()),
          ptr(dsolve_.whole.subtree_first.data()),
          ptr(dsolve_.whole.subtree_last.data()),
          ptr(dsolve_.whole.part_offset.data()),
          ptr(dsolve_.part.data()),
          ptr(dsolve_.whole.chain_first.data()),
          ptr(dsolve_.whole.chain_last.data()),
          ptr(dsolve_.whole.chain_wait.data()),
          ptr(dsolve_.whole.chain_parent.data()),
          ptr(dsolve_.whole.chain_sync.data())};
}

void CudaExecutor::drop_solve_graph() noexcept {
  if (dsolve_.graph) cudaGraphExecDestroy(dsolve_.graph);
  dsolve_.graph = nullptr;
  dsolve_.graph_key.clear();
}

SolveTree CudaExecutor::solve_tree(const Analysis& an, const SweepPlanDevice& sp,
                                   const double* panels) {
  return SolveTree{n_rows_.data(),
                   n_pivots_.data(),
                   dsolve_.row_offsets.data(),
                   dsolve_.first_pivot.data(),
                   dsolve_.rows.data(),
                   dsolve_.inv_offsets.data(),
                   dsolve_.inv_src.data(),
                   dsolve_.u_offset.data(),
                   sp.panel_offset.data(),
                   panels,
                   dsolve_.pivot_row.data(),
                   an.n,
                   dsolve_.u_offset_host.back(),
                   sp.part_offset.data(),
                   dsolve_.part.data()};
}

SolveChain CudaExecutor::solve_chain(const SweepPlanDevice& sp) {
  return SolveChain{sp.chain_first.data(),
                    sp.chain_last.data(),
                    sp.chain_wait.data(),
                    sp.chain_parent.data(),
                    sp.chain_sync.data(),
                    static_cast<std::int64_t>(sp.plan.chain_wait.size()),
                    static_cast<std::int64_t>(sp.plan.chain_first.size())};
}

void CudaExecutor::enqueue_forward_subtrees(const Analysis& an, const numeric::NumericFactor& fac,
                                            const SweepPlanDevice& sp, const double* panels,
                                            index_t nrhs) {
  const bool lu = fac.type == MatrixType::general;
  const bool unit = lu || fac.type == MatrixType::symmetric_indefinite;
  const SolveTree st = solve_tree(an, sp, panels);
  if (sp.plan.chain_levels > 0) {
    launch_chain_forward(st, solve_chain(sp), dsolve_.x.data(), dsolve_.u.data(),
                         dsolve_.scratch.data(), nrhs, unit, lu, stream_);
    return;
  }
  launch_fronts_forward(st, sp.subtree_first.data(), sp.subtree_last.data(), 0,
                        static_cast<std::int64_t>(sp.plan.subtree_first.size()), dsolve_.x.data(),
                        dsolve_.u.data(), dsolve_.scratch.data(), nrhs, unit, lu, stream_);
}

void CudaExecutor::enqueue_solve_sweeps(const Analysis& an, const numeric::NumericFactor& fac,
                                        const SweepPlanDevice& sp, const double* panels,
                                        index_t nrhs, bool forward, bool backward,
                                        bool forward_subtrees) {
  const auto& t = an.tree;
  const SolvePlan& p = sp.plan;
  const bool lu = fac.type == MatrixType::general;
  const bool ldlt = fac.type == MatrixType::symmetric_indefinite;
  const bool unit = lu || ldlt;
  const SolveTree st = solve_tree(an, sp, panels);
  const SolveChunks chunks{sp.chunk_front.data(), sp.chunk_row.data()};
  double* X = dsolve_.x.data();
  double* U = dsolve_.u.data();
  double* S = dsolve_.scratch.data();
  const int nr = static_cast<int>(nrhs);
  // A level's library-solved fronts: the j-th (largest first) on lane j mod kSolveLanes,
  // the lanes forked from the executor's stream and joined back to it (within a graph's
  // capture these become parallel branches). Each front's block W and panel to `run`.
  static_assert(kSolveLanes <= kLanes, "the solve's library fronts use the executor's lanes");
  // One right-hand side: the library fronts' triangles by tiles (trsv_tiles.cuh) where
  // their inverses were made for this factorization (make_trsv_inverses).
  const bool tiled = nrhs == 1 && trsv_current(sp, fac.type);
  auto large = [&](std::int64_t q0, std::int64_t q1, auto&& run) {
    const std::int64_t count = q1 - q0;
    if (count <= 0) return;
    std::vector<std::unique_ptr<Lane>>& lane = lanes();
    const std::int64_t used = std::min<std::int64_t>(count, kSolveLanes);
    if (used > 1) {
      STRATA_CUDA(cudaEventRecord(lane[0]->done, stream_));
      for (std::int64_t j = 1; j < used; ++j)
        STRATA_CUDA(cudaStreamWaitEvent(lane[j]->stream, lane[0]->done, 0));
    }
    for (std::int64_t q = q0; q < q1; ++q) {
      const std::int64_t f = p.large_fronts[q];
      DeviceOps ops{lane[(q - q0) % used]->blas};
      if (tiled && sp.trsv_inverse_at[f] >= 0) {
        const std::int64_t at = sp.trsv_inverse_at[f];
        int* flags = sp.trsv_sync.data() + sp.trsv_sync_at[f];
        ops.inverse_forward = sp.trsv_forward.data() + at;
        ops.inverse_backward = sp.trsv_backward.data() + at;
        ops.sync = {flags + 2, flags, flags + 1};
      }
      run(ops, panels + sp.panel_offset_host[f], static_cast<int>(t.n_rows(f)),
          static_cast<int>(t.n_pivots(f)), S + t.row_offsets[f] * nrhs);
    }
    for (std::int64_t j = 1; j < used; ++j) {
      STRATA_CUDA(cudaEventRecord(lane[j]->done, lane[j]->stream));
      STRATA_CUDA(cudaStreamWaitEvent(stream_, lane[j]->done, 0));
    }
  };
  const index_t levels = an.schedule.n_levels();
  const std::int64_t* small = sp.small_fronts.data();
  const std::int64_t* tall = sp.tall_fronts.data();
  const std::int64_t n_subtrees = static_cast<std::int64_t>(p.subtree_first.size());
  if (forward && forward_subtrees) enqueue_forward_subtrees(an, fac, sp, panels, nrhs);
  const index_t chained = static_cast<index_t>(p.chain_levels);  // in the chain's launches
  for (index_t l = chained; forward && l < levels; ++l) {
    const std::int64_t c0 = p.chunk_offsets[l], nc = p.chunk_offsets[l + 1] - c0;
    const std::int64_t s0 = p.small_offsets[l], ns = p.small_offsets[l + 1] - s0;
    const std::int64_t t0 = p.tall_offsets[l], nt = p.tall_offsets[l + 1] - t0;
    launch_fronts_forward(st, small, small, s0, ns, X, U, S, nrhs, unit, lu, stream_);
    launch_gather_forward(st, chunks, c0, nc, X, U, S, nrhs, stream_);
    launch_sweep_forward(st, tall, t0, nt, S, nrhs, unit, stream_);
    large(p.large_offsets[l], p.large_offsets[l + 1],
          [&](DeviceOps& ops, const double* L, int m, int k, double* W) {
            large_front_forward(ops, L, m, k, nr, unit, W);
          });
    launch_scatter_forward(st, chunks, c0, nc, X, U, S, nrhs, lu, stream_);
  }
  if (ldlt && forward && backward)
    launch_solve_diagonal(st, dsolve_.d_diag.data(), dsolve_.d_off.data(),
                          dsolve_.pivot_size.data(), X, nrhs, stream_);
  for (index_t l = levels - 1; backward && l >= chained; --l) {
    const std::int64_t c0 = p.chunk_offsets[l], nc = p.chunk_offsets[l + 1] - c0;
    const std::int64_t s0 = p.small_offsets[l], ns = p.small_offsets[l + 1] - s0;
    const std::int64_t t0 = p.tall_offsets[l], nt = p.tall_offsets[l + 1] - t0;
    launch_fronts_backward(st, small, small, s0, ns, X, S, nrhs, lu, unit, stream_);
    launch_gather_backward(st, chunks, c0, nc, X, S, nrhs, lu, stream_);
    launch_sweep_backward(st, tall, t0, nt, S, nrhs, lu, unit, stream_);
    large(p.large_offsets[l], p.large_offsets[l + 1],
          [&](DeviceOps& ops, const double* L, int m, int k, double* W) {
            large_front_backward(ops, L, m, k, nr, lu, unit, W);
          });
    launch_scatter_backward(st, chunks, c0, nc, X, S, nrhs, lu, stream_);
  }
  if (backward && chained > 0)
    launch_chain_backward(st, solve_chain(sp), X, S, nrhs, lu, unit, stream_);
  else if (backward)
    launch_fronts_backward(st, sp.subtree_first.data(), sp.subtree_last.data(), 0, n_subtrees, X, S,
                           nrhs, lu, unit, stream_);
}

}  // namespace strata::cuda
