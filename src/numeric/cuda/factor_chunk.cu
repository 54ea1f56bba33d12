// strata — one chunk of fronts on the GPU (steps 1–4 of cuda_executor.cu's header):
// the batch is walked chunk by chunk (a tiled front on its own, tiled_front.cu); a chunk
// is assembled in one launch, its small fronts factored in one launch, its large fronts
// on the lanes, its contribution blocks stored and its panels packed and copied back.
// The host bookkeeping of a chunk (pivot checks, LDLᵀ's D and pivot sizes, the
// statistics) runs while the next chunk computes (flush_chunk / finish_chunk).
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>

#include "base/alloc.hpp"
#include "base/host_copy.hpp"
#include "base/timer.hpp"
#include "numeric/cpu/dense_front.hpp"
#include "numeric/cuda/cuda_executor.hpp"

namespace strata::cuda {

namespace {
// Fronts in a chunk from which their host bookkeeping runs over the host's threads.
constexpr std::size_t kParallelFinishFronts = 64;
}  // namespace

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
  ++chunks_;
  ChunkRecord& rec = chunk_[slot_];
  slot_ ^= 1;
  rec.begin = begin;
  rec.end = end;
  rec.lu = ctx.type == MatrixType::general;
  rec.ldlt = ctx.type == MatrixType::symmetric_indefinite;
  rec.dev_only = device_only_ || part_device_only_;
  rec.max_rows = 0;
  for (index_t p = begin; p < end; ++p)
    rec.max_rows = std::max(rec.max_rows, t.n_rows(s.fronts[p]));
  const bool llt = !rec.lu && !rec.ldlt;
  rec.fused = fused_small_batches_ && (rec.lu || llt) && rec.dev_only &&
              rec.max_rows <= small_front_rows_ &&
              rec.max_rows <= (rec.lu ? lu_shared_max_rows() : llt_fused_max_rows());
  chunk_layout(ctx, rec);
  if (rec.fused) {
    factor_chunk_fused(ctx, rec);
    return;
  }
  STRATA_CUDA(cudaEventRecord(rec.ev[0], stream_));
  launch_assemble(cur_->tree, begin, end - begin, rec.max_rows, values_.data(), pool_.data(),
                  !rec.lu, stream_);
  STRATA_CUDA(cudaEventRecord(rec.ev[1], stream_));
  // a level's small and large fronts are independent: with both, the small fronts' kernel
  // runs on small_stream_ beside the large fronts' work, and the stores wait for both (the
  // large-front phase is then what they took beyond the small fronts' end)
  const bool side = !rec.small.empty() && !rec.big.empty();
  if (side) STRATA_CUDA(cudaStreamWaitEvent(small_stream_, rec.ev[1], 0));
  chunk_small_fronts(ctx, rec, side ? small_stream_ : stream_);
  chunk_large_fronts(ctx, rec, side ? rec.ev[1] : rec.ev[2]);
  if (side) STRATA_CUDA(cudaStreamWaitEvent(stream_, rec.ev[2], 0));
  STRATA_CUDA(cudaEventRecord(rec.ev[3], stream_));
  launch_store_cb(cur_->tree, begin, end - begin, rec.max_rows, pool_.data(), !rec.lu, stream_);
  chunk_pack_panels(ctx, rec);
  const bool packed = chunk_pack_results(rec);
  STRATA_CUDA(cudaEventRecord(rec.ev[4], stream_));
  if (packed) {  // one copy beside the next chunk's launches (see chunk_pack_results)
    STRATA_CUDA(cudaStreamWaitEvent(copy_stream_, rec.ev[4], 0));
    STRATA_CUDA(cudaMemcpyAsync(rec.packed.data(), packed_half(rec),
                                sizeof(std::int64_t) * rec.packed_words, cudaMemcpyDeviceToHost,
                                copy_stream_));
    STRATA_CUDA(cudaEventRecord(rec.ev[5], copy_stream_));
  } else {
    chunk_fetch_results(rec);
    STRATA_CUDA(cudaEventRecord(rec.ev[5], stream_));
  }
  // the previous chunk's host part, while the GPU runs this one; this one's waits when it
  // writes to the host factor (panels copied back, LDLᵀ): the next chunk's stores would
  // overwrite the staging area it reads
  flush_chunk(ctx);
  pending_ = &rec;
  if (rec.ldlt && !rec.dev_only) flush_chunk(ctx);
}

