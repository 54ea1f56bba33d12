// strata — the large LU fronts of a chunk on the CUDA executor (CudaExecutor::
// lu_large_fronts): fronts over Options::gpu_small_front_rows rows, each m × m in the pool
// with k fully summed rows and columns, to be left as the CPU's factor_front_lu leaves them
// (L11\U11, L21, U12, the Schur complement in the contribution block, the local row
// permutation).
//
// Restricted threshold partial pivoting (the CPU's rule: the diagonal when it is at least
// u = Options::diagonal_pivot_threshold times the largest magnitude among the fully summed rows,
// else that largest, the first on ties) interchanges no row in most fronts once the
// matching has put large entries on the diagonal. So every front is first eliminated
// without interchanges and kept when that was what the rule would have done — every
// multiplier of a fully summed row at most 1/u in magnitude — and when no pivot needs
// static pivoting; the others are factored again (lu_fronts_redo). Two ways to eliminate
// without interchanges:
//
//   by strips (Options::gpu_lu_strip_pivots = nb > 0, the default): the blocked
//   right-looking LU (Golub & Van Loan, "Matrix Computations", 4th ed., §3.2.11) with
//   blocks of nb pivot columns. A strip's pivot block and L and U panels come from the
//   batched kernels of kernels_lu_panel.cu — for every front of the chunk with pivots left
//   in that strip, in one launch sequence; the rest of the pivot rows and columns gets the
//   strip's rank-nb update by two cuBLAS GEMMs per front, on the lanes; after a front's
//   last strip its contribution block gets its one rank-k update, on a lane, while the
//   larger fronts go on with their strips: for all the fronts ending in a strip whose
//   blocks are small (kLuBatchedCbMaxRows) one launch of launch_lu_cb_update_batched —
//   their GEMMs are a few microseconds of device time each, and launched one by one the
//   host's calls were the longer part — otherwise a cuBLAS GEMM (or split_update over the
//   team). Nothing waits for
//   the checks: they are read once, after the last strip's kernels, while the GEMMs run.
//   A rejected front's speculative updates are wasted work and harmless, since that front
//   is assembled again from scratch. A front of one 64-column step (k ≤ 64, k ≤ nb) is
//   the exception: its whole pivot block is the kernels' diagonal block, so they factor it
//   with the interchanges themselves (the multibody Newton matrices have many such fronts:
//   862 of the flexible plate's 1,051, whose rejections fell from 276 to 19).
//
//   by the library (nb = 0): cuSOLVER GETRF without pivoting on A11 (several times faster
//   than with pivoting at the large fronts' k) and its check, one wait, then two cuBLAS
//   TRSMs and the GEMM — what ran before the batched kernels, kept for comparison
//   (bench_gpu_memory --parts lu-panel).
//
// Factoring again (lu_fronts_redo): the front is assembled again — its original entries
// and its children's contribution blocks are where the chunk's assembly read them, since
// no block is stored before all the chunk's fronts are factored — then, with u = 1,
// cuSOLVER GETRF with partial pivoting on A11, the interchanges on A12, the TRSMs and the
// GEMM; a pivot GETRF chose that is below the static-pivot threshold (or an exact zero, or
// not finite) sends the front, assembled once more, to the blocked path with our panel
// kernel, which perturbs tiny pivots as the CPU does (kernels_lu.cu). With u < 1 GETRF's
// rule is not the CPU's, so the front goes to that blocked path straight away, whose
// panel kernel applies the threshold.
#include <algorithm>
#include <string>

#include "numeric/cuda/cuda_executor.hpp"
#include "numeric/cuda_testing.hpp"
#include "strata/errors.hpp"

