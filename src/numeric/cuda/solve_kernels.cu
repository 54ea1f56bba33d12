// strata — CUDA kernels of the triangular solves (see solve_kernels.cuh): thin __global__
// wrappers around the device code of solve_device.cuh, which the CPU tests also run, the
// permutation and scaling of the right-hand sides into the factor's numbering and of the
// solutions back, and the GEMV of the library-path fronts' products (launch_gemv_n).
#include <algorithm>
#include <cfloat>
#include <cuda/atomic>
#include <limits>
#include <string>
#include <vector>

#include "numeric/cuda/cuda_check.hpp"
#include "numeric/cuda/device_buffer.hpp"
#include "numeric/cuda/multiprocessors.hpp"
#include "numeric/cuda/solve_device.cuh"
#include "numeric/cuda/solve_kernels.cuh"
#include "numeric/cuda_testing.hpp"

namespace strata::cuda {
namespace {

// gather/scatter and the diagonal: one thread per row (whole warps: backward_partials)
constexpr int kThreads = 256;
constexpr int kSweepThreads = 256;  // one front: 8 warps (a multiple of 32, solve_device.cuh)
// the sweeps and the forward scatter of the tall and library fronts: few blocks, many loads
// in flight per thread (solve_device::tile_dot)
constexpr int kTallBatch = 16;
static_assert(kSweepThreads % 32 == 0 && kThreads % 32 == 0, "the sweeps work in whole warps");

__device__ void chunk_rows(const SolveTree& t, SolveChunks c, std::int64_t at, std::int64_t* f,
                           std::int64_t* i0, std::int64_t* i1) {
  *f = c.front[at];
  *i0 = c.row[at];
  *i1 = solve_device::min64(*i0 + kChunkRows, t.n_rows[*f]);
}

__global__ void gather_forward_kernel(SolveTree t, SolveChunks c, std::int64_t begin,
                                      const double* x, const double* u, double* scratch,
                                      std::int64_t nrhs) {
  std::int64_t f, i0, i1;
  chunk_rows(t, c, begin + blockIdx.x, &f, &i0, &i1);
  solve_device::gather_forward(t, f, i0, i1, x, u, scratch, nrhs);
}

__global__ void scatter_forward_kernel(SolveTree t, SolveChunks c, std::int64_t begin, double* x,
                                       double* u, const double* scratch, std::int64_t nrhs,
                                       bool lu) {
  std::int64_t f, i0, i1;
  chunk_rows(t, c, begin + blockIdx.x, &f, &i0, &i1);
  solve_device::scatter_forward<kTallBatch>(t, f, i0, i1, x, u, scratch, nrhs, lu);
}

__global__ void gather_backward_kernel(SolveTree t, SolveChunks c, std::int64_t begin,
                                       const double* x, double* scratch, std::int64_t nrhs,
                                       bool lu) {
  std::int64_t f, i0, i1;
  chunk_rows(t, c, begin + blockIdx.x, &f, &i0, &i1);
  solve_device::gather_backward(t, f, i0, i1, x, scratch, nrhs, lu);
  solve_device::backward_partials(t, f, i0, i1, x, nrhs, lu);
}

__global__ void scatter_backward_kernel(SolveTree t, SolveChunks c, std::int64_t begin, double* x,
                                        const double* scratch, std::int64_t nrhs, bool lu) {
  std::int64_t f, i0, i1;
  chunk_rows(t, c, begin + blockIdx.x, &f, &i0, &i1);
  solve_device::scatter_backward(t, f, i0, i1, x, scratch, nrhs, lu);
}

__global__ void __launch_bounds__(kSweepThreads, 2)
    sweep_forward_kernel(SolveTree t, const std::int64_t* fronts, std::int64_t begin,
                         double* scratch, std::int64_t nrhs, bool unit) {
  solve_device::sweep_forward<kTallBatch>(t, fronts[begin + blockIdx.x], scratch, nrhs, unit);
}

__global__ void __launch_bounds__(kSweepThreads, 2)
    sweep_backward_kernel(SolveTree t, const std::int64_t* fronts, std::int64_t begin,
                          double* scratch, std::int64_t nrhs, bool lu, bool unit) {
  solve_device::sweep_backward<kTallBatch>(t, fronts[begin + blockIdx.x], scratch, nrhs, lu, unit);
}

// Block q solves fronts first[begin + q] .. last[begin + q] in that order (forward) or in
// the reverse order (backward): one front per block for a level's fronts (first == last),
// a subtree in postorder for the subtrees. Batch 16 (launches of at most kFewFrontBlocks
// blocks): more loads in flight per thread, 128 registers, two blocks per SM; Batch 4: 64
// registers, four blocks per SM, for launches of many blocks.
template <int Batch>
__global__ void __launch_bounds__(kSweepThreads, Batch >= 16 ? 2 : 4)
    fronts_forward_kernel(SolveTree t, const std::int64_t* first, const std::int64_t* last,
                          std::int64_t begin, double* x, double* u, double* scratch,
                          std::int64_t nrhs, bool unit, bool lu) {
  const std::int64_t q = begin + blockIdx.x;
  for (std::int64_t f = first[q]; f <= last[q]; ++f)
    solve_device::front_forward<Batch>(t, f, x, u, scratch, nrhs, unit, lu);
}

template <int Batch>
__global__ void __launch_bounds__(kSweepThreads, Batch >= 16 ? 2 : 4)
    fronts_backward_kernel(SolveTree t, const std::int64_t* first, const std::int64_t* last,
                           std::int64_t begin, double* x, double* scratch, std::int64_t nrhs,
                           bool lu, bool unit) {
  const std::int64_t q = begin + blockIdx.x;
  for (std::int64_t f = last[q]; f >= first[q]; --f)
    solve_device::front_backward<Batch>(t, f, x, scratch, nrhs, lu, unit);
}

// The chain (launch_chain_forward/backward). Thread 0 takes the item and waits; the
// barrier after it hands what the acquire made visible to the block. Before waiting, the
// block asks for the front's rows, index maps and panel (prefetch_front), which no block
// writes, so that its step's latency after the wait is that of x and u alone. At the end every
// thread's writes are fenced, the barrier gathers them, and thread 0 releases them to the
// waiting item; the last block to finish clears the ticket and the count and advances the
// epoch (every block read it before it counted itself finished).
using ChainWord = ::cuda::atomic_ref<unsigned long long, ::cuda::thread_scope_device>;

struct ChainItem {
  std::int64_t q;
  unsigned long long epoch;
};

__device__ ChainItem chain_take(const SolveChain& c, bool reverse) {
  __shared__ ChainItem item;
  if (threadIdx.x == 0) {
    unsigned long long* words = c.sync + 2 * c.n_fronts;
    const auto ticket = static_cast<std::int64_t>(atomicAdd(words, 1ull));
    item.q = reverse ? c.items - 1 - ticket : ticket;
    item.epoch = ChainWord(words[2]).load(::cuda::memory_order_relaxed);
  }
  __syncthreads();
  return item;
}

// Thread 0 spins until *word reaches `value` (acquire), then the block goes on.
__device__ void chain_wait_for(unsigned long long* word, unsigned long long value) {
  if (threadIdx.x == 0) {
    ChainWord w(*word);
    while (w.load(::cuda::memory_order_acquire) < value) __nanosleep(32);
  }
  __syncthreads();
}

__device__ void chain_finish(const SolveChain& c) {
  if (threadIdx.x == 0) {
    unsigned long long* words = c.sync + 2 * c.n_fronts;
    ChainWord finished(words[1]);
    if (finished.fetch_add(1, ::cuda::memory_order_acq_rel) ==
        static_cast<unsigned long long>(c.items - 1)) {
      words[0] = 0;
      finished.store(0, ::cuda::memory_order_relaxed);
      ChainWord(words[2]).fetch_add(1, ::cuda::memory_order_release);
    }
  }
}

template <int Batch>
__global__ void __launch_bounds__(kSweepThreads, Batch >= 16 ? 2 : 4)
    chain_forward_kernel(SolveTree t, SolveChain c, double* x, double* u, double* scratch,
                         std::int64_t nrhs, bool unit, bool lu) {
  const ChainItem item = chain_take(c, false);
  const std::int64_t first = c.first[item.q], last = c.last[item.q];
  unsigned long long* arrived = c.sync;
  if (c.wait[first] > 0) {  // a level front (first == last): its children first
    solve_device::prefetch_front(t, first, true, lu);
    chain_wait_for(arrived + first, static_cast<unsigned long long>(c.wait[first]));
    if (threadIdx.x == 0) arrived[first] = 0;  // every child has counted: ready for the next
  }
  for (std::int64_t f = first; f <= last; ++f)
    solve_device::front_forward<Batch>(t, f, x, u, scratch, nrhs, unit, lu);
  __threadfence();
  __syncthreads();
  const std::int64_t parent = c.parent[last];
  if (threadIdx.x == 0 && parent >= 0)
    ChainWord(arrived[parent]).fetch_add(1, ::cuda::memory_order_release);
  chain_finish(c);
}

template <int Batch>
__global__ void __launch_bounds__(kSweepThreads, Batch >= 16 ? 2 : 4)
    chain_backward_kernel(SolveTree t, SolveChain c, double* x, double* scratch, std::int64_t nrhs,
                          bool lu, bool unit) {
  const ChainItem item = chain_take(c, true);
  const std::int64_t first = c.first[item.q], last = c.last[item.q];
  unsigned long long* ended = c.sync + c.n_fronts;  // epoch + 1 once a front's step ended
  const std::int64_t parent = c.parent[last];
  if (parent >= 0) {
    solve_device::prefetch_front(t, last, false, lu);
    chain_wait_for(ended + parent, item.epoch + 1);
  }
  for (std::int64_t f = last; f >= first; --f)
    solve_device::front_backward<Batch>(t, f, x, scratch, nrhs, lu, unit);
  __threadfence();
  __syncthreads();
  if (threadIdx.x == 0 && c.wait[last] > 0)  // a level front: its children wait for it
    ChainWord(ended[last]).store(item.epoch + 1, ::cuda::memory_order_release);
  chain_finish(c);
}

__global__ void diagonal_kernel(SolveTree t, const double* d_diag, const double* d_off,
                                const int* pivot_size, double* x, std::int64_t nrhs) {
  const std::int64_t p = blockIdx.x * static_cast<std::int64_t>(blockDim.x) + threadIdx.x;
  if (p < t.n) solve_device::diagonal(t, p, d_diag, d_off, pivot_size, x, nrhs);
}

// v·d·e as core/solve_phase.cpp's scaled_by: one rounding when d·e is a normal number
__device__ double scaled_by(double v, double d, double e) {
  const double f = d * e;
  const double a = fabs(f);
  return a >= DBL_MIN && a <= DBL_MAX ? v * f : v * d * e;
}

// Out = false: to[k + r·n] = scaled(from[index[k] + r·n], ...) (launch_permute_in);
// Out = true: to[index[k] + r·n] = scaled(from[k + r·n], ...) (launch_permute_out).
// Nothing when `unless` is given and is not zero (the check of the right-hand sides found
// an entry that is not finite). With Check, the entries of the original-numbered array
// (from for Out = false, to for Out = true) are checked as they pass (EntryCheck): per
// block the largest complement of a non-finite entry's index and the largest magnitude's
// bits, through the warps' shuffles and then shared memory, then one atomic each.
template <bool Out, bool Check>
__global__ void permute_kernel(const double* from, const std::int64_t* index, const double* scale,
                               const double* rescale, double* to, std::int64_t n,
                               std::int64_t total, const unsigned long long* unless,
                               EntryCheck check) {
  if (unless && *unless != 0) return;
  const std::int64_t e = blockIdx.x * static_cast<std::int64_t>(blockDim.x) + threadIdx.x;
  unsigned long long bad = 0, big = 0;
  if (e < total) {
    const std::int64_t k = e % n, r = e / n, i = index[k];
    const double a = Out ? from[e] : from[i + r * n];
    const double v = scaled_by(a, scale[k], rescale ? rescale[i] : 1.0);
    (Out ? to[i + r * n] : to[e]) = v;
    if constexpr (Check) {
      const double m = fabs(Out ? v : a);
      if (!(m <= DBL_MAX))  // infinite or NaN
        bad = ~static_cast<unsigned long long>(i + r * n);
      else
        big = static_cast<unsigned long long>(__double_as_longlong(m));
    }
  }
  if constexpr (Check) {
    __shared__ unsigned long long warp_bad[kThreads / 32], warp_big[kThreads / 32];
    for (int h = 16; h > 0; h /= 2) {
      bad = max(bad, __shfl_down_sync(0xffffffffu, bad, h));
      big = max(big, __shfl_down_sync(0xffffffffu, big, h));
    }
    const int lane = threadIdx.x % 32, warp = threadIdx.x / 32;
    if (lane == 0) {
      warp_bad[warp] = bad;
      warp_big[warp] = big;
    }
    __syncthreads();
    if (threadIdx.x == 0) {
      for (int w = 1; w < kThreads / 32; ++w) {
        bad = max(bad, warp_bad[w]);
        big = max(big, warp_big[w]);
      }
      if (bad != 0) atomicMax(check.bad, bad);
      atomicMax(check.max_bits, big);
    }
  }
}

template <bool Out>
void launch_permute(const double* from, const std::int64_t* index, const double* scale,
                    const double* rescale, double* to, std::int64_t n, std::int64_t nrhs,
                    cudaStream_t s, const unsigned long long* unless, EntryCheck check) {
  const std::int64_t total = n * nrhs;
  if (total == 0) return;
  const auto blocks = static_cast<unsigned>((total + kThreads - 1) / kThreads);
  if (check.bad)
    permute_kernel<Out, true>
        <<<blocks, kThreads, 0, s>>>(from, index, scale, rescale, to, n, total, unless, check);
  else
    permute_kernel<Out, false>
        <<<blocks, kThreads, 0, s>>>(from, index, scale, rescale, to, n, total, unless, check);
  STRATA_CUDA_LAUNCH();
}

// y += alpha·A·x, A rows × cols column-major with leading dimension lda: block b takes rows
// [R·b, R·b + R), thread t row R·b + t mod R and the columns j ≡ t / R (mod S), S =
// kGemvThreads / R slices, kGemvLoads loads in flight; the slices' sums are then added in
// slice order, so the result does not depend on timing. R (4, 8, 16 or 32, a function of rows
// only) is the largest that still gives the device a block per SM: a front's L21 or U12 of
// a few hundred rows then has every thread few columns, and each column's R rows are one
// coalesced load.
constexpr int kGemvThreads = 256;
constexpr int kGemvLoads = 8;
__global__ void __launch_bounds__(kGemvThreads)
    gemv_n_kernel(std::int64_t rows, std::int64_t cols, int rows_per_block, double alpha,
                  const double* a, std::int64_t lda, const double* x, double* y) {
  __shared__ double part[kGemvThreads];
  const int R = rows_per_block, slices = kGemvThreads / R;
  const int r = threadIdx.x % R, sl = threadIdx.x / R;
  const std::int64_t i = static_cast<std::int64_t>(blockIdx.x) * R + r;
  double acc[kGemvLoads] = {};
  if (i < rows) {
    const double* ai = a + i;
    std::int64_t j = sl;
    for (; j + (kGemvLoads - 1) * slices < cols; j += kGemvLoads * slices) {
      double av[kGemvLoads], xv[kGemvLoads];
#pragma unroll
      for (int q = 0; q < kGemvLoads; ++q) {
        av[q] = ai[(j + q * slices) * lda];
        xv[q] = x[j + q * slices];
      }
#pragma unroll
      for (int q = 0; q < kGemvLoads; ++q) acc[q] += av[q] * xv[q];
    }
    // the last columns (fewer than kGemvLoads) with their loads together too, added
    // into acc[0] in column order
    if (j < cols) {
      double av[kGemvLoads - 1], xv[kGemvLoads - 1];
#pragma unroll
      for (int q = 0; q < kGemvLoads - 1; ++q) {
        const std::int64_t jq = j + q * slices;
        av[q] = jq < cols ? ai[jq * lda] : 0.0;
        xv[q] = jq < cols ? x[jq] : 0.0;
      }
#pragma unroll
      for (int q = 0; q < kGemvLoads - 1; ++q)
        if (j + q * slices < cols) acc[0] += av[q] * xv[q];
    }
  }
  part[threadIdx.x] = solve_device::pair_sum<kGemvLoads>(acc);
  __syncthreads();
  if (sl == 0 && i < rows) {
    double sum = 0.0;
    for (int q = 0; q < slices; ++q) sum += part[q * R + r];
    y[i] += alpha * sum;
  }
}

}  // namespace

void launch_gemv_n(std::int64_t rows, std::int64_t cols, double alpha, const double* a,
                   std::int64_t lda, const double* x, double* y, cudaStream_t s) {
  if (rows <= 0 || cols <= 0) return;
  const int sms = multiprocessor_count();
  int R = 32;
  while (R > 4 && (rows + R - 1) / R < sms) R /= 2;
  gemv_n_kernel<<<static_cast<unsigned>((rows + R - 1) / R), kGemvThreads, 0, s>>>(
      rows, cols, R, alpha, a, lda, x, y);
  STRATA_CUDA_LAUNCH();
}

void launch_trsv_inverses(const trsv_tiles::TrsvTileJob* jobs, std::int64_t count,
                          const double* panels, double* inverses, trsv_tiles::TrsvForm form,
                          bool unit, cudaStream_t s) {
  using trsv_tiles::trsv_inverse_kernel;
  using trsv_tiles::TrsvForm;
  if (count <= 0) return;
  const auto blocks = static_cast<unsigned>(count);
  constexpr int T = trsv_tiles::kTrsvTile;
  if (form == TrsvForm::lower)
    unit ? trsv_inverse_kernel<TrsvForm::lower, true><<<blocks, T, 0, s>>>(jobs, panels, inverses)
         : trsv_inverse_kernel<TrsvForm::lower, false><<<blocks, T, 0, s>>>(jobs, panels, inverses);
  else if (form == TrsvForm::upper)
    unit ? trsv_inverse_kernel<TrsvForm::upper, true><<<blocks, T, 0, s>>>(jobs, panels, inverses)
         : trsv_inverse_kernel<TrsvForm::upper, false><<<blocks, T, 0, s>>>(jobs, panels, inverses);
  else
    unit ? trsv_inverse_kernel<TrsvForm::lower_transposed, true>
        <<<blocks, T, 0, s>>>(jobs, panels, inverses)
         : trsv_inverse_kernel<TrsvForm::lower_transposed, false>
        <<<blocks, T, 0, s>>>(jobs, panels, inverses);
  STRATA_CUDA_LAUNCH();
}

void launch_trsv_tiles(trsv_tiles::TrsvForm form, std::int64_t n, const double* a, std::int64_t lda,
                       double* x, const double* inv, trsv_tiles::TrsvSync sync, cudaStream_t s) {
  using trsv_tiles::trsv_tiles_kernel;
  using trsv_tiles::TrsvForm;
  if (n <= 0) return;
  const auto blocks =
      static_cast<unsigned>((n + trsv_tiles::kTrsvTile - 1) / trsv_tiles::kTrsvTile);
  const int nn = static_cast<int>(n), threads = trsv_tiles::kTrsvThreads;
  if (form == TrsvForm::lower)
    trsv_tiles_kernel<TrsvForm::lower><<<blocks, threads, 0, s>>>(nn, a, lda, x, inv, sync);
  else if (form == TrsvForm::upper)
    trsv_tiles_kernel<TrsvForm::upper><<<blocks, threads, 0, s>>>(nn, a, lda, x, inv, sync);
  else
    trsv_tiles_kernel<TrsvForm::lower_transposed>
        <<<blocks, threads, 0, s>>>(nn, a, lda, x, inv, sync);
  STRATA_CUDA_LAUNCH();
}

void launch_permute_in(const double* from, const std::int64_t* index, const double* scale,
                       const double* rescale, double* to, std::int64_t n, std::int64_t nrhs,
                       cudaStream_t s, EntryCheck check) {
  launch_permute<false>(from, index, scale, rescale, to, n, nrhs, s, nullptr, check);
}

void launch_permute_out(const double* from, const std::int64_t* index, const double* scale,
                        const double* rescale, double* to, std::int64_t n, std::int64_t nrhs,
                        cudaStream_t s, const unsigned long long* unless, EntryCheck check) {
  launch_permute<true>(from, index, scale, rescale, to, n, nrhs, s, unless, check);
}

void launch_gather_forward(const SolveTree& t, SolveChunks c, std::int64_t begin,
                           std::int64_t count, const double* x, const double* u, double* scratch,
                           std::int64_t nrhs, cudaStream_t s) {
  if (count == 0) return;
  gather_forward_kernel<<<static_cast<unsigned>(count), kThreads, 0, s>>>(t, c, begin, x, u,
                                                                          scratch, nrhs);
  STRATA_CUDA_LAUNCH();
}

void launch_scatter_forward(const SolveTree& t, SolveChunks c, std::int64_t begin,
                            std::int64_t count, double* x, double* u, const double* scratch,
                            std::int64_t nrhs, bool lu, cudaStream_t s) {
  if (count == 0) return;
  scatter_forward_kernel<<<static_cast<unsigned>(count), kThreads, 0, s>>>(t, c, begin, x, u,
                                                                           scratch, nrhs, lu);
  STRATA_CUDA_LAUNCH();
}

void launch_sweep_forward(const SolveTree& t, const std::int64_t* fronts, std::int64_t begin,
                          std::int64_t count, double* scratch, std::int64_t nrhs, bool unit,
                          cudaStream_t s) {
  if (count == 0) return;
  sweep_forward_kernel<<<static_cast<unsigned>(count), kSweepThreads, 0, s>>>(t, fronts, begin,
                                                                              scratch, nrhs, unit);
  STRATA_CUDA_LAUNCH();
}

void launch_fronts_forward(const SolveTree& t, const std::int64_t* first, const std::int64_t* last,
                           std::int64_t begin, std::int64_t count, double* x, double* u,
                           double* scratch, std::int64_t nrhs, bool unit, bool lu, cudaStream_t s) {
  if (count == 0) return;
  if (count <= kFewFrontBlocks)
    fronts_forward_kernel<kTallBatch><<<static_cast<unsigned>(count), kSweepThreads, 0, s>>>(
        t, first, last, begin, x, u, scratch, nrhs, unit, lu);
  else
    fronts_forward_kernel<4><<<static_cast<unsigned>(count), kSweepThreads, 0, s>>>(
        t, first, last, begin, x, u, scratch, nrhs, unit, lu);
  STRATA_CUDA_LAUNCH();
}

void launch_fronts_backward(const SolveTree& t, const std::int64_t* first, const std::int64_t* last,
                            std::int64_t begin, std::int64_t count, double* x, double* scratch,
                            std::int64_t nrhs, bool lu, bool unit, cudaStream_t s) {
  if (count == 0) return;
  if (count <= kFewFrontBlocks)
    fronts_backward_kernel<kTallBatch><<<static_cast<unsigned>(count), kSweepThreads, 0, s>>>(
        t, first, last, begin, x, scratch, nrhs, lu, unit);
  else
    fronts_backward_kernel<4><<<static_cast<unsigned>(count), kSweepThreads, 0, s>>>(
        t, first, last, begin, x, scratch, nrhs, lu, unit);
  STRATA_CUDA_LAUNCH();
}

void launch_chain_forward(const SolveTree& t, const SolveChain& c, double* x, double* u,
                          double* scratch, std::int64_t nrhs, bool unit, bool lu, cudaStream_t s) {
  if (c.items == 0) return;
  if (c.items <= kFewFrontBlocks)
    chain_forward_kernel<kTallBatch><<<static_cast<unsigned>(c.items), kSweepThreads, 0, s>>>(
        t, c, x, u, scratch, nrhs, unit, lu);
  else
    chain_forward_kernel<4><<<static_cast<unsigned>(c.items), kSweepThreads, 0, s>>>(
        t, c, x, u, scratch, nrhs, unit, lu);
  STRATA_CUDA_LAUNCH();
}

void launch_chain_backward(const SolveTree& t, const SolveChain& c, double* x, double* scratch,
                           std::int64_t nrhs, bool lu, bool unit, cudaStream_t s) {
  if (c.items == 0) return;
  if (c.items <= kFewFrontBlocks)
    chain_backward_kernel<kTallBatch>
        <<<static_cast<unsigned>(c.items), kSweepThreads, 0, s>>>(t, c, x, scratch, nrhs, lu, unit);
  else
    chain_backward_kernel<4>
        <<<static_cast<unsigned>(c.items), kSweepThreads, 0, s>>>(t, c, x, scratch, nrhs, lu, unit);
  STRATA_CUDA_LAUNCH();
}

void launch_solve_diagonal(const SolveTree& t, const double* d_diag, const double* d_off,
                           const int* pivot_size, double* x, std::int64_t nrhs, cudaStream_t s) {
  if (t.n == 0) return;
  const unsigned blocks = static_cast<unsigned>((t.n + kThreads - 1) / kThreads);
  diagonal_kernel<<<blocks, kThreads, 0, s>>>(t, d_diag, d_off, pivot_size, x, nrhs);
  STRATA_CUDA_LAUNCH();
}

void launch_gather_backward(const SolveTree& t, SolveChunks c, std::int64_t begin,
                            std::int64_t count, const double* x, double* scratch, std::int64_t nrhs,
                            bool lu, cudaStream_t s) {
  if (count == 0) return;
  gather_backward_kernel<<<static_cast<unsigned>(count), kThreads, 0, s>>>(t, c, begin, x, scratch,
                                                                           nrhs, lu);
  STRATA_CUDA_LAUNCH();
}

void launch_sweep_backward(const SolveTree& t, const std::int64_t* fronts, std::int64_t begin,
                           std::int64_t count, double* scratch, std::int64_t nrhs, bool lu,
                           bool unit, cudaStream_t s) {
  if (count == 0) return;
  sweep_backward_kernel<<<static_cast<unsigned>(count), kSweepThreads, 0, s>>>(
      t, fronts, begin, scratch, nrhs, lu, unit);
  STRATA_CUDA_LAUNCH();
}

void launch_scatter_backward(const SolveTree& t, SolveChunks c, std::int64_t begin,
                             std::int64_t count, double* x, const double* scratch,
                             std::int64_t nrhs, bool lu, cudaStream_t s) {
  if (count == 0) return;
  scatter_backward_kernel<<<static_cast<unsigned>(count), kThreads, 0, s>>>(t, c, begin, x, scratch,
                                                                            nrhs, lu);
  STRATA_CUDA_LAUNCH();
}

}  // namespace strata::cuda