// A chunk of small LU or Cholesky fronts whose panels stay on the device, by one launch
// (launch_small_fused), its results (pivot checks, permutations, diagonals) written
// back to back into the record's half of packed_results_ and fetched by one copy instead
// of four, on copy_stream_: each copy has a latency of its own, and a chunk of the
// multibody matrices' lower levels computes for a few tens of microseconds, so the next
// chunk's launch does not wait for it. The half is not written again before this chunk's
// host part has waited for the copy (the record's next chunk comes after that). Timed
// from ev[1] to ev[2] (small fronts); ev[5] ends the copy.
void CudaExecutor::factor_chunk_fused(const numeric::FactorContext& ctx, ChunkRecord& rec) {
  ++fused_chunks_;
  double* const pack_to = chunk_panel_target(ctx);
  const std::size_t ns = rec.small.size(), np = static_cast<std::size_t>(rec.perm_total);
  const std::size_t nd = static_cast<std::size_t>(rec.diag_off.back());
  const std::size_t half = packed_results_.size() / 2;
  std::int64_t* const r = packed_half(rec);
  rec.packed_words = 0;  // the fused layout below (no POTRF infos or pivot sizes)
  if (2 * ns + np + nd > half)
    throw InternalError("factor_chunk_fused: the results buffer was not sized for this chunk");
  STRATA_CUDA(cudaEventRecord(rec.ev[1], stream_));
  launch_small_fused(cur_->tree, rec.lu, rec.small_pos, static_cast<std::int64_t>(ns), rec.max_rows,
                     values_.data(), ctx.static_pivot, ctx.diagonal_pivot_threshold, r, r + ns,
                     r + 2 * ns, rec.perm_offset, rec.stage_offset, pack_to, rec.diag_offset,
                     reinterpret_cast<double*>(r + 2 * ns + np), small_front_threads_, stream_);
  STRATA_CUDA(cudaEventRecord(rec.ev[2], stream_));
  rec.panels_async = false;
  const std::size_t words = 2 * ns + np + nd;
  STRATA_CUDA(cudaStreamWaitEvent(copy_stream_, rec.ev[2], 0));
  if (words)
    STRATA_CUDA(cudaMemcpyAsync(rec.packed.data(), r, sizeof(std::int64_t) * words,
                                cudaMemcpyDeviceToHost, copy_stream_));
  rec.info_at = rec.packed.data();
  rec.perturbed_at = rec.info_at + ns;
  rec.perm_at = rec.info_at + 2 * ns;
  rec.diag_at = reinterpret_cast<const double*>(rec.info_at + 2 * ns + np);
  STRATA_CUDA(cudaEventRecord(rec.ev[5], copy_stream_));
  flush_chunk(ctx);  // the previous chunk's host part, while the GPU runs this one
  pending_ = &rec;
}

// Step 2 for the small fronts (rec.small from chunk_layout, one thread block each, one
// launch for all), on stream s; ev[2] marks its end there.
void CudaExecutor::chunk_small_fronts(const numeric::FactorContext& ctx, ChunkRecord& rec,
                                      cudaStream_t s) {
  const std::size_t ns = rec.small.size(), nb = rec.big.size();
  info_.resize(ns + nb + 1);  // presized at planning: no allocation here
  perturbed_.resize(ns + nb + 1);
  perm_.resize(rec.perm_total + 1);
  potrf_info_.resize(nb + 1);
  pivot_size_.resize(rec.perm_total + 1);
  std::int64_t small_rows = 0;
  for (std::int64_t p : rec.small)
    small_rows = std::max<std::int64_t>(small_rows,
                                        ctx.analysis->tree.n_rows(ctx.part->schedule->fronts[p]));
  const DeviceTree& tree = cur_->tree;
  if (rec.ldlt)
    launch_ldlt_small(tree, rec.small_pos, static_cast<std::int64_t>(ns), pool_.data(),
                      ctx.static_pivot, perturbed_.data(), perm_.data(), pivot_size_.data(),
                      rec.perm_offset, s);
  else
    launch_factor_small(tree, rec.small_pos, static_cast<std::int64_t>(ns), small_rows,
                        pool_.data(), rec.lu, ctx.static_pivot, ctx.diagonal_pivot_threshold,
                        info_.data(), perturbed_.data(), perm_.data(), rec.perm_offset,
                        small_front_threads_, s);
  STRATA_CUDA(cudaEventRecord(rec.ev[2], s));
}

