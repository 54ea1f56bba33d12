// strata — the CUDA executor's device memory plan and per-analysis uploads (see
// cuda_executor.cu's header for what lives where): the budget split between the pool of
// one chunk, the contribution-block arena and the resident factor; every part's chunks
// (positions of one batch whose fronts fit the pool together) and which fronts are tiled;
// the index arrays of the analysis and of each part uploaded once, and the chunk buffers
// sized for the largest chunk, so that a refactorization allocates nothing.
#include <algorithm>
#include <cmath>
#include <cstring>

#include "base/alloc.hpp"
#include "base/host_copy.hpp"
#include "base/host_memory.hpp"
#include "base/timer.hpp"
#include "numeric/cpu/dense_front.hpp"
#include "numeric/cuda/cuda_executor.hpp"

namespace strata::cuda {

namespace {

// fn(f, offset, size) for every contribution block the part `v` writes or reads (its
// fronts' and their children's): its offset in the part's arena layout and its order.
template <class Fn>
void for_each_cb(const symbolic::AssemblyTree& t, const numeric::PartView& v, Fn&& fn) {
  auto one = [&](index_t f) {
    const std::size_t cb = static_cast<std::size_t>(t.cb_size(f));
    if (cb == 0 || t.parent[f] < 0) return;
    fn(f, v.cb_layout->cb_offset[f], cb);
  };
  for (const index_t f : v.schedule->fronts) {
    one(f);
    for (index_t q = t.child_offsets[f]; q < t.child_offsets[f + 1]; ++q) one(t.children[q]);
  }
}

}  // namespace

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
  std::size_t largest = 0;  // the largest front the pool holds alone
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
          largest = std::max(largest, sq(t.n_rows(f)));
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
        std::max(pool, static_cast<std::size_t>(tiled_.pool_share * static_cast<double>(budget_d)));
  }
  // the contribution-block arena (the largest part's) and, for the whole tree, the factor
  std::size_t arena = 0;
  bool whole = false;
  for (const numeric::PartView& v : views) {
    arena = std::max(arena, v.cb_layout->arena_size);
    whole = whole || v.id == -1;
  }
  const std::size_t factor = an.factor_layout.total;
  // A whole untiled tree whose factor and arena fit beside a smaller pool keeps its factor
  // on the device, and its solves run there: the pool gives up its share down to the
  // largest front it must hold alone (a smaller pool only cuts batches into more chunks,
  // where the factor left behind would be copied to the host and solved there).
  const std::size_t need = arena + factor;
  if (whole && tiled_rows == 0 && budget_d > need && pool > budget_d - need &&
      budget_d - need >= largest)
    pool = budget_d - need;
  if (limit_ > 0 && pool > budget_d)
    throw OutOfMemory(pool * sizeof(double),
                      "the device pool for the largest front (device_memory_limit is " +
                          std::to_string(limit_) + " bytes)");
  p.pool = std::max<std::size_t>(pool, 1);
  // Host memory. A factor that does not stay on the device is copied chunk by chunk into
  // the host factor through two pinned buffers (one per chunk slot) of the largest
  // chunk's panels; with a pool of half the device those two alone could take more than
  // the host has (page-locked memory is never swapped, and the kernel's out-of-memory
  // killer ends the process without a message). So a chunk's panels are capped too: the
  // two slots together at an eighth of the host memory left beside the host factor, but
  // never below the largest single front's panels.
  std::size_t rest = budget_d > p.pool ? budget_d - p.pool : 0;
  const bool resident = whole && rest >= arena + factor;
  const std::size_t host_bytes = host_limit_ > 0 ? host_limit_ : available_host_memory();
  const std::size_t host_avail = host_bytes / sizeof(double);  // 0: unknown
  // the host factor, and the arrays of values a factorization makes (the input gathered
  // into the analyzed pattern, scaled, and their sums: about three of nnz(A))
  const std::size_t values_host = 3 * an.pattern_indices.size();
  const std::size_t factor_host = (resident ? 0 : factor) + values_host;
  std::size_t largest_panel = 1;
  for (const numeric::PartView& v : views)
    for (std::size_t q = 0; q < v.schedule->fronts.size(); ++q)
      if (!parts_[v.id].tiled[q])
        largest_panel =
            std::max(largest_panel, panel_size(t, v.schedule->fronts[q], !an.symmetric));
  std::size_t panel_cap = p.pool;
  if (host_avail > 0 && !resident)
    panel_cap =
        std::max(largest_panel,
                 std::min(p.pool, (host_avail > factor_host ? host_avail - factor_host : 0) / 16));
  // The chunks, the panels' staging, the arena's device part and what the host must hold,
  // for chunks whose panels are at most `cap`: consecutive non-tiled positions of a batch
  // whose fronts fit the pool and whose panels fit the cap.
  auto lay_out = [&](std::size_t cap) {
    p.staging = 1;
    for (const numeric::PartView& v : views) {
      const auto& s = *v.schedule;
      PartDevice& pd = parts_[v.id];
      pd.pos_offset_host.assign(s.fronts.size(), 0);
      pd.chunk_end.assign(s.fronts.size(), 0);
      for (const BatchInfo& b : *v.batches) {
        index_t start = b.begin;
        std::size_t off = 0, panels = 0;
        for (index_t q = b.begin; q <= b.end; ++q) {
          const std::size_t pan = q == b.end ? 0 : panel_size(t, s.fronts[q], !an.symmetric);
          const bool flush = q == b.end || pd.tiled[q] ||
                             off + sq(t.n_rows(s.fronts[q])) > p.pool || panels + pan > cap;
          if (flush && q > start) {
            pd.chunk_end[start] = q;
            start = q;
            off = 0;
            panels = 0;
          }
          if (q == b.end) break;
          if (pd.tiled[q]) {
            start = q + 1;
            continue;
          }
          pd.pos_offset_host[q] = static_cast<std::int64_t>(off);
          off += sq(t.n_rows(s.fronts[q]));
          panels += pan;
        }
      }
    }
    // the panels of the largest chunk, staged on the device on their way to the host factor
    // (each front's panels are at most its m² entries, so the staging is at most the pool)
    for (const numeric::PartView& v : views) {
      const auto& s = *v.schedule;
      const PartDevice& pd = parts_[v.id];
      for (index_t q = 0; q < static_cast<index_t>(s.fronts.size()); ++q)
        if (!pd.tiled[q] && pd.chunk_end[q] > q) {
          std::size_t sum = 0;
          for (index_t r = q; r < pd.chunk_end[q]; ++r)
            sum += panel_size(t, s.fronts[r], !an.symmetric);
          p.staging = std::max(p.staging, sum);
        }
    }
    // the arena, then the resident factor (whole tree only; its panels need no staging), in
    // what the pool leaves; otherwise the arena's device part in what the pool and the
    // staging leave (the rest of it in host memory)
    if (resident) {
      p.arena_device = arena;
      p.factor_resident = true;
    } else {
      p.arena_device = std::min(arena, rest > p.staging ? rest - p.staging : 0);
    }
    p.arena_on_host = p.arena_device < arena;
    // the spilled blocks' host arena starts at the first block that does not fit the device
    p.host_arena_base = arena;
    if (p.arena_on_host)
      for (const numeric::PartView& v : views)
        for_each_cb(t, v, [&](index_t f, std::size_t off, std::size_t cb) {
          if (off + cb * cb > p.arena_device) p.host_arena_base = std::min(p.host_arena_base, off);
        });
    // what the host must hold: the host factor, the spilled blocks, the panels' pinned
    // buffers and the largest tiled front's host copy (tiled_front.cu, tiled_llt.cu)
    const bool pinned_panels = !resident && an.type != MatrixType::symmetric_indefinite;
    p.host_pinned = sizeof(double) * ((arena - std::min(arena, p.host_arena_base)) +
                                      (pinned_panels ? 2 * p.staging : 0) + sq(tiled_rows));
    // with a reserve of an eighth for what the rest of the process allocates meanwhile
    const std::size_t need = p.host_pinned + sizeof(double) * factor_host;
    return need + need / 8;
  };
  // The layout for a cap, after the pool has given way to the arena where that keeps
  // every block on the device: blocks spilled to the host are read and written by the
  // kernels over the bus and take page-locked host memory, so a smaller pool (down to the
  // largest front it must hold alone) is better, as it is above for a resident factor.
  const std::size_t pool0 = p.pool;
  auto plan_with = [&](std::size_t cap) {
    p.pool = pool0;
    rest = budget_d > p.pool ? budget_d - p.pool : 0;
    std::size_t need = lay_out(cap);
    if (p.arena_on_host && tiled_rows == 0 && budget_d > arena + p.staging &&
        budget_d - arena - p.staging >= largest && budget_d - arena - p.staging < p.pool) {
      p.pool = budget_d - arena - p.staging;
      rest = budget_d - p.pool;
      need = lay_out(std::min(cap, p.pool));
    }
    return need;
  };
  std::size_t host_need = plan_with(panel_cap);
  // over what the host has: the smallest chunks the largest front allows
  if (host_bytes > 0 && host_need > host_bytes && panel_cap > largest_panel)
    host_need = plan_with(largest_panel);
  if (host_bytes > 0 && host_need > host_bytes)
    throw OutOfMemory(host_need, "host memory for the GPU factorization (the host factor " +
                                     std::to_string(sizeof(double) * (resident ? 0 : factor)) +
                                     " bytes, the factorization's value arrays " +
                                     std::to_string(sizeof(double) * values_host) +
                                     " bytes, page-locked buffers " +
                                     std::to_string(p.host_pinned) +
                                     " bytes and a reserve of an eighth; " +
                                     std::to_string(host_bytes) + " bytes available)");
  plan_ = p;
}