namespace strata::cuda {
namespace {

constexpr std::int64_t kLuPanel = 64;      // panel width of the blocked LU with static pivoting
constexpr std::int64_t kStepPivots = 64;   // pivot columns per step of the batched kernels
constexpr std::int64_t kMinTallPanel = 8;  // narrowest panel of the shared-memory panel kernel

}  // namespace

void enqueue_lu_strips(const std::vector<LuPanelItem>& fronts, std::int64_t nb,
                       const std::vector<Lane*>& lanes, DeviceBuffer<LuPanelItem>& items,
                       DeviceBuffer<LuPanelItem>& cb_items, DeviceBuffer<double>& work, int* bad,
                       const numeric::PivotPolicy& pivots, cudaEvent_t strip_done,
                       const LuLookahead* ahead, const std::function<bool(std::size_t)>& may_batch,
                       const LuFinalUpdate& final_update, std::vector<Lane*>& lane_of) {
  const std::size_t n = fronts.size();
  lane_of.assign(n, nullptr);
  if (n == 0) return;
  if (nb < 1) throw InvalidInput("enqueue_lu_strips: strip width " + std::to_string(nb));
  Lane& k0 = *lanes.front();
  const std::int64_t strips = (fronts.front().k + nb - 1) / nb;
  // every strip's items (the active fronts of a strip are a prefix), uploaded at once
  std::vector<LuPanelItem> all;
  std::vector<std::size_t> strip_at{0};
  for (std::int64_t s = 0; s < strips; ++s) {
    const std::int64_t b0 = s * nb;
    for (std::size_t i = 0; i < n && fronts[i].k > b0; ++i) {
      const LuPanelItem& f = fronts[i];
      // a front of one step and one strip is factored with its interchanges by the kernels
      const bool one_step = s == 0 && f.k <= std::min<std::int64_t>(nb, kStepPivots);
      all.push_back({f.F + b0 * f.ld + b0, f.ld, f.m - b0, std::min(nb, f.k - b0), f.k - b0,
                     one_step ? f.perm : nullptr});
    }
    strip_at.push_back(all.size());
  }
  items.upload(all.data(), all.size(), k0.stream);
  // the contribution blocks updated by one launch per strip, of the fronts ending there
  // (launch_lu_cb_update_batched), in the order of the strips
  std::vector<char> batched(n, 0);
  std::vector<LuPanelItem> cb_all;
  std::vector<std::size_t> cb_at{0};
  std::vector<std::int64_t> cb_tiles;
  std::vector<double> cb_flops;
  for (std::int64_t s = 0; s < strips; ++s) {
    std::int64_t tiles = 0;
    double flops = 0;
    for (std::size_t i = 0; i < n && fronts[i].k > s * nb; ++i) {
      const LuPanelItem& f = fronts[i];
      const std::int64_t cb = f.m - f.k;
      if (f.k > (s + 1) * nb || cb < 1 || cb > kLuBatchedCbMaxRows || !may_batch(i)) continue;
      batched[i] = 1;
      cb_all.push_back({f.F, f.ld, f.m, f.k, f.k, nullptr});
      const std::int64_t t = (cb + 63) / 64;
      tiles = std::max(tiles, t * t);
      flops += 2.0 * cb * cb * f.k;
    }
    cb_at.push_back(cb_all.size());
    cb_tiles.push_back(tiles);
    cb_flops.push_back(flops);
  }
  if (!cb_all.empty()) cb_items.upload(cb_all.data(), cb_all.size(), k0.stream);
  work.resize(lu_panel_work_size(static_cast<std::int64_t>(n)));
  STRATA_CUDA(cudaMemsetAsync(bad, 0, sizeof(int) * n, k0.stream));
  // the updates go to the lanes other than the kernels' own (when there are any), the
  // least loaded first: those of the fronts that go on to lanes [1, L/2), the contribution
  // blocks' to [L/2, L), so that the next strip never waits behind a contribution block
  const std::size_t L = lanes.size();
  const std::size_t go_on_end = L > 1 ? std::max<std::size_t>(2, L / 2) : 1;
  const std::size_t cb_first = go_on_end < L ? go_on_end : (L > 1 ? 1 : 0);
  std::vector<double> load(L, 0.0);
  auto pick = [&](bool ending, double flops) {
    const std::size_t lo = ending ? cb_first : (L > 1 ? 1 : 0), hi = ending ? L : go_on_end;
    std::size_t l = lo;
    for (std::size_t x = lo + 1; x < hi; ++x)
      if (load[x] < load[l]) l = x;
    load[l] += flops;
    return l;
  };
  const double one = 1.0, minus_one = -1.0;
  for (std::int64_t s = 0; s < strips; ++s) {
    const std::int64_t b0 = s * nb, b1 = b0 + nb;
    const std::size_t active = strip_at[s + 1] - strip_at[s];
    std::vector<std::int64_t> rows(active), pivot_counts(active);
    for (std::size_t i = 0; i < active; ++i) {
      rows[i] = all[strip_at[s] + i].m;
      pivot_counts[i] = all[strip_at[s] + i].k;
    }
    launch_lu_panel_batched(items.data() + strip_at[s], rows, pivot_counts, work.data(), bad,
                            pivots.static_pivot, pivots.threshold, k0.stream, ahead);
    STRATA_CUDA(cudaEventRecord(strip_done, k0.stream));
    std::vector<char> waited(lanes.size(), 0), continued(lanes.size(), 0);
    // first the rest of the pivot rows and columns of the fronts that go on (the next
    // strip's kernels wait for those), then the contribution blocks of those that end here
    for (int ending = 0; ending < 2; ++ending) {
      if (ending && cb_at[s + 1] > cb_at[s]) {
        const std::size_t l = pick(true, cb_flops[s]);
        Lane& ln = *lanes[l];
        if (l != 0 && !waited[l]) STRATA_CUDA(cudaStreamWaitEvent(ln.stream, strip_done, 0));
        waited[l] = 1;
        launch_lu_cb_update_batched(cb_items.data() + cb_at[s],
                                    static_cast<std::int64_t>(cb_at[s + 1] - cb_at[s]), cb_tiles[s],
                                    ln.stream);
        for (std::size_t i = 0; i < active; ++i)
          if (batched[i] && fronts[i].k <= b1) lane_of[i] = &ln;
      }
      for (std::size_t i = 0; i < active; ++i) {
        const LuPanelItem& f = fronts[i];
        if ((f.k <= b1) != static_cast<bool>(ending)) continue;
        if (ending && batched[i]) continue;
        const std::int64_t m = f.m, k = f.k, ld = f.ld;
        const double flops = ending ? 2.0 * (m - k) * (m - k) * k
                                    : 2.0 * nb * ((m - b1) * (k - b1) + (k - b1) * (m - k));
        const std::size_t l = pick(ending, flops);
        Lane& ln = *lanes[l];
        if (l != 0 && !waited[l]) STRATA_CUDA(cudaStreamWaitEvent(ln.stream, strip_done, 0));
        waited[l] = 1;
        if (ending) {
          lane_of[i] = &ln;
          final_update(i, ln);
          continue;
        }
        continued[l] = 1;
        double* F = f.F;
        // rows b1.. of the pivot columns b1..k, then rows b1..k of the columns k..m
        STRATA_CUBLAS(cublasDgemm(
            ln.blas, CUBLAS_OP_N, CUBLAS_OP_N, static_cast<int>(m - b1), static_cast<int>(k - b1),
            static_cast<int>(nb), &minus_one, F + b0 * ld + b1, static_cast<int>(ld),
            F + b1 * ld + b0, static_cast<int>(ld), &one, F + b1 * ld + b1, static_cast<int>(ld)));
        if (m > k)
          STRATA_CUBLAS(cublasDgemm(
              ln.blas, CUBLAS_OP_N, CUBLAS_OP_N, static_cast<int>(k - b1), static_cast<int>(m - k),
              static_cast<int>(nb), &minus_one, F + b0 * ld + b1, static_cast<int>(ld),
              F + k * ld + b0, static_cast<int>(ld), &one, F + k * ld + b1, static_cast<int>(ld)));
      }
      if (!ending && s + 1 < strips)
        for (std::size_t l = 1; l < lanes.size(); ++l)
          if (continued[l]) {
            STRATA_CUDA(cudaEventRecord(lanes[l]->done, lanes[l]->stream));
            STRATA_CUDA(cudaStreamWaitEvent(k0.stream, lanes[l]->done, 0));
          }
    }
  }
}

void CudaExecutor::lu_large_fronts(std::vector<LuFront>& fronts, const numeric::PivotPolicy& pivots,
                                   cudaEvent_t assembled) {
  const std::size_t n = fronts.size();
  std::size_t sum_k = 0;
  for (const LuFront& fr : fronts) sum_k += static_cast<std::size_t>(fr.k);
  // growing a buffer frees the old one: wait for the lanes first (cudaFree would too)
  if (lu_.ipiv.size() < sum_k || lu_.bad.size() < n) STRATA_CUDA(cudaDeviceSynchronize());
  lu_.ipiv.resize(std::max<std::size_t>(sum_k, 1));
  lu_.info.resize(n);
  lu_.bad.resize(n);
  lu_.bad_host.resize(n);
  lu_.fronts += static_cast<index_t>(n);
  std::vector<std::size_t> redo = lu_strip_pivots_ > 0
                                      ? lu_fronts_by_strips(fronts, pivots, assembled)
                                      : lu_fronts_by_library(fronts, pivots, assembled);
  if (!redo.empty()) lu_fronts_redo(fronts, redo, pivots, assembled);
}

// The identity as each front's local permutation and no perturbed pivot: one kernel and
// one memset when the fronts' slots are consecutive (as factor_chunk lays them out).
void CudaExecutor::lu_unpivoted_results(const std::vector<LuFront>& fronts, cudaStream_t s) {
  if (fronts.empty()) return;
  bool consecutive = true;
  std::vector<std::int64_t> off{0};
  for (std::size_t i = 0; i < fronts.size(); ++i) {
    consecutive = consecutive && fronts[i].perm == fronts[0].perm + off.back() &&
                  fronts[i].perturbed == fronts[0].perturbed + i;
    off.push_back(off.back() + fronts[i].k);
  }
  if (!consecutive) {
    for (const LuFront& fr : fronts) {
      STRATA_CUDA(cudaMemsetAsync(fr.perturbed, 0, sizeof(std::int64_t), s));
      launch_identity_perm(fr.k, fr.perm, s);
    }
    return;
  }
  lu_.perm_offset.upload(off.data(), off.size(), s);
  count_h2d(off.size() * sizeof(std::int64_t));
  launch_identity_perms(lu_.perm_offset.data(), static_cast<std::int64_t>(fronts.size()),
                        fronts[0].perm, s);
  STRATA_CUDA(cudaMemsetAsync(fronts[0].perturbed, 0, sizeof(std::int64_t) * fronts.size(), s));
}

std::vector<std::size_t> CudaExecutor::lu_fronts_by_strips(std::vector<LuFront>& fronts,
                                                           const numeric::PivotPolicy& pivots,
                                                           cudaEvent_t assembled) {
  const std::size_t n = fronts.size();
  lu_unpivoted_results(fronts, stream_);
  std::vector<std::size_t> order(n);
  for (std::size_t i = 0; i < n; ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return fronts[a].k > fronts[b].k; });
  std::vector<LuPanelItem> items(n);
  for (std::size_t q = 0; q < n; ++q) {
    const LuFront& fr = fronts[order[q]];
    items[q] = {fr.F, fr.m, fr.m, fr.k, fr.k, fr.perm};
  }
  std::vector<Lane*> lanes;
  for (auto& l : this->lanes()) lanes.push_back(l.get());
  const double one = 1.0, minus_one = -1.0;
  std::vector<Lane*> lane_of;
  enqueue_lu_strips(
      items, lu_strip_pivots_, lanes, lu_.items, lu_.cb_items, lu_.work, lu_.bad.data(), pivots,
      lu_.strip_done, &lu_.ahead,
      [&](std::size_t q) {
        const LuFront& fr = fronts[order[q]];
        return !split_front(fr.m, fr.k);  // the team's fronts: split_update
      },
      [&](std::size_t q, Lane& ln) {
        const LuFront& fr = fronts[order[q]];
        const int m = fr.m, k = fr.k;
        if (m == k) return;
        double* a12 = fr.F + static_cast<std::size_t>(k) * m;
        if (split_front(m, k))
          split_update(ln, fr.F, m, k, true, assembled);
        else
          STRATA_CUBLAS(cublasDgemm(ln.blas, CUBLAS_OP_N, CUBLAS_OP_N, m - k, m - k, k, &minus_one,
                                    fr.F + k, m, a12, m, &one, a12 + k, m));
      },
      lane_of);
  for (std::size_t q = 0; q < n; ++q) fronts[order[q]].lane = lane_of[q];
  lu_.fronts_batched += static_cast<index_t>(n);
  // the checks, read once the last strip's kernels are done (the updates go on meanwhile)
  STRATA_CUDA(cudaStreamWaitEvent(lu_.check_stream, lu_.strip_done, 0));
  STRATA_CUDA(cudaMemcpyAsync(lu_.bad_host.data(), lu_.bad.data(), sizeof(int) * n,
                              cudaMemcpyDeviceToHost, lu_.check_stream));
  STRATA_CUDA(cudaStreamSynchronize(lu_.check_stream));
  std::vector<std::size_t> redo;
  for (std::size_t q = 0; q < n; ++q)
    if (lu_.bad_host.data()[q]) redo.push_back(order[q]);
  return redo;
}

