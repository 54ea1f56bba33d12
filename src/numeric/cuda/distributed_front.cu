// strata — a large Cholesky front factored over the GPU that owns it and the idle GPUs
// of its team, its columns distributed 1-D block-cyclically (several GPUs; issue 6's
// "large top fronts are split across GPUs by tiles", docs/multigpu.md).
//
// What: while GPU 0 factors the top part, every other GPU has nothing left to do (the
// multi-worker driver hands them over as helpers, FactorContext::helpers). A front F
// (m × m, lower triangle, k pivots) with at least Options::distributed_front_min_rows
// rows is then cut into column blocks — the k pivot columns in blocks of nb
// (Options::distributed_front_block_size), then the m − k contribution-block columns in
// blocks of nb — and block j lives on GPU
// j mod G (G: the owner and its helpers): the owner keeps its blocks in place in F, a
// helper copies its blocks (rows from the block's first column down) into its pool (free:
// its own parts are done; sized for the largest chunk of any part, so it holds a share of
// any top front). The
// factorization is LAPACK's right-looking blocked Cholesky (DPOTRF; Golub & Van Loan,
// Matrix Computations, 4th ed., §4.2.9) over that layout, as ScaLAPACK's PDPOTRF does on
// a 1 × G process grid (Choi, Dongarra, Ostrouchov, Petitet, Walker & Whaley, "The
// design and implementation of the ScaLAPACK LU, QR and Cholesky factorization routines",
// Scientific Programming 5, 1996): for each pivot block p,
//   1. its GPU factors it: the diagonal block and the rows below it, by the recursive
//      pivot block and panel of llt_recursive.cu (the one-GPU code for large fronts);
//   2. the factored block — the panel L[c_p:m, p] — is copied to every other GPU that
//      holds a block right of it (peer copies, into one of two panel slots);
//   3. every GPU updates each of its blocks j > p, A[c_j:m, j] −= L[c_j:m, p]·L[c_j:c_j+w_j, p]ᵀ
//      (one DGEMM per block; it also writes the strict upper triangle of the block's
//      diagonal part, which nothing reads: the next step 1 zeroes it for pivot blocks, and
//      the contribution block is read as a lower triangle).
// Lookahead of one step: the GPU holding block p + 1 updates that block first, factors
// it and starts its copies before its other updates of step p, so the next panel is on
// its way while every GPU is still busy with step p (the standard remedy for the serial
// chain of panels; the panels are what ran slowly on one GPU: the recursive pivot block
// and panel of a 4,096-pivot front reached about half the update's rate). A helper's
// pivot block that the owner receives as a panel is written into F from the owner's slot
// as the steps go on; at the end each helper copies its other blocks back into F, so the
// front leaves as the one-GPU code leaves it — its contribution block stored, its panel
// packed, by the chunk as usual.
//
// Why whole columns and not strips of the update (split_update.cu): the pivot block and
// panel, most of a top front's time on one GPU, are spread over the GPUs too, and what
// moves per front is each helper's share of F twice plus every panel once — about
// (m²/2·(G − 1)/G·2 + m·k)·8 bytes over NVLink against m·k²-order flops.
//
// Streams and events (all enqueued by the owner's host thread): each GPU g computes on
// one stream W_g (the owner: the front's lane; a helper: its help lane) and receives
// panels on a copy stream C_g. E_g[p] is recorded on W_g after block p's step 1; the
// copy of panel p to GPU g waits for E[p] and for D_g[p − 2] (g done with the slot it
// overwrites), then records R_g[p]; W_g waits for R_g[p] before its step-3 updates of p
// and records D_g[p] after them. One stream per GPU for compute keeps the blocks' updates
// in step order without more events. A helper's first block is copied out of F on W_g, its
// other blocks on C_g behind panel 0's copy, recording the fill event that W_g waits for
// before its first update of those blocks: the helper starts on its first block and the
// next panel while the rest arrives.
//
// Results: every entry gets the same products as in the one-GPU factorization, in
// another order of summation (blocks of nb columns), so the factor agrees with the
// one-GPU factor to rounding; test_multi_gpu compares within 1e-12. A non-positive pivot
// sets the front's status as one POTRF of order k would (the first failing block's
// column plus its own status), gathered from the GPUs' per-block statuses.
#include <algorithm>

#include "numeric/cuda/cuda_executor.hpp"

