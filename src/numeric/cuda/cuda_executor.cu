// strata — the CUDA executor: level-batched multifrontal factorization on one GPU, with
// any amount of device memory.
//
// Per batch of the memory plan (fronts of one level, DESIGN.md §2), cut further into
// chunks whose fronts fit the device pool:
//   1. one launch assembles every front of the chunk in the pool (zero, scatter original
//      entries, extend-add children's contribution blocks);
//   2. one launch factors all small fronts (one thread block each); large fronts go to
//      cuSOLVER POTRF + cuBLAS TRSM/SYRK (LLᵀ), a blocked LU with our panel kernel and
//      cuBLAS TRSM/GEMM, or a blocked Bunch–Kaufman LDLᵀ with our panel kernel and cuBLAS
//      SYRKX (kernels_ldlt.cuh), all with pivoting restricted to the fully summed rows
//      and the CPU backend's static pivoting;
//   3. one launch stores the contribution blocks where the plan put them;
//   4. one launch packs the chunk's factor panels (contiguous in the factor layout) into
//      the device factor, which is copied to the host factor in one transfer.
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
#include <algorithm>
#include <cmath>
#include <cstring>

#include "numeric/cuda/cuda_executor.hpp"

namespace strata::cuda {

[[noreturn]] void throw_cuda(cudaError_t e, const char* call, const char* file, int line) {
  if (e == cudaErrorMemoryAllocation)
    throw OutOfMemory(0, std::string(call) + " at " + file + ":" + std::to_string(line));
  throw DeviceError(std::string(call) + " failed at " + file + ":" + std::to_string(line) + ": " +
                    cudaGetErrorName(e) + " (" + cudaGetErrorString(e) + ")");
}
[[noreturn]] void throw_cublas(cublasStatus_t s, const char* call, const char* file, int line) {
  throw DeviceError(std::string(call) + " failed at " + file + ":" + std::to_string(line) + ": " +
                    cublasGetStatusName(s) + " (" + cublasGetStatusString(s) + ")");
}
[[noreturn]] void throw_cusolver(cusolverStatus_t s, const char* call, const char* file, int line) {
  throw DeviceError(std::string(call) + " failed at " + file + ":" + std::to_string(line) +
                    ": cusolver status " + std::to_string(static_cast<int>(s)));
}

namespace {
constexpr std::int64_t kSmallFront = 256;  // fronts up to this many rows: one block each
constexpr std::int64_t kLuPanel = 64;      // panel width of the blocked LU of large fronts
constexpr std::int64_t kMinSlab = 16;      // narrowest slab worth a library call
}  // namespace

CudaExecutor::CudaExecutor(const Options& o, int device)
    : device_(device), limit_(o.device_memory_limit) {
  STRATA_CUDA(cudaSetDevice(device_));
  STRATA_CUDA(cudaStreamCreate(&stream_));
  STRATA_CUBLAS(cublasCreate(&blas_));
  STRATA_CUBLAS(cublasSetStream(blas_, stream_));
  STRATA_CUSOLVER(cusolverDnCreate(&solver_));
  STRATA_CUSOLVER(cusolverDnSetStream(solver_, stream_));
  STRATA_CUDA(cudaEventCreate(&start_));
  STRATA_CUDA(cudaEventCreate(&stop_));
}

CudaExecutor::~CudaExecutor() {
  cudaSetDevice(device_);
  cudaEventDestroy(start_);
  cudaEventDestroy(stop_);
  cusolverDnDestroy(solver_);
  cublasDestroy(blas_);
  cudaStreamDestroy(stream_);
}

void CudaExecutor::begin(const numeric::FactorContext& ctx) {
  STRATA_CUDA(cudaSetDevice(device_));
  const Analysis& an = *ctx.analysis;
  bytes_h2d_ = bytes_d2h_ = 0;
  chunks_ = tiled_count_ = 0;
  resident_for_ = nullptr;
  if (an.id != analysis_id_) upload_analysis(an);
  STRATA_CUDA(cudaEventRecord(start_, stream_));
  values_.upload(ctx.values, an.pattern_indices.size(), stream_);
  count_h2d(an.pattern_indices.size() * sizeof(double));
}

void CudaExecutor::end(const numeric::FactorContext& ctx) {
  STRATA_CUDA(cudaEventRecord(stop_, stream_));
  STRATA_CUDA(cudaEventSynchronize(stop_));
  float ms = 0;
  STRATA_CUDA(cudaEventElapsedTime(&ms, start_, stop_));
  device_seconds_ = ms * 1e-3;
  if (plan_.factor_resident) {
    const Analysis& an = *ctx.analysis;
    const numeric::NumericFactor& fac = *ctx.factor;
    const auto& t = an.tree;
    // what the device solve needs besides the panels: the factored row order, where
    // each pivot went in its front (LU, LDLᵀ), and D (LDLᵀ)
    std::vector<std::int64_t> rows(fac.rows.begin(), fac.rows.end());
    std::vector<std::int64_t> pivot_pos(an.n), pivot_row(an.n);
    for (index_t f = 0; f < t.n_fronts(); ++f) {
      const index_t fp = t.first_pivot[f];
      const index_t* prow = fac.rows.data() + t.row_offsets[f];
      for (index_t i = 0; i < t.n_pivots(f); ++i) {
        pivot_pos[prow[i]] = i;  // prow[i] is a pivot of this front: fp ≤ prow[i] < fp + k
        pivot_row[fp + i] = prow[i];
      }
    }
    upload(s_rows_, rows);
    upload(s_pivot_pos_, pivot_pos);
    upload(s_pivot_row_, pivot_row);
    if (ctx.type == MatrixType::symmetric_indefinite) {
      upload(s_d_diag_, fac.d_diag);
      upload(s_d_off_, fac.d_off);
      upload(s_pivot_size_, fac.pivot_size);
    }
    STRATA_CUDA(cudaStreamSynchronize(stream_));
    resident_for_ = ctx.factor;
    resident_analysis_ = an.id;
  }
}

void CudaExecutor::report(FactorStats& fs) const {
  fs.device_seconds = device_seconds_;
  fs.bytes_to_device = bytes_h2d_;
  fs.bytes_to_host = bytes_d2h_;
  fs.device_batches = chunks_;
  fs.tiled_fronts = tiled_count_;
  fs.device_budget = plan_.budget;
  fs.contribution_blocks_on_host = plan_.arena_on_host;
  fs.factor_resident = plan_.factor_resident;
}

// Decides what lives where (see the file header) and lays out the chunks: positions
// [p, chunk_end_[p]) of one batch share the pool; tiled_[p] marks a front factored by
// slabs.
void CudaExecutor::plan_device_memory(const Analysis& an) {
  const auto& t = an.tree;
  const auto& s = an.schedule;
  const bool lu = !an.symmetric;
  std::size_t free_b = 0, total_b = 0;
  STRATA_CUDA(cudaMemGetInfo(&free_b, &total_b));
  DevicePlan p;
  p.budget = limit_ > 0 ? limit_ : static_cast<std::size_t>(0.9 * static_cast<double>(free_b));
  const std::size_t budget_d = p.budget / sizeof(double);
  auto sq = [](index_t m) { return static_cast<std::size_t>(m) * static_cast<std::size_t>(m); };

  // pool: the largest batch of fronts that are not tiled, capped (without a user limit)
  // at half the budget so that the arena and the factor have room
  std::size_t cap = limit_ > 0 ? budget_d : budget_d / 2;
  tiled_.assign(s.fronts.size(), 0);
  std::size_t pool = 0;
  index_t tiled_rows = 0;
  for (const BatchInfo& b : an.plan.batches) {
    std::size_t sum = 0;
    for (index_t q = b.begin; q < b.end; ++q) {
      const index_t f = s.fronts[q];
      if (b.tiled || sq(t.n_rows(f)) > cap) {
        tiled_[q] = 1;
        tiled_rows = std::max(tiled_rows, t.n_rows(f));
      } else {
        sum += sq(t.n_rows(f));
      }
    }
    pool = std::max(pool, std::min(sum, cap));
  }
  // a tiled front needs a slab and a column block of at least kMinSlab columns
  if (tiled_rows > 0)
    pool = std::max<std::size_t>(pool, 2 * static_cast<std::size_t>(tiled_rows) * kMinSlab);
  if (limit_ > 0 && pool > budget_d)
    throw OutOfMemory(pool * sizeof(double),
                      "the device pool for the largest front (device_memory_limit is " +
                          std::to_string(limit_) + " bytes)");
  p.pool = std::max<std::size_t>(pool, 1);
  // chunks: consecutive non-tiled positions of a batch whose fronts fit the pool
  pos_offset_host_.assign(s.fronts.size(), 0);
  chunk_end_.assign(s.fronts.size(), 0);
  for (const BatchInfo& b : an.plan.batches) {
    index_t start = b.begin;
    std::size_t off = 0;
    for (index_t q = b.begin; q <= b.end; ++q) {
      const bool flush = q == b.end || tiled_[q] || off + sq(t.n_rows(s.fronts[q])) > p.pool;
      if (flush && q > start) {
        chunk_end_[start] = q;
        start = q;
        off = 0;
      }
      if (q == b.end) break;
      if (tiled_[q]) {
        start = q + 1;
        continue;
      }
      pos_offset_host_[q] = static_cast<std::int64_t>(off);
      off += sq(t.n_rows(s.fronts[q]));
    }
  }
  // arena, then the resident factor, in what the pool leaves
  const std::size_t rest = budget_d > p.pool ? budget_d - p.pool : 0;
  const std::size_t arena = an.cb_layout.arena_size, factor = an.factor_layout.total;
  if (rest >= arena + factor) {
    p.arena_device = arena;
    p.factor_resident = true;
  } else {
    p.arena_device = std::min(arena, rest);
  }
  p.arena_on_host = p.arena_device < arena;
  (void)lu;
  plan_ = p;
}

void CudaExecutor::upload_analysis(const Analysis& an) {
  const auto& t = an.tree;
  const auto& s = an.schedule;
  const index_t nf = t.n_fronts();
  // free what the previous analysis held before measuring free memory
  for (auto* b : {&pool_, &arena_, &panels_, &values_}) b->clear();
  host_arena_.clear();
  analysis_id_ = 0;
  std::vector<std::int64_t> n_rows(nf), n_piv(nf);
  for (index_t f = 0; f < nf; ++f) {
    n_rows[f] = t.n_rows(f);
    n_piv[f] = t.n_pivots(f);
  }
  // relative positions of each child's contribution rows in its parent
  std::vector<std::int64_t> rel_off(nf + 1, 0), rel;
  std::vector<index_t> position(an.n, -1);
  for (index_t f = 0; f < nf; ++f) rel_off[f + 1] = rel_off[f] + t.cb_size(f);
  rel.resize(rel_off[nf]);
  for (index_t f = 0; f < nf; ++f) {
    const index_t* rows = t.rows_of(f);
    for (index_t i = 0; i < t.n_rows(f); ++i) position[rows[i]] = i;
    for (index_t q = t.child_offsets[f]; q < t.child_offsets[f + 1]; ++q) {
      const index_t c = t.children[q];
      const index_t* crow = t.rows_of(c) + t.n_pivots(c);
      for (index_t i = 0; i < t.cb_size(c); ++i) rel[rel_off[c] + i] = position[crow[i]];
    }
    for (index_t i = 0; i < t.n_rows(f); ++i) position[rows[i]] = -1;
  }
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

  plan_device_memory(an);
  upload(pos_offset_, pos_offset_host_);
  pool_.resize(plan_.pool);
  arena_.resize(std::max<std::size_t>(plan_.arena_device, 1));
  if (plan_.arena_on_host) host_arena_.resize(std::max<std::size_t>(an.cb_layout.arena_size, 1));
  // staging for the panels of one chunk, or the whole resident factor
  std::size_t chunk_panels = 1;
  for (index_t q = 0; q < static_cast<index_t>(s.fronts.size()); ++q)
    if (!tiled_[q] && chunk_end_[q] > q) {
      std::size_t sum = 0;
      for (index_t r = q; r < chunk_end_[q]; ++r) sum += panel_size(t, s.fronts[r], !an.symmetric);
      chunk_panels = std::max(chunk_panels, sum);
    }
  panels_.resize(plan_.factor_resident ? std::max<std::size_t>(an.factor_layout.total, 1)
                                       : chunk_panels);
  host_staging_.resize(chunk_panels);
  // where each contribution block lives
  cb_ptr_host_.assign(nf, nullptr);
  for (index_t f = 0; f < nf; ++f) {
    const std::size_t cb = static_cast<std::size_t>(t.cb_size(f));
    if (cb == 0 || t.parent[f] < 0) continue;
    const std::size_t off = an.cb_layout.cb_offset[f];
    cb_ptr_host_[f] =
        off + cb * cb <= plan_.arena_device ? arena_.data() + off : host_arena_.data() + off;
  }
  upload(cb_ptr_, cb_ptr_host_);
  tree_ = DeviceTree{fronts_.data(),    pos_offset_.data(), n_rows_.data(),
                     n_pivots_.data(),  parent_.data(),     entry_offsets_.data(),
                     entry_src_.data(), entry_dst_.data(),  child_offsets_.data(),
                     children_.data(),  cb_ptr_.data(),     rel_offsets_.data(),
                     rel_.data()};
  STRATA_CUDA(cudaStreamSynchronize(stream_));
  analysis_id_ = an.id;
}

void CudaExecutor::factor_batch(const numeric::FactorContext& ctx, const BatchInfo& b) {
  for (index_t q = b.begin; q < b.end;) {
    if (tiled_[q]) {
      factor_tiled(ctx, q);
      ++q;
    } else {
      factor_chunk(ctx, q, chunk_end_[q]);
      q = chunk_end_[q];
    }
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
  const auto& s = an.schedule;
  const bool lu = ctx.type == MatrixType::general;
  const bool ldlt = ctx.type == MatrixType::symmetric_indefinite;
  const std::int64_t count = end - begin;
  ++chunks_;
  launch_assemble(tree_, begin, count, values_.data(), pool_.data(), !lu, stream_);

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
    launch_ldlt_small(tree_, small_pos_.data(), static_cast<std::int64_t>(ns), pool_.data(),
                      ctx.static_pivot, perturbed_.data(), perm_.data(), pivot_size_.data(),
                      perm_offset_.data(), stream_);
  else
    launch_factor_small(tree_, small_pos_.data(), static_cast<std::int64_t>(ns), pool_.data(), lu,
                        ctx.static_pivot, info_.data(), perturbed_.data(), perm_.data(),
                        perm_offset_.data(), stream_);

  // large fronts: library calls, one front after another on the stream
  const double one = 1.0, minus_one = -1.0;
  std::int64_t perm_at = perm_off.back();
  std::vector<std::int64_t> big_perm_at;
  for (std::size_t i = 0; i < big.size(); ++i) {
    const index_t p = big[i], f = s.fronts[p];
    const int m = static_cast<int>(t.n_rows(f)), k = static_cast<int>(t.n_pivots(f));
    double* F = pool_.data() + pos_offset_host_[p];
    big_perm_at.push_back(perm_at);
    if (ldlt) {
      ldlt_large_.factor(blas_, stream_, F, m, k, ctx.static_pivot, perm_.data() + perm_at,
                         pivot_size_.data() + perm_at, perturbed_.data() + ns + i);
    } else if (!lu) {
      grow_potrf_work(solver_, potrf_work_, F, k, m);
      STRATA_CUSOLVER(cusolverDnDpotrf(solver_, CUBLAS_FILL_MODE_LOWER, k, F, m, potrf_work_.data(),
                                       static_cast<int>(potrf_work_.size()),
                                       potrf_info_.data() + i));
      if (m > k) {
        STRATA_CUBLAS(cublasDtrsm(blas_, CUBLAS_SIDE_RIGHT, CUBLAS_FILL_MODE_LOWER, CUBLAS_OP_T,
                                  CUBLAS_DIAG_NON_UNIT, m - k, k, &one, F, m, F + k, m));
        STRATA_CUBLAS(cublasDsyrk(blas_, CUBLAS_FILL_MODE_LOWER, CUBLAS_OP_N, m - k, k, &minus_one,
                                  F + k, m, &one, F + static_cast<std::size_t>(k) * m + k, m));
      }
    } else {
      // iota_ outlives the asynchronous copy (it is a member, only ever grown)
      if (static_cast<int>(iota_.size()) < k) {
        STRATA_CUDA(cudaStreamSynchronize(stream_));
        iota_.resize(k);
        for (int r = 0; r < k; ++r) iota_[r] = r;
      }
      STRATA_CUDA(cudaMemcpyAsync(perm_.data() + perm_at, iota_.data(), sizeof(std::int64_t) * k,
                                  cudaMemcpyHostToDevice, stream_));
      STRATA_CUDA(cudaMemsetAsync(perturbed_.data() + ns + i, 0, sizeof(std::int64_t), stream_));
      for (int p0 = 0; p0 < k; p0 += kLuPanel) {
        const int w = std::min<int>(kLuPanel, k - p0), rest = m - p0 - w;
        launch_lu_panel(F, m, k, p0, w, ctx.static_pivot, perm_.data() + perm_at,
                        perturbed_.data() + ns + i, stream_);
        if (rest > 0) {
          double* a11 = F + static_cast<std::size_t>(p0) * m + p0;
          double* a12 = F + static_cast<std::size_t>(p0 + w) * m + p0;
          STRATA_CUBLAS(cublasDtrsm(blas_, CUBLAS_SIDE_LEFT, CUBLAS_FILL_MODE_LOWER, CUBLAS_OP_N,
                                    CUBLAS_DIAG_UNIT, w, rest, &one, a11, m, a12, m));
          STRATA_CUBLAS(cublasDgemm(blas_, CUBLAS_OP_N, CUBLAS_OP_N, rest, rest, w, &minus_one,
                                    a11 + w, m, a12, m, &one, a12 + w, m));
        }
      }
    }
    perm_at += k;
  }
  launch_store_cb(tree_, begin, count, pool_.data(), !lu, stream_);

  // factor panels: packed into the device factor (resident) or the chunk's staging
  // area, then to the host in one copy
  const std::size_t base = an.factor_layout.panel_offset[s.fronts[begin]];
  std::vector<std::int64_t> stage_off(count);
  std::size_t total = 0;
  for (std::int64_t i = 0; i < count; ++i) {
    const index_t f = s.fronts[begin + i];
    stage_off[i] = static_cast<std::int64_t>(an.factor_layout.panel_offset[f] -
                                             (plan_.factor_resident ? 0 : base));
    total += panel_size(t, f, lu);
  }
  upload(stage_offset_, stage_off);
  launch_pack_panels(tree_, begin, count, pool_.data(), stage_offset_.data(), panels_.data(), lu,
                     stream_);
  copy_panels_back(ctx, begin, end);
  const std::size_t nall = ns + big.size();
  std::vector<std::int64_t> info(nall), perturbed(nall), perm(perm_at);
  std::vector<int> pinfo(big.size()), psize(ldlt ? perm_at : 0);
  if (ns && !ldlt)
    STRATA_CUDA(
        cudaMemcpyAsync(info.data(), info_.data(), 8 * ns, cudaMemcpyDeviceToHost, stream_));
  if (nall)
    STRATA_CUDA(cudaMemcpyAsync(perturbed.data(), perturbed_.data(), 8 * nall,
                                cudaMemcpyDeviceToHost, stream_));
  if (perm_at)
    STRATA_CUDA(
        cudaMemcpyAsync(perm.data(), perm_.data(), 8 * perm_at, cudaMemcpyDeviceToHost, stream_));
  if (!big.empty() && !lu && !ldlt)
    STRATA_CUDA(cudaMemcpyAsync(pinfo.data(), potrf_info_.data(), sizeof(int) * big.size(),
                                cudaMemcpyDeviceToHost, stream_));
  if (ldlt && perm_at)
    STRATA_CUDA(cudaMemcpyAsync(psize.data(), pivot_size_.data(), sizeof(int) * perm_at,
                                cudaMemcpyDeviceToHost, stream_));
  STRATA_CUDA(cudaStreamSynchronize(stream_));
  (void)total;
  if (ldlt) {  // D out of the panels, pivot sizes, rows: the CPU executor's code; statistics
    std::vector<std::int64_t> psize_at(count);
    for (std::size_t i = 0; i < nall; ++i) {
      const index_t p = i < ns ? small[i] : big[i - ns], f = s.fronts[p];
      const std::int64_t at = i < ns ? perm_off[i] : big_perm_at[i - ns];
      psize_at[p - begin] = at;
      numeric::store_ldlt_front(an, f, perm.data() + at, psize.data() + at, *ctx.factor);
      numeric::cpu::PivotStats& ps = ctx.factor->front_stats[f];
      ps = numeric::cpu::PivotStats{};
      const index_t p0 = t.first_pivot[f];
      numeric::cpu::ldlt_stats_from_d(t.n_pivots(f), ctx.factor->d_diag.data() + p0,
                                      ctx.factor->d_off.data() + p0,
                                      ctx.factor->pivot_size.data() + p0, ps);
      ps.perturbed = perturbed[i];
    }
    if (plan_.factor_resident) {  // the device copy of the panels still holds D
      upload(psize_at_, psize_at);
      launch_ldlt_unit_panels(tree_, begin, count, stage_offset_.data(), pivot_size_.data(),
                              psize_at_.data(), panels_.data(), stream_);
    }
    return;
  }
  for (std::size_t i = 0; i < ns; ++i)
    finish_front(ctx, s.fronts[small[i]], lu ? -1 : info[i], perturbed[i],
                 perm.data() + perm_off[i]);
  for (std::size_t i = 0; i < big.size(); ++i)
    finish_front(ctx, s.fronts[big[i]], (!lu && pinfo[i] > 0) ? pinfo[i] - 1 : -1,
                 perturbed[ns + i], perm.data() + big_perm_at[i]);
}

// The panels of positions [begin, end) — contiguous in the factor layout — to the host
// factor through the pinned staging buffer.
void CudaExecutor::copy_panels_back(const numeric::FactorContext& ctx, index_t begin, index_t end) {
  const Analysis& an = *ctx.analysis;
  const auto& t = an.tree;
  const auto& s = an.schedule;
  const bool lu = !an.symmetric;
  const std::size_t base = an.factor_layout.panel_offset[s.fronts[begin]];
  const index_t last = s.fronts[end - 1];
  const std::size_t total = an.factor_layout.panel_offset[last] + panel_size(t, last, lu) - base;
  if (total == 0) return;
  const double* src = panels_.data() + (plan_.factor_resident ? base : 0);
  STRATA_CUDA(cudaMemcpyAsync(host_staging_.data(), src, sizeof(double) * total,
                              cudaMemcpyDeviceToHost, stream_));
  STRATA_CUDA(cudaStreamSynchronize(stream_));
  std::memcpy(ctx.factor->panels.data() + base, host_staging_.data(), sizeof(double) * total);
  bytes_d2h_ += sizeof(double) * total;
}

// Host bookkeeping of one factored front: failure, permuted rows, pivot statistics.
void CudaExecutor::finish_front(const numeric::FactorContext& ctx, index_t f, std::int64_t bad,
                                std::int64_t npert, const std::int64_t* lperm) {
  const Analysis& an = *ctx.analysis;
  const auto& t = an.tree;
  numeric::NumericFactor& fac = *ctx.factor;
  const bool lu = ctx.type == MatrixType::general;
  const index_t m = t.n_rows(f), k = t.n_pivots(f);
  const double* panel = fac.panels.data() + an.factor_layout.panel_offset[f];
  if (bad >= 0) throw NotPositiveDefinite(an.perm[t.first_pivot[f] + bad], std::nan(""));
  const index_t* rows = t.rows_of(f);
  index_t* frows = fac.rows.data() + t.row_offsets[f];
  numeric::cpu::PivotStats& ps = fac.front_stats[f];
  ps = numeric::cpu::PivotStats{};
  int sign = 1;
  for (index_t i = 0; i < k; ++i) {
    frows[i] = rows[lu ? lperm[i] : i];
    const double d = panel[i * m + i];
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

std::unique_ptr<Executor> make_cuda_executor(const Options& opts) {
  if (!cuda::device_present())
    throw NotSupported("the CUDA backend was asked for, but no CUDA GPU is visible");
  return std::make_unique<cuda::CudaExecutor>(opts);
}

}  // namespace strata::numeric