// The chunk's layout: its fronts split into small ones (rec.small) and large ones
// (rec.big), the pivot permutations laid out (small fronts first, then the large ones in
// order), each position's panel offset in chunk_panel_target's buffer (the device factor,
// the part's own buffer, or the staging area in chunk order; rec.panels_total doubles in
// all) and each front's first diagonal slot (rec.diag_off). Made once per plan and what it
// depends on (`key`): the factorizations of the engine's Newton matrices then upload
// nothing per chunk.
void CudaExecutor::chunk_layout(const numeric::FactorContext& ctx, ChunkRecord& rec) {
  const Analysis& an = *ctx.analysis;
  const auto& t = an.tree;
  const auto& s = *ctx.part->schedule;
  PartDevice& pd = *cur_;
  const index_t begin = rec.begin;
  const std::int64_t count = rec.end - rec.begin;
  const int key = (rec.lu ? 1 : 0) | (rec.dev_only ? 2 : 0) | (keep_resident() ? 4 : 0) |
                  (part_device_only_ ? 8 : 0);
  if (pd.layouts.size() < s.fronts.size()) pd.layouts.resize(s.fronts.size());
  ChunkLayout& L = pd.layouts[begin];
  if (L.key != key) {
    L.key = -1;  // until made whole
    L.small.clear();
    L.big.clear();
    L.perm_off.assign(1, 0);
    for (index_t p = begin; p < rec.end; ++p) {
      const index_t f = s.fronts[p];
      if (t.n_rows(f) <= small_front_rows_) {
        L.small.push_back(p);
        L.perm_off.push_back(L.perm_off.back() + t.n_pivots(f));
      } else {
        L.big.push_back(p);
      }
    }
    L.perm_total = L.perm_off.back();
    L.big_perm_at.resize(L.big.size());
    for (std::size_t i = 0; i < L.big.size(); ++i) {
      L.big_perm_at[i] = L.perm_total;
      L.perm_total += t.n_pivots(s.fronts[L.big[i]]);
    }
    std::vector<std::int64_t> stage_off(count);
    L.diag_off.assign(count + 1, 0);
    std::size_t total = 0;
    for (std::int64_t i = 0; i < count; ++i) {
      const index_t f = s.fronts[begin + i];
      stage_off[i] = keep_resident() ? static_cast<std::int64_t>(an.factor_layout.panel_offset[f])
                     : part_device_only_ ? pd.panel_off_host[begin + i]
                                         : static_cast<std::int64_t>(total);
      total += panel_size(t, f, rec.lu);
      L.diag_off[i + 1] = L.diag_off[i] + t.n_pivots(f);
    }
    L.panels_total = total;
    // small, perm_off, stage offsets, diag_off: 2·ns + 2·count + 2 ≤ 6·count entries
    std::vector<std::int64_t> dev(L.small);
    dev.insert(dev.end(), L.perm_off.begin(), L.perm_off.end());
    dev.insert(dev.end(), stage_off.begin(), stage_off.end());
    dev.insert(dev.end(), L.diag_off.begin(), L.diag_off.end());
    L.device_at = 6 * static_cast<std::size_t>(begin);
    if (L.device_at + dev.size() > pd.layout.size())
      throw InternalError("chunk_layout: the part's layout buffer was not sized for its chunks");
    STRATA_CUDA(cudaMemcpyAsync(pd.layout.data() + L.device_at, dev.data(),
                                sizeof(std::int64_t) * dev.size(), cudaMemcpyHostToDevice,
                                stream_));
    L.key = key;
  }
  rec.small.assign(L.small.begin(), L.small.end());
  rec.big.assign(L.big.begin(), L.big.end());
  rec.perm_off.assign(L.perm_off.begin(), L.perm_off.end());
  rec.big_perm_at.assign(L.big_perm_at.begin(), L.big_perm_at.end());
  rec.diag_off.assign(L.diag_off.begin(), L.diag_off.end());
  rec.perm_total = L.perm_total;
  rec.panels_total = L.panels_total;
  const std::size_t ns = L.small.size();
  rec.small_pos = pd.layout.data() + L.device_at;
  rec.perm_offset = rec.small_pos + ns;
  rec.stage_offset = rec.perm_offset + ns + 1;
  rec.diag_offset = rec.stage_offset + count;
  if (rec.dev_only) diag_.resize(static_cast<std::size_t>(rec.diag_off[count]) + 1);
}