std::vector<std::size_t> CudaExecutor::lu_fronts_by_library(std::vector<LuFront>& fronts,
                                                            const numeric::PivotPolicy& pivots,
                                                            cudaEvent_t assembled) {
  const std::size_t n = fronts.size();
  std::size_t ipiv_at = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const LuFront& fr = fronts[i];
    Lane& lane = *fr.lane;
    grow_getrf_work(lane, fr);
    // without pivoting (devIpiv null); kept only where the pivoting rule would have
    // interchanged nothing (kernels_lu.cu)
    STRATA_CUSOLVER(cusolverDnDgetrf(lane.solver, fr.k, fr.k, fr.F, fr.m, lane.getrf_work.data(),
                                     nullptr, lu_.info.data() + i));
    launch_lu_unpivoted_check(fr.F, fr.m, fr.k, pivots.static_pivot, pivots.threshold,
                              lu_.info.data() + i, lu_.ipiv.data() + ipiv_at, lu_.bad.data() + i,
                              lane.stream);
    ipiv_at += static_cast<std::size_t>(fr.k);
  }
  fetch_lu_checks(n);
  std::vector<std::size_t> redo;
  for (std::size_t i = 0; i < n; ++i) {
    if (lu_.bad_host.data()[i]) {
      redo.push_back(i);
      continue;
    }
    const LuFront& fr = fronts[i];
    Lane& lane = *fr.lane;
    STRATA_CUDA(cudaMemsetAsync(fr.perturbed, 0, sizeof(std::int64_t), lane.stream));
    // no interchange: neither the serial ipiv-to-permutation kernel nor DLASWP
    launch_identity_perm(fr.k, fr.perm, lane.stream);
    lu_panels_and_update(fr, nullptr, assembled);
  }
  return redo;
}

