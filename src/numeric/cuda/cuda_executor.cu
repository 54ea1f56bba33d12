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
//      front redone with interchanges where the threshold pivoting rule wanted them
//      (kernels_lu.cu), or
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
//      only (NumericFactor::held names it; download_panels on demand) and
//      only the pivots' diagonal entries come back for the host bookkeeping.
// A chunk of LU or Cholesky fronts that all fit shared memory, whose panels stay on the device,
// takes steps 1–4 in one launch instead (factor_chunk_fused, Options::gpu_fused_small_batches).
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
// kept resident so that the solve runs on the device (cuda_solve.cu). The pool takes up to
// half the budget, but gives that up, down to the largest front it must hold alone, when
// a smaller pool lets the factor and the arena stay. The per-analysis index arrays, the
// values (O(nnz(A))) and the device solve's plan and workspaces (made at set-up, with the
// resident factor) are not counted in the budget.
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
#include <atomic>
#include <cmath>
#include <cstring>
#include <string>

#include "base/host_copy.hpp"
#include "base/host_memory.hpp"
#include "base/timer.hpp"
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

CudaExecutor::CudaExecutor(const Options& o, int device)
    : device_(device),
      limit_(o.device_memory_limit),
      host_limit_(o.host_memory_limit),
      small_front_rows_(std::min<std::int64_t>(o.gpu_small_front_rows, kSmallFront)),
      small_front_threads_(o.gpu_small_front_threads),
      fused_small_batches_(o.gpu_fused_small_batches),
      panel_max_pivots_(o.gpu_panel_kernel_max_pivots),
      lu_strip_pivots_(o.gpu_lu_strip_pivots),
      split_min_cb_(o.split_front_min_cb),
      dist_min_rows_(o.distributed_front_min_rows),
      dist_block_(std::max<index_t>(64, o.distributed_front_block_size)),
      potrf_block_(static_cast<int>(o.gpu_potrf_block_size)),
      recursive_panel_(o.gpu_recursive_panel),
      solve_graph_(o.gpu_solve_graph),
      solve_chain_(o.gpu_solve_chain),
      solve_parts_(o.gpu_solve_parts) {
  tiled_.pool_share = o.gpu_tiled_pool_share;
  tiled_.stream_cols = o.gpu_tiled_stream_columns;
  tiled_.prefetch_on = o.gpu_tiled_prefetch;
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
  STRATA_CUDA(cudaStreamCreateWithFlags(&lu_.check_stream, cudaStreamNonBlocking));
  STRATA_CUDA(cudaEventCreateWithFlags(&lu_.strip_done, cudaEventDisableTiming));
  STRATA_CUDA(cudaStreamCreateWithFlags(&lu_.ahead.stream, cudaStreamNonBlocking));
  STRATA_CUDA(cudaEventCreateWithFlags(&lu_.ahead.ready, cudaEventDisableTiming));
  STRATA_CUDA(cudaEventCreateWithFlags(&lu_.ahead.done, cudaEventDisableTiming));
  STRATA_CUDA(cudaEventCreateWithFlags(&panels_copied_, cudaEventDisableTiming));
  for (cudaEvent_t* e : {&team_.split_ready, &team_.help_ready, &team_.help_done, &team_.dist_ready,
                         &team_.dist_done})
    STRATA_CUDA(cudaEventCreateWithFlags(e, cudaEventDisableTiming));
  STRATA_CUDA(cudaStreamCreateWithFlags(&team_.dist_copy, cudaStreamNonBlocking));
  STRATA_CUDA(cudaStreamCreateWithFlags(&push_stream_, cudaStreamNonBlocking));
  STRATA_CUDA(cudaStreamCreateWithFlags(&small_stream_, cudaStreamNonBlocking));
  for (ChunkRecord& c : chunk_)
    for (cudaEvent_t& e : c.ev) STRATA_CUDA(cudaEventCreate(&e));
}

