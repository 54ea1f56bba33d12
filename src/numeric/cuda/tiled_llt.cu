// strata — a Cholesky front larger than the device budget, factored through the device
// in pieces (issue 5's "any device memory").
//
// The front F (m × m, k pivots, contribution block of mc = m − k rows) never exists
// whole: its k pivot columns P = [L11; L21] (m × k, leading dimension m — the panel's
// layout) are assembled into pinned host memory, its contribution block C (lower
// triangle, mc × mc) straight into its destination, the pinned host arena or — when
// the plan kept it on the device — a staging area uploaded once (tiled_host.cpp).
//
//   1. The pivot columns, left-looking by slabs of w columns. For slab J (columns
//      p0 .. p0+w, rows p0 .. m): upload it; for the earlier columns, piece by piece
//      (pieces of wq columns), upload their rows p0 .. m on a copy lane (two lanes, two
//      buffers: one's copy runs while the other's update computes) and subtract
//      L_q·L_q[top]ᵀ (SYRK on the w × w top, GEMM below); factor the slab (POTRF and
//      TRSM, or the recursive panel); download it. Nothing of the slab goes back to the
//      host until it is final. w and wq: tiled_llt_widths — by default a third of the
//      pool each (w = wq = pool / 3m); with Options::gpu_tiled_stream_columns = s > 0,
//      wq ≤ s and the slab takes the rest (w ≈ pool/m − 2s).
//   2. The contribution block, C −= L21·L21ᵀ, by square tiles of b rows: for each tile
//      row i, its rows of L21 (b × k) stay on the device while, for j ≤ i, the tile C_ij
//      comes in on a lane of its own (lanes 3 and 4) and the rows of tile row j in pieces
//      of kc columns on the copy lanes (kc = k by default, ≤ s with the option), one GEMM
//      per piece updates the tile (the whole square of a diagonal tile: the upper
//      triangle of a block is never read), and it goes back. b is the largest with
//      b·k + 2·b·kc + 2·b² doubles in the pool (without the 2·b² when C is on the
//      device: the tiles are updated in place there).
//
// With Options::gpu_tiled_prefetch, once a front is assembled the host starts assembling
// the next tiled front of the same level on a thread of its own (start_tiled_prefetch)
// while this thread drives the device through steps 1 and 2 and the fronts between the
// two: nothing it reads or writes is touched by them (the blocks of a level's children
// and the blocks the level writes lie apart), its children's blocks that the device holds
// are copied over before it starts, and a block whose place is on the device is assembled
// into the panel buffer's tail like an unprefetched front's. A pending one is joined
// before any failure leaves the executor (factor_batch) and at every part's start and end. Both
// panel buffers are sized once, at the largest tiled front's need (presize_chunk_buffers): they
// trade places at every prefetched front, and when each grew on demand the prefetch was slower
// than none — each growth is a cudaFreeHost, which waits for the device, and the pinning of the
// pages again.
//
// Traffic, against the right-looking slab scheme this replaced (every slab read and
// wrote the whole trailing lower triangle, about k·m²/(2w) doubles each way): step 1
// reads about k²·m/(2w) and writes the panel once; step 2 reads about mc²·(k/b + 1)/2
// and writes the lower triangle of C once — b ≫ w on a front that does not fit, so the
// contribution block, the bulk of a top front, is read a few times instead of k/w times,
// and written once. Narrow pieces (the option) make w and b larger still — up to 3× —
// for products of depth s instead of w or k (bench/REPORT.md §4 measures the default
// pieces).
//
// Source: the left-looking (jki / "lazy") Cholesky of Golub & Van Loan, "Matrix
// Computations", 4th ed., §4.2.8–4.2.9, with the slab as the unit of transfer, and the
// tiled out-of-core product whose traffic falls as the square root of the memory, as in
// Toledo, "A survey of out-of-core algorithms in numerical linear algebra" (1999) §2–3.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <future>

#include "base/host_copy.hpp"
#include "numeric/cuda/cuda_executor.hpp"