// LLᵀ fronts up to gpu_panel_kernel_max_pivots: their pivot blocks and panels by our
// kernels for all of them together (kernels_panel.cu), so that only their SYRK is a
// library call on the lanes. Returns, per large front, whether the kernels took it.
std::vector<char> CudaExecutor::chunk_panel_kernels(const numeric::FactorContext& ctx,
                                                    const ChunkRecord& rec) {
  const auto& t = ctx.analysis->tree;
  const auto& s = *ctx.part->schedule;
  const std::vector<std::int64_t>& big = rec.big;
  std::vector<char> by_kernels(big.size(), 0);
  std::vector<std::size_t> panel_order;
  if (!rec.lu && !rec.ldlt)
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
      by_kernels[i] = 1;
    }
    upload(panel_items_, items);
    panel_work_.resize(llt_panel_work_size(static_cast<std::int64_t>(pivots.size())));
    launch_llt_panel(cur_->tree, panel_items_.data(), rows, pivots, pool_.data(),
                     panel_work_.data(), potrf_info_.data(), stream_);
  }
  STRATA_CUDA(cudaEventRecord(panels_done_, stream_));
  return by_kernels;
}

// Step 2 for the large fronts: library calls, each front on one lane, the lanes side by
// side (the least-loaded lane takes the next front; LDLᵀ's panel workspace is single: one
// lane). The fronts the panel kernels did not take go first, their lanes not waiting for
// those kernels (lane 0 is stream_ itself, behind them); then the updates of the ones they
// took, each lane waiting once for panels_done_. Ends with the lanes and the GPU team
// joined on stream_: the stores read every front.
void CudaExecutor::chunk_large_fronts(const numeric::FactorContext& ctx, const ChunkRecord& rec,
                                      cudaEvent_t after) {
  const auto& t = ctx.analysis->tree;
  const auto& s = *ctx.part->schedule;
  const std::vector<std::int64_t>& big = rec.big;
  const std::size_t ns = rec.small.size();
  const bool lu = rec.lu, ldlt = rec.ldlt;
  const std::vector<char> by_kernels = chunk_panel_kernels(ctx, rec);
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
    if (l > 0) STRATA_CUDA(cudaStreamWaitEvent(lane[l]->stream, after, 0));
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
      std::int64_t* const perm_f = perm_.data() + rec.big_perm_at[i];
      if (ldlt) {
        ldlt_large_.factor(blas_, stream_, F, m, k, ctx.static_pivot, perm_f,
                           pivot_size_.data() + rec.big_perm_at[i], perturbed_.data() + ns + i);
      } else if (by_kernels[i]) {  // pivot block and panel done by the panel kernels
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
            split_update(*ln, F, m, k, false, rec.ev[1]);
          else
            llt_update(ln->blas, m - k, k, F + k, m, F + static_cast<std::size_t>(k) * m + k, m);
        }
      } else {  // first pass: GETRF and its pivot check; the rest after one wait below
        lu_fronts.push_back({ln, F, m, k, p, perm_f, perturbed_.data() + ns + i});
      }
    }
  if (!lu_fronts.empty()) {
    // the LU fronts' pivot checks make the host wait for this chunk's kernels: the
    // previous chunk's host part runs now, in that wait, rather than after this chunk's
    // stores are launched, where the device would have nothing left to do behind it
    flush_chunk(ctx);
    lu_large_fronts(lu_fronts, numeric::PivotPolicy(ctx.static_pivot, ctx.diagonal_pivot_threshold),
                    rec.ev[1]);
  }
  for (std::size_t l = 1; l < n_lanes; ++l) {
    STRATA_CUDA(cudaEventRecord(lane[l]->done, lane[l]->stream));
    STRATA_CUDA(cudaStreamWaitEvent(stream_, lane[l]->done, 0));
  }
  join_team();
}