CudaExecutor::~CudaExecutor() {
  drop_tiled_prefetch();
  cudaSetDevice(device_);
  drop_solve_graph();
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
  cudaStreamDestroy(lu_.check_stream);
  cudaEventDestroy(lu_.strip_done);
  cudaStreamDestroy(lu_.ahead.stream);
  cudaEventDestroy(lu_.ahead.ready);
  cudaEventDestroy(lu_.ahead.done);
  for (cudaEvent_t e :
       {team_.split_ready, team_.help_ready, team_.help_done, team_.dist_ready, team_.dist_done})
    cudaEventDestroy(e);
  for (cudaEvent_t e : team_.dist_events) cudaEventDestroy(e);
  cudaStreamDestroy(team_.dist_copy);
  drop_landings();
  cudaSetDevice(device_);
  cudaStreamDestroy(push_stream_);
  cudaStreamDestroy(small_stream_);
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
  // before the plan, which sizes the pools from the memory left
  if (workers <= 1 && value_pass_.analysis != an.id) prepare_value_pass(an);
  // the same plans begin_part makes on first use: the whole tree, or every part of the
  // split (any subtree may run on any GPU)
  if (workers <= 1 && planned_ != 1) plan_parts(an, true);
  if (workers > 1 && planned_ != 2 &&
      an.partition.part_of.size() == static_cast<std::size_t>(an.tree.n_fronts()))
    plan_parts(an, false);
  // a split factor's parts are solved where they are held: what that solve needs besides
  // the parts' own plans (part_solve.cu), here rather than in the first solve
  if (workers > 1 && planned_ == 2 && solve_parts_) prepare_part_solve(an);
  // A Cholesky factor keeps the analysis' row order (no pivoting): the device solve's row
  // arrays are known now, and are uploaded here rather than at the end of the first
  // factorization (end() finds them current).
  // An LU factor's rows differ from the analysis' only where a front's pivots were
  // interchanged: uploaded now, its arrays need only those fronts after each factorization.
  const bool cholesky = an.type == MatrixType::spd || an.type == MatrixType::automatic;
  const MatrixType rows_type = cholesky ? MatrixType::spd : an.type;
  if (workers <= 1 && plan_.factor_resident && (cholesky || an.type == MatrixType::general) &&
      !(dsolve_.rows_analysis == an.id && dsolve_.rows_type == rows_type))
    upload_solve_rows(an, an.tree.rows.data(), rows_type, nullptr);
  // the device solve's plan and its workspaces for one right-hand side, here at the
  // analysis as cuDSS's analysis phase prepares its solve, not in the first solve (the
  // plan's host pass over every front row is a large share of a first solve's time)
  if (workers <= 1 && plan_.factor_resident) {
    prepare_solve_plan(an);
    dsolve_.x.resize(std::max<std::size_t>(static_cast<std::size_t>(an.n), 1));
    dsolve_.u.resize(
        std::max<std::size_t>(static_cast<std::size_t>(dsolve_.u_offset_host.back()), 1));
    dsolve_.scratch.resize(std::max<std::size_t>(an.tree.rows.size(), 1));
    dsolve_.part.resize(
        std::max<std::size_t>(static_cast<std::size_t>(dsolve_.whole.plan.part_total), 1));
  }
  STRATA_CUDA(cudaStreamSynchronize(stream_));
}

bool CudaExecutor::reads_host_values() const {
  if (planned_ == 0 || parts_.empty()) return true;  // the plan made in begin_part may tile
  for (const auto& [id, part] : parts_)
    for (const char tiled : part.tiled)
      if (tiled) return true;  // assembled on the host (tiled_host.cpp)
  return false;
}