namespace strata::cuda {

// Two events, destroyed on every way out (a failed pivot throws mid-front).
struct EventPair {
  cudaEvent_t ev[2] = {};
  EventPair() {
    for (auto& e : ev) STRATA_CUDA(cudaEventCreateWithFlags(&e, cudaEventDisableTiming));
  }
  ~EventPair() {
    for (auto& e : ev)
      if (e) (void)cudaEventDestroy(e);
  }
  EventPair(const EventPair&) = delete;
  EventPair& operator=(const EventPair&) = delete;
};

// The front factor_tiled_llt works on: front f (m rows, k pivots) assembled in the host
// buffers P (its first k columns, m × k) and C (its contribution block, (m−k)², or null
// for a root), C's place in the arena (dst) on the device or in host memory.
struct CudaExecutor::TiledLltFront {
  index_t f;
  std::int64_t m, k;
  double* P;
  double* C;
  double* dst;
  bool cb_on_host;
};

namespace {

// The copy lanes 1–4 start after everything on `main` so far (the slab or panel they
// read was downloaded there).
void follow_main_stream(std::vector<std::unique_ptr<Lane>>& lane, cudaStream_t main) {
  STRATA_CUDA(cudaEventRecord(lane[0]->done, main));
  for (int l = 1; l <= 4; ++l) STRATA_CUDA(cudaStreamWaitEvent(lane[l]->stream, lane[0]->done, 0));
}

// The largest tile side b ≤ cap with b·k + 2·b·kc + (c_tiles ? 2·b² : 0) ≤ pool, at least
// 1: the tile row's rows of L21 (b × k), two streamed pieces of another tile row's (b × kc)
// and, when the block is on the host, two tiles of it.
std::int64_t tile_side(std::size_t pool, std::int64_t k, std::int64_t kc, std::int64_t cap,
                       bool c_tiles) {
  const double p = static_cast<double>(pool), lin = static_cast<double>(k + 2 * kc);
  const double b = c_tiles ? (std::sqrt(lin * lin + 8 * p) - lin) / 4 : p / std::max(lin, 1.0);
  auto need = [&](std::int64_t s) {
    return static_cast<double>(s) * lin + (c_tiles ? 2 * static_cast<double>(s) * s : 0);
  };
  std::int64_t s = std::min<std::int64_t>(cap, static_cast<std::int64_t>(b));
  while (s > 1 && need(s) > p) --s;
  return std::max<std::int64_t>(s, 1);
}

}  // namespace

CudaExecutor::TiledWidths CudaExecutor::tiled_llt_widths(std::int64_t m, std::int64_t k) const {
  TiledWidths tw;
  const std::int64_t third = slab_width(m, k);  // three pieces of m rows: at least 1, at most k
  if (tiled_.stream_cols <= 0) {
    tw.slab = tw.stream = third;
    return tw;
  }
  tw.stream = std::min<std::int64_t>(third, tiled_.stream_cols);
  const std::int64_t rest = static_cast<std::int64_t>(plan_.pool) / m - 2 * tw.stream;
  tw.slab =
      std::max<std::int64_t>(tw.stream, std::min<std::int64_t>(std::max<std::int64_t>(k, 1), rest));
  return tw;
}

bool CudaExecutor::take_tiled_prefetch(int part, index_t pos) {
  if (!tiled_.prefetch.done.valid()) return false;
  const bool mine = tiled_.prefetch.part == part && tiled_.prefetch.pos == pos;
  auto done = std::move(tiled_.prefetch.done);
  tiled_.prefetch = TiledFronts::Prefetch{};
  try {
    done.get();
  } catch (...) {  // a failed assembly (an allocation): the front is assembled again
    return false;
  }
  return mine;
}

void CudaExecutor::start_tiled_prefetch(const numeric::FactorContext& ctx, index_t f, index_t pos) {
  if (!tiled_.prefetch_on || ctx.type != MatrixType::spd) return;
  const Analysis& an = *ctx.analysis;
  const auto& t = an.tree;
  const auto& s = *ctx.part->schedule;
  // the next tiled front of f's level: the fronts of a level are one another's inputs
  // neither way, and its tiled fronts are most often apart, between fronts that are not
  // tiled (lap3d 100³ under 1/20 of its factor: 52 tiled fronts, none next to another)
  const index_t n = static_cast<index_t>(s.fronts.size()), level = s.level_of[f];
  index_t next = pos + 1;
  while (next < n && s.level_of[s.fronts[next]] == level && !cur_->tiled[next]) ++next;
  if (next >= n || s.level_of[s.fronts[next]] != level) return;
  const index_t g = s.fronts[next];
  // every input final: the children are a level below, enqueued on stream_ before the
  // level's first tiled front, whose own assembly waited for stream_ (that front is never
  // a prefetched one). What the fronts between f and g write (their blocks, their panels)
  // and read (their children's blocks) lies apart from g's block and g's inputs: the
  // arena layout keeps apart the blocks a level writes and every block it reads
  // (schedule/memory_plan.hpp).
  const std::int64_t m = t.n_rows(g), k = t.n_pivots(g), mc = m - k;
  const bool has_cb = mc > 0 && t.parent[g] >= 0;
  double* const dst = has_cb ? cur_->cb_ptr_host[g] : nullptr;
  const bool cb_on_host = has_cb && in_host_arena(dst);
  std::vector<const double*> block;
  std::size_t staged = 0;  // children's blocks on the device: copied into tiled_.staging_next
  for (index_t q = t.child_offsets[g]; q < t.child_offsets[g + 1]; ++q) {
    const index_t c = t.children[q];
    const std::size_t cm = static_cast<std::size_t>(t.cb_size(c));
    const double* cb = cm > 0 ? cur_->cb_ptr_host[c] : nullptr;
    if (cb && !in_host_arena(cb)) staged += cm * cm;
    block.push_back(cb);
  }
  // the panel, and the block when its place is on the device (uploaded once at g's turn,
  // from the same place as an unprefetched front's: factor_tiled_llt)
  const std::size_t panel = static_cast<std::size_t>(m) * k;
  try {
    tiled_.front_next.resize(panel +
                             (has_cb && !cb_on_host ? static_cast<std::size_t>(mc) * mc : 0));
    if (staged > 0) tiled_.staging_next.resize(staged);
  } catch (const OutOfMemory&) {  // no room for a second panel buffer: no prefetch
    return;
  }
  double* const P = tiled_.front_next.data();
  double* const C = !has_cb ? nullptr : cb_on_host ? dst : P + panel;
  if (staged > 0) {  // on stream_, after the level below; waited for here (they are small:
                     // the device holds only the arena's first part)
    double* to = tiled_.staging_next.data();
    for (std::size_t i = 0; i < block.size(); ++i) {
      if (!block[i] || in_host_arena(block[i])) continue;
      const std::size_t cm =
          static_cast<std::size_t>(t.cb_size(t.children[t.child_offsets[g] + i]));
      STRATA_CUDA(
          cudaMemcpyAsync(to, block[i], sizeof(double) * cm * cm, cudaMemcpyDeviceToHost, stream_));
      bytes_d2h_ += sizeof(double) * cm * cm;
      block[i] = to;
      to += cm * cm;
    }
    STRATA_CUDA(cudaStreamSynchronize(stream_));
  }
  const double* values = ctx.values;
  tiled_.prefetch.part = ctx.part->id;
  tiled_.prefetch.pos = next;
  tiled_.prefetch.done = std::async(std::launch::async, [this, &an, values, g, P, C, block] {
    assemble_llt_split_from(an, values, g, P, C, block);
  });
}

// Step 1 of a tiled Cholesky front: the pivot columns, left-looking by slabs: each slab
// of w columns comes to the device, takes the updates of the earlier columns (streamed in
// pieces on lanes 1 and 2, double-buffered), is factored (pivot block and panel) and goes
// back to P. Throws NotPositiveDefinite naming the column.
void CudaExecutor::tiled_llt_pivot_columns(const numeric::FactorContext& ctx,
                                           const TiledLltFront& fr, EventPair& computed) {
  const Analysis& an = *ctx.analysis;
  const auto& t = an.tree;
  const index_t f = fr.f;
  const std::int64_t m = fr.m, k = fr.k;
  double* const P = fr.P;
  std::vector<std::unique_ptr<Lane>>& lane = lanes();
  Lane& main = *lane[0];  // stream_ and blas_: the arithmetic
  const double one = 1.0, minus_one = -1.0;
  const TiledWidths tw = tiled_llt_widths(m, k);
  const std::int64_t w_max = tw.slab, wq_max = tw.stream;
  double* const S = pool_.data();
  double* const B[2] = {S + static_cast<std::size_t>(m) * w_max,
                        S + static_cast<std::size_t>(m) * (w_max + wq_max)};
  potrf_info_.resize(1);
  for (std::int64_t p0 = 0; p0 < k; p0 += w_max) {
    const std::int64_t w = std::min(w_max, k - p0), r = m - p0;
    copy_host_block(stream_, S, P, m, p0, p0, r, w, true);
    bytes_h2d_ += sizeof(double) * r * w;
    follow_main_stream(lane, stream_);
    std::int64_t use = 0;
    for (std::int64_t q0 = 0; q0 < p0; q0 += wq_max, ++use) {  // earlier columns, by pieces
      const std::int64_t wq = std::min(wq_max, p0 - q0);
      const int slot = static_cast<int>(use % 2);
      Lane& ln = *lane[1 + slot];
      STRATA_CUDA(cudaStreamWaitEvent(ln.stream, computed.ev[slot], 0));
      copy_host_block(ln.stream, B[slot], P, m, p0, q0, r, wq, true);  // rows p0..m
      bytes_h2d_ += sizeof(double) * r * wq;
      STRATA_CUDA(cudaEventRecord(ln.done, ln.stream));
      STRATA_CUDA(cudaStreamWaitEvent(stream_, ln.done, 0));
      STRATA_CUBLAS(cublasDsyrk(main.blas, CUBLAS_FILL_MODE_LOWER, CUBLAS_OP_N, static_cast<int>(w),
                                static_cast<int>(wq), &minus_one, B[slot], static_cast<int>(r),
                                &one, S, static_cast<int>(r)));
      if (r > w)
        STRATA_CUBLAS(cublasDgemm(main.blas, CUBLAS_OP_N, CUBLAS_OP_T, static_cast<int>(r - w),
                                  static_cast<int>(w), static_cast<int>(wq), &minus_one,
                                  B[slot] + w, static_cast<int>(r), B[slot], static_cast<int>(r),
                                  &one, S + w, static_cast<int>(r)));
      STRATA_CUDA(cudaEventRecord(computed.ev[slot], stream_));
    }
    if (recursive_panel_) {  // the slab is an r × r front's first w columns, ld r
      llt_pivot_block_and_panel_recursive(main, S, r, w, potrf_info_.data());
    } else {
      grow_potrf_work(solver_, potrf_work_, S, static_cast<int>(w), static_cast<int>(r));
      STRATA_CUSOLVER(cusolverDnDpotrf(solver_, CUBLAS_FILL_MODE_LOWER, static_cast<int>(w), S,
                                       static_cast<int>(r), potrf_work_.data(),
                                       static_cast<int>(potrf_work_.size()), potrf_info_.data()));
      if (r > w)
        STRATA_CUBLAS(cublasDtrsm(main.blas, CUBLAS_SIDE_RIGHT, CUBLAS_FILL_MODE_LOWER, CUBLAS_OP_T,
                                  CUBLAS_DIAG_NON_UNIT, static_cast<int>(r - w),
                                  static_cast<int>(w), &one, S, static_cast<int>(r), S + w,
                                  static_cast<int>(r)));
    }
    int info = 0;
    STRATA_CUDA(
        cudaMemcpyAsync(&info, potrf_info_.data(), sizeof(int), cudaMemcpyDeviceToHost, stream_));
    STRATA_CUDA(cudaStreamSynchronize(stream_));
    if (info > 0)
      throw NotPositiveDefinite(an.perm[t.first_pivot[f] + p0 + info - 1], std::nan(""));
    copy_host_block(stream_, S, P, m, p0, p0, r, w, false);
    bytes_d2h_ += sizeof(double) * r * w;
  }
}

// Step 2: the contribution block, C −= L21·L21ᵀ by tiles of the lower triangle: a tile
// row's rows of L21 on stream_, the other tile row's in pieces on lanes 1 and 2, the
// tile itself in place on the device or, for a block in host memory, brought over and
// back on lanes 3 and 4.
void CudaExecutor::tiled_llt_cb_update(const TiledLltFront& fr, EventPair& computed) {
  const std::int64_t m = fr.m, k = fr.k, mc = fr.m - fr.k;
  const bool cb_on_host = fr.cb_on_host;
  double* const P = fr.P;
  double* const C = fr.C;
  double* const dst = fr.dst;
  std::vector<std::unique_ptr<Lane>>& lane = lanes();
  Lane& main = *lane[0];
  const double one = 1.0, minus_one = -1.0;
  // another tile row's rows of L21 come in pieces of kc columns (all k by default)
  const std::int64_t kc = tiled_.stream_cols > 0 ? std::min(k, tiled_.stream_cols) : k;
  const std::int64_t b = tile_side(plan_.pool, k, kc, mc, cb_on_host);
  const std::size_t bk = static_cast<std::size_t>(b) * k, bkc = static_cast<std::size_t>(b) * kc;
  double* const Li = pool_.data();
  double* const Lj[2] = {Li + bk, Li + bk + bkc};
  double* const Ct[2] = {Li + bk + 2 * bkc, Li + bk + 2 * bkc + static_cast<std::size_t>(b) * b};
  follow_main_stream(lane, stream_);  // the panel's last slab has been downloaded
  std::int64_t use = 0, tiles = 0;
  for (std::int64_t ri = 0; ri < mc; ri += b) {
    const std::int64_t bi = std::min(b, mc - ri);
    // on stream_, after the previous tile row's updates that read it
    copy_host_block(stream_, Li, P, m, k + ri, 0, bi, k, true);
    bytes_h2d_ += sizeof(double) * bi * k;
    for (std::int64_t rj = 0; rj <= ri; rj += b, ++tiles) {
      const std::int64_t bj = std::min(b, mc - rj);
      // the tile: in place on the device, or brought over on a lane of its own (3, 4)
      const int ts = static_cast<int>(tiles % 2);
      Lane& tl = *lane[3 + ts];
      double* tile = dst + rj * mc + ri;
      std::int64_t ldt = mc;
      if (cb_on_host) {
        tile = Ct[ts];
        ldt = bi;
        copy_host_block(tl.stream, tile, C, mc, ri, rj, bi, bj, true);  // after its last use
        bytes_h2d_ += sizeof(double) * bi * bj;
        STRATA_CUDA(cudaEventRecord(tl.done, tl.stream));
        STRATA_CUDA(cudaStreamWaitEvent(stream_, tl.done, 0));
      }
      for (std::int64_t c0 = 0; c0 < k; c0 += kc) {
        const std::int64_t kcc = std::min(kc, k - c0);
        const double* L = Li + c0 * bi;  // the diagonal tile: its own rows
        std::int64_t ldl = bi;
        int slot = -1;
        if (rj != ri) {  // tile row j's rows, this piece, on a copy lane
          slot = static_cast<int>(use++ % 2);
          Lane& ln = *lane[1 + slot];
          STRATA_CUDA(cudaStreamWaitEvent(ln.stream, computed.ev[slot], 0));
          copy_host_block(ln.stream, Lj[slot], P, m, k + rj, c0, bj, kcc, true);
          bytes_h2d_ += sizeof(double) * bj * kcc;
          STRATA_CUDA(cudaEventRecord(ln.done, ln.stream));
          STRATA_CUDA(cudaStreamWaitEvent(stream_, ln.done, 0));
          L = Lj[slot];
          ldl = bj;
        }
        STRATA_CUBLAS(cublasDgemm(main.blas, CUBLAS_OP_N, CUBLAS_OP_T, static_cast<int>(bi),
                                  static_cast<int>(bj), static_cast<int>(kcc), &minus_one,
                                  Li + c0 * bi, static_cast<int>(bi), L, static_cast<int>(ldl),
                                  &one, tile, static_cast<int>(ldt)));
        if (slot >= 0) STRATA_CUDA(cudaEventRecord(computed.ev[slot], stream_));
      }
      if (cb_on_host) {  // back, on its lane, once updated
        STRATA_CUDA(cudaEventRecord(main.done, stream_));
        STRATA_CUDA(cudaStreamWaitEvent(tl.stream, main.done, 0));
        copy_host_block(tl.stream, tile, C, mc, ri, rj, bi, bj, false);
        bytes_d2h_ += sizeof(double) * bi * bj;
      }
    }
  }
  for (int l = 1; l <= 4; ++l) {  // the pieces' and the tiles' copies
    STRATA_CUDA(cudaEventRecord(lane[l]->done, lane[l]->stream));
    STRATA_CUDA(cudaStreamWaitEvent(stream_, lane[l]->done, 0));
  }
}

void CudaExecutor::factor_tiled_llt(const numeric::FactorContext& ctx, index_t pos) {
  const auto wall_start = std::chrono::steady_clock::now();
  const Analysis& an = *ctx.analysis;
  const auto& t = an.tree;
  const index_t f = ctx.part->schedule->fronts[pos];
  const std::int64_t m = t.n_rows(f), k = t.n_pivots(f), mc = m - k;
  ++tiled_.count;
  ++chunks_;
  const bool has_cb = mc > 0 && t.parent[f] >= 0;  // a root's block is not needed
  double* const dst = has_cb ? cur_->cb_ptr_host[f] : nullptr;
  const bool cb_on_host = has_cb && in_host_arena(dst);
  const std::size_t panel_doubles = static_cast<std::size_t>(m) * k;
  // assembled already, beside the previous front's device work (start_tiled_prefetch)?
  const bool assembled = take_tiled_prefetch(ctx.part->id, pos);
  if (assembled) {
    tiled_.front.swap(tiled_.front_next);
    ++tiled_.prefetched;
  }
  tiled_.front.resize(panel_doubles +
                      (has_cb && !cb_on_host ? static_cast<std::size_t>(mc) * mc : 0));
  double* const P = tiled_.front.data();
  double* const C = !has_cb ? nullptr : cb_on_host ? dst : P + panel_doubles;
  if (!assembled) assemble_llt_split(ctx, f, P, C);  // tiled_host.cpp
  start_tiled_prefetch(ctx, f, pos);  // the next tiled front's, while this one's goes on
  if (has_cb && !cb_on_host) {        // the block's place is on the device: it goes there once
    STRATA_CUDA(cudaMemcpyAsync(dst, C, sizeof(double) * mc * mc, cudaMemcpyHostToDevice, stream_));
    bytes_h2d_ += sizeof(double) * mc * mc;
  }
  const auto slabs_start = std::chrono::steady_clock::now();
  phases_.tiled_assembly += std::chrono::duration<double>(slabs_start - wall_start).count();

  TiledLltFront fr{f, m, k, P, C, dst, cb_on_host};
  EventPair computed;  // per buffer: the last update that read it was enqueued
  for (cudaEvent_t e : computed.ev) STRATA_CUDA(cudaEventRecord(e, stream_));
  tiled_llt_pivot_columns(ctx, fr, computed);

  // (waits for the last slab's download: the split of tiled_slabs between the two steps)
  STRATA_CUDA(cudaStreamSynchronize(stream_));
  const auto update_start = std::chrono::steady_clock::now();
  phases_.tiled_pivot_columns += std::chrono::duration<double>(update_start - slabs_start).count();

  if (has_cb && k > 0) tiled_llt_cb_update(fr, computed);
  STRATA_CUDA(cudaStreamSynchronize(stream_));

  const auto store_start = std::chrono::steady_clock::now();
  phases_.tiled_cb_update += std::chrono::duration<double>(store_start - update_start).count();
  phases_.tiled_slabs += std::chrono::duration<double>(store_start - slabs_start).count();
  // the panel to the host factor (and the resident device factor, if any)
  double* panel = ctx.factor->panels.data() + an.factor_layout.panel_offset[f];
  parallel_copy(panel, P, panel_doubles);
  if (keep_resident()) {
    STRATA_CUDA(cudaMemcpyAsync(panels_.data() + an.factor_layout.panel_offset[f], P,
                                sizeof(double) * panel_doubles, cudaMemcpyHostToDevice, stream_));
    bytes_h2d_ += sizeof(double) * panel_doubles;
    STRATA_CUDA(cudaStreamSynchronize(stream_));
  }
  std::vector<std::int64_t> lperm(k);
  std::vector<double> diag(k);
  for (std::int64_t i = 0; i < k; ++i) {
    lperm[i] = i;
    diag[i] = P[i * m + i];
  }
  finish_front(ctx, f, -1, 0, lperm.data(), diag.data());
  const auto end = std::chrono::steady_clock::now();
  phases_.tiled_store += std::chrono::duration<double>(end - store_start).count();
  phases_.tiled_fronts += std::chrono::duration<double>(end - wall_start).count();
}

}  // namespace strata::cuda