namespace strata::cuda {

// Where one GPU of a distributed front keeps things: its executor, its compute stream
// (the owner: the front's lane; a helper: its help lane) and copy stream, its blocks (by
// block index, null when not held here) with their leading dimensions, two panel slots
// and its per-block statuses (P ints, block p's at p).
struct TeamGpu {
  CudaExecutor* ex;
  Lane* work;
  cudaStream_t copy;
  std::vector<double*> block;
  std::vector<std::int64_t> ld;
  double* slots[2];
  int* status;
};

namespace {

// The front's status from the per-block statuses: `all` holds G rows of P ints (row g:
// GPU g's blocks; block p's status is in row p mod G); block p starts at column p·nb.
__global__ void first_failed_block_kernel(const int* all, int P, int G, int nb, int* info) {
  int r = 0;
  for (int p = 0; p < P; ++p) {
    const int v = all[(p % G) * P + p];
    if (v != 0) {
      r = v > 0 ? p * nb + v : v;
      break;
    }
  }
  *info = r;
}

// Event i of `pool`, the pool grown to it first (events created on the current device).
cudaEvent_t event_at(std::vector<cudaEvent_t>& pool, std::size_t i) {
  while (pool.size() <= i) {
    cudaEvent_t e = nullptr;
    STRATA_CUDA(cudaEventCreateWithFlags(&e, cudaEventDisableTiming));
    pool.push_back(e);
  }
  return pool[i];
}

}  // namespace

// The distributed front's layout (distributed_llt): block j of F's columns c[j]..c[j+1]
// on GPU j mod G (the owner and the first G − 1 helpers), the owner's in place in F, a helper's
// packed in its pool; the panel slots and statuses sized, the events made. False, with nothing
// changed that matters, when a helper's pool cannot hold its share or the slots do not fit beside
// the plan.
bool CudaExecutor::team_layout(Lane& lane, double* F, std::int64_t m,
                               const std::vector<std::int64_t>& c, int P, int G,
                               std::vector<TeamGpu>& gpu) {
  const int NB = static_cast<int>(c.size()) - 1;
  const std::int64_t nb = dist_block_;
  auto rows = [&](int j) { return m - c[j]; };
  auto width = [&](int j) { return c[j + 1] - c[j]; };
  const std::size_t slot = static_cast<std::size_t>(m) * static_cast<std::size_t>(nb);
  gpu.assign(G, TeamGpu{});
  for (int g = 0; g < G; ++g) {
    CudaExecutor& x = g == 0 ? *this : *team_.members[g - 1];
    TeamGpu& u = gpu[g];
    u.ex = &x;
    u.block.assign(NB, nullptr);
    u.ld.assign(NB, 0);
    std::size_t need = 0;
    for (int j = g; j < NB; j += G) need += static_cast<std::size_t>(rows(j) * width(j));
    STRATA_CUDA(cudaSetDevice(x.device_));
    if (g > 0 && x.pool_.size() < need) {  // its pool is the helper's room: not this front
      STRATA_CUDA(cudaSetDevice(device_));
      return false;
    }
    try {  // grown once (the chain's first front is its largest); refactorizations reuse it
      x.team_.dist_panels.resize(2 * slot);
      x.team_.dist_status.resize(static_cast<std::size_t>(G) * P);
    } catch (const OutOfMemory&) {  // no room beside the plan: this front on one GPU
      STRATA_CUDA(cudaSetDevice(device_));
      return false;
    }
    u.slots[0] = x.team_.dist_panels.data();
    u.slots[1] = u.slots[0] + slot;
    if (g == 0) {
      for (int j = 0; j < NB; j += G) {
        u.block[j] = F + c[j] * static_cast<std::int64_t>(m) + c[j];
        u.ld[j] = m;
      }
    } else {
      double* at = x.pool_.data();
      for (int j = g; j < NB; j += G) {
        u.block[j] = at;
        u.ld[j] = rows(j);
        at += rows(j) * width(j);
      }
    }
    u.status = x.team_.dist_status.data();
    u.work = g == 0 ? &lane : &x.help_lane();
    u.copy = x.team_.dist_copy;
    // a helper's copies land in its pool: after its own last work (set_team's event)
    if (g > 0) STRATA_CUDA(cudaStreamWaitEvent(u.copy, x.team_.help_ready, 0));
    u.work->diag_work.resize(llt_recursive_work_size(nb));  // no reallocation between steps
    // E, R and D of every step, then the end of the helper's fill (distributed_llt)
    event_at(x.team_.dist_events, 3 * static_cast<std::size_t>(P));
  }
  return true;
}

bool CudaExecutor::distributed_llt(Lane& lane, double* F, int m, int k, int* info) {
  const std::int64_t nb = dist_block_;
  // column bounds: pivot blocks of nb up to k, then contribution-block blocks of nb
  std::vector<std::int64_t> c{0};
  while (c.back() < k) c.push_back(std::min<std::int64_t>(c.back() + nb, k));
  const int P = static_cast<int>(c.size()) - 1;
  while (c.back() < m) c.push_back(std::min<std::int64_t>(c.back() + nb, m));
  const int NB = static_cast<int>(c.size()) - 1;
  // the owner and as many helpers as there are blocks beside its first one
  const int G = std::min(static_cast<int>(team_.members.size()) + 1, NB);
  if (P < 1 || G < 2) return false;
  auto owner = [G](int j) { return j % G; };
  auto rows = [&](int j) { return m - c[j]; };
  auto width = [&](int j) { return c[j + 1] - c[j]; };

  // where each GPU keeps things
  std::vector<TeamGpu> gpu;
  if (!team_layout(lane, F, m, c, P, G, gpu)) return false;
  auto E = [&](int g, int p) { return gpu[g].ex->team_.dist_events[3 * p]; };
  auto R = [&](int g, int p) { return gpu[g].ex->team_.dist_events[3 * p + 1]; };
  auto D = [&](int g, int p) { return gpu[g].ex->team_.dist_events[3 * p + 2]; };
  // whether GPU g holds a block right of block p (its first one after p)
  auto holds_right_of = [&](int g, int p) { return p + 1 + ((g - p - 1) % G + G) % G < NB; };

  // after the previous distributed front (another lane of this chunk may have had one:
  // the helpers' pools and the panel slots are shared), the helpers' blocks copied out
  // of F once it is assembled: a helper's first block on its compute stream (it updates
  // that block first), the others on its copy stream after panel 0 (below: fill), so that
  // the helper starts on its first block and the first panel while the rest arrives
  STRATA_CUDA(cudaSetDevice(device_));
  if (team_.dist_done_recorded) STRATA_CUDA(cudaStreamWaitEvent(lane.stream, team_.dist_done, 0));
  STRATA_CUDA(cudaEventRecord(team_.dist_ready, lane.stream));
  auto copy_out = [&](TeamGpu& u, int j, cudaStream_t stream) {
    const std::size_t rb = sizeof(double) * static_cast<std::size_t>(rows(j));
    STRATA_CUDA(cudaMemcpy2DAsync(u.block[j], rb, F + c[j] * static_cast<std::int64_t>(m) + c[j],
                                  sizeof(double) * m, rb, width(j), cudaMemcpyDefault, stream));
    u.ex->team_.help_bytes += 2 * rb * static_cast<std::size_t>(width(j));  // out and back
  };
  for (int g = 1; g < G; ++g) {
    TeamGpu& u = gpu[g];
    STRATA_CUDA(cudaSetDevice(u.ex->device_));
    STRATA_CUDA(cudaStreamWaitEvent(u.work->stream, team_.dist_ready, 0));
    STRATA_CUDA(cudaStreamWaitEvent(u.copy, team_.dist_ready, 0));
    copy_out(u, g, u.work->stream);
  }
  // the end of helper g's fill: the event after its other blocks' copies
  auto filled = [&](int g) { return gpu[g].ex->team_.dist_events[3 * P]; };
  auto fill = [&](int g) {
    TeamGpu& u = gpu[g];
    STRATA_CUDA(cudaSetDevice(u.ex->device_));
    for (int j = g + G; j < NB; j += G) copy_out(u, j, u.copy);
    STRATA_CUDA(cudaEventRecord(filled(g), u.copy));
  };

  const double one = 1.0, minus_one = -1.0;
  // step 1 of block p on its GPU, then its copies to the GPUs that need it
  auto panel = [&](int p) {
    const int g = owner(p);
    TeamGpu& u = gpu[g];
    STRATA_CUDA(cudaSetDevice(u.ex->device_));
    llt_pivot_block_and_panel_recursive(*u.work, u.block[p], u.ld[p], rows(p), width(p),
                                        u.status + p);
    STRATA_CUDA(cudaEventRecord(E(g, p), u.work->stream));
    for (int h = 0; h < G; ++h) {
      if (h == g || !holds_right_of(h, p)) continue;
      TeamGpu& v = gpu[h];
      STRATA_CUDA(cudaSetDevice(v.ex->device_));
      STRATA_CUDA(cudaStreamWaitEvent(v.copy, E(g, p), 0));
      if (p >= 2) STRATA_CUDA(cudaStreamWaitEvent(v.copy, D(h, p - 2), 0));
      const std::size_t rb = sizeof(double) * static_cast<std::size_t>(rows(p));
      STRATA_CUDA(cudaMemcpy2DAsync(v.slots[p % 2], rb, u.block[p], sizeof(double) * u.ld[p], rb,
                                    width(p), cudaMemcpyDefault, v.copy));
      STRATA_CUDA(cudaEventRecord(R(h, p), v.copy));
      (h == 0 ? u.ex : v.ex)->team_.help_bytes += rb * static_cast<std::size_t>(width(p));
    }
  };
  // step 3: block j (on GPU g) updated by panel p
  auto update = [&](int g, int j, int p) {
    TeamGpu& u = gpu[g];
    const bool here = owner(p) == g;
    const double* L = here ? u.block[p] : u.slots[p % 2];
    const std::int64_t ldl = here ? u.ld[p] : rows(p);
    const double* Lj = L + (c[j] - c[p]);
    STRATA_CUBLAS(cublasDgemm(u.work->blas, CUBLAS_OP_N, CUBLAS_OP_T, static_cast<int>(rows(j)),
                              static_cast<int>(width(j)), static_cast<int>(width(p)), &minus_one,
                              Lj, static_cast<int>(ldl), Lj, static_cast<int>(ldl), &one,
                              u.block[j], static_cast<int>(u.ld[j])));
  };

  panel(0);
  for (int g = 1; g < G; ++g) fill(g);  // queued behind panel 0's copy to g
  // a helper's pivot block that the owner received as a panel goes into F from there, on
  // the owner's stream while the factorization goes on, not back from the helper at the end
  auto placed_by_owner = [&](int p) { return p < P && owner(p) != 0 && holds_right_of(0, p); };
  for (int p = 0; p < P; ++p)
    for (int g = 0; g < G; ++g) {
      if (!holds_right_of(g, p)) continue;
      TeamGpu& u = gpu[g];
      STRATA_CUDA(cudaSetDevice(u.ex->device_));
      if (owner(p) != g) STRATA_CUDA(cudaStreamWaitEvent(u.work->stream, R(g, p), 0));
      int first = p + 1;
      if (p + 1 < P && owner(p + 1) == g) {  // lookahead: the next panel first
        update(g, p + 1, p);
        panel(p + 1);
        STRATA_CUDA(cudaSetDevice(u.ex->device_));
        first = p + 2;
      }
      for (int j = first; j < NB; ++j) {
        if (owner(j) != g) continue;
        // a helper's blocks after its first are there once its fill is (step 0 only:
        // the stream then holds the wait for the later steps)
        if (p == 0 && g > 0 && j > g)
          STRATA_CUDA(cudaStreamWaitEvent(u.work->stream, filled(g), 0));
        update(g, j, p);
      }
      if (g == 0 && placed_by_owner(p)) {  // before D(0, p): slot p mod 2 is read here
        const std::size_t rb = sizeof(double) * static_cast<std::size_t>(rows(p));
        STRATA_CUDA(cudaMemcpy2DAsync(F + c[p] * static_cast<std::int64_t>(m) + c[p],
                                      sizeof(double) * m, u.slots[p % 2], rb, rb, width(p),
                                      cudaMemcpyDeviceToDevice, u.work->stream));
      }
      STRATA_CUDA(cudaEventRecord(D(g, p), u.work->stream));
    }

  // the helpers' other blocks and statuses back to the owner; the owner waits for them
  for (int g = 1; g < G; ++g) {
    TeamGpu& u = gpu[g];
    STRATA_CUDA(cudaSetDevice(u.ex->device_));
    for (int j = g; j < NB; j += G) {
      if (placed_by_owner(j)) continue;
      const std::size_t rb = sizeof(double) * static_cast<std::size_t>(rows(j));
      STRATA_CUDA(cudaMemcpy2DAsync(F + c[j] * static_cast<std::int64_t>(m) + c[j],
                                    sizeof(double) * m, u.block[j], rb, rb, width(j),
                                    cudaMemcpyDefault, u.work->stream));
    }
    STRATA_CUDA(cudaMemcpyAsync(gpu[0].status + static_cast<std::size_t>(g) * P, u.status,
                                sizeof(int) * P, cudaMemcpyDefault, u.work->stream));
    STRATA_CUDA(cudaEventRecord(u.ex->team_.help_done, u.work->stream));
    u.ex->team_.helped = true;
    STRATA_CUDA(cudaSetDevice(device_));
    STRATA_CUDA(cudaStreamWaitEvent(lane.stream, u.ex->team_.help_done, 0));
  }
  STRATA_CUDA(cudaSetDevice(device_));
  first_failed_block_kernel<<<1, 1, 0, lane.stream>>>(gpu[0].status, P, G, static_cast<int>(nb),
                                                      info);
  STRATA_CUDA_LAUNCH();
  STRATA_CUDA(cudaEventRecord(team_.dist_done, lane.stream));
  team_.dist_done_recorded = true;
  ++team_.fronts_distributed;
  return true;
}

}  // namespace strata::cuda