void CudaExecutor::begin(const numeric::FactorContext& ctx) {
  STRATA_CUDA(cudaSetDevice(device_));
  whole_ = false;  // until begin_part says which part: no resident factor from no part
  const Analysis& an = *ctx.analysis;
  bytes_h2d_ = bytes_d2h_ = 0;
  chunks_ = fused_chunks_ = tiled_.count = tiled_.prefetched = 0;
  lu_.fronts = lu_.fronts_pivoted = lu_.fronts_batched = 0;
  phases_ = FactorStats::DevicePhases{};
  held_parts_.clear();
  ++factorization_count_;  // the panels change: the solve's tile inverses are stale
  dsolve_.resident_for = nullptr;
  dsolve_.part_rows_current = false;
  pending_ = nullptr;  // a chunk left by a factorization that failed
  // strips of another executor's front still in flight (its factorization failed before
  // its end_part): they write into this pool
  if (team_.helped) {
    STRATA_CUDA(cudaStreamSynchronize(help_lane().stream));
    STRATA_CUDA(cudaStreamSynchronize(team_.dist_copy));
  }
  team_.helped = false;
  team_.members.clear();
  team_.used.clear();
  team_.fronts_split = team_.strips_helped = team_.fronts_distributed = 0;
  team_.help_bytes = 0;
  if (an.id != analysis_id_) {
    const Timer setup;
    upload_analysis(an);
    phases_.setup += setup.seconds();
  }
  STRATA_CUDA(cudaEventRecord(start_, stream_));
  if (ctx.values_on_device) {
    if (value_pass_.analysis != an.id)
      throw InternalError("values on the device from no value pass of this analysis");
    count_h2d(an.pattern_indices.size() * sizeof(double));  // copied by the value pass
    return;  // scale_values_on_device left them in values_
  }
  const std::size_t nnz = an.pattern_indices.size();
  if (ctx.device_values) {
    // already on a GPU (a distributed rank's share, or another GPU's value pass): device to
    // device, over NVLink or PCIe when that GPU is another (explicit devices: no peer
    // access needed); nothing to copy when they are this executor's own value pass's
    if (ctx.device_values == values_.data() && ctx.device_values_device == device_) {
      count_h2d(nnz * sizeof(double));  // copied by the value pass
      return;
    }
    values_.resize(std::max<std::size_t>(nnz, 1));
    if (nnz > 0)
      STRATA_CUDA(cudaMemcpyPeerAsync(values_.data(), device_, ctx.device_values,
                                      ctx.device_values_device, nnz * sizeof(double), stream_));
    return;
  }
  values_.upload(ctx.values, nnz, stream_);
  count_h2d(nnz * sizeof(double));
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

void CudaExecutor::download_panels(const Analysis& an, int part, numeric::NumericFactor& fac) {
  STRATA_CUDA(cudaSetDevice(device_));
  if (fac.panels.size() != an.factor_layout.total)
    throw InternalError("download_panels: the host factor is not sized for this analysis");
  if (part == -1) {  // the resident factor of the whole tree
    if (!keep_resident() || dsolve_.resident_for != &fac || dsolve_.resident_analysis != an.id)
      throw InvalidState("download_panels: the device holds no factor for this analysis");
    STRATA_CUDA(cudaMemcpyAsync(fac.panels.data(), panels_.data(),
                                sizeof(double) * an.factor_layout.total, cudaMemcpyDeviceToHost,
                                stream_));
    STRATA_CUDA(cudaStreamSynchronize(stream_));
    return;
  }
  // a part of a multi-GPU split: its buffer, front by front
  if (an.id != analysis_id_ ||
      std::find(held_parts_.begin(), held_parts_.end(), part) == held_parts_.end())
    throw InvalidState("download_panels: the device holds no panels of part " +
                       std::to_string(part) + " for this analysis");
  const bool lu = !an.symmetric;
  const PartDevice& pd = parts_.at(part);
  // through pinned memory (a pageable buffer made the first host solve after a multi-GPU
  // factorization several times slower than copying the panels back during the
  // factorization); a pageable one when pinned memory cannot be had
  std::vector<double> pageable;
  double* host = nullptr;
  try {
    host_staging_.resize(pd.panel_total);
    host = host_staging_.data();
  } catch (const OutOfMemory&) {
    pageable.resize(pd.panel_total);
    host = pageable.data();
  }
  STRATA_CUDA(cudaMemcpy(host, part_panels_.at(part).data(), sizeof(double) * pd.panel_total,
                         cudaMemcpyDeviceToHost));
  for (std::size_t q = 0; q < pd.fronts_host.size(); ++q) {
    const index_t f = pd.fronts_host[q];
    std::memcpy(fac.panels.data() + an.factor_layout.panel_offset[f], host + pd.panel_off_host[q],
                sizeof(double) * panel_size(an.tree, f, lu));
  }
}

namespace {

// Page-locked transfer buffers (TransferMemory): portable (every GPU of the process copies
// to and from them at the full rate), each with its size in a 64-byte header so that the
// process's total can be kept; none while that total would pass a quarter of the host
// memory available (base/host_memory.hpp): the rest of the process still needs pageable
// memory, and a block that gets none is allocated by new[] instead.
constexpr std::size_t kTransferHeader = 64 / sizeof(double);
std::atomic<std::size_t> g_transfer_pinned{0};

double* allocate_transfer(std::size_t doubles) {
  const std::size_t bytes = (doubles + kTransferHeader) * sizeof(double);
  const std::size_t avail = available_host_memory();
  if (avail > 0 && g_transfer_pinned.load() + bytes > avail / 4) return nullptr;
  void* p = nullptr;
  if (cudaHostAlloc(&p, bytes, cudaHostAllocPortable) != cudaSuccess) {
    (void)cudaGetLastError();
    return nullptr;
  }
  g_transfer_pinned += bytes;
  *static_cast<std::size_t*>(p) = bytes;
  return static_cast<double*>(p) + kTransferHeader;
}

void release_transfer(double* p) {
  double* base = p - kTransferHeader;
  g_transfer_pinned -= *reinterpret_cast<std::size_t*>(base);
  cudaFreeHost(base);
}

}  // namespace

numeric::TransferMemory CudaExecutor::transfer_memory() const {
  return {&allocate_transfer, &release_transfer};
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
    // the box is kept from one factorization to the next: after the last push out of it
    if (const auto l = landing_.find(t.front); l != landing_.end() && l->second.ready)
      STRATA_CUDA(cudaStreamWaitEvent(stream_, l->second.ready, 0));
    STRATA_CUDA(cudaMemcpyAsync(box.data(), src, bytes, cudaMemcpyDefault, stream_));
    STRATA_CUDA(cudaStreamSynchronize(stream_));
    t.device = box.data();
    t.device_ordinal = device_;
    t.on_host = false;
    t.device_ready = nullptr;
    // another GPU's block: on its way to that GPU now, while it still works
    if (peer && push_block(t)) return bytes;
    return 0;  // nothing crossed the bus yet: the importer counts the copy
  }
  STRATA_CUDA(cudaMemcpyAsync(t.host_buffer(), src, bytes, cudaMemcpyDefault, stream_));
  STRATA_CUDA(cudaStreamSynchronize(stream_));
  t.on_host = true;
  bytes_d2h_ += bytes;
  return bytes;
}