void CudaExecutor::lu_panels_and_update(const LuFront& fr, const int* ipiv, cudaEvent_t assembled) {
  const double one = 1.0, minus_one = -1.0;
  Lane& lane = *fr.lane;
  const int m = fr.m, k = fr.k;
  if (m == k) return;
  double* a12 = fr.F + static_cast<std::size_t>(k) * m;
  if (ipiv) launch_laswp(a12, m, m - k, ipiv, k, lane.stream);
  STRATA_CUBLAS(cublasDtrsm(lane.blas, CUBLAS_SIDE_RIGHT, CUBLAS_FILL_MODE_UPPER, CUBLAS_OP_N,
                            CUBLAS_DIAG_NON_UNIT, m - k, k, &one, fr.F, m, fr.F + k, m));
  STRATA_CUBLAS(cublasDtrsm(lane.blas, CUBLAS_SIDE_LEFT, CUBLAS_FILL_MODE_LOWER, CUBLAS_OP_N,
                            CUBLAS_DIAG_UNIT, k, m - k, &one, fr.F, m, a12, m));
  if (split_front(m, k))
    split_update(lane, fr.F, m, k, true, assembled);
  else
    STRATA_CUBLAS(cublasDgemm(lane.blas, CUBLAS_OP_N, CUBLAS_OP_N, m - k, m - k, k, &minus_one,
                              fr.F + k, m, a12, m, &one, a12 + k, m));
}