// Step 4: the factor panels packed into the device factor (resident), the part's own
// buffer (a part whose panels stay on this device), or the chunk's staging area (in chunk
// order: for the whole tree that is the layout's order); panels for the host factor
// copied on copy_stream_ while the next chunk computes (the host part, after the next
// chunk is launched, moves them into the factor); device-only panels give the host only
// the pivots' diagonal entries.
void CudaExecutor::chunk_pack_panels(const numeric::FactorContext& ctx, ChunkRecord& rec) {
  const Analysis& an = *ctx.analysis;
  const auto& s = *ctx.part->schedule;
  const index_t begin = rec.begin;
  const std::int64_t count = rec.end - rec.begin;
  double* const pack_to = chunk_panel_target(ctx);
  const std::size_t total = rec.panels_total;
  // the staging area is free once the previous chunk's panels are on their way out
  if (copy_issued_) STRATA_CUDA(cudaStreamWaitEvent(stream_, panels_copied_, 0));
  launch_pack_panels(cur_->tree, begin, count, rec.max_rows, pool_.data(), rec.stage_offset,
                     pack_to, rec.lu, stream_);
  rec.panels_async = !rec.dev_only && !rec.ldlt;
  if (rec.panels_async) {
    STRATA_CUDA(cudaEventRecord(rec.ev[6], stream_));
    STRATA_CUDA(cudaStreamWaitEvent(copy_stream_, rec.ev[6], 0));
    rec.panels.resize(total);  // presized at planning
    const std::size_t base = an.factor_layout.panel_offset[s.fronts[begin]];
    const double* src = panels_.data() + (keep_resident() ? base : 0);
    if (total)
      STRATA_CUDA(cudaMemcpyAsync(rec.panels.data(), src, sizeof(double) * total,
                                  cudaMemcpyDeviceToHost, copy_stream_));
    STRATA_CUDA(cudaEventRecord(rec.ev[7], copy_stream_));
    STRATA_CUDA(cudaEventRecord(panels_copied_, copy_stream_));
    copy_issued_ = true;
    bytes_d2h_ += sizeof(double) * total;
  }
  if (rec.dev_only)
    launch_gather_diagonals(cur_->tree, begin, count, rec.stage_offset, pack_to, rec.diag_offset,
                            diag_.data(), stream_);
}

// Where a chunk's panels are packed, as chunk_layout's panel offsets assume.
double* CudaExecutor::chunk_panel_target(const numeric::FactorContext& ctx) {
  return part_device_only_ ? part_panels_.at(ctx.part->id).data() : panels_.data();
}

std::int64_t* CudaExecutor::packed_half(const ChunkRecord& rec) {
  return packed_results_.data() + (&rec == &chunk_[0] ? 0 : packed_results_.size() / 2);
}