// A block for another GPU, pushed by its exporter (export_cb) into a buffer on the
// importing GPU as soon as it is made, instead of being pulled by the importer once it
// needs it: the importer is often still busy with its own parts then, and a large block
// takes milliseconds to cross the link, which the importer would otherwise wait for
// before its next part. The copy runs on this GPU's push stream from the outbox (the arena
// is reused by the next part at once) and records `ready`, which the importer's stream
// waits for. Not with a device memory budget (the plan does not hold the buffer) or where
// the importer has too little free memory for it; false then, and the importer pulls the
// block.
bool CudaExecutor::push_block(numeric::CbTransfer& t) {
  if (limit_ != 0 || t.size == 0) return false;
  const std::size_t bytes = sizeof(double) * t.size;
  Landing& l = landing_[t.front];
  if (l.device >= 0 && l.device != t.target_device) {  // another importer now: a new buffer
    if (l.ready) STRATA_CUDA(cudaEventSynchronize(l.ready));
    STRATA_CUDA(cudaSetDevice(l.device));
    l.buffer.clear();
    STRATA_CUDA(cudaSetDevice(device_));
    l.device = -1;
  }
  if (l.ready) STRATA_CUDA(cudaEventSynchronize(l.ready));  // the previous push into it
  if (l.buffer.size() < t.size) {
    STRATA_CUDA(cudaSetDevice(t.target_device));
    std::size_t free_bytes = 0, total = 0;
    STRATA_CUDA(cudaMemGetInfo(&free_bytes, &total));
    bool room = free_bytes > bytes + total / 8;  // leave the importer's plan its margin
    if (room) {
      try {
        l.buffer.resize(t.size);
      } catch (const OutOfMemory&) {
        room = false;
      }
    }
    STRATA_CUDA(cudaSetDevice(device_));
    if (!room) return false;
  }
  l.device = t.target_device;
  if (!l.ready) STRATA_CUDA(cudaEventCreateWithFlags(&l.ready, cudaEventDisableTiming));
  const cudaError_t e = cudaDeviceEnablePeerAccess(t.target_device, 0);
  if (e == cudaErrorPeerAccessAlreadyEnabled)
    (void)cudaGetLastError();
  else
    STRATA_CUDA(e);
  STRATA_CUDA(cudaMemcpyPeerAsync(l.buffer.data(), t.target_device, t.device, device_, bytes,
                                  push_stream_));
  STRATA_CUDA(cudaEventRecord(l.ready, push_stream_));
  t.device = l.buffer.data();
  t.device_ordinal = t.target_device;
  t.device_ready = l.ready;
  return true;
}

