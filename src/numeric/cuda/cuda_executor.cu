// strata — the CUDA executor: level-batched multifrontal factorization on one GPU, with
// any amount of device memory.
//
// Per batch of the memory plan (fronts of one level, DESIGN.md §2), cut further into
// chunks whose fronts fit the device pool:
//   1. one launch assembles every front of the chunk in the pool (zero, scatter original
//      entries, extend-add children's contribution blocks);
//   2. one launch factors all small fronts (one thread block each); large fronts go to
//      the recursive pivot block and panel (llt_recursive.cu) + the update of
//      llt_update.cu (cuBLAS SYRK, or a GEMM where SYRK is slow) for LLᵀ (cuSOLVER POTRF +
//      cuBLAS TRSM with gpu_recursive_panel off), for LU the pivot block and both panels
//      by our batched kernels without interchanges (kernels_lu_panel.cu; cuSOLVER GETRF on
//      the fully summed block + TRSMs for fronts with more pivots) + the GEMM, the
//      front redone with partial pivoting where interchanges were due (kernels_lu.cu), or
//      a blocked Bunch–Kaufman LDLᵀ with our panel kernel and
//      cuBLAS SYRKX (kernels_ldlt.cuh), all with pivoting restricted to the fully summed
//      rows and the CPU backend's static pivoting. The large fronts of a chunk run side by
//      side on kLanes streams (each with its own handles), joined before step 3 — an LLᵀ
//      front with at most Options::gpu_panel_kernel_max_pivots pivots has its pivot block and panel
//      done for the whole chunk by our kernels first (kernels_panel.cu, three launches per 64 pivot
//      columns) and only its update on a lane;
//   3. one launch stores the contribution blocks where the plan put them;
//   4. one launch packs the chunk's factor panels (contiguous in the factor layout) into
//      the device factor, which is copied to the host factor in one transfer — unless
//      the factor stays resident for an LLᵀ or LU: then the panels stay on the device
//      only (NumericFactor::panels_on_host is false; download_panels on demand) and
//      only the pivots' diagonal entries come back for the host bookkeeping.
// CUDA events between the steps give FactorStats::device_phases.
// A front whose working set alone is over the budget is factored slab by slab from
// pinned host memory (tiled_front.cu; LLᵀ and LU only).
// LDLᵀ fronts come back in the CPU kernel's layout; D, pivot sizes, rows and statistics are
// then filled by the same host code as the CPU executor's (store_ldlt_front), and the
// resident device factor gets the same unit diagonal (launch_ldlt_unit_panels).
//
// Device memory (plan_device_memory): the budget is Options::device_memory_limit, or 90%
// of the free device memory when it is 0. It holds, in this order of priority: the pool
// of one chunk; the contribution-block arena (blocks that do not fit stay in mapped
// pinned host memory, which the kernels read and write over the bus); the whole factor,
// kept resident so that the solve runs on the device (cuda_solve.cu). The per-analysis
// index arrays and the values (O(nnz(A))) are not counted in the budget.
//
// What stays on the device between factorizations of one analysis: the index arrays,
// the pool, the arena and the resident factor — refactorization allocates nothing.
//
// Several GPUs (numeric/multi_device.cpp): one executor per GPU, every call made with its
// device current. The executor then factors parts of the tree — subtrees, upper-layer
// parts and the top part of an.partition — each with its own schedule, chunks and arena
// layout (PartDevice, all planned and uploaded once per analysis, so any subtree can run
// on any GPU: stealing);
// they share one pool and one arena, sized for the largest part. There is no resident
// factor then (each GPU holds only its parts); with FactorContext::keep_part_panels (the
// Solver sets it) each part's panels stay in a buffer of the GPU that factored it, and
// download_panels copies them to the host factor when a host solve needs them — the copy
// after every chunk was what made several GPUs slower than one. A part
// root's contribution block is exported either to the driver's host buffer (device to
// host), or — when the importing GPU can access this one's memory (cudaDeviceCanAccessPeer),
// or is this one — to a device buffer here (the outbox, one per exported root) that the
// importer copies from directly (cudaMemcpyPeerAsync); the outbox lives until the next
// factorization. An upper part may import blocks from several GPUs, each from its own
// outbox (peer access enabled per source GPU on first use).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>

#include "core/alloc.hpp"
#include "core/host_copy.hpp"
#include "core/timer.hpp"
#include "numeric/cpu/dense_front.hpp"
#include "numeric/cuda/cuda_executor.hpp"