namespace strata::numeric {

std::vector<double> cuda_gemv_n(index_t rows, index_t cols, double alpha,
                                const std::vector<double>& a, index_t lda,
                                const std::vector<double>& x, std::vector<double> y) {
  if (rows < 0 || cols < 0 || lda < std::max<index_t>(rows, 1) ||
      a.size() < static_cast<std::size_t>(lda) * static_cast<std::size_t>(cols) ||
      x.size() != static_cast<std::size_t>(cols) || y.size() != static_cast<std::size_t>(rows))
    throw InvalidInput("cuda_gemv_n: inconsistent sizes (rows " + std::to_string(rows) + ", cols " +
                       std::to_string(cols) + ", lda " + std::to_string(lda) + ", a " +
                       std::to_string(a.size()) + ", x " + std::to_string(x.size()) + ", y " +
                       std::to_string(y.size()) + ")");
  STRATA_CUDA(cudaSetDevice(0));
  cuda::DeviceBuffer<double> A(std::max<std::size_t>(a.size(), 1)),
      X(std::max<std::size_t>(x.size(), 1)), Y(std::max<std::size_t>(y.size(), 1));
  STRATA_CUDA(cudaMemcpy(A.data(), a.data(), a.size() * sizeof(double), cudaMemcpyHostToDevice));
  STRATA_CUDA(cudaMemcpy(X.data(), x.data(), x.size() * sizeof(double), cudaMemcpyHostToDevice));
  STRATA_CUDA(cudaMemcpy(Y.data(), y.data(), y.size() * sizeof(double), cudaMemcpyHostToDevice));
  cuda::launch_gemv_n(rows, cols, alpha, A.data(), lda, X.data(), Y.data(), nullptr);
  STRATA_CUDA(cudaMemcpy(y.data(), Y.data(), y.size() * sizeof(double), cudaMemcpyDeviceToHost));
  return y;
}

std::vector<double> cuda_trsv_tiles(int form, bool unit, index_t n, const std::vector<double>& a,
                                    index_t lda, std::vector<double> x) {
  if (form < 0 || form > 2 || n < 0 || lda < std::max<index_t>(n, 1) ||
      a.size() < static_cast<std::size_t>(lda) * static_cast<std::size_t>(n) ||
      x.size() != static_cast<std::size_t>(n) || n > std::numeric_limits<int>::max())
    throw InvalidInput("cuda_trsv_tiles: inconsistent arguments (form " + std::to_string(form) +
                       ", n " + std::to_string(n) + ", lda " + std::to_string(lda) + ", a " +
                       std::to_string(a.size()) + ", x " + std::to_string(x.size()) + ")");
  if (n == 0) return x;
  using cuda::trsv_tiles::kTrsvTile;
  STRATA_CUDA(cudaSetDevice(0));
  const index_t tiles = (n + kTrsvTile - 1) / kTrsvTile;
  std::vector<cuda::trsv_tiles::TrsvTileJob> jobs(static_cast<std::size_t>(tiles));
  for (index_t t = 0; t < tiles; ++t) jobs[t] = {0, lda, n, t, t * kTrsvTile * kTrsvTile};
  cuda::DeviceBuffer<double> A(a.size()), X(x.size()),
      inv(static_cast<std::size_t>(tiles) * kTrsvTile * kTrsvTile);
  cuda::DeviceBuffer<std::int64_t> J(jobs.size() * 5);
  cuda::DeviceBuffer<int> sync(static_cast<std::size_t>(tiles) + 2);
  STRATA_CUDA(cudaMemcpy(A.data(), a.data(), a.size() * sizeof(double), cudaMemcpyHostToDevice));
  STRATA_CUDA(cudaMemcpy(X.data(), x.data(), x.size() * sizeof(double), cudaMemcpyHostToDevice));
  STRATA_CUDA(
      cudaMemcpy(J.data(), jobs.data(), jobs.size() * sizeof(jobs[0]), cudaMemcpyHostToDevice));
  STRATA_CUDA(cudaMemset(sync.data(), 0, sync.size() * sizeof(int)));
  const auto f = static_cast<cuda::trsv_tiles::TrsvForm>(form);
  const auto* job_ptr = reinterpret_cast<const cuda::trsv_tiles::TrsvTileJob*>(J.data());
  cuda::launch_trsv_inverses(job_ptr, tiles, A.data(), inv.data(), f, unit, nullptr);
  const cuda::trsv_tiles::TrsvSync s{sync.data() + 2, sync.data(), sync.data() + 1};
  // twice: the second launch finds the flags the first one left, which must be zero again
  for (int run = 0; run < 2; ++run) {
    if (run == 1)
      STRATA_CUDA(
          cudaMemcpy(X.data(), x.data(), x.size() * sizeof(double), cudaMemcpyHostToDevice));
    cuda::launch_trsv_tiles(f, n, A.data(), lda, X.data(), inv.data(), s, nullptr);
  }
  STRATA_CUDA(cudaMemcpy(x.data(), X.data(), x.size() * sizeof(double), cudaMemcpyDeviceToHost));
  return x;
}

}  // namespace strata::numeric