void CudaExecutor::grow_getrf_work(Lane& lane, const LuFront& fr) {
  int lwork = 0;
  STRATA_CUSOLVER(cusolverDnDgetrf_bufferSize(lane.solver, fr.k, fr.k, fr.F, fr.m, &lwork));
  if (lane.getrf_work.size() < static_cast<std::size_t>(std::max(lwork, 1))) {
    STRATA_CUDA(cudaStreamSynchronize(lane.stream));
    lane.getrf_work.resize(static_cast<std::size_t>(std::max(lwork, 1)));
  }
}

void CudaExecutor::fetch_lu_checks(std::size_t n) {
  for (const auto& l : lanes_) STRATA_CUDA(cudaStreamSynchronize(l->stream));
  STRATA_CUDA(
      cudaMemcpy(lu_.bad_host.data(), lu_.bad.data(), sizeof(int) * n, cudaMemcpyDeviceToHost));
}

void CudaExecutor::lu_fronts_redo(std::vector<LuFront>& fronts,
                                  const std::vector<std::size_t>& redo,
                                  const numeric::PivotPolicy& pivots, cudaEvent_t assembled) {
  const double one = 1.0, minus_one = -1.0;
  // nothing of the rejected fronts may still be in flight on a lane or a helper GPU
  join_team();
  for (const auto& l : lanes_) STRATA_CUDA(cudaStreamSynchronize(l->stream));
  std::vector<std::size_t> ipiv_at(fronts.size() + 1, 0);
  for (std::size_t i = 0; i < fronts.size(); ++i)
    ipiv_at[i + 1] = ipiv_at[i] + static_cast<std::size_t>(fronts[i].k);
  auto reassemble = [&](const LuFront& fr) {
    launch_assemble(cur_->tree, fr.pos, 1, fr.m, values_.data(), pool_.data(), false,
                    fr.lane->stream);
  };
  // GETRF with pivoting (partial pivoting: the CPU's rule only for u = 1); its flags in the
  // first redo.size() slots
  const bool getrf = pivots.threshold >= 1.0;
  for (std::size_t x = 0; getrf && x < redo.size(); ++x) {
    const LuFront& fr = fronts[redo[x]];
    Lane& lane = *fr.lane;
    reassemble(fr);
    grow_getrf_work(lane, fr);
    STRATA_CUSOLVER(cusolverDnDgetrf(lane.solver, fr.k, fr.k, fr.F, fr.m, lane.getrf_work.data(),
                                     lu_.ipiv.data() + ipiv_at[redo[x]], lu_.info.data() + x));
    launch_lu_check(fr.F, fr.m, fr.k, pivots.static_pivot, lu_.info.data() + x, lu_.bad.data() + x,
                    lane.stream);
  }
  lu_.fronts_pivoted += static_cast<index_t>(redo.size());
  if (getrf) fetch_lu_checks(redo.size());
  for (std::size_t x = 0; x < redo.size(); ++x) {
    const LuFront& fr = fronts[redo[x]];
    Lane& lane = *fr.lane;
    const cudaStream_t stream = lane.stream;
    const int m = fr.m, k = fr.k;
    const std::size_t ld = static_cast<std::size_t>(m);
    const int* ipiv = lu_.ipiv.data() + ipiv_at[redo[x]];
    STRATA_CUDA(cudaMemsetAsync(fr.perturbed, 0, sizeof(std::int64_t), stream));
    if (getrf && !lu_.bad_host.data()[x]) {
      launch_ipiv_to_perm(ipiv, k, fr.perm, stream);
      lu_panels_and_update(fr, ipiv, assembled);
      continue;
    }
    // a pivot needs static pivoting, or u < 1: the front again, and the panel-kernel path
    reassemble(fr);
    // iota_ outlives the asynchronous copy (it is a member, only ever grown)
    if (static_cast<int>(iota_.size()) < k) {
      STRATA_CUDA(cudaDeviceSynchronize());
      iota_.resize(k);
      for (int r = 0; r < k; ++r) iota_[r] = r;
    }
    STRATA_CUDA(cudaMemcpyAsync(fr.perm, iota_.data(), sizeof(std::int64_t) * k,
                                cudaMemcpyHostToDevice, stream));
    for (int p0 = 0, w = 0; p0 < k; p0 += w) {
      // the panel's fully summed rows in shared memory — as many columns as fit, up to
      // 64 — then its other rows by a TRSM; or, too tall for kMinTallPanel columns, the
      // whole panel of 64 in global memory
      const std::int64_t fit = lu_tall_panel_columns(k - p0);
      const bool tall = fit >= std::min<std::int64_t>(kMinTallPanel, k - p0);
      w = static_cast<int>(std::min<std::int64_t>(tall ? fit : kLuPanel, k - p0));
      const int rest = m - p0 - w;
      double* a11 = fr.F + static_cast<std::size_t>(p0) * ld + p0;
      if (tall && launch_lu_tall_panel(fr.F, m, k, p0, w, pivots.static_pivot, pivots.threshold,
                                       fr.perm, fr.perturbed, stream)) {
        if (m > k)
          STRATA_CUBLAS(cublasDtrsm(lane.blas, CUBLAS_SIDE_RIGHT, CUBLAS_FILL_MODE_UPPER,
                                    CUBLAS_OP_N, CUBLAS_DIAG_NON_UNIT, m - k, w, &one, a11, m,
                                    a11 + (k - p0), m));
      } else {
        launch_lu_panel(fr.F, m, k, p0, w, pivots.static_pivot, pivots.threshold, fr.perm,
                        fr.perturbed, stream);
      }
      if (rest > 0) {
        double* a12 = fr.F + static_cast<std::size_t>(p0 + w) * ld + p0;
        STRATA_CUBLAS(cublasDtrsm(lane.blas, CUBLAS_SIDE_LEFT, CUBLAS_FILL_MODE_LOWER, CUBLAS_OP_N,
                                  CUBLAS_DIAG_UNIT, w, rest, &one, a11, m, a12, m));
        STRATA_CUBLAS(cublasDgemm(lane.blas, CUBLAS_OP_N, CUBLAS_OP_N, rest, rest, w, &minus_one,
                                  a11 + w, m, a12, m, &one, a12 + w, m));
      }
    }
  }
}

}  // namespace strata::cuda