namespace strata::cuda {

[[noreturn]] void throw_cuda(cudaError_t e, const char* call, const char* file, int line) {
  if (e == cudaErrorMemoryAllocation)
    throw OutOfMemory(0, std::string(call) + " at " + file + ":" + std::to_string(line));
  throw DeviceError(std::string(call) + " failed at " + file + ":" + std::to_string(line) + ": " +
                    cudaGetErrorName(e) + " (" + cudaGetErrorString(e) + ")");
}
[[noreturn]] void throw_cublas(cublasStatus_t s, const char* call, const char* file, int line) {
  if (s == CUBLAS_STATUS_ALLOC_FAILED)
    throw OutOfMemory(0, std::string(call) + " at " + file + ":" + std::to_string(line));
  throw DeviceError(std::string(call) + " failed at " + file + ":" + std::to_string(line) + ": " +
                    cublasGetStatusName(s) + " (" + cublasGetStatusString(s) + ")");
}
[[noreturn]] void throw_cusolver(cusolverStatus_t s, const char* call, const char* file, int line) {
  if (s == CUSOLVER_STATUS_ALLOC_FAILED)
    throw OutOfMemory(0, std::string(call) + " at " + file + ":" + std::to_string(line));
  throw DeviceError(std::string(call) + " failed at " + file + ":" + std::to_string(line) +
                    ": cusolver status " + std::to_string(static_cast<int>(s)));
}

namespace {
constexpr std::int64_t kSmallFront = 256;  // fronts up to this many rows: one block each
constexpr std::int64_t kMinSlab = 16;      // narrowest slab worth a library call
// Streams for the large fronts of one chunk. The fronts of a level below the top few are
// many and medium-sized (hundreds to a few thousand rows): one after another on one
// stream, each library call leaves most of the GPU idle. Eight lanes fill it without
// many handles (each cuBLAS handle holds its own workspace).
constexpr std::size_t kLanes = 8;
}  // namespace

CudaExecutor::CudaExecutor(const Options& o, int device)
    : device_(device),
      limit_(o.device_memory_limit),
      panel_max_pivots_(o.gpu_panel_kernel_max_pivots),
      lu_strip_pivots_(o.gpu_lu_strip_pivots),
      tiled_pool_share_(o.gpu_tiled_pool_share),
      tiled_stream_cols_(o.gpu_tiled_stream_columns),
      tiled_prefetch_(o.gpu_tiled_prefetch),
      split_min_cb_(o.split_front_min_cb),
      dist_min_rows_(o.distributed_front_min_rows),
      dist_block_(std::max<index_t>(64, o.distributed_front_block_size)),
      potrf_block_(static_cast<int>(o.gpu_potrf_block_size)),
      recursive_panel_(o.gpu_recursive_panel) {
  STRATA_CUDA(cudaSetDevice(device_));
  STRATA_CUDA(cudaStreamCreate(&stream_));
  STRATA_CUBLAS(cublasCreate(&blas_));
  STRATA_CUBLAS(cublasSetStream(blas_, stream_));
  STRATA_CUSOLVER(cusolverDnCreate(&solver_));
  STRATA_CUSOLVER(cusolverDnSetStream(solver_, stream_));
  STRATA_CUDA(cudaEventCreate(&start_));
  STRATA_CUDA(cudaEventCreate(&stop_));
  STRATA_CUDA(cudaEventCreateWithFlags(&panels_done_, cudaEventDisableTiming));
  STRATA_CUDA(cudaStreamCreateWithFlags(&copy_stream_, cudaStreamNonBlocking));
  STRATA_CUDA(cudaStreamCreateWithFlags(&check_stream_, cudaStreamNonBlocking));
  STRATA_CUDA(cudaEventCreateWithFlags(&lu_strip_done_, cudaEventDisableTiming));
  STRATA_CUDA(cudaEventCreateWithFlags(&panels_copied_, cudaEventDisableTiming));
  for (cudaEvent_t* e : {&split_ready_, &help_ready_, &help_done_, &dist_ready_, &dist_done_})
    STRATA_CUDA(cudaEventCreateWithFlags(e, cudaEventDisableTiming));
  STRATA_CUDA(cudaStreamCreateWithFlags(&dist_copy_, cudaStreamNonBlocking));
  for (ChunkRecord& c : chunk_)
    for (cudaEvent_t& e : c.ev) STRATA_CUDA(cudaEventCreate(&e));
}

CudaExecutor::~CudaExecutor() {
  drop_tiled_prefetch();
  cudaSetDevice(device_);
  for (auto& lp : lanes_) {
    Lane& l = *lp;
    if (l.done) cudaEventDestroy(l.done);
    if (!l.owned) continue;
    // a lane whose creation failed part way has null handles after the failed one
    if (l.solver) cusolverDnDestroy(l.solver);
    if (l.blas) cublasDestroy(l.blas);
    if (l.stream) cudaStreamDestroy(l.stream);
  }
  lanes_.clear();
  cudaEventDestroy(start_);
  cudaEventDestroy(stop_);
  cudaEventDestroy(panels_done_);
  cudaEventDestroy(panels_copied_);
  cudaStreamDestroy(copy_stream_);
  cudaStreamDestroy(check_stream_);
  cudaEventDestroy(lu_strip_done_);
  for (cudaEvent_t e : {split_ready_, help_ready_, help_done_, dist_ready_, dist_done_})
    cudaEventDestroy(e);
  for (cudaEvent_t e : dist_events_) cudaEventDestroy(e);
  cudaStreamDestroy(dist_copy_);
  for (ChunkRecord& c : chunk_)
    for (cudaEvent_t e : c.ev) cudaEventDestroy(e);
  if (solver_) cusolverDnDestroy(solver_);
  if (blas_) cublasDestroy(blas_);
  if (stream_) cudaStreamDestroy(stream_);
}

void CudaExecutor::prepare(const Analysis& an, int workers) {
  STRATA_CUDA(cudaSetDevice(device_));
  // the lanes' library handles hold device workspace: created before the plan sizes its
  // pools from the memory that is free
  if (lanes_.empty()) lanes();
  if (an.id != analysis_id_) upload_analysis(an);
  // the same plans begin_part makes on first use: the whole tree, or every part of the
  // split (any subtree may run on any GPU)
  if (workers <= 1 && planned_ != 1) plan_parts(an, true);
  if (workers > 1 && planned_ != 2 &&
      an.partition.part_of.size() == static_cast<std::size_t>(an.tree.n_fronts()))
    plan_parts(an, false);
  // A Cholesky factor keeps the analysis' row order (no pivoting): the device solve's row
  // arrays are known now, and uploading them here rather than at the end of the first
  // factorization took 0.04 s off a Laplacian 100³'s (end() finds them current).
  // An LU factor's rows differ from the analysis' only where a front's pivots were
  // interchanged: uploaded now, its arrays need only those fronts after each factorization.
  const bool cholesky = an.type == MatrixType::spd || an.type == MatrixType::automatic;
  const MatrixType rows_type = cholesky ? MatrixType::spd : an.type;
  if (workers <= 1 && plan_.factor_resident && (cholesky || an.type == MatrixType::general) &&
      !(rows_analysis_ == an.id && rows_type_ == rows_type))
    upload_solve_rows(an, an.tree.rows.data(), rows_type, nullptr);
  STRATA_CUDA(cudaStreamSynchronize(stream_));
}

void CudaExecutor::begin(const numeric::FactorContext& ctx) {
  STRATA_CUDA(cudaSetDevice(device_));
  outbox_.clear();
  whole_ = false;  // until begin_part says which part: no resident factor from no part
  const Analysis& an = *ctx.analysis;
  bytes_h2d_ = bytes_d2h_ = 0;
  chunks_ = tiled_count_ = prefetched_count_ = 0;
  lu_fronts_ = lu_fronts_pivoted_ = lu_fronts_batched_ = 0;
  phases_ = FactorStats::DevicePhases{};
  held_parts_.clear();
  resident_for_ = nullptr;
  pending_ = nullptr;  // a chunk left by a factorization that failed
  // strips of another executor's front still in flight (its factorization failed before
  // its end_part): they write into this pool
  if (helped_) {
    STRATA_CUDA(cudaStreamSynchronize(help_lane().stream));
    STRATA_CUDA(cudaStreamSynchronize(dist_copy_));
  }
  helped_ = false;
  team_.clear();
  team_used_.clear();
  fronts_split_ = strips_helped_ = fronts_distributed_ = 0;
  help_bytes_ = 0;
  if (an.id != analysis_id_) {
    const Timer setup;
    upload_analysis(an);
    phases_.setup += setup.seconds();
  }
  STRATA_CUDA(cudaEventRecord(start_, stream_));
  values_.upload(ctx.values, an.pattern_indices.size(), stream_);
  count_h2d(an.pattern_indices.size() * sizeof(double));
}

void CudaExecutor::begin_part(const numeric::FactorContext& ctx) {
  STRATA_CUDA(cudaSetDevice(device_));
  drop_tiled_prefetch();  // one left by a factorization that failed
  const Analysis& an = *ctx.analysis;
  const bool whole = ctx.part->id == -1;
  const Timer setup;
  if (whole && planned_ != 1) plan_parts(an, true);
  if (!whole && planned_ != 2) {
    if (an.partition.part_of.size() != static_cast<std::size_t>(an.tree.n_fronts()))
      throw InternalError("a part of an analysis that was not split");
    plan_parts(an, false);
  }
  if (lanes_.empty()) lanes();  // streams and library handles, created once
  auto it = parts_.find(ctx.part->id);
  if (it == parts_.end())
    throw InternalError("part " + std::to_string(ctx.part->id) + " was not planned");
  cur_ = &it->second;
  whole_ = whole;
  // LDLᵀ keeps the host copy: its D and pivot bookkeeping are done on the host panels
  // (store_ldlt_front); a tiled front goes through host memory anyway
  const bool untiled =
      std::none_of(cur_->tiled.begin(), cur_->tiled.end(), [](char c) { return c; });
  device_only_ = keep_resident() && ctx.type != MatrixType::symmetric_indefinite && untiled;
  part_device_only_ = false;
  if (!whole && ctx.keep_part_panels && limit_ == 0 &&
      ctx.type != MatrixType::symmetric_indefinite && untiled) {
    try {  // no room: this part's panels go to the host as before
      part_panels_[ctx.part->id].resize(std::max<std::size_t>(cur_->panel_total, 1));
      part_device_only_ = true;
    } catch (const OutOfMemory&) {
      part_panels_.erase(ctx.part->id);
    }
  }
  phases_.setup += setup.seconds();
  set_team(ctx);
}

void CudaExecutor::end_part(const numeric::FactorContext& ctx) {
  STRATA_CUDA(cudaSetDevice(device_));
  drop_tiled_prefetch();  // none is left when the part ends well
  flush_chunk(ctx);       // the last chunk's host part, while ctx.part is still this part
  release_team();
  if (part_device_only_) held_parts_.push_back(ctx.part->id);
  part_device_only_ = false;
}

std::vector<std::unique_ptr<Lane>>& CudaExecutor::lanes() {
  if (!lanes_.empty()) return lanes_;
  for (std::size_t i = 0; i < kLanes; ++i) {
    lanes_.push_back(std::make_unique<Lane>());
    Lane& l = *lanes_.back();
    STRATA_CUDA(cudaEventCreateWithFlags(&l.done, cudaEventDisableTiming));
    if (i == 0) {
      l.stream = stream_;
      l.blas = blas_;
      l.solver = solver_;
      continue;
    }
    l.owned = true;
    STRATA_CUDA(cudaStreamCreateWithFlags(&l.stream, cudaStreamNonBlocking));
    STRATA_CUBLAS(cublasCreate(&l.blas));
    STRATA_CUBLAS(cublasSetStream(l.blas, l.stream));
    STRATA_CUSOLVER(cusolverDnCreate(&l.solver));
    STRATA_CUSOLVER(cusolverDnSetStream(l.solver, l.stream));
  }
  return lanes_;
}

void CudaExecutor::download_panels(const Analysis& an, numeric::NumericFactor& fac) {
  STRATA_CUDA(cudaSetDevice(device_));
  if (!held_parts_.empty()) {  // parts of a multi-GPU split: each part's buffer, front by front
    if (an.id != analysis_id_)
      throw InvalidState("download_panels: the device holds no factor for this analysis");
    const bool lu = !an.symmetric;
    std::vector<double> pageable;  // when pinned memory cannot be had
    for (const int id : held_parts_) {
      const PartDevice& pd = parts_.at(id);
      // through pinned memory (with a pageable buffer, the first host solve after a 4-GPU
      // factorization of lap3d 80³ took 2.4 s against 0.6 s when the panels came back
      // during the factorization; the pinned path is not yet measured)
      double* host = nullptr;
      try {
        host_staging_.resize(pd.panel_total);
        host = host_staging_.data();
      } catch (const OutOfMemory&) {
        pageable.resize(pd.panel_total);
        host = pageable.data();
      }
      STRATA_CUDA(cudaMemcpy(host, part_panels_.at(id).data(), sizeof(double) * pd.panel_total,
                             cudaMemcpyDeviceToHost));
      for (std::size_t q = 0; q < pd.fronts_host.size(); ++q) {
        const index_t f = pd.fronts_host[q];
        std::memcpy(fac.panels.data() + an.factor_layout.panel_offset[f],
                    host + pd.panel_off_host[q], sizeof(double) * panel_size(an.tree, f, lu));
      }
    }
    return;
  }
  if (!keep_resident() || resident_for_ != &fac || resident_analysis_ != an.id)
    throw InvalidState("download_panels: the device holds no factor for this analysis");
  sized_resize(fac.panels, an.factor_layout.total, "download_panels: factor panels");
  STRATA_CUDA(cudaMemcpyAsync(fac.panels.data(), panels_.data(),
                              sizeof(double) * an.factor_layout.total, cudaMemcpyDeviceToHost,
                              stream_));
  STRATA_CUDA(cudaStreamSynchronize(stream_));
}

std::size_t CudaExecutor::export_cb(const numeric::FactorContext& ctx, numeric::CbTransfer& t) {
  STRATA_CUDA(cudaSetDevice(device_));
  const double* src = cur_->cb_ptr_host[t.front];
  const std::size_t bytes = sizeof(double) * t.size;
  int peer = 0;
  if (t.target_device >= 0 && t.target_device != device_)
    STRATA_CUDA(cudaDeviceCanAccessPeer(&peer, t.target_device, device_));
  if (t.target_device == device_ || peer) {  // stays on this GPU until the importer copies
    DeviceBuffer<double>& box = outbox_[t.front];
    box.resize(t.size);
    STRATA_CUDA(cudaMemcpyAsync(box.data(), src, bytes, cudaMemcpyDefault, stream_));
    STRATA_CUDA(cudaStreamSynchronize(stream_));
    t.device = box.data();
    t.device_ordinal = device_;
    t.on_host = false;
    return 0;  // nothing crossed the bus yet: the importer counts the copy
  }
  STRATA_CUDA(cudaMemcpyAsync(t.host_buffer(), src, bytes, cudaMemcpyDefault, stream_));
  STRATA_CUDA(cudaStreamSynchronize(stream_));
  t.on_host = true;
  bytes_d2h_ += bytes;
  return bytes;
}

std::size_t CudaExecutor::import_cb(const numeric::FactorContext& ctx,
                                    const numeric::CbTransfer& t) {
  STRATA_CUDA(cudaSetDevice(device_));
  double* dst = cur_->cb_ptr_host[t.front];
  const std::size_t bytes = sizeof(double) * t.size;
  const bool dst_on_device = dst >= arena_.data() && dst < arena_.data() + arena_.size();
  if (t.on_host) {
    STRATA_CUDA(cudaMemcpyAsync(dst, t.host, bytes, cudaMemcpyDefault, stream_));
    bytes_h2d_ += bytes;
  } else if (t.device_ordinal != device_ && dst_on_device) {
    const cudaError_t e = cudaDeviceEnablePeerAccess(t.device_ordinal, 0);
    if (e == cudaErrorPeerAccessAlreadyEnabled)
      (void)cudaGetLastError();
    else
      STRATA_CUDA(e);
    STRATA_CUDA(cudaMemcpyPeerAsync(dst, device_, t.device, t.device_ordinal, bytes, stream_));
  } else {  // same GPU, or into mapped host memory: unified addressing finds the way
    STRATA_CUDA(cudaMemcpyAsync(dst, t.device, bytes, cudaMemcpyDefault, stream_));
  }
  STRATA_CUDA(cudaStreamSynchronize(stream_));
  return t.device_ordinal == device_ && !t.on_host ? 0 : bytes;
}

void CudaExecutor::end(const numeric::FactorContext& ctx) {
  STRATA_CUDA(cudaSetDevice(device_));
  flush_chunk(ctx);
  STRATA_CUDA(cudaEventRecord(stop_, stream_));
  STRATA_CUDA(cudaEventSynchronize(stop_));
  // panels of parts another GPU factored this time (stealing moves subtrees): give back
  for (auto it = part_panels_.begin(); it != part_panels_.end();)
    if (std::find(held_parts_.begin(), held_parts_.end(), it->first) == held_parts_.end())
      it = part_panels_.erase(it);
    else
      ++it;
  float ms = 0;
  STRATA_CUDA(cudaEventElapsedTime(&ms, start_, stop_));
  device_seconds_ = ms * 1e-3;
  // LLᵀ has no pivoting: the solve's row arrays of the previous factorization of this
  // analysis still hold (a refactorization uploads nothing here)
  const bool rows_current = rows_analysis_ == ctx.analysis->id && rows_type_ == MatrixType::spd &&
                            ctx.type == MatrixType::spd;
  if (keep_resident() && rows_current) {
    resident_for_ = ctx.factor;
    resident_analysis_ = ctx.analysis->id;
  } else if (keep_resident()) {
    const Timer setup;
    upload_solve_rows(*ctx.analysis, ctx.factor->rows.data(), ctx.type, ctx.factor);
    resident_for_ = ctx.factor;
    resident_analysis_ = ctx.analysis->id;
    phases_.setup += setup.seconds();
  }
}

void CudaExecutor::upload_solve_rows(const Analysis& an, const index_t* factor_rows,
                                     MatrixType type, const numeric::NumericFactor* fac) {
  const auto& t = an.tree;
  // LU: a front's local permutation moves its pivot rows only (factor_front_lu), so once
  // this analysis' arrays are on the device only the pivot rows of the fronts whose pivots
  // moved since are sent, packed into one copy and scattered on the device, with the two
  // n-long pivot arrays. Sending all the rows (Σ m over the fronts) took 0.035 s of a
  // 0.175 s refactorization of the flexible plate's Newton matrix on the H100; one copy
  // per moved front took the tracked vehicle's (thousands of small fronts that pivot) from
  // 15 to 21 ms per factorization.
  if (type == MatrixType::general && rows_analysis_ == an.id && rows_type_ == MatrixType::general &&
      s_rows_host_.size() == t.rows.size()) {
    std::vector<std::int64_t> packed, seg;  // seg: destination, length, offset in packed
    for (index_t f = 0; f < t.n_fronts(); ++f) {
      const index_t fp = t.first_pivot[f], k = t.n_pivots(f), ro = t.row_offsets[f];
      const index_t* prow = factor_rows + ro;
      std::int64_t* held = s_rows_host_.data() + ro;
      if (std::equal(prow, prow + k, held)) continue;
      seg.insert(seg.end(), {ro, k, static_cast<std::int64_t>(packed.size())});
      packed.insert(packed.end(), prow, prow + k);
      for (index_t i = 0; i < k; ++i) {
        held[i] = prow[i];
        s_pivot_pos_host_[prow[i]] = i;
        s_pivot_row_host_[fp + i] = prow[i];
      }
    }
    if (seg.empty()) return;
    upload(s_moved_rows_, packed);
    upload(s_moved_segments_, seg);
    launch_scatter_segments(s_moved_segments_.data(), static_cast<std::int64_t>(seg.size() / 3),
                            s_moved_rows_.data(), s_rows_.data(), stream_);
    upload(s_pivot_pos_, s_pivot_pos_host_);
    upload(s_pivot_row_, s_pivot_row_host_);
    STRATA_CUDA(cudaStreamSynchronize(stream_));  // the copies read the host arrays
    return;
  }
  // what the device solve needs besides the panels: the factored row order, where each
  // pivot went in its front (LU, LDLᵀ), and D (LDLᵀ)
  s_rows_host_.assign(factor_rows, factor_rows + t.rows.size());
  s_pivot_pos_host_.assign(an.n, 0);
  s_pivot_row_host_.assign(an.n, 0);
  for (index_t f = 0; f < t.n_fronts(); ++f) {
    const index_t fp = t.first_pivot[f];
    const index_t* prow = factor_rows + t.row_offsets[f];
    for (index_t i = 0; i < t.n_pivots(f); ++i) {
      s_pivot_pos_host_[prow[i]] = i;  // prow[i] is a pivot of this front: fp ≤ prow[i] < fp + k
      s_pivot_row_host_[fp + i] = prow[i];
    }
  }
  upload(s_rows_, s_rows_host_);
  upload(s_pivot_pos_, s_pivot_pos_host_);
  upload(s_pivot_row_, s_pivot_row_host_);
  if (type == MatrixType::symmetric_indefinite) {
    upload(s_d_diag_, fac->d_diag);
    upload(s_d_off_, fac->d_off);
    upload(s_pivot_size_, fac->pivot_size);
  }
  STRATA_CUDA(cudaStreamSynchronize(stream_));
  rows_analysis_ = an.id;
  rows_type_ = type;
}

void CudaExecutor::report(FactorStats& fs) const {
  fs.device_seconds = device_seconds_;
  fs.bytes_to_device = bytes_h2d_;
  fs.bytes_to_host = bytes_d2h_;
  fs.device_batches = chunks_;
  fs.tiled_fronts = tiled_count_;
  fs.tiled_fronts_prefetched = prefetched_count_;
  fs.lu_large_fronts = lu_fronts_;
  fs.lu_large_fronts_pivoted = lu_fronts_pivoted_;
  fs.lu_large_fronts_batched = lu_fronts_batched_;
  fs.device_budget = plan_.budget;
  fs.device_pool_bytes = plan_.pool * sizeof(double);
  fs.contribution_blocks_on_host = plan_.arena_on_host;
  fs.factor_resident = keep_resident();
  fs.device_phases = phases_;
}

// Decides what lives where (see the file header) and lays out the chunks of every part
// in `views`: positions [p, chunk_end[p]) of one batch share the pool; tiled[p] marks a
// front factored by slabs. The pool and the arena serve every part (largest of each).
void CudaExecutor::plan_device_memory(const Analysis& an,
                                      const std::vector<numeric::PartView>& views) {
  const auto& t = an.tree;
  std::size_t free_b = 0, total_b = 0;
  STRATA_CUDA(cudaMemGetInfo(&free_b, &total_b));
  DevicePlan p;
  p.budget = limit_ > 0 ? limit_ : static_cast<std::size_t>(0.9 * static_cast<double>(free_b));
  const std::size_t budget_d = p.budget / sizeof(double);
  auto sq = [](index_t m) { return static_cast<std::size_t>(m) * static_cast<std::size_t>(m); };

  // pool: the largest batch of fronts that are not tiled, capped (without a user limit)
  // at half the budget so that the arena and the factor have room
  std::size_t cap = limit_ > 0 ? budget_d : budget_d / 2;
  std::size_t pool = 0;
  index_t tiled_rows = 0;
  for (const numeric::PartView& v : views) {
    const auto& s = *v.schedule;
    PartDevice& pd = parts_[v.id];
    pd.tiled.assign(s.fronts.size(), 0);
    for (const BatchInfo& b : *v.batches) {
      std::size_t sum = 0;
      for (index_t q = b.begin; q < b.end; ++q) {
        const index_t f = s.fronts[q];
        if (b.tiled || sq(t.n_rows(f)) > cap) {
          pd.tiled[q] = 1;
          tiled_rows = std::max(tiled_rows, t.n_rows(f));
        } else {
          sum += sq(t.n_rows(f));
        }
      }
      pool = std::max(pool, std::min(sum, cap));
    }
  }
  // a tiled front needs a slab and two column blocks of at least kMinSlab columns
  if (tiled_rows > 0) {
    pool = std::max<std::size_t>(pool, 3 * static_cast<std::size_t>(tiled_rows) * kMinSlab);
    // a larger pool means larger pieces of the tiled fronts (Options::gpu_tiled_pool_share)
    pool =
        std::max(pool, static_cast<std::size_t>(tiled_pool_share_ * static_cast<double>(budget_d)));
  }
  if (limit_ > 0 && pool > budget_d)
    throw OutOfMemory(pool * sizeof(double),
                      "the device pool for the largest front (device_memory_limit is " +
                          std::to_string(limit_) + " bytes)");
  p.pool = std::max<std::size_t>(pool, 1);
  // chunks: consecutive non-tiled positions of a batch whose fronts fit the pool
  for (const numeric::PartView& v : views) {
    const auto& s = *v.schedule;
    PartDevice& pd = parts_[v.id];
    pd.pos_offset_host.assign(s.fronts.size(), 0);
    pd.chunk_end.assign(s.fronts.size(), 0);
    for (const BatchInfo& b : *v.batches) {
      index_t start = b.begin;
      std::size_t off = 0;
      for (index_t q = b.begin; q <= b.end; ++q) {
        const bool flush = q == b.end || pd.tiled[q] || off + sq(t.n_rows(s.fronts[q])) > p.pool;
        if (flush && q > start) {
          pd.chunk_end[start] = q;
          start = q;
          off = 0;
        }
        if (q == b.end) break;
        if (pd.tiled[q]) {
          start = q + 1;
          continue;
        }
        pd.pos_offset_host[q] = static_cast<std::int64_t>(off);
        off += sq(t.n_rows(s.fronts[q]));
      }
    }
  }
  // arena (the largest part's), then the resident factor (whole tree only), in what the
  // pool leaves
  std::size_t arena = 0;
  bool whole = false;
  for (const numeric::PartView& v : views) {
    arena = std::max(arena, v.cb_layout->arena_size);
    whole = whole || v.id == -1;
  }
  const std::size_t rest = budget_d > p.pool ? budget_d - p.pool : 0;
  const std::size_t factor = an.factor_layout.total;
  if (whole && rest >= arena + factor) {
    p.arena_device = arena;
    p.factor_resident = true;
  } else {
    p.arena_device = std::min(arena, rest);
  }
  p.arena_on_host = p.arena_device < arena;
  plan_ = p;
}

void CudaExecutor::upload_analysis(const Analysis& an) {
  const auto& t = an.tree;
  const auto& s = an.schedule;
  const index_t nf = t.n_fronts();
  // free what the previous analysis held before measuring free memory
  for (auto* b : {&pool_, &arena_, &panels_, &values_}) b->clear();
  host_arena_.clear();
  parts_.clear();
  outbox_.clear();
  cur_ = nullptr;
  planned_ = 0;
  analysis_id_ = 0;
  std::vector<std::int64_t> n_rows(nf), n_piv(nf);
  for (index_t f = 0; f < nf; ++f) {
    n_rows[f] = t.n_rows(f);
    n_piv[f] = t.n_pivots(f);
  }
  // relative positions of each child's contribution rows in its parent: the analysis's
  const std::vector<std::int64_t>& rel_off = an.child_rows.offsets;
  const std::vector<std::int64_t>& rel = an.child_rows.rel;
  upload(fronts_, s.fronts);
  upload(n_rows_, n_rows);
  upload(n_pivots_, n_piv);
  upload(parent_, t.parent);
  upload(entry_offsets_, an.assembly.entry_offsets);
  upload(entry_src_, an.assembly.entry_src);
  upload(entry_dst_, an.assembly.entry_dst);
  upload(child_offsets_, t.child_offsets);
  upload(children_, t.children);
  upload(rel_offsets_, rel_off);
  upload(rel_, rel);
  // solve arrays
  std::vector<std::int64_t> u_off(nf + 1, 0);
  for (index_t f = 0; f < nf; ++f) u_off[f + 1] = u_off[f] + t.cb_size(f);
  u_offset_host_ = u_off;
  upload(s_u_offset_, u_off);
  upload(s_panel_offset_, std::vector<std::int64_t>(an.factor_layout.panel_offset.begin(),
                                                    an.factor_layout.panel_offset.end()));
  upload(s_row_offsets_, t.row_offsets);
  upload(s_first_pivot_, t.first_pivot);
  upload(s_level_offsets_, s.level_offsets);
  values_.resize(std::max<std::size_t>(an.pattern_indices.size(), 1));
  STRATA_CUDA(cudaStreamSynchronize(stream_));

  STRATA_CUDA(cudaStreamSynchronize(stream_));
  analysis_id_ = an.id;
}

// Plans and uploads the parts a factorization will use: the whole tree, or every part of
// an.partition — subtrees, upper parts and the top part (any GPU may run any subtree).
void CudaExecutor::plan_parts(const Analysis& an, bool whole) {
  const auto& t = an.tree;
  for (auto* b : {&pool_, &arena_, &panels_}) b->clear();
  host_arena_.clear();
  parts_.clear();
  part_panels_.clear();
  held_parts_.clear();
  cur_ = nullptr;
  planned_ = 0;
  std::vector<numeric::PartView> views;
  if (whole) {
    views.push_back(numeric::PartView::whole(an));
  } else {
    // every part by id: subtrees, the top part, the upper layers' parts
    const auto& p = an.partition;
    for (int id = 0; id < p.n_parts(); ++id) views.push_back(numeric::PartView::of(p.part(id), id));
  }
  plan_device_memory(an, views);
  pool_.resize(plan_.pool);
  std::size_t arena = 1, chunk_panels = 1;
  for (const numeric::PartView& v : views) {
    arena = std::max(arena, v.cb_layout->arena_size);
    const PartDevice& pd = parts_.at(v.id);
    const auto& s = *v.schedule;
    for (index_t q = 0; q < static_cast<index_t>(s.fronts.size()); ++q)
      if (!pd.tiled[q] && pd.chunk_end[q] > q) {
        std::size_t sum = 0;
        for (index_t r = q; r < pd.chunk_end[q]; ++r)
          sum += panel_size(t, s.fronts[r], !an.symmetric);
        chunk_panels = std::max(chunk_panels, sum);
      }
  }
  arena_.resize(std::max<std::size_t>(plan_.arena_device, 1));
  if (plan_.arena_on_host) host_arena_.resize(arena);
  // staging for the panels of one chunk, or the whole resident factor
  panels_.resize(plan_.factor_resident ? std::max<std::size_t>(an.factor_layout.total, 1)
                                       : chunk_panels);
  // and their way to the host factor, one buffer per chunk slot (factor_chunk)
  if (!plan_.factor_resident && an.type != MatrixType::symmetric_indefinite)
    for (ChunkRecord& c : chunk_) c.panels.resize(chunk_panels);
  for (const numeric::PartView& v : views) upload_part(an, v);
  presize_chunk_buffers(an, views);
  STRATA_CUDA(cudaStreamSynchronize(stream_));
  planned_ = whole ? 1 : 2;
}

// Every buffer a chunk grows on demand, at the largest size any chunk of `views` needs.
// Growing frees the old allocation, and cudaFree / cudaFreeHost wait for the whole
// device: done during the first factorization, each growth stalled the chunk pipeline
// (the first factorization of lap3d 100³ took 0.52–0.64 s against 0.37 s for the
// refactorizations on an H200; loading the CUDA modules eagerly did not change that).
// Done here, at analysis (prepare) or at the first begin_part, the factorizations
// allocate nothing on the device.
void CudaExecutor::presize_chunk_buffers(const Analysis& an,
                                         const std::vector<numeric::PartView>& views) {
  const auto& t = an.tree;
  const bool lu = !an.symmetric;
  std::size_t count = 1, big = 1, small = 1, pivots = 1, diag = 1, diag_slab = 1, strips = 1;
  std::size_t host_front = 0;  // pinned doubles for the largest tiled front's host side
  int potrf = 1, getrf = 1, blocks = 1;
  std::vector<std::unique_ptr<Lane>>& lane = lanes();
  for (const numeric::PartView& v : views) {
    const PartDevice& pd = parts_.at(v.id);
    const auto& s = *v.schedule;
    for (index_t q = 0; q < static_cast<index_t>(s.fronts.size()); ++q) {
      if (pd.tiled[q]) {  // LU: the whole front (tiled_front.cu); LLᵀ: its panel, and its
                          // block when that lives on the device (tiled_llt.cu)
        const index_t f = s.fronts[q];
        const std::size_t m = static_cast<std::size_t>(t.n_rows(f));
        const std::size_t k = static_cast<std::size_t>(t.n_pivots(f)), mc = m - k;
        const double* cb = pd.cb_ptr_host[f];
        host_front =
            std::max(host_front, lu ? m * m : m * k + (cb && !in_host_arena(cb) ? mc * mc : 0));
      }
      if (pd.tiled[q] && !lu && recursive_panel_) {  // its slabs, on lane 0 (tiled_llt.cu)
        const index_t f = s.fronts[q];
        diag_slab = std::max(
            diag_slab, llt_recursive_work_size(tiled_llt_widths(t.n_rows(f), t.n_pivots(f)).slab));
      }
      if (pd.tiled[q] || pd.chunk_end[q] <= q) continue;
      std::size_t nb = 0, ns = 0, np = 0, ni = 0;
      for (index_t r = q; r < pd.chunk_end[q]; ++r) {
        const index_t f = s.fronts[r];
        const int m = static_cast<int>(t.n_rows(f)), k = static_cast<int>(t.n_pivots(f));
        np += static_cast<std::size_t>(k);
        if (m <= kSmallFront) {
          ++ns;
          continue;
        }
        ++nb;
        if (lu_strip_pivots_ > 0)  // enqueue_lu_strips' items: one per strip
          ni += static_cast<std::size_t>((k + lu_strip_pivots_ - 1) / lu_strip_pivots_);
        int lwork = 0;
        if (lu) {
          STRATA_CUSOLVER(cusolverDnDgetrf_bufferSize(solver_, k, k, pool_.data(), m, &lwork));
          getrf = std::max(getrf, lwork);
        } else if (k > panel_max_pivots_ && recursive_panel_) {
          diag = std::max(diag, llt_recursive_work_size(k));
        } else if (k > panel_max_pivots_) {
          const bool blocked = potrf_block_ > 0 && potrf_block_ < k;
          STRATA_CUSOLVER(cusolverDnDpotrf_bufferSize(solver_, CUBLAS_FILL_MODE_LOWER,
                                                      blocked ? potrf_block_ : k, pool_.data(), m,
                                                      &lwork));
          potrf = std::max(potrf, lwork);
          if (blocked) blocks = std::max(blocks, (k + potrf_block_ - 1) / potrf_block_);
        }
      }
      count = std::max(count, static_cast<std::size_t>(pd.chunk_end[q] - q));
      big = std::max(big, nb);
      small = std::max(small, ns);
      pivots = std::max(pivots, np);
      strips = std::max(strips, ni);
    }
  }
  for (auto* b : {&info_, &perturbed_, &stage_offset_, &diag_offset_}) b->resize(count + 1);
  // the tiled fronts' pinned buffers: the prefetch's (LLᵀ) the same size, since the two
  // trade places at every prefetched front and must not grow on the way
  if (host_front > 0) {
    host_front_.resize(host_front);
    if (tiled_prefetch_ && !lu) try {
        host_front_next_.resize(host_front);
      } catch (const OutOfMemory&) {  // no room for the second: no prefetch (tiled_llt.cu)
      }
  }
  small_pos_.resize(small);
  perm_offset_.resize(small + 1);
  potrf_info_.resize(big + 1);
  panel_items_.resize(2 * big);
  if (!lu) panel_work_.resize(llt_panel_work_size(static_cast<std::int64_t>(big)));
  perm_.resize(pivots + 1);
  pivot_size_.resize(pivots + 1);
  diag_.resize(pivots + 1);
  for (ChunkRecord& c : chunk_) {
    c.info.resize(count + 1);
    c.perturbed.resize(count + 1);
    c.perm.resize(pivots + 1);
    c.pinfo.resize(big + 1);
    c.psize.resize(pivots + 1);
    c.diag.resize(pivots + 1);
  }
  for (auto& l : lane) {
    l->potrf_work.resize(static_cast<std::size_t>(potrf));
    l->block_info.resize(static_cast<std::size_t>(blocks));
    l->diag_work.resize(l == lane.front() ? std::max(diag, diag_slab) : diag);
  }
  if (lu) {
    lu_items_.resize(strips);
    lu_work_.resize(lu_panel_work_size(static_cast<std::int64_t>(big)));
    lu_perm_offset_.resize(big + 1);
    lu_ipiv_.resize(pivots);
    lu_info_.resize(big);
    lu_bad_.resize(big);
    lu_bad_host_.resize(big);
    for (auto& l : lane) l->getrf_work.resize(static_cast<std::size_t>(getrf));
  }
}

// A part's schedule, pool offsets and block locations on the device.
void CudaExecutor::upload_part(const Analysis& an, const numeric::PartView& v) {
  const auto& t = an.tree;
  const index_t nf = t.n_fronts();
  PartDevice& pd = parts_.at(v.id);
  upload(pd.fronts, v.schedule->fronts);
  pd.fronts_host.assign(v.schedule->fronts.begin(), v.schedule->fronts.end());
  pd.panel_off_host.assign(pd.fronts_host.size(), 0);
  pd.panel_total = 0;
  for (std::size_t q = 0; q < pd.fronts_host.size(); ++q) {
    pd.panel_off_host[q] = static_cast<std::int64_t>(pd.panel_total);
    pd.panel_total += panel_size(t, pd.fronts_host[q], !an.symmetric);
  }
  upload(pd.pos_offset, pd.pos_offset_host);
  // where each contribution block the part writes or reads lives
  pd.cb_ptr_host.assign(nf, nullptr);
  auto place = [&](index_t f) {
    const std::size_t cb = static_cast<std::size_t>(t.cb_size(f));
    if (cb == 0 || t.parent[f] < 0) return;
    const std::size_t off = v.cb_layout->cb_offset[f];
    pd.cb_ptr_host[f] =
        off + cb * cb <= plan_.arena_device ? arena_.data() + off : host_arena_.data() + off;
  };
  for (const index_t f : v.schedule->fronts) {
    place(f);
    for (index_t q = t.child_offsets[f]; q < t.child_offsets[f + 1]; ++q) place(t.children[q]);
  }
  upload(pd.cb_ptr, pd.cb_ptr_host);
  pd.tree = DeviceTree{pd.fronts.data(),  pd.pos_offset.data(), n_rows_.data(),
                       n_pivots_.data(),  parent_.data(),       entry_offsets_.data(),
                       entry_src_.data(), entry_dst_.data(),    child_offsets_.data(),
                       children_.data(),  pd.cb_ptr.data(),     rel_offsets_.data(),
                       rel_.data()};
}

void CudaExecutor::factor_batch(const numeric::FactorContext& ctx, const BatchInfo& b) {
  STRATA_CUDA(cudaSetDevice(device_));
  try {
    for (index_t q = b.begin; q < b.end;) {
      if (cur_->tiled[q]) {
        flush_chunk(ctx);  // the tiled path syncs and works on the host
        factor_tiled(ctx, q);
        ++q;
      } else {
        factor_chunk(ctx, q, cur_->chunk_end[q]);
        q = cur_->chunk_end[q];
      }
    }
  } catch (...) {
    // a next front's host assembly must not outlive the factorization whose values and
    // analysis it reads
    drop_tiled_prefetch();
    throw;
  }
}

void grow_potrf_work(cusolverDnHandle_t h, DeviceBuffer<double>& work, double* a, int k, int ld) {
  int lwork = 0;
  STRATA_CUSOLVER(cusolverDnDpotrf_bufferSize(h, CUBLAS_FILL_MODE_LOWER, k, a, ld, &lwork));
  work.resize(static_cast<std::size_t>(std::max(lwork, 1)));
}

void CudaExecutor::factor_chunk(const numeric::FactorContext& ctx, index_t begin, index_t end) {
  const Analysis& an = *ctx.analysis;
  const auto& t = an.tree;
  const auto& s = *ctx.part->schedule;
  const DeviceTree& tree = cur_->tree;
  const bool lu = ctx.type == MatrixType::general;
  const bool ldlt = ctx.type == MatrixType::symmetric_indefinite;
  const std::int64_t count = end - begin;
  ++chunks_;
  ChunkRecord& rec = chunk_[slot_];
  slot_ ^= 1;
  cudaEvent_t* const ev = rec.ev;
  index_t max_rows = 0;
  for (index_t p = begin; p < end; ++p) max_rows = std::max(max_rows, t.n_rows(s.fronts[p]));
  STRATA_CUDA(cudaEventRecord(ev[0], stream_));
  launch_assemble(tree, begin, count, max_rows, values_.data(), pool_.data(), !lu, stream_);
  STRATA_CUDA(cudaEventRecord(ev[1], stream_));

  // small fronts: one launch for the whole chunk
  std::vector<std::int64_t> small, big, perm_off{0};
  for (index_t p = begin; p < end; ++p) {
    const index_t f = s.fronts[p];
    if (t.n_rows(f) <= kSmallFront) {
      small.push_back(p);
      perm_off.push_back(perm_off.back() + t.n_pivots(f));
    } else {
      big.push_back(p);
    }
  }
  const std::size_t ns = small.size();
  upload(small_pos_, small);
  upload(perm_offset_, perm_off);
  info_.resize(ns + big.size() + 1);
  perturbed_.resize(ns + big.size() + 1);
  std::int64_t big_perm = 0;
  for (std::int64_t p : big) big_perm += t.n_pivots(s.fronts[p]);
  perm_.resize(perm_off.back() + big_perm + 1);
  potrf_info_.resize(big.size() + 1);
  pivot_size_.resize(perm_off.back() + big_perm + 1);
  if (ldlt)
    launch_ldlt_small(tree, small_pos_.data(), static_cast<std::int64_t>(ns), pool_.data(),
                      ctx.static_pivot, perturbed_.data(), perm_.data(), pivot_size_.data(),
                      perm_offset_.data(), stream_);
  else
    launch_factor_small(tree, small_pos_.data(), static_cast<std::int64_t>(ns), pool_.data(), lu,
                        ctx.static_pivot, info_.data(), perturbed_.data(), perm_.data(),
                        perm_offset_.data(), stream_);
  STRATA_CUDA(cudaEventRecord(ev[2], stream_));

  // LLᵀ fronts up to gpu_panel_kernel_max_pivots: their pivot blocks and panels by our
  // kernels for all of them together (kernels_panel.cu), so that only their SYRK is a
  // library call below
  const bool llt = !lu && !ldlt;
  std::vector<std::size_t> panel_order;
  if (llt)
    for (std::size_t i = 0; i < big.size(); ++i)
      if (t.n_pivots(s.fronts[big[i]]) <= panel_max_pivots_) panel_order.push_back(i);
  if (!panel_order.empty()) {
    // largest k first: the fronts still active at a step are then a prefix
    std::stable_sort(panel_order.begin(), panel_order.end(), [&](std::size_t a, std::size_t b) {
      return t.n_pivots(s.fronts[big[a]]) > t.n_pivots(s.fronts[big[b]]);
    });
    std::vector<std::int64_t> items, rows, pivots;
    for (std::size_t i : panel_order) {
      const index_t f = s.fronts[big[i]];
      items.push_back(big[i]);
      items.push_back(static_cast<std::int64_t>(i));
      rows.push_back(t.n_rows(f));
      pivots.push_back(t.n_pivots(f));
    }
    upload(panel_items_, items);
    panel_work_.resize(llt_panel_work_size(static_cast<std::int64_t>(pivots.size())));
    launch_llt_panel(tree, panel_items_.data(), rows, pivots, pool_.data(), panel_work_.data(),
                     potrf_info_.data(), stream_);
  }
  STRATA_CUDA(cudaEventRecord(panels_done_, stream_));

  // large fronts: library calls, each front on one lane, the lanes side by side (the
  // least-loaded lane takes the next front; LDLᵀ's panel workspace is single: one lane).
  // The fronts the panel kernels did not take go first, their lanes not waiting for those
  // kernels (lane 0 is stream_ itself, behind them); then the updates of the ones they took,
  // each lane waiting once for panels_done_.
  std::int64_t perm_at = perm_off.back();
  std::vector<std::int64_t> big_perm_at(big.size());
  for (std::size_t i = 0; i < big.size(); ++i) {
    big_perm_at[i] = perm_at;
    perm_at += t.n_pivots(s.fronts[big[i]]);
  }
  std::vector<char> by_kernels(big.size(), 0);
  for (std::size_t i : panel_order) by_kernels[i] = 1;
  std::vector<std::unique_ptr<Lane>>& lane = lanes();
  std::vector<LuFront> lu_fronts;
  // the lanes this chunk may use, which the stores wait for below: LU by strips spreads its
  // updates over every lane (lu_fronts.cu) however few the fronts
  const bool lu_strips = lu && lu_strip_pivots_ > 0 && !big.empty();
  const std::size_t n_lanes =
      ldlt ? 1 : (lu_strips ? lane.size() : std::min(lane.size(), big.size()));
  std::vector<char> waited(n_lanes, 0);
  for (std::size_t l = 0; l < n_lanes; ++l) {
    lane[l]->load = 0;
    if (l > 0) STRATA_CUDA(cudaStreamWaitEvent(lane[l]->stream, ev[2], 0));
  }
  for (int pass = 0; pass < 2; ++pass)
    for (std::size_t i = 0; i < big.size(); ++i) {
      if (by_kernels[i] != pass) continue;
      const index_t p = big[i], f = s.fronts[p];
      const int m = static_cast<int>(t.n_rows(f)), k = static_cast<int>(t.n_pivots(f));
      double* F = pool_.data() + cur_->pos_offset_host[p];
      std::size_t li = 0;
      for (std::size_t l = 1; l < n_lanes; ++l)
        if (lane[l]->load < lane[li]->load) li = l;
      Lane* ln = lane[li].get();
      ln->load += static_cast<double>(m) * m * k;
      std::int64_t* const perm_f = perm_.data() + big_perm_at[i];
      if (ldlt) {
        ldlt_large_.factor(blas_, stream_, F, m, k, ctx.static_pivot, perm_f,
                           pivot_size_.data() + big_perm_at[i], perturbed_.data() + ns + i);
      } else if (by_kernels[i]) {  // pivot block and panel done by the kernels above
        if (li > 0 && !waited[li]) STRATA_CUDA(cudaStreamWaitEvent(ln->stream, panels_done_, 0));
        waited[li] = 1;
        llt_update(ln->blas, m - k, k, F + k, m, F + static_cast<std::size_t>(k) * m + k, m);
      } else if (!lu && distribute_front(m) &&
                 distributed_llt(*ln, F, m, k, potrf_info_.data() + i)) {
        // pivot block, panel and update over the team (distributed_front.cu)
      } else if (!lu) {
        if (recursive_panel_)
          llt_pivot_block_and_panel_recursive(*ln, F, m, k, potrf_info_.data() + i);
        else
          llt_pivot_block_and_panel(*ln, F, m, k, potrf_block_, potrf_info_.data() + i);
        if (m > k) {
          if (split_front(m, k))
            split_update(*ln, F, m, k, false, ev[1]);
          else
            llt_update(ln->blas, m - k, k, F + k, m, F + static_cast<std::size_t>(k) * m + k, m);
        }
      } else {  // first pass: GETRF and its pivot check; the rest after one wait below
        lu_fronts.push_back({ln, F, m, k, p, perm_f, perturbed_.data() + ns + i});
      }
    }
  if (!lu_fronts.empty()) lu_large_fronts(lu_fronts, ctx.static_pivot, ev[1]);
  for (std::size_t l = 1; l < n_lanes; ++l) {  // join: the stores read every front
    STRATA_CUDA(cudaEventRecord(lane[l]->done, lane[l]->stream));
    STRATA_CUDA(cudaStreamWaitEvent(stream_, lane[l]->done, 0));
  }
  join_team();
  STRATA_CUDA(cudaEventRecord(ev[3], stream_));
  launch_store_cb(tree, begin, count, max_rows, pool_.data(), !lu, stream_);

  // factor panels: packed into the device factor (resident), the part's own buffer (a
  // part whose panels stay on this device), or the chunk's staging area (in chunk order:
  // for the whole tree that is the layout's order)
  const bool dev_only = device_only_ || part_device_only_;
  double* const pack_to = part_device_only_ ? part_panels_.at(ctx.part->id).data() : panels_.data();
  std::vector<std::int64_t> stage_off(count), diag_off(count + 1, 0);
  std::size_t total = 0;
  for (std::int64_t i = 0; i < count; ++i) {
    const index_t f = s.fronts[begin + i];
    stage_off[i] = keep_resident()     ? static_cast<std::int64_t>(an.factor_layout.panel_offset[f])
                   : part_device_only_ ? cur_->panel_off_host[begin + i]
                                       : static_cast<std::int64_t>(total);
    total += panel_size(t, f, lu);
    diag_off[i + 1] = diag_off[i] + t.n_pivots(f);
  }
  upload(stage_offset_, stage_off);
  // the staging area is free once the previous chunk's panels are on their way out
  if (copy_issued_) STRATA_CUDA(cudaStreamWaitEvent(stream_, panels_copied_, 0));
  launch_pack_panels(tree, begin, count, max_rows, pool_.data(), stage_offset_.data(), pack_to, lu,
                     stream_);
  // panels for the host factor: copied on copy_stream_ while the next chunk computes; the
  // host part (after the next chunk is launched) moves them into the factor
  rec.panels_async = !dev_only && !ldlt;
  if (rec.panels_async) {
    STRATA_CUDA(cudaEventRecord(ev[6], stream_));
    STRATA_CUDA(cudaStreamWaitEvent(copy_stream_, ev[6], 0));
    rec.panels.resize(total);  // presized at planning
    const std::size_t base = an.factor_layout.panel_offset[s.fronts[begin]];
    const double* src = panels_.data() + (keep_resident() ? base : 0);
    if (total)
      STRATA_CUDA(cudaMemcpyAsync(rec.panels.data(), src, sizeof(double) * total,
                                  cudaMemcpyDeviceToHost, copy_stream_));
    STRATA_CUDA(cudaEventRecord(ev[7], copy_stream_));
    STRATA_CUDA(cudaEventRecord(panels_copied_, copy_stream_));
    copy_issued_ = true;
    bytes_d2h_ += sizeof(double) * total;
  }
  // device-only panels: the host bookkeeping needs only the pivots' diagonal entries
  if (dev_only) {
    upload(diag_offset_, diag_off);
    diag_.resize(static_cast<std::size_t>(diag_off[count]) + 1);
    launch_gather_diagonals(tree, begin, count, stage_offset_.data(), pack_to, diag_offset_.data(),
                            diag_.data(), stream_);
  }
  STRATA_CUDA(cudaEventRecord(ev[4], stream_));
  // the results the host part needs, into this slot's pinned buffers (so that the copies
  // do not hold the host): the host part runs after the next chunk is launched
  const std::size_t nall = ns + big.size();
  rec.info.resize(nall + 1);
  rec.perturbed.resize(nall + 1);
  rec.perm.resize(static_cast<std::size_t>(perm_at) + 1);
  rec.pinfo.resize(big.size() + 1);
  rec.psize.resize(static_cast<std::size_t>(perm_at) + 1);
  rec.diag.resize(dev_only ? static_cast<std::size_t>(diag_off[count]) + 1 : 1);
  if (ns && !ldlt)
    STRATA_CUDA(
        cudaMemcpyAsync(rec.info.data(), info_.data(), 8 * ns, cudaMemcpyDeviceToHost, stream_));
  if (nall)
    STRATA_CUDA(cudaMemcpyAsync(rec.perturbed.data(), perturbed_.data(), 8 * nall,
                                cudaMemcpyDeviceToHost, stream_));
  if (perm_at)
    STRATA_CUDA(cudaMemcpyAsync(rec.perm.data(), perm_.data(), 8 * perm_at, cudaMemcpyDeviceToHost,
                                stream_));
  if (!big.empty() && !lu && !ldlt)
    STRATA_CUDA(cudaMemcpyAsync(rec.pinfo.data(), potrf_info_.data(), sizeof(int) * big.size(),
                                cudaMemcpyDeviceToHost, stream_));
  if (ldlt && perm_at)
    STRATA_CUDA(cudaMemcpyAsync(rec.psize.data(), pivot_size_.data(), sizeof(int) * perm_at,
                                cudaMemcpyDeviceToHost, stream_));
  if (dev_only && diag_off[count] > 0)
    STRATA_CUDA(cudaMemcpyAsync(rec.diag.data(), diag_.data(), sizeof(double) * diag_off[count],
                                cudaMemcpyDeviceToHost, stream_));
  STRATA_CUDA(cudaEventRecord(ev[5], stream_));
  rec.begin = begin;
  rec.end = end;
  rec.lu = lu;
  rec.ldlt = ldlt;
  rec.dev_only = dev_only;
  rec.small = std::move(small);
  rec.big = std::move(big);
  rec.perm_off = std::move(perm_off);
  rec.big_perm_at = std::move(big_perm_at);
  rec.diag_off = std::move(diag_off);
  // the previous chunk's host part, while the GPU runs this one; this one's waits when it
  // writes to the host factor (panels copied back, LDLᵀ): the next chunk's stores would
  // overwrite the staging area it reads
  flush_chunk(ctx);
  pending_ = &rec;
  if (ldlt && !dev_only) flush_chunk(ctx);
}

void CudaExecutor::flush_chunk(const numeric::FactorContext& ctx) {
  if (!pending_) return;
  ChunkRecord& c = *pending_;
  pending_ = nullptr;
  try {
    finish_chunk(ctx, c);
  } catch (...) {
    // a later chunk may still run (on a failed pivot's NaNs): let it end before the
    // buffers it uses can be freed or reused
    (void)cudaDeviceSynchronize();
    (void)cudaGetLastError();
    throw;
  }
}

// The host part of a launched chunk: its phase times, the panels copied back (unless
// they stay on the device), per-front bookkeeping and pivot failures.
void CudaExecutor::finish_chunk(const numeric::FactorContext& ctx, ChunkRecord& c) {
  const Analysis& an = *ctx.analysis;
  const auto& t = an.tree;
  const auto& s = *ctx.part->schedule;
  const DeviceTree& tree = cur_->tree;
  const index_t begin = c.begin, end = c.end;
  const std::int64_t count = end - begin;
  const bool lu = c.lu, ldlt = c.ldlt, dev_only = c.dev_only;
  const std::vector<std::int64_t>& small = c.small;
  const std::vector<std::int64_t>& big = c.big;
  const std::vector<std::int64_t>& perm_off = c.perm_off;
  const std::vector<std::int64_t>& big_perm_at = c.big_perm_at;
  const std::vector<std::int64_t>& diag_off = c.diag_off;
  const std::size_t ns = small.size(), nall = ns + big.size();
  const std::int64_t* info = c.info.data();
  const std::int64_t* perturbed = c.perturbed.data();
  const std::int64_t* perm = c.perm.data();
  const int* pinfo = c.pinfo.data();
  const int* psize = c.psize.data();
  STRATA_CUDA(cudaEventSynchronize(c.ev[5]));
  if (c.panels_async) STRATA_CUDA(cudaEventSynchronize(c.ev[7]));
  float ms[4] = {};
  for (int e = 0; e < 4; ++e) STRATA_CUDA(cudaEventElapsedTime(&ms[e], c.ev[e], c.ev[e + 1]));
  phases_.assembly += 1e-3 * ms[0];
  phases_.small_fronts += 1e-3 * ms[1];
  phases_.large_fronts += 1e-3 * ms[2];
  phases_.store += 1e-3 * ms[3];
  const auto host_start = std::chrono::steady_clock::now();
  struct HostTime {  // adds the host part's wall time on every way out
    FactorStats::DevicePhases& ph;
    std::chrono::steady_clock::time_point t0;
    ~HostTime() {
      ph.host += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    }
  } host_time{phases_, host_start};
  if (c.panels_async)
    store_staged_panels(ctx, begin, end, c.panels.data());
  else if (!dev_only)
    copy_panels_back(ctx, begin, end);
  if (ldlt) {  // D out of the panels, pivot sizes, rows: the CPU executor's code; statistics
    std::vector<std::int64_t> psize_at(count);
    for (std::size_t i = 0; i < nall; ++i) {
      const index_t p = i < ns ? small[i] : big[i - ns], f = s.fronts[p];
      const std::int64_t at = i < ns ? perm_off[i] : big_perm_at[i - ns];
      psize_at[p - begin] = at;
      numeric::store_ldlt_front(an, f, perm + at, psize + at, *ctx.factor);
      numeric::PivotStats& ps = ctx.factor->front_stats[f];
      ps = numeric::PivotStats{};
      const index_t p0 = t.first_pivot[f];
      numeric::cpu::ldlt_stats_from_d(t.n_pivots(f), ctx.factor->d_diag.data() + p0,
                                      ctx.factor->d_off.data() + p0,
                                      ctx.factor->pivot_size.data() + p0, ps);
      ps.perturbed = perturbed[i];
    }
    if (keep_resident()) {  // the device copy of the panels still holds D
      upload(psize_at_, psize_at);
      launch_ldlt_unit_panels(tree, begin, count, stage_offset_.data(), pivot_size_.data(),
                              psize_at_.data(), panels_.data(), stream_);
    }
    return;
  }
  // the diagonal of each front's panel: gathered on the device, or read in the host copy
  std::vector<double> diag;
  auto diag_of = [&](index_t p) -> const double* {
    const index_t f = s.fronts[p];
    if (dev_only) return c.diag.data() + diag_off[p - begin];
    const index_t m = t.n_rows(f), k = t.n_pivots(f);
    const double* panel = ctx.factor->panels.data() + an.factor_layout.panel_offset[f];
    diag.resize(k);
    for (index_t i = 0; i < k; ++i) diag[i] = panel[i * m + i];
    return diag.data();
  };
  for (std::size_t i = 0; i < ns; ++i)
    finish_front(ctx, s.fronts[small[i]], lu ? -1 : info[i], perturbed[i], perm + perm_off[i],
                 diag_of(small[i]));
  for (std::size_t i = 0; i < big.size(); ++i)
    finish_front(ctx, s.fronts[big[i]], (!lu && pinfo[i] > 0) ? pinfo[i] - 1 : -1,
                 perturbed[ns + i], perm + big_perm_at[i], diag_of(big[i]));
}

// The panels of positions [begin, end) to the host factor through the pinned staging
// buffer: for the whole tree they are contiguous in the factor layout (one copy); for a
// part they are staged in chunk order and placed front by front.
void CudaExecutor::copy_panels_back(const numeric::FactorContext& ctx, index_t begin, index_t end) {
  const Analysis& an = *ctx.analysis;
  const auto& t = an.tree;
  const auto& s = *ctx.part->schedule;
  const bool lu = !an.symmetric;
  std::size_t total = 0;
  for (index_t q = begin; q < end; ++q) total += panel_size(t, s.fronts[q], lu);
  if (total == 0) return;
  host_staging_.resize(total);  // grown on first use: a device-only factor never needs it
  const std::size_t base = an.factor_layout.panel_offset[s.fronts[begin]];
  const double* src = panels_.data() + (keep_resident() ? base : 0);
  STRATA_CUDA(cudaMemcpyAsync(host_staging_.data(), src, sizeof(double) * total,
                              cudaMemcpyDeviceToHost, stream_));
  STRATA_CUDA(cudaStreamSynchronize(stream_));
  store_staged_panels(ctx, begin, end, host_staging_.data());
  bytes_d2h_ += sizeof(double) * total;
}

void CudaExecutor::store_staged_panels(const numeric::FactorContext& ctx, index_t begin,
                                       index_t end, const double* staged) {
  const Analysis& an = *ctx.analysis;
  const auto& t = an.tree;
  const auto& s = *ctx.part->schedule;
  const bool lu = !an.symmetric;
  // on the host's threads: one thread's memcpy (≈ 6 GB/s) was half the factorization of
  // lap3d 100³ when its factor did not stay on the device (core/host_copy.hpp)
  if (whole_) {
    std::size_t total = 0;
    for (index_t q = begin; q < end; ++q) total += panel_size(t, s.fronts[q], lu);
    const std::size_t base = an.factor_layout.panel_offset[s.fronts[begin]];
    parallel_copy(ctx.factor->panels.data() + base, staged, total);
  } else {
    std::size_t at = 0;
    for (index_t q = begin; q < end; ++q) {
      const index_t f = s.fronts[q];
      const std::size_t sz = panel_size(t, f, lu);
      parallel_copy(ctx.factor->panels.data() + an.factor_layout.panel_offset[f], staged + at, sz);
      at += sz;
    }
  }
}

// Host bookkeeping of one factored front: failure, permuted rows, pivot statistics.
void CudaExecutor::finish_front(const numeric::FactorContext& ctx, index_t f, std::int64_t bad,
                                std::int64_t npert, const std::int64_t* lperm, const double* diag) {
  const Analysis& an = *ctx.analysis;
  const auto& t = an.tree;
  numeric::NumericFactor& fac = *ctx.factor;
  const bool lu = ctx.type == MatrixType::general;
  const index_t m = t.n_rows(f), k = t.n_pivots(f);
  if (bad >= 0) throw NotPositiveDefinite(an.perm[t.first_pivot[f] + bad], std::nan(""));
  const index_t* rows = t.rows_of(f);
  index_t* frows = fac.rows.data() + t.row_offsets[f];
  numeric::PivotStats& ps = fac.front_stats[f];
  ps = numeric::PivotStats{};
  int sign = 1;
  for (index_t i = 0; i < k; ++i) {
    frows[i] = rows[lu ? lperm[i] : i];
    const double d = diag[i];
    ps.log_abs_det += lu ? std::log(std::abs(d)) : 2.0 * std::log(d);
    if (d < 0) sign = -sign;
  }
  for (index_t i = k; i < m; ++i) frows[i] = rows[i];
  if (lu) {  // parity of the local row permutation
    std::vector<char> seen(k, 0);
    for (index_t i = 0; i < k; ++i) {
      if (seen[i]) continue;
      index_t len = 0;
      for (index_t j = i; !seen[j]; j = lperm[j]) {
        seen[j] = 1;
        ++len;
      }
      if (len % 2 == 0) sign = -sign;
    }
    ps.perturbed = npert;
  } else {
    ps.positive = k;
  }
  ps.det_sign = sign;
}

bool device_present() {
  int count = 0;
  if (cudaGetDeviceCount(&count) != cudaSuccess) {
    (void)cudaGetLastError();
    return false;
  }
  return count > 0;
}

}  // namespace strata::cuda