void CudaExecutor::drop_landings() noexcept {
  for (auto& [front, l] : landing_) {
    if (l.ready) {
      cudaEventSynchronize(l.ready);
      cudaEventDestroy(l.ready);
    }
    if (l.device >= 0) {
      cudaSetDevice(l.device);
      l.buffer.clear();
    }
  }
  landing_.clear();
  cudaSetDevice(device_);
}

std::size_t CudaExecutor::import_cb(const numeric::FactorContext& ctx,
                                    const numeric::CbTransfer& t) {
  STRATA_CUDA(cudaSetDevice(device_));
  double* dst = cur_->cb_ptr_host[t.front];
  const std::size_t bytes = sizeof(double) * t.size;
  const bool dst_on_device = dst >= arena_.data() && dst < arena_.data() + arena_.size();
  if (!t.on_host && t.device_ready)  // pushed here: once its copy is done
    STRATA_CUDA(cudaStreamWaitEvent(stream_, static_cast<cudaEvent_t>(t.device_ready), 0));
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
  const bool rows_current = dsolve_.rows_analysis == ctx.analysis->id &&
                            dsolve_.rows_type == MatrixType::spd && ctx.type == MatrixType::spd;
  if (keep_resident() && rows_current) {
    dsolve_.resident_for = ctx.factor;
    dsolve_.resident_analysis = ctx.analysis->id;
  } else if (keep_resident()) {
    const Timer setup;
    upload_solve_rows(*ctx.analysis, ctx.factor->rows.data(), ctx.type, ctx.factor);
    dsolve_.resident_for = ctx.factor;
    dsolve_.resident_analysis = ctx.analysis->id;
    phases_.setup += setup.seconds();
  }
}