namespace strata::numeric {

std::vector<char> cuda_lu_fronts_batched(std::vector<std::vector<double>>& fronts,
                                         const std::vector<index_t>& m,
                                         const std::vector<index_t>& k, index_t strip,
                                         double static_pivot, double threshold,
                                         std::vector<std::vector<index_t>>* perms, bool lookahead) {
  const std::size_t n = fronts.size();
  if (m.size() != n || k.size() != n || strip < 1)
    throw InvalidInput("cuda_lu_fronts_batched: " + std::to_string(n) + " fronts, " +
                       std::to_string(m.size()) + " row counts, " + std::to_string(k.size()) +
                       " pivot counts, strip width " + std::to_string(strip));
  std::vector<std::size_t> offset(n + 1, 0);
  for (std::size_t i = 0; i < n; ++i) {
    if (m[i] < 1 || k[i] < 1 || k[i] > m[i] ||
        fronts[i].size() != static_cast<std::size_t>(m[i]) * static_cast<std::size_t>(m[i]))
      throw InvalidInput("cuda_lu_fronts_batched: front " + std::to_string(i) +
                         " needs 1 <= k <= m and m*m values (m = " + std::to_string(m[i]) +
                         ", k = " + std::to_string(k[i]) + ")");
    offset[i + 1] = offset[i] + fronts[i].size();
  }
  STRATA_CUDA(cudaSetDevice(0));
  // the strips take the fronts largest k first
  std::vector<std::size_t> order(n);
  for (std::size_t i = 0; i < n; ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(), [&](auto a, auto b) { return k[a] > k[b]; });
  cuda::DeviceBuffer<double> pool(std::max<std::size_t>(offset[n], 1)), work;
  cuda::DeviceBuffer<cuda::LuPanelItem> items, cb_items;
  cuda::DeviceBuffer<int> bad(std::max<std::size_t>(n, 1));
  // the local permutations, the identity unless the kernels interchange rows
  std::vector<std::size_t> perm_at(n + 1, 0);
  for (std::size_t i = 0; i < n; ++i) perm_at[i + 1] = perm_at[i] + static_cast<std::size_t>(k[i]);
  std::vector<std::int64_t> perm(perm_at[n]);
  for (std::size_t i = 0; i < n; ++i)
    for (index_t r = 0; r < k[i]; ++r) perm[perm_at[i] + r] = r;
  cuda::DeviceBuffer<std::int64_t> dperm(std::max<std::size_t>(perm.size(), 1));
  STRATA_CUDA(cudaMemcpy(dperm.data(), perm.data(), sizeof(std::int64_t) * perm.size(),
                         cudaMemcpyHostToDevice));
  std::vector<cuda::LuPanelItem> fr(n);
  for (std::size_t q = 0; q < n; ++q) {
    const std::size_t i = order[q];
    STRATA_CUDA(cudaMemcpy(pool.data() + offset[i], fronts[i].data(),
                           sizeof(double) * fronts[i].size(), cudaMemcpyHostToDevice));
    fr[q] = {pool.data() + offset[i], m[i], m[i], k[i], k[i], dperm.data() + perm_at[i]};
  }
  cuda::Lane ln;  // the legacy default stream, with a handle of its own
  STRATA_CUBLAS(cublasCreate(&ln.blas));
  STRATA_CUDA(cudaEventCreateWithFlags(&ln.done, cudaEventDisableTiming));
  cudaEvent_t strip_done = nullptr;
  STRATA_CUDA(cudaEventCreateWithFlags(&strip_done, cudaEventDisableTiming));
  struct Handles {
    cublasHandle_t b;
    cudaEvent_t e1, e2;
    cuda::LuLookahead a;
    ~Handles() {
      cublasDestroy(b);
      cudaEventDestroy(e1);
      cudaEventDestroy(e2);
      if (a.stream) cudaStreamDestroy(a.stream);
      if (a.ready) cudaEventDestroy(a.ready);
      if (a.done) cudaEventDestroy(a.done);
    }
  } owned{ln.blas, ln.done, strip_done, {}};
  if (lookahead) {  // the executor's look-ahead stream and events
    STRATA_CUDA(cudaStreamCreateWithFlags(&owned.a.stream, cudaStreamNonBlocking));
    STRATA_CUDA(cudaEventCreateWithFlags(&owned.a.ready, cudaEventDisableTiming));
    STRATA_CUDA(cudaEventCreateWithFlags(&owned.a.done, cudaEventDisableTiming));
  }
  const double one = 1.0, minus_one = -1.0;
  std::vector<cuda::Lane*> lane_of;
  cuda::enqueue_lu_strips(
      fr, strip, {&ln}, items, cb_items, work, bad.data(),
      numeric::PivotPolicy(static_pivot, threshold), strip_done, lookahead ? &owned.a : nullptr,
      [](std::size_t) { return true; },
      [&](std::size_t q, cuda::Lane& l) {
        const int mi = static_cast<int>(fr[q].m), ki = static_cast<int>(fr[q].k);
        double* F = fr[q].F;
        if (mi > ki)
          STRATA_CUBLAS(cublasDgemm(l.blas, CUBLAS_OP_N, CUBLAS_OP_N, mi - ki, mi - ki, ki,
                                    &minus_one, F + ki, mi, F + static_cast<std::size_t>(ki) * mi,
                                    mi, &one, F + static_cast<std::size_t>(ki) * mi + ki, mi));
      },
      lane_of);
  std::vector<int> flags(n);
  STRATA_CUDA(cudaMemcpy(flags.data(), bad.data(), sizeof(int) * n, cudaMemcpyDeviceToHost));
  std::vector<char> kept(n);
  for (std::size_t q = 0; q < n; ++q) kept[order[q]] = flags[q] == 0;
  for (std::size_t i = 0; i < n; ++i)
    STRATA_CUDA(cudaMemcpy(fronts[i].data(), pool.data() + offset[i],
                           sizeof(double) * fronts[i].size(), cudaMemcpyDeviceToHost));
  if (perms) {
    STRATA_CUDA(cudaMemcpy(perm.data(), dperm.data(), sizeof(std::int64_t) * perm.size(),
                           cudaMemcpyDeviceToHost));
    perms->assign(n, {});
    for (std::size_t i = 0; i < n; ++i)
      (*perms)[i].assign(perm.begin() + perm_at[i], perm.begin() + perm_at[i + 1]);
  }
  return kept;
}

}  // namespace strata::numeric