// A chunk whose panels stay on the device: its results (small fronts' checks, every
// front's perturbed count, the permutations, POTRF's infos, LDLᵀ's pivot sizes, the
// diagonals) packed by one kernel into the record's half of packed_results_, for one copy
// on copy_stream_. The shared result buffers are then free for the next chunk as soon as
// the kernel has read them, and the next chunk's launches do not queue behind five small
// copies; the half is not written again before this chunk's host part has waited for
// the copy (ev[5]; the record's next chunk comes after it). False, having done nothing,
// for a chunk whose panels come back to the host (its host part waits for them anyway)
// or whose results do not fit the half.
bool CudaExecutor::chunk_pack_results(ChunkRecord& rec) {
  rec.packed_words = 0;
  if (!rec.dev_only) return false;
  const std::int64_t ns = static_cast<std::int64_t>(rec.small.size());
  const std::int64_t nb = static_cast<std::int64_t>(rec.big.size()), nall = ns + nb;
  const std::int64_t np = rec.perm_total, nd = rec.diag_off.back();
  const bool llt = !rec.lu && !rec.ldlt;
  ResultSegments g;
  std::int64_t at = 0;
  auto segment = [&](int q, const void* src, std::int64_t n, int kind) {
    at += n;
    g.src[q] = src;
    g.end[q] = at;
    g.kind[q] = kind;
  };
  segment(0, info_.data(), rec.ldlt ? 0 : ns, 0);
  segment(1, perturbed_.data(), nall, 0);
  segment(2, perm_.data(), np, 0);
  segment(3, potrf_info_.data(), llt ? nb : 0, 1);
  segment(4, pivot_size_.data(), rec.ldlt ? np : 0, 1);
  segment(5, diag_.data(), nd, 2);
  if (static_cast<std::size_t>(at) > packed_results_.size() / 2) return false;
  launch_pack_results(g, packed_half(rec), stream_);
  rec.packed.resize(static_cast<std::size_t>(at) + 1);  // presized at planning
  const std::int64_t* h = rec.packed.data();
  rec.info_at = h;
  rec.perturbed_at = h + g.end[0];
  rec.perm_at = h + g.end[1];
  rec.pinfo_at = h + g.end[2];
  rec.psize_at = h + g.end[3];
  rec.diag_at = reinterpret_cast<const double*>(h + g.end[4]);
  rec.packed_words = static_cast<std::size_t>(at);
  return true;
}