void CudaExecutor::upload_solve_rows(const Analysis& an, const index_t* factor_rows,
                                     MatrixType type, const numeric::NumericFactor* fac) {
  const auto& t = an.tree;
  // LU: a front's local permutation moves its pivot rows only (factor_front_lu), so once
  // this analysis' arrays are on the device only the pivot rows of the fronts whose pivots
  // moved since are sent, packed into one copy and scattered on the device, with the two
  // n-long pivot arrays: sending all the rows (Σ m over the fronts), or one copy per
  // moved front, costs a large share of a multibody refactorization (thousands of small
  // fronts that pivot).
  if (type == MatrixType::general && dsolve_.rows_analysis == an.id &&
      dsolve_.rows_type == MatrixType::general && dsolve_.rows_host.size() == t.rows.size() &&
      dsolve_.rows_moved.size() == static_cast<std::size_t>(t.n_fronts())) {
    std::vector<std::int64_t> packed, seg;  // seg: destination, length, offset in packed
    for (index_t f = 0; f < t.n_fronts(); ++f) {
      if (!dsolve_.rows_moved[f]) continue;  // finish_front compared its rows
      dsolve_.rows_moved[f] = 0;
      const index_t fp = t.first_pivot[f], k = t.n_pivots(f), ro = t.row_offsets[f];
      const index_t* prow = factor_rows + ro;
      std::int64_t* held = dsolve_.rows_host.data() + ro;
      if (std::equal(prow, prow + k, held)) continue;
      seg.insert(seg.end(), {ro, k, static_cast<std::int64_t>(packed.size())});
      packed.insert(packed.end(), prow, prow + k);
      for (index_t i = 0; i < k; ++i) {
        held[i] = prow[i];
        dsolve_.pivot_pos_host[prow[i]] = i;
        dsolve_.pivot_row_host[fp + i] = prow[i];
      }
    }
    if (seg.empty()) return;
    upload(dsolve_.moved_rows, packed);
    upload(dsolve_.moved_segments, seg);
    launch_scatter_segments(dsolve_.moved_segments.data(),
                            static_cast<std::int64_t>(seg.size() / 3), dsolve_.moved_rows.data(),
                            dsolve_.rows.data(), stream_);
    upload(dsolve_.pivot_pos, dsolve_.pivot_pos_host);
    upload(dsolve_.pivot_row, dsolve_.pivot_row_host);
    STRATA_CUDA(cudaStreamSynchronize(stream_));  // the copies read the host arrays
    return;
  }
  // what the device solve needs besides the panels: the factored row order, where each
  // pivot went in its front (LU, LDLᵀ), and D (LDLᵀ)
  dsolve_.rows_host.assign(factor_rows, factor_rows + t.rows.size());
  dsolve_.rows_moved.assign(type == MatrixType::general ? t.n_fronts() : 0, 0);
  dsolve_.pivot_pos_host.assign(an.n, 0);
  dsolve_.pivot_row_host.assign(an.n, 0);
  for (index_t f = 0; f < t.n_fronts(); ++f) {
    const index_t fp = t.first_pivot[f];
    const index_t* prow = factor_rows + t.row_offsets[f];
    for (index_t i = 0; i < t.n_pivots(f); ++i) {
      dsolve_.pivot_pos_host[prow[i]] =
          i;  // prow[i] is a pivot of this front: fp ≤ prow[i] < fp + k
      dsolve_.pivot_row_host[fp + i] = prow[i];
    }
  }
  upload(dsolve_.rows, dsolve_.rows_host);
  upload(dsolve_.pivot_pos, dsolve_.pivot_pos_host);
  upload(dsolve_.pivot_row, dsolve_.pivot_row_host);
  if (type == MatrixType::symmetric_indefinite) {
    upload(dsolve_.d_diag, fac->d_diag);
    upload(dsolve_.d_off, fac->d_off);
    upload(dsolve_.pivot_size, fac->pivot_size);
  }
  STRATA_CUDA(cudaStreamSynchronize(stream_));
  dsolve_.rows_analysis = an.id;
  dsolve_.rows_type = type;
}

void CudaExecutor::report(FactorStats& fs) const {
  fs.device_seconds = device_seconds_;
  fs.bytes_to_device = bytes_h2d_;
  fs.bytes_to_host = bytes_d2h_;
  fs.device_batches = chunks_;
  fs.device_fused_batches = fused_chunks_;
  fs.tiled_fronts = tiled_.count;
  fs.tiled_fronts_prefetched = tiled_.prefetched;
  fs.lu_large_fronts = lu_.fronts;
  fs.lu_large_fronts_pivoted = lu_.fronts_pivoted;
  fs.lu_large_fronts_batched = lu_.fronts_batched;
  fs.device_budget = plan_.budget;
  fs.device_pool_bytes = plan_.pool * sizeof(double);
  fs.device_working_bytes = (pool_.size() + arena_.size() + panels_.size()) * sizeof(double);
  fs.host_pinned_bytes = plan_.host_pinned;
  fs.contribution_blocks_on_host = plan_.arena_on_host;
  fs.factor_resident = keep_resident();
  fs.device_phases = phases_;
}

}  // namespace strata::cuda