void CudaExecutor::upload_analysis(const Analysis& an) {
  const auto& t = an.tree;
  const auto& s = an.schedule;
  const index_t nf = t.n_fronts();
  // free what the previous analysis held before measuring free memory
  for (auto* b : {&pool_, &arena_, &panels_, &values_}) b->clear();
  value_pass_.analysis = 0;  // its arrays are remade by prepare_value_pass
  host_arena_.clear();
  parts_.clear();
  outbox_.clear();
  drop_landings();
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
  // every panel of every front tries its diagonal first in the first factorization
  upload(lu_interchanges_, std::vector<std::uint32_t>(nf, 0u));
  // solve arrays
  std::vector<std::int64_t> u_off(nf + 1, 0);
  for (index_t f = 0; f < nf; ++f) u_off[f + 1] = u_off[f] + t.cb_size(f);
  dsolve_.u_offset_host = u_off;
  upload(dsolve_.u_offset, u_off);
  upload(dsolve_.row_offsets, t.row_offsets);
  upload(dsolve_.first_pivot, t.first_pivot);
  upload(dsolve_.level_offsets, s.level_offsets);
  values_.resize(std::max<std::size_t>(an.pattern_indices.size(), 1));
  STRATA_CUDA(cudaStreamSynchronize(stream_));

  STRATA_CUDA(cudaStreamSynchronize(stream_));
  analysis_id_ = an.id;
}