// The results the host part needs (pivot checks, permutations, LDLᵀ pivot sizes, the
// diagonal of device-only panels), into the record's pinned buffers, so that the copies
// do not hold the host: the host part runs after the next chunk is launched.
void CudaExecutor::chunk_fetch_results(ChunkRecord& rec) {
  const std::size_t ns = rec.small.size(), nb = rec.big.size(), nall = ns + nb;
  const std::int64_t perm_at = rec.perm_total;
  const std::int64_t n_diag = rec.diag_off.back();
  const bool llt = !rec.lu && !rec.ldlt;
  rec.info.resize(nall + 1);
  rec.perturbed.resize(nall + 1);
  rec.perm.resize(static_cast<std::size_t>(perm_at) + 1);
  rec.pinfo.resize(nb + 1);
  rec.psize.resize(static_cast<std::size_t>(perm_at) + 1);
  rec.diag.resize(rec.dev_only ? static_cast<std::size_t>(n_diag) + 1 : 1);
  if (ns && !rec.ldlt)
    STRATA_CUDA(
        cudaMemcpyAsync(rec.info.data(), info_.data(), 8 * ns, cudaMemcpyDeviceToHost, stream_));
  if (nall)
    STRATA_CUDA(cudaMemcpyAsync(rec.perturbed.data(), perturbed_.data(), 8 * nall,
                                cudaMemcpyDeviceToHost, stream_));
  if (perm_at)
    STRATA_CUDA(cudaMemcpyAsync(rec.perm.data(), perm_.data(), 8 * perm_at, cudaMemcpyDeviceToHost,
                                stream_));
  if (nb && llt)
    STRATA_CUDA(cudaMemcpyAsync(rec.pinfo.data(), potrf_info_.data(), sizeof(int) * nb,
                                cudaMemcpyDeviceToHost, stream_));
  if (rec.ldlt && perm_at)
    STRATA_CUDA(cudaMemcpyAsync(rec.psize.data(), pivot_size_.data(), sizeof(int) * perm_at,
                                cudaMemcpyDeviceToHost, stream_));
  if (rec.dev_only && n_diag > 0)
    STRATA_CUDA(cudaMemcpyAsync(rec.diag.data(), diag_.data(), sizeof(double) * n_diag,
                                cudaMemcpyDeviceToHost, stream_));
  rec.info_at = rec.info.data();
  rec.perturbed_at = rec.perturbed.data();
  rec.perm_at = rec.perm.data();
  rec.diag_at = rec.diag.data();
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
  const std::int64_t* info = c.info_at;
  const std::int64_t* perturbed = c.perturbed_at;
  const std::int64_t* perm = c.perm_at;
  STRATA_CUDA(cudaEventSynchronize(c.ev[5]));
  if (c.packed_words > 0) {  // POTRF's infos and LDLᵀ's pivot sizes from their words
    const std::size_t nb = big.size(), np = static_cast<std::size_t>(c.perm_total);
    c.pinfo.resize(nb + 1);
    c.psize.resize(np + 1);
    if (!lu && !ldlt)
      for (std::size_t i = 0; i < nb; ++i) c.pinfo.data()[i] = static_cast<int>(c.pinfo_at[i]);
    if (ldlt)
      for (std::size_t i = 0; i < np; ++i) c.psize.data()[i] = static_cast<int>(c.psize_at[i]);
  }
  const int* pinfo = c.pinfo.data();
  const int* psize = c.psize.data();
  if (c.panels_async) STRATA_CUDA(cudaEventSynchronize(c.ev[7]));
  float ms[4] = {};
  for (int e = c.fused ? 1 : 0; e < (c.fused ? 2 : 4); ++e)
    STRATA_CUDA(cudaEventElapsedTime(&ms[e], c.ev[e], c.ev[e + 1]));
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
      launch_ldlt_unit_panels(tree, begin, count, c.stage_offset, pivot_size_.data(),
                              psize_at_.data(), panels_.data(), stream_);
    }
    return;
  }
  // the diagonal of each front's panel: gathered on the device, or read in the host copy
  // (into `buffer`)
  auto diag_of = [&](index_t p, std::vector<double>& buffer) -> const double* {
    const index_t f = s.fronts[p];
    if (dev_only) return c.diag_at + diag_off[p - begin];
    const index_t m = t.n_rows(f), k = t.n_pivots(f);
    const double* panel = ctx.factor->panels.data() + an.factor_layout.panel_offset[f];
    buffer.resize(k);
    for (index_t i = 0; i < k; ++i) buffer[i] = panel[i * m + i];
    return buffer.data();
  };
  // front i of the chunk: the small fronts, then the large ones
  auto failed = [&](std::size_t i) -> std::int64_t {
    if (lu) return -1;
    return i < ns ? info[i] : (pinfo[i - ns] > 0 ? pinfo[i - ns] - 1 : -1);
  };
  auto finish = [&](std::size_t i, std::vector<double>& buffer) {
    const std::int64_t p = i < ns ? small[i] : big[i - ns];
    finish_front(ctx, s.fronts[p], failed(i), perturbed[i],
                 perm + (i < ns ? perm_off[i] : big_perm_at[i - ns]), diag_of(p, buffer));
  };
  // Each front's bookkeeping is its own (its rows, its statistics), so a chunk of many
  // fronts is done over the host's threads; a failed pivot is reported as the loop in
  // order reports it (the first failed front's), from that loop.
  bool any_failed = false;
  for (std::size_t i = 0; i < nall && !any_failed; ++i) any_failed = failed(i) >= 0;
  if (any_failed || nall < kParallelFinishFronts) {
    std::vector<double> buffer;
    for (std::size_t i = 0; i < nall; ++i) finish(i, buffer);
    return;
  }
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nall, kParallelFinishFronts / 2),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      std::vector<double> buffer;
                      for (std::size_t i = r.begin(); i != r.end(); ++i) finish(i, buffer);
                    });
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
  // lap3d 100³ when its factor did not stay on the device (base/host_copy.hpp)
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
    if (npert > 0) numeric::mark_static_pivots(diag, 1, k, t.first_pivot[f], ctx.static_pivot, fac);
    // the device solve's rows of this analysis: whether this front's pivot rows differ
    // from those it holds (upload_solve_rows then sends only the fronts marked)
    if (dsolve_.rows_moved.size() == static_cast<std::size_t>(t.n_fronts()) &&
        dsolve_.rows_analysis == an.id && dsolve_.rows_type == MatrixType::general &&
        !std::equal(frows, frows + k, dsolve_.rows_host.data() + t.row_offsets[f]))
      dsolve_.rows_moved[f] = 1;
  } else {
    ps.positive = k;
  }
  ps.det_sign = sign;
}

}  // namespace strata::cuda