namespace strata::numeric {

bool cuda_available() { return cuda::device_present(); }

int cuda_device_count() {
  int count = 0;
  if (cudaGetDeviceCount(&count) != cudaSuccess) {
    (void)cudaGetLastError();
    return 0;
  }
  return count;
}

namespace {
class CudaPinnedRange final : public PinnedHostRange {
 public:
  using PinnedHostRange::PinnedHostRange;
  ~CudaPinnedRange() override { cudaHostUnregister(const_cast<void*>(data())); }
};
}  // namespace

std::unique_ptr<PinnedHostRange> pin_host_memory(void* p, std::size_t bytes) {
  if (!p || bytes == 0 || !cuda::device_present()) return nullptr;
  if (cudaHostRegister(p, bytes, cudaHostRegisterPortable) != cudaSuccess) {
    (void)cudaGetLastError();
    return nullptr;
  }
  return std::make_unique<CudaPinnedRange>(p, bytes);
}

std::unique_ptr<Executor> make_cuda_executor(const Options& opts, int device) {
  if (!cuda::device_present())
    throw NotSupported("the CUDA backend was asked for, but no CUDA GPU is visible");
  const int count = cuda_device_count();
  if (device < 0 || device >= count)
    throw NotSupported("CUDA device " + std::to_string(device) + " was asked for, " +
                       std::to_string(count) + " are visible");
  return std::make_unique<cuda::CudaExecutor>(opts, device);
}

}  // namespace strata::numeric