// Plans and uploads the parts a factorization will use: the whole tree, or every part of
// an.partition — subtrees, upper parts and the top part (any GPU may run any subtree).
void CudaExecutor::plan_parts(const Analysis& an, bool whole) {
  for (auto* b : {&pool_, &arena_, &panels_}) b->clear();
  host_arena_.clear();
  for (ChunkRecord& c : chunk_) c.panels.clear();  // resized below, for this plan
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
  std::size_t arena = 1;
  for (const numeric::PartView& v : views) arena = std::max(arena, v.cb_layout->arena_size);
  const std::size_t chunk_panels = plan_.staging;
  arena_.resize(std::max<std::size_t>(plan_.arena_device, 1));
  if (plan_.arena_on_host) host_arena_.resize(arena - plan_.host_arena_base);
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
// and made the first factorization markedly slower than the refactorizations.
// Done here, at analysis (prepare) or at the first begin_part, the factorizations
// allocate nothing on the device.
void CudaExecutor::presize_chunk_buffers(const Analysis& an,
                                         const std::vector<numeric::PartView>& views) {
  const auto& t = an.tree;
  const bool lu = !an.symmetric;
  std::size_t count = 1, big = 1, pivots = 1, diag = 1, diag_slab = 1, strips = 1;
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
      std::size_t nb = 0, np = 0, ni = 0;
      for (index_t r = q; r < pd.chunk_end[q]; ++r) {
        const index_t f = s.fronts[r];
        const int m = static_cast<int>(t.n_rows(f)), k = static_cast<int>(t.n_pivots(f));
        np += static_cast<std::size_t>(k);
        if (m <= small_front_rows_) continue;
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
      pivots = std::max(pivots, np);
      strips = std::max(strips, ni);
    }
  }
  for (auto* b : {&info_, &perturbed_}) b->resize(count + 1);
  // a chunk's results, one half per chunk record: info and perturbed per front, POTRF's
  // info per large front, then its pivots' permutation, LDLᵀ pivot sizes and diagonal
  // entries (factor_chunk_fused, chunk_pack_results)
  packed_results_.resize(2 * (3 * count + 3 * pivots + 1));
  // every chunk's layout at 6 × its first position (chunk_layout)
  for (const numeric::PartView& v : views) {
    PartDevice& pd = parts_.at(v.id);
    pd.layout.resize(6 * v.schedule->fronts.size() + 1);
    pd.layouts.assign(v.schedule->fronts.size(), ChunkLayout{});
  }
  // the tiled fronts' pinned buffers: the prefetch's (LLᵀ) the same size, since the two
  // trade places at every prefetched front and must not grow on the way
  if (host_front > 0) {
    tiled_.front.resize(host_front);
    if (tiled_.prefetch_on && !lu) try {
        tiled_.front_next.resize(host_front);
      } catch (const OutOfMemory&) {  // no room for the second: no prefetch (tiled_llt.cu)
      }
  }
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
    c.packed.resize(3 * count + 3 * pivots + 1);
  }
  for (auto& l : lane) {
    l->potrf_work.resize(static_cast<std::size_t>(potrf));
    l->block_info.resize(static_cast<std::size_t>(blocks));
    l->diag_work.resize(l == lane.front() ? std::max(diag, diag_slab) : diag);
  }
  if (lu) {
    lu_.items.resize(strips);
    lu_.work.resize(lu_panel_work_size(static_cast<std::int64_t>(big)));
    lu_.perm_offset.resize(big + 1);
    lu_.ipiv.resize(pivots);
    lu_.info.resize(big);
    lu_.bad.resize(big);
    lu_.bad_host.resize(big);
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
  for_each_cb(t, v, [&](index_t f, std::size_t off, std::size_t cb) {
    pd.cb_ptr_host[f] = off + cb * cb <= plan_.arena_device
                            ? arena_.data() + off
                            : host_arena_.data() + (off - plan_.host_arena_base);
  });
  upload(pd.cb_ptr, pd.cb_ptr_host);
  pd.tree = DeviceTree{pd.fronts.data(),  pd.pos_offset.data(),   n_rows_.data(),
                       n_pivots_.data(),  parent_.data(),         entry_offsets_.data(),
                       entry_src_.data(), entry_dst_.data(),      child_offsets_.data(),
                       children_.data(),  pd.cb_ptr.data(),       rel_offsets_.data(),
                       rel_.data(),       lu_interchanges_.data()};
}

}  // namespace strata::cuda
