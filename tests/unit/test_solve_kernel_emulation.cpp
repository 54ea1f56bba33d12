// The device solve of the CUDA backend, emulated on the host: the device code
// (src/numeric/cuda/solve_device.cuh) compiled for the host and run with one fiber per CUDA
// thread, the plan (solve_plan.hpp) and the large-front BLAS sequence
// (large_front_forward/backward) run with the host BLAS — driven level by level in the
// order of cuda_solve.cu — on factors made by the CPU executor, and compared with the CPU
// solve (solve_in_place) on the same factor, for LLᵀ, LDLᵀ with 2×2 pivots and LU with row
// pivoting, 1, 2 and 5 right-hand sides, every front on the block path, every front on the
// library path, and the planner's split. This runs in CI without a GPU: it checks the
// index arithmetic (gather by inverse extend-add lists, permuted pivot rows, scatter
// targets, the LU U12 layout, leading dimensions and offsets of the BLAS calls), that
// every thread reaches every barrier and every lane every shuffle (a divergent one leaves
// the others waiting: the emulated barrier then aborts with a message). What only a GPU
// shows (memory model, cuBLAS itself) is left to tests/gpu/test_cuda_backend.cpp.
//
// The emulation (below): a block's threads are fibers; __syncthreads() is a barrier of the
// block's threads; __shfl_sync/__shfl_down_sync exchange through a per-warp slot array
// between two barriers of the warp's 32 threads.
#include <gtest/gtest.h>
#include <ucontext.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <memory>
#include <random>
#include <vector>

#include "analysis/analysis.hpp"
#include "base/blas.hpp"
#include "numeric/factor.hpp"
#include "schedule/tree_partition.hpp"
#include "sparse/generators.hpp"
#include "strata/strata.hpp"
#include "support/test_support.hpp"

// --- host stand-ins for the CUDA names the device code uses -----------------------------
//
// A block's threads are fibers (ucontext) on the calling OS thread, run round-robin: a
// fiber runs until it waits at a barrier, and a barrier opens when every thread it
// counts (the block's, or the warp's) has arrived. When no fiber can run while some are
// still waiting, a barrier is not reached by every thread that should reach it: the test
// then aborts with a message. Cheap (a context switch per wait), and deterministic.

namespace {

struct EmuDim {
  unsigned x = 0;
};
EmuDim threadIdx;
EmuDim blockDim;

constexpr unsigned kEmuWarp = 32;
constexpr std::size_t kFiberStack = 256 * 1024;

struct EmuGate {  // a barrier: who has arrived in the current generation
  unsigned arrived = 0, count = 0;
  unsigned long long generation = 0;
};

struct Fiber {
  ucontext_t ctx{};
  std::vector<char> stack;
  EmuGate* waiting_on = nullptr;
  unsigned long long waiting_gen = 0;
  bool done = false;
};

ucontext_t scheduler_ctx;
std::vector<Fiber> fibers;
EmuGate block_gate;
std::vector<EmuGate> warp_gates;
std::vector<double> warp_slots;  // kEmuWarp doubles per warp
const void* fiber_body = nullptr;
void (*fiber_call)(const void*) = nullptr;

void arrive(EmuGate& g) {
  Fiber& me = fibers[threadIdx.x];
  if (++g.arrived == g.count) {  // the last one opens the gate and goes on
    g.arrived = 0;
    ++g.generation;
    return;
  }
  me.waiting_on = &g;
  me.waiting_gen = g.generation;
  swapcontext(&me.ctx, &scheduler_ctx);
}

void __syncthreads() { arrive(block_gate); }

template <class Pick>
double warp_exchange(double v, Pick pick) {
  const unsigned w = threadIdx.x / kEmuWarp, lane = threadIdx.x % kEmuWarp;
  double* slot = warp_slots.data() + w * kEmuWarp;
  slot[lane] = v;
  arrive(warp_gates[w]);
  const double r = slot[pick(lane)];
  arrive(warp_gates[w]);
  return r;
}
double __shfl_sync(unsigned, double v, int src) {
  return warp_exchange(v, [src](unsigned) { return static_cast<unsigned>(src) % kEmuWarp; });
}
double __shfl_down_sync(unsigned, double v, unsigned delta) {
  return warp_exchange(
      v, [delta](unsigned lane) { return lane + delta < kEmuWarp ? lane + delta : lane; });
}

void fiber_entry() {
  fiber_call(fiber_body);
  fibers[threadIdx.x].done = true;
  swapcontext(&fibers[threadIdx.x].ctx, &scheduler_ctx);
}

// Runs body() as one block of `threads` threads (whole warps: the sweeps shuffle).
template <class Body>
void run_block(unsigned threads, const Body& body) {
  blockDim.x = threads;
  block_gate = EmuGate{0, threads, 0};
  const unsigned nw = (threads + kEmuWarp - 1) / kEmuWarp;
  warp_gates.assign(nw, EmuGate{0, kEmuWarp, 0});
  warp_slots.assign(nw * kEmuWarp, 0.0);
  fiber_body = &body;
  fiber_call = [](const void* b) { (*static_cast<const Body*>(b))(); };
  fibers.resize(threads);
  for (unsigned t = 0; t < threads; ++t) {
    Fiber& f = fibers[t];
    f.stack.resize(kFiberStack);
    f.waiting_on = nullptr;
    f.done = false;
    getcontext(&f.ctx);
    f.ctx.uc_stack.ss_sp = f.stack.data();
    f.ctx.uc_stack.ss_size = f.stack.size();
    f.ctx.uc_link = nullptr;
    makecontext(&f.ctx, fiber_entry, 0);
  }
  for (unsigned finished = 0; finished < threads;) {
    bool progress = false;
    finished = 0;
    for (unsigned t = 0; t < threads; ++t) {
      Fiber& f = fibers[t];
      if (f.done) {
        ++finished;
        continue;
      }
      if (f.waiting_on && f.waiting_on->generation == f.waiting_gen) continue;
      f.waiting_on = nullptr;
      threadIdx.x = t;
      swapcontext(&scheduler_ctx, &f.ctx);
      progress = true;
    }
    if (!progress && finished < threads) {
      std::fprintf(stderr,
                   "emulated block of %u threads: %u finished, the others wait at a barrier or "
                   "shuffle that not every thread reaches\n",
                   threads, finished);
      std::abort();
    }
  }
}

}  // namespace

// __shared__: a function-local static, one per function, which the fibers of the block
// share (blocks run one after another)
#define __device__ inline
#define __shared__ static
#include "numeric/cuda/solve_device.cuh"
#undef __shared__
#undef __device__

namespace strata {
namespace {

using cuda::SolvePath;
using cuda::SolvePlan;
using cuda::SolveTree;

// large_front_forward/backward's BLAS on the host (the reference BLAS interface).
struct HostOps {
  static const char* uplo(bool upper) { return upper ? "U" : "L"; }
  static const char* tr(bool trans) { return trans ? "T" : "N"; }
  static const char* diag(bool unit) { return unit ? "U" : "N"; }
  int calls = 0;
  void trsv(bool upper, bool trans, bool unit, int n, const double* a, int lda, double* x) {
    const int inc = 1;
    dtrsv_(uplo(upper), tr(trans), diag(unit), &n, a, &lda, x, &inc);
    ++calls;
  }
  void trsm(bool upper, bool trans, bool unit, int n, int nrhs, const double* a, int lda, double* b,
            int ldb) {
    const double one = 1.0;
    dtrsm_("L", uplo(upper), tr(trans), diag(unit), &n, &nrhs, &one, a, &lda, b, &ldb);
    ++calls;
  }
  void gemv(bool trans, int rows, int cols, double alpha, const double* a, int lda, const double* x,
            double beta, double* y) {
    const int inc = 1;
    dgemv_(tr(trans), &rows, &cols, &alpha, a, &lda, x, &inc, &beta, y, &inc);
    ++calls;
  }
  void gemm(bool trans_a, int m, int n, int k, double alpha, const double* a, int lda,
            const double* b, int ldb, double beta, double* c, int ldc) {
    dgemm_(tr(trans_a), "N", &m, &n, &k, &alpha, a, &lda, b, &ldb, &beta, c, &ldc);
    ++calls;
  }
};

struct EmulationCounts {
  index_t block_fronts = 0, library_fronts = 0, subtrees = 0, tall_fronts = 0;
  index_t batch4_fronts = 0, batch16_fronts = 0;  ///< block-path fronts by kernel variant
  index_t chain_items = 0;                        ///< items of the chain's launches (forward)
};

// A device's arrays for the emulated sweeps: x (n × nrhs), the update-vector arena, the
// fronts' scratch and the tall fronts' partial products (sized by the caller).
struct EmulatedDevice {
  std::vector<double> x, u, scratch, part;
};

// The sweeps of cuda_solve.cu's enqueue_solve_sweeps, step for step, on the host: plan p's
// forward sweep, its backward sweep or both (the LDLᵀ diagonal between them), over the
// arrays of `device`; `inverse` holds the update vectors' offsets and the inverse
// extend-add map (plan_inverse_extend_add of the whole tree); the panels are fac's.
// few_blocks: the block path's launches of at most this many blocks run the 16-batch
// variant (kFewFrontBlocks on the device; 0 runs the other everywhere).
void emulate_sweeps(const Analysis& an, const numeric::NumericFactor& fac, const SolvePlan& inverse,
                    const SolvePlan& p, EmulatedDevice& device, index_t nrhs, bool do_forward,
                    bool do_backward, unsigned sweep_threads, EmulationCounts& counts,
                    std::int64_t few_blocks = cuda::kFewFrontBlocks) {
  const auto& t = an.tree;
  const index_t nf = t.n_fronts();
  const bool lu = fac.type == MatrixType::general;
  const bool ldlt = fac.type == MatrixType::symmetric_indefinite;
  const bool unit = lu || ldlt;
  std::vector<std::int64_t> n_rows(nf), n_piv(nf), panel_offset(nf), pivot_row(an.n);
  for (index_t f = 0; f < nf; ++f) {
    n_rows[f] = t.n_rows(f);
    n_piv[f] = t.n_pivots(f);
    panel_offset[f] = static_cast<std::int64_t>(an.factor_layout.panel_offset[f]);
    for (index_t i = 0; i < t.n_pivots(f); ++i)
      pivot_row[t.first_pivot[f] + i] = fac.rows[t.row_offsets[f] + i];
  }
  const std::int64_t u_total = inverse.u_offset.back();
  SolveTree st{n_rows.data(),
               n_piv.data(),
               t.row_offsets.data(),
               t.first_pivot.data(),
               fac.rows.data(),
               inverse.inv_offsets.data(),
               inverse.inv_src.data(),
               inverse.u_offset.data(),
               panel_offset.data(),
               fac.panels.data(),
               pivot_row.data(),
               an.n,
               u_total,
               p.part_offset.data(),
               nullptr};
  if (device.part.size() < static_cast<std::size_t>(p.part_total * nrhs) + 1)
    device.part.resize(static_cast<std::size_t>(p.part_total * nrhs) + 1,
                       std::numeric_limits<double>::quiet_NaN());
  st.part = device.part.data();
  double* X = device.x.data();
  double* U = device.u.data();
  double* S = device.scratch.data();
  HostOps ops;
  const int nr = static_cast<int>(nrhs);
  // the gather/scatter use no barrier or shuffle: the calling thread plays a block of 3
  auto chunks = [&](index_t l, auto&& body) {
    for (std::int64_t c = p.chunk_offsets[l]; c < p.chunk_offsets[l + 1]; ++c) {
      const std::int64_t f = p.chunk_front[c], i0 = p.chunk_row[c];
      const std::int64_t i1 = std::min(i0 + cuda::kChunkRows, n_rows[f]);
      blockDim.x = 3;
      for (unsigned th = 0; th < blockDim.x; ++th) {
        threadIdx.x = th;
        body(f, i0, i1);
      }
    }
  };
  auto large = [&](std::int64_t f, auto&& run) {
    run(fac.panels.data() + panel_offset[f], static_cast<int>(n_rows[f]),
        static_cast<int>(n_piv[f]), S + t.row_offsets[f] * nrhs);
  };
  namespace dev = cuda::solve_device;
  const std::size_t n_subtrees = p.subtree_first.size();
  // the block path's launches: the variant the device picks by the launch's block count
  const bool few_subtrees = static_cast<std::int64_t>(n_subtrees) <= few_blocks;
  auto few = [&](index_t l) { return p.small_offsets[l + 1] - p.small_offsets[l] <= few_blocks; };
  auto forward = [&](std::int64_t f, bool batch16) {
    if (batch16)
      dev::front_forward<16>(st, f, X, U, S, nrhs, unit, lu);
    else
      dev::front_forward<4>(st, f, X, U, S, nrhs, unit, lu);
  };
  auto backward = [&](std::int64_t f, bool batch16) {
    if (batch16)
      dev::front_backward<16>(st, f, X, S, nrhs, lu, unit);
    else
      dev::front_backward<4>(st, f, X, S, nrhs, lu, unit);
  };
  // the chain (plan_chain): its items in ticket order forward, the reverse backward, each
  // only once what its device block would wait for is done
  const std::int64_t chained = p.chain_levels, items = std::ssize(p.chain_first);
  const bool few_items = items <= few_blocks;
  std::vector<char> done(static_cast<std::size_t>(nf), 0);
  for (std::int64_t q = 0; do_forward && q < items; ++q) {
    const std::int64_t first = p.chain_first[q], last = p.chain_last[q];
    index_t children = 0;
    for (index_t c = t.child_offsets[first]; c < t.child_offsets[first + 1]; ++c) {
      EXPECT_TRUE(done[t.children[c]]) << "front " << first << " before its child";
      children += p.chain_parent[t.children[c]] == first;
    }
    EXPECT_EQ(p.chain_wait[first], first == last ? children : 0) << "front " << first;
    run_block(sweep_threads, [&] {
      for (std::int64_t f = first; f <= last; ++f) forward(f, few_items);
    });
    done[last] = 1;
    counts.chain_items += 1;
  }
  if (chained > 0) std::fill(done.begin(), done.end(), 0);
  for (std::size_t q = 0; do_forward && chained == 0 && q < n_subtrees; ++q) {
    run_block(sweep_threads, [&] {
      for (std::int64_t f = p.subtree_first[q]; f <= p.subtree_last[q]; ++f)
        forward(f, few_subtrees);
    });
    counts.block_fronts += p.subtree_last[q] - p.subtree_first[q] + 1;
    (few_subtrees ? counts.batch16_fronts : counts.batch4_fronts) +=
        p.subtree_last[q] - p.subtree_first[q] + 1;
    ++counts.subtrees;
  }
  for (index_t l = static_cast<index_t>(chained); do_forward && l < an.schedule.n_levels(); ++l) {
    for (std::int64_t q = p.small_offsets[l]; q < p.small_offsets[l + 1]; ++q) {
      run_block(sweep_threads, [&] { forward(p.small_fronts[q], few(l)); });
      ++counts.block_fronts;
      ++(few(l) ? counts.batch16_fronts : counts.batch4_fronts);
    }
    chunks(l, [&](std::int64_t f, std::int64_t i0, std::int64_t i1) {
      dev::gather_forward(st, f, i0, i1, X, U, S, nrhs);
    });
    for (std::int64_t q = p.tall_offsets[l]; q < p.tall_offsets[l + 1]; ++q) {
      run_block(sweep_threads,
                [&] { dev::sweep_forward<16>(st, p.tall_fronts[q], S, nrhs, unit); });
      ++counts.block_fronts;
      ++counts.tall_fronts;
    }
    for (std::int64_t q = p.large_offsets[l]; q < p.large_offsets[l + 1]; ++q) {
      large(p.large_fronts[q], [&](const double* L, int m, int k, double* W) {
        cuda::large_front_forward(ops, L, m, k, nr, unit, W);
      });
      ++counts.library_fronts;
    }
    chunks(l, [&](std::int64_t f, std::int64_t i0, std::int64_t i1) {
      dev::scatter_forward<16>(st, f, i0, i1, X, U, S, nrhs, lu);
    });
  }
  if (ldlt && do_forward && do_backward)
    for (index_t q = 0; q < an.n; ++q)
      dev::diagonal(st, q, fac.d_diag.data(), fac.d_off.data(), fac.pivot_size.data(), X, nrhs);
  for (index_t l = an.schedule.n_levels() - 1; do_backward && l >= chained; --l) {
    for (std::int64_t q = p.small_offsets[l]; q < p.small_offsets[l + 1]; ++q)
      run_block(sweep_threads, [&] { backward(p.small_fronts[q], few(l)); });
    chunks(l, [&](std::int64_t f, std::int64_t i0, std::int64_t i1) {
      dev::gather_backward(st, f, i0, i1, X, S, nrhs, lu);
    });
    // the tall fronts' partial products (warp shuffles: a whole block of OS threads)
    for (std::int64_t c = p.chunk_offsets[l]; c < p.chunk_offsets[l + 1]; ++c) {
      const std::int64_t f = p.chunk_front[c], i0 = p.chunk_row[c];
      const std::int64_t i1 = std::min(i0 + cuda::kChunkRows, n_rows[f]);
      run_block(sweep_threads, [&] { dev::backward_partials(st, f, i0, i1, X, nrhs, lu); });
    }
    for (std::int64_t q = p.tall_offsets[l]; q < p.tall_offsets[l + 1]; ++q)
      run_block(sweep_threads,
                [&] { dev::sweep_backward<16>(st, p.tall_fronts[q], S, nrhs, lu, unit); });
    for (std::int64_t q = p.large_offsets[l]; q < p.large_offsets[l + 1]; ++q)
      large(p.large_fronts[q], [&](const double* L, int m, int k, double* W) {
        cuda::large_front_backward(ops, L, m, k, nr, lu, unit, W);
      });
    chunks(l, [&](std::int64_t f, std::int64_t i0, std::int64_t i1) {
      dev::scatter_backward(st, f, i0, i1, X, S, nrhs, lu);
    });
  }
  for (std::int64_t q = items - 1; do_backward && q >= 0; --q) {
    const std::int64_t first = p.chain_first[q], last = p.chain_last[q];
    const std::int64_t parent = p.chain_parent[last];
    if (parent >= 0) EXPECT_TRUE(done[parent]) << "front " << last << " before its parent";
    EXPECT_EQ(parent >= 0, t.parent[last] >= 0 && an.schedule.level_of[t.parent[last]] < chained);
    run_block(sweep_threads, [&] {
      for (std::int64_t f = last; f >= first; --f) backward(f, few_items);
    });
    done[last] = 1;
  }
  for (std::size_t q = 0; do_backward && chained == 0 && q < n_subtrees; ++q)
    run_block(sweep_threads, [&] {
      for (std::int64_t f = p.subtree_last[q]; f >= p.subtree_first[q]; --f)
        backward(f, few_subtrees);
    });
}

// The whole-tree device solve of cuda_solve.cu on the host (fresh arrays as the device's
// workspaces). x: n×nrhs.
void emulate_device_solve(const Analysis& an, const numeric::NumericFactor& fac, const SolvePlan& p,
                          std::vector<double>& x, index_t nrhs, unsigned sweep_threads,
                          EmulationCounts& counts,
                          std::int64_t few_blocks = cuda::kFewFrontBlocks) {
  EmulatedDevice dev;
  dev.x = x;
  // NaN, as the device's workspaces hold whatever they held: an entry read before it is
  // written poisons the solution
  const double nan = std::numeric_limits<double>::quiet_NaN();
  dev.u.assign(static_cast<std::size_t>(p.u_offset.back() * nrhs) + 1, nan);
  dev.scratch.assign(an.tree.rows.size() * nrhs + 1, nan);
  dev.part.assign(static_cast<std::size_t>(p.part_total * nrhs) + 1, nan);
  emulate_sweeps(an, fac, p, p, dev, nrhs, true, true, sweep_threads, counts, few_blocks);
  x = dev.x;
}

using Problem = test::NamedMatrix;

double max_abs(const std::vector<double>& v) {
  double m = 0;
  for (double x : v) m = std::max(m, std::abs(x));
  return m;
}

// pr's matrix scaled as the Solver scales it for `an` (into `values`) and factored by the
// CPU executor (one thread).
numeric::NumericFactor factor_on_cpu(const Analysis& an, const Problem& pr,
                                     std::vector<double>& values) {
  double pivot = 0;
  values = test::scaled_values(an, pr.a, &pivot);
  numeric::NumericFactor fac;
  std::vector<double> arena;
  auto cpu = numeric::make_cpu_executor(1);
  numeric::factorize(an, values, pr.type, pivot, *cpu, fac, arena);
  return fac;
}

// Factors a on the CPU, then solves random right-hand sides both ways and compares.
void check_problem(const Problem& pr, std::mt19937_64& rng, std::initializer_list<SolvePath> paths,
                   unsigned sweep_threads, int n_sm, EmulationCounts& counts,
                   std::int64_t few_blocks = cuda::kFewFrontBlocks) {
  SCOPED_TRACE(pr.name);
  Options o;
  o.type = pr.type;
  Analysis an = analyze_matrix(pr.a, o);
  std::vector<double> values;
  const numeric::NumericFactor fac = factor_on_cpu(an, pr, values);
  std::uniform_real_distribution<double> u(-1, 1);
  const double bmax = max_abs(values);
  for (const SolvePath path : paths) {
    const SolvePlan plan = cuda::make_solve_plan(an.tree, an.child_rows, an.schedule, n_sm, path);
    // the subtrees and the bottom levels in one launch (the model pricing it so)
    const SolvePlan chained =
        cuda::make_solve_plan(an.tree, an.child_rows, an.schedule, n_sm, path, true);
    for (index_t nrhs : {1, 2, 5})
      for (const bool chain : {false, true}) {
        if (chain && chained.chain_levels == 0) continue;
        SCOPED_TRACE("path " + std::to_string(static_cast<int>(path)) + " nrhs " +
                     std::to_string(nrhs) + (chain ? " chained" : ""));
        std::vector<double> b(static_cast<std::size_t>(an.n * nrhs));
        for (double& v : b) v = u(rng);
        std::vector<double> ref = b, got = b;
        numeric::solve_in_place(an, fac, ref.data(), nrhs);
        emulate_device_solve(an, fac, chain ? chained : plan, got, nrhs, sweep_threads, counts,
                             few_blocks);
        // Two summation orders of a solve with the same factor differ by about u·κ relative
        // to x, and random matrices are now and then badly conditioned. κ̂ = max|B|·‖x‖∞/‖b‖∞
        // is a lower bound on κ∞(B) that for random b is within about √n·(entries per row)
        // of it; 1e-13·√n·κ̂ leaves ~10³ over u·κ̂ and stays far below the O(1) difference an
        // index or ordering error gives.
        const double kappa = bmax * max_abs(ref) / std::max(max_abs(b), 1e-300);
        const double tol = std::max(1e-10, 1e-13 * std::sqrt(static_cast<double>(an.n)) * kappa);
        EXPECT_LT(test::relative_difference(got, ref), tol) << "κ̂ " << kappa;
      }
  }
}

MatrixType kTypes[] = {MatrixType::spd, MatrixType::symmetric_indefinite, MatrixType::general};

test::RandomKind kind_of(MatrixType type) {
  return type == MatrixType::spd                    ? test::RandomKind::spd
         : type == MatrixType::symmetric_indefinite ? test::RandomKind::symmetric_indefinite
                                                    : test::RandomKind::general;
}

// Awkward orders and every path, one warp per block (the warp and block barriers coincide).
TEST(SolveKernelEmulation, SmallProblemsEveryPath) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  EmulationCounts counts;
  for (MatrixType type : kTypes)
    for (index_t n : {1, 2, 3, 5, 40, 97}) {
      Problem pr{std::string(to_string(type)) + " random n=" + std::to_string(n),
                 test::random_sparse(n, 3, kind_of(type), rng), type};
      check_problem(pr, rng,
                    {SolvePath::all_block, SolvePath::all_library, SolvePath::model,
                     SolvePath::block_subtrees},
                    32, 132, counts);
    }
  EXPECT_GT(counts.block_fronts, 0);
  EXPECT_GT(counts.library_fronts, 0);
  EXPECT_GT(counts.subtrees, 0);
  EXPECT_GT(counts.chain_items, 0);
}

// LDLᵀ with 2×2 pivots (KKT matrices) and LU with row pivoting on fronts of more than one
// tile (k > 32), blocks of several warps (64 and 256 threads: the warps split the
// right-hand sides and the backward dot products).
TEST(SolveKernelEmulation, MultiTileFrontsSeveralWarps) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  EmulationCounts counts;
  std::vector<Problem> problems;
  problems.push_back({"kkt 150", test::random_kkt(150, rng), MatrixType::symmetric_indefinite});
  // a 3D Laplacian (root front of 30 pivots and more: several tiles), made indefinite by
  // a shift of the diagonal, or unsymmetric with a small diagonal (row pivoting)
  std::uniform_real_distribution<double> scale(0.5, 1.5);
  for (MatrixType type : kTypes) {
    SparseMatrix a = generators::laplacian_3d(7, 6, 5);
    if (type == MatrixType::symmetric_indefinite)
      for (index_t j = 0; j < a.n_cols; ++j) a.values[a.offsets[j]] -= 1.3;  // diagonal first
    if (type == MatrixType::general) {
      a = expand_symmetric(a);
      for (index_t j = 0; j < a.n_cols; ++j)
        for (index_t q = a.offsets[j]; q < a.offsets[j + 1]; ++q)
          a.values[q] *= a.indices[q] == j ? 0.1 : scale(rng);
    }
    problems.push_back({std::string(to_string(type)) + " laplacian 7x6x5", std::move(a), type});
  }
  for (const Problem& pr : problems) {
    check_problem(pr, rng, {SolvePath::all_block, SolvePath::model, SolvePath::block_subtrees}, 64,
                  4, counts);
    // the device's block size
    check_problem(pr, rng, {SolvePath::all_block, SolvePath::block_subtrees}, 256, 4, counts);
  }
  EXPECT_GT(counts.block_fronts, 0);
  EXPECT_GT(counts.subtrees, 0);
}

// The library path (no threads, so larger problems): every front through the BLAS
// sequence, several thousand unknowns, a root front of hundreds of rows; and the same
// Laplacian on the block path, whose fronts below the root are taller than kChunkRows.
TEST(SolveKernelEmulation, LibraryPathLargeFronts) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  EmulationCounts counts;
  std::vector<Problem> problems;
  problems.push_back({"laplacian 14^3", generators::laplacian_3d(14, 14, 14), MatrixType::spd});
  problems.push_back({"kkt 733", test::random_kkt(733, rng), MatrixType::symmetric_indefinite});
  problems.push_back({"general 733", test::random_sparse(733, 4, test::RandomKind::general, rng),
                      MatrixType::general});
  for (const Problem& pr : problems)
    check_problem(pr, rng, {SolvePath::all_library}, 32, 132, counts);
  EXPECT_GT(counts.library_fronts, 0);
  // the block path's fronts of more than kChunkRows rows: gathered and scattered by chunks
  // (their products with L21, L21ᵀ and U12 there), their triangles swept by one block; for
  // each factor type
  for (const Problem& pr : problems) {
    SCOPED_TRACE(pr.name);
    const index_t before = counts.tall_fronts;
    check_problem(pr, rng, {SolvePath::all_block}, 32, 132, counts);
    EXPECT_GT(counts.tall_fronts, before);
  }
  // the block path's two kernel variants: the device's choice by block count ran the one
  // with 16 loads in flight above; the other one (launches of more than kFewFrontBlocks
  // blocks), forced on every launch
  EXPECT_GT(counts.batch16_fronts, 0);
  for (const Problem& pr : problems) {
    SCOPED_TRACE(pr.name + ", the 4-batch variant");
    check_problem(pr, rng, {SolvePath::all_block, SolvePath::block_subtrees}, 32, 132, counts, 0);
  }
  EXPECT_GT(counts.batch4_fronts, 0);
}

// A factor split for several GPUs and solved part by part where its panels live
// (cuda/part_solve.cu, driven as the multi-worker driver's solve_where_held does),
// emulated: each part's plan over its own fronts (plan_sweeps with the part's front set)
// runs on the arrays of the "device" that holds the part, which start as NaN, so that a row
// of x or an update vector the exchange (part_exchange) fails to bring poisons the result;
// the layers of the split run forward from the subtrees to the top part, then backward,
// the x rows and update vectors going through host arrays. Compared with the CPU solve;
// and each part's plan solves exactly the part's fronts.
TEST(SolveKernelEmulation, SplitFactorSolvedPartByPart) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  std::vector<Problem> problems;
  problems.push_back({"laplacian 14^3", generators::laplacian_3d(14, 14, 14), MatrixType::spd});
  problems.push_back({"general 733", test::random_sparse(733, 4, test::RandomKind::general, rng),
                      MatrixType::general});
  for (index_t n : {1, 2, 3, 5})
    problems.push_back({"general " + std::to_string(n),
                        test::random_sparse(n, 3, test::RandomKind::general, rng),
                        MatrixType::general});
  problems.push_back(
      {"spd 97", test::random_sparse(97, 3, test::RandomKind::spd, rng), MatrixType::spd});
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::uniform_real_distribution<double> uni(-1, 1);
  EmulationCounts counts;
  index_t split_problems = 0;
  for (const Problem& pr : problems)
    for (int workers : {2, 3}) {
      SCOPED_TRACE(pr.name + ", " + std::to_string(workers) + " workers");
      Options o;
      o.type = pr.type;
      Analysis an = analyze_matrix(pr.a, o);
      schedule::PartitionOptions po;
      po.workers = workers;
      po.subtrees_per_worker = 2;
      po.unsymmetric = pr.type == MatrixType::general;
      an.partition = schedule::partition_tree(an.tree, po);
      const schedule::TreePartition& tp = an.partition;
      const auto& t = an.tree;
      const index_t nf = t.n_fronts();
      std::vector<double> values;
      const numeric::NumericFactor fac = factor_on_cpu(an, pr, values);
      SolvePlan inverse;
      cuda::plan_inverse_extend_add(t, an.child_rows, inverse);
      const std::int64_t u_total = inverse.u_offset.back();
      // the layers: subtrees, upper layers, the top part; a part's device: its id modulo
      // the workers (the top part's id is the number of subtrees)
      const std::vector<std::vector<int>> layers = tp.layers();
      if (tp.n_parts() > 2) ++split_problems;
      for (SolvePath path : {SolvePath::model, SolvePath::all_block, SolvePath::all_library,
                             SolvePath::block_subtrees}) {
        SCOPED_TRACE("path " + std::to_string(static_cast<int>(path)));
        std::vector<SolvePlan> plans(static_cast<std::size_t>(tp.n_parts()));
        std::vector<cuda::PartExchange> exchange(plans.size());
        std::vector<int> seen(nf, 0);
        // the model path as the executor plans it: the parts take the whole tree's
        // subtree limit; the forced paths choose per part
        SolvePlan whole;
        cuda::plan_sweeps(t, an.schedule, 132, path, nullptr, whole);
        const double* limit = path == SolvePath::model ? &whole.subtree_limit : nullptr;
        for (int id = 0; id < tp.n_parts(); ++id) {
          const std::vector<index_t>& fronts = tp.part(id).fronts;
          std::vector<char> in(nf, 0);
          for (index_t f : fronts) in[f] = 1;
          cuda::plan_sweeps(t, an.schedule, 132, path, &in, plans[id], limit);
          exchange[id] = cuda::part_exchange(t, fronts, inverse.u_offset);
          const SolvePlan& p = plans[id];
          std::vector<std::int64_t> planned;
          for (std::size_t q = 0; q < p.subtree_first.size(); ++q)
            for (std::int64_t f = p.subtree_first[q]; f <= p.subtree_last[q]; ++f)
              planned.push_back(f);
          for (const auto* list : {&p.small_fronts, &p.tall_fronts, &p.large_fronts})
            planned.insert(planned.end(), list->begin(), list->end());
          for (std::int64_t f : planned) {
            EXPECT_TRUE(in[f]) << "part " << id << " plans front " << f << " of another part";
            ++seen[f];
          }
        }
        for (index_t f = 0; f < nf; ++f) EXPECT_EQ(seen[f], 1) << "front " << f;
        for (index_t nrhs : {1, 3}) {
          SCOPED_TRACE("nrhs " + std::to_string(nrhs));
          const std::size_t nx = static_cast<std::size_t>(an.n * nrhs);
          std::vector<double> b(nx);
          for (double& v : b) v = uni(rng);
          std::vector<double> ref = b, x = b;
          numeric::solve_in_place(an, fac, ref.data(), nrhs);
          std::vector<double> u(static_cast<std::size_t>(u_total * nrhs) + 1, nan);
          std::vector<EmulatedDevice> devs(static_cast<std::size_t>(workers));
          for (EmulatedDevice& d : devs) {
            d.x.assign(nx + 1, nan);
            d.u.assign(u.size(), nan);
            d.scratch.assign(t.rows.size() * nrhs + 1, nan);
            d.part.assign(1, nan);
          }
          auto copy = [&](std::vector<double>& to, const std::vector<double>& from,
                          const cuda::SolveRanges& ranges, std::int64_t ld) {
            for (index_t r = 0; r < nrhs; ++r)
              for (const auto& [lo, hi] : ranges)
                std::copy(from.begin() + lo + r * ld, from.begin() + hi + r * ld,
                          to.begin() + lo + r * ld);
          };
          auto sweep = [&](int id, bool forward) {
            EmulatedDevice& d = devs[static_cast<std::size_t>(id % workers)];
            const cuda::PartExchange& e = exchange[id];
            copy(d.x, x, e.own_rows, an.n);
            if (forward)
              copy(d.u, u, e.imports, u_total);
            else
              copy(d.x, x, e.above_rows, an.n);
            emulate_sweeps(an, fac, inverse, plans[id], d, nrhs, forward, !forward, 32, counts);
            copy(x, d.x, e.own_rows, an.n);
            if (forward) copy(u, d.u, e.exports, u_total);
          };
          for (const auto& layer : layers)
            for (int id : layer) sweep(id, true);
          for (auto l = layers.rbegin(); l != layers.rend(); ++l)
            for (int id : *l) sweep(id, false);
          for (std::size_t i = 0; i < nx; ++i)
            ASSERT_FALSE(std::isnan(x[i])) << "row " << i % an.n << " rhs " << i / an.n;
          // tolerance as check_problem's (κ̂ a lower bound on the conditioning)
          const double kappa = max_abs(values) * max_abs(ref) / std::max(max_abs(b), 1e-300);
          const double tol = std::max(1e-10, 1e-13 * std::sqrt(static_cast<double>(an.n)) * kappa);
          EXPECT_LT(test::relative_difference(x, ref), tol) << "κ̂ " << kappa;
        }
      }
    }
  EXPECT_GT(split_problems, 0);  // some problem was cut into several parts
  EXPECT_GT(counts.library_fronts, 0);
  EXPECT_GT(counts.subtrees, 0);
}

// The planner: every front solved exactly once, in a subtree (a front and all its
// descendants) or on one path at its own level; the library's fronts' rows covered once by
// the gather/scatter chunks; the model puts a lone large root front on the library and
// solves the bottom of the tree by subtrees when launches would cost more.
TEST(SolveKernelEmulation, PlanCoversEveryFrontOnce) {
  SparseMatrix a = generators::laplacian_3d(16, 16, 16);
  Options o;
  o.type = MatrixType::spd;
  Analysis an = analyze_matrix(a, o);
  const auto& t = an.tree;
  const auto& s = an.schedule;
  const index_t nf = t.n_fronts();
  for (SolvePath path : {SolvePath::model, SolvePath::block_subtrees, SolvePath::all_block})
    for (int n_sm : {1, 132}) {
      SCOPED_TRACE("path " + std::to_string(static_cast<int>(path)) + " SMs " +
                   std::to_string(n_sm));
      const SolvePlan p = cuda::make_solve_plan(t, an.child_rows, s, n_sm, path);
      ASSERT_EQ(p.small_offsets.size(), static_cast<std::size_t>(s.n_levels() + 1));
      ASSERT_EQ(p.subtree_first.size(), p.subtree_last.size());
      std::vector<int> seen(nf, 0);
      for (std::size_t q = 0; q < p.subtree_first.size(); ++q) {
        const std::int64_t root = p.subtree_last[q];
        for (std::int64_t f = p.subtree_first[q]; f <= root; ++f) {
          ++seen[f];
          EXPECT_LE(t.n_rows(f), cuda::kChunkRows);
          std::int64_t g = f;  // f descends from the subtree's root
          while (g >= 0 && g != root) g = t.parent[g];
          EXPECT_EQ(g, root) << "front " << f;
        }
        for (index_t q2 = t.child_offsets[root]; q2 < t.child_offsets[root + 1]; ++q2)
          EXPECT_GE(t.children[q2], p.subtree_first[q]);  // every child inside
      }
      for (index_t l = 0; l < s.n_levels(); ++l) {
        std::int64_t large_rows = 0, chunk_rows = 0;
        for (std::int64_t q = p.small_offsets[l]; q < p.small_offsets[l + 1]; ++q) {
          EXPECT_EQ(s.level_of[p.small_fronts[q]], l);
          ++seen[p.small_fronts[q]];
        }
        for (std::int64_t q = p.large_offsets[l]; q < p.large_offsets[l + 1]; ++q) {
          EXPECT_EQ(s.level_of[p.large_fronts[q]], l);
          ++seen[p.large_fronts[q]];
          large_rows += t.n_rows(p.large_fronts[q]);
        }
        for (std::int64_t q = p.tall_offsets[l]; q < p.tall_offsets[l + 1]; ++q) {
          EXPECT_EQ(s.level_of[p.tall_fronts[q]], l);
          EXPECT_GT(t.n_rows(p.tall_fronts[q]), cuda::kChunkRows);
          ++seen[p.tall_fronts[q]];
          large_rows += t.n_rows(p.tall_fronts[q]);
        }
        for (std::int64_t q = p.small_offsets[l]; q < p.small_offsets[l + 1]; ++q)
          EXPECT_LE(t.n_rows(p.small_fronts[q]), cuda::kChunkRows);
        for (std::int64_t c = p.chunk_offsets[l]; c < p.chunk_offsets[l + 1]; ++c)
          chunk_rows += std::min(cuda::kChunkRows, t.n_rows(p.chunk_front[c]) - p.chunk_row[c]);
        EXPECT_EQ(chunk_rows, large_rows) << "level " << l;  // the tall and library fronts
      }
      for (index_t f = 0; f < nf; ++f) EXPECT_EQ(seen[f], 1) << "front " << f;
      // the tall fronts' partial products: a slot of product_chunks × k each, disjoint,
      // within part_total; no slot for any other front
      ASSERT_EQ(p.part_offset.size(), static_cast<std::size_t>(nf));
      std::vector<char> is_tall(nf, 0), used(static_cast<std::size_t>(p.part_total), 0);
      for (std::int64_t f : p.tall_fronts) is_tall[f] = 1;
      for (index_t f = 0; f < nf; ++f) {
        if (!is_tall[f]) {
          EXPECT_EQ(p.part_offset[f], -1) << "front " << f;
          continue;
        }
        const std::int64_t size = cuda::product_chunks(t.n_rows(f), t.n_pivots(f)) * t.n_pivots(f);
        ASSERT_GE(p.part_offset[f], 0);
        ASSERT_LE(p.part_offset[f] + size, p.part_total);
        for (std::int64_t e = p.part_offset[f]; e < p.part_offset[f] + size; ++e)
          EXPECT_EQ(used[e]++, 0) << "front " << f;
      }
      if (path == SolvePath::all_block) EXPECT_TRUE(p.subtree_first.empty());
      if (path == SolvePath::block_subtrees) EXPECT_FALSE(p.subtree_first.empty());
      if (path != SolvePath::model) EXPECT_TRUE(p.large_fronts.empty());
    }
  const index_t root_level = s.n_levels() - 1;
  ASSERT_EQ(s.level_offsets[root_level + 1] - s.level_offsets[root_level], 1);
  const index_t root = s.fronts[s.level_offsets[root_level]];
  ASSERT_GE(t.n_rows(root) * t.n_pivots(root), 30000);
  const SolvePlan p = cuda::make_solve_plan(t, an.child_rows, s, 132);
  EXPECT_EQ(p.large_offsets[root_level + 1] - p.large_offsets[root_level], 1);
  // a long thin grid: a deep tree of tiny fronts, whose launches cost more than solving
  // most of it by subtrees
  Analysis thin = analyze_matrix(generators::laplacian_3d(64, 2, 2), o);
  const SolvePlan pt = cuda::make_solve_plan(thin.tree, thin.child_rows, thin.schedule, 132);
  EXPECT_FALSE(pt.subtree_first.empty());
}

// The chain (plan_chain): the subtrees, then the bottom levels' fronts one item each, every
// front of them once; the levels it takes hold no tall or library front and the first it
// leaves holds one; a level front waits for all its children, each of them the last front
// of an earlier item that names it as the parent it signals; nothing else waits or signals.
TEST(SolveKernelEmulation, ChainItemsComeAfterWhatTheyWaitFor) {
  Options o;
  o.type = MatrixType::spd;
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  std::vector<Analysis> analyses;
  analyses.push_back(analyze_matrix(generators::laplacian_3d(16, 16, 16), o));
  analyses.push_back(analyze_matrix(generators::laplacian_3d(64, 2, 2), o));
  o.type = MatrixType::general;
  analyses.push_back(
      analyze_matrix(test::random_sparse(733, 3, test::RandomKind::general, rng), o));
  index_t with_chain = 0;
  for (const Analysis& an : analyses)
    for (SolvePath path : {SolvePath::model, SolvePath::block_subtrees, SolvePath::all_block,
                           SolvePath::all_library})
      for (int n_sm : {1, 132})
        for (const bool priced : {false, true}) {  // plan_sweeps's model with the chain or not
          SCOPED_TRACE("n " + std::to_string(an.n) + " path " +
                       std::to_string(static_cast<int>(path)) + " SMs " + std::to_string(n_sm) +
                       (priced ? " priced as chained" : ""));
          const auto& t = an.tree;
          const auto& s = an.schedule;
          const index_t nf = t.n_fronts();
          SolvePlan p = cuda::make_solve_plan(t, an.child_rows, s, n_sm, path, priced);
          cuda::plan_chain(t, s, p);  // again: the same
          auto plain = [&](index_t l) {
            return p.tall_offsets[l] == p.tall_offsets[l + 1] &&
                   p.large_offsets[l] == p.large_offsets[l + 1] &&
                   p.chunk_offsets[l] == p.chunk_offsets[l + 1];
          };
          for (index_t l = 0; l < p.chain_levels; ++l) EXPECT_TRUE(plain(l)) << "level " << l;
          if (p.chain_levels < s.n_levels())
            EXPECT_FALSE(plain(static_cast<index_t>(p.chain_levels)));
          if (p.chain_levels == 0) {
            EXPECT_TRUE(p.chain_first.empty());
            continue;
          }
          ++with_chain;
          ASSERT_EQ(p.chain_first.size(), p.chain_last.size());
          ASSERT_EQ(p.chain_wait.size(), static_cast<std::size_t>(nf));
          ASSERT_EQ(p.chain_parent.size(), static_cast<std::size_t>(nf));
          EXPECT_TRUE(
              std::equal(p.subtree_first.begin(), p.subtree_first.end(), p.chain_first.begin()));
          std::vector<int> seen(nf, 0);
          std::vector<std::int64_t> item_of(nf, -1);
          for (std::size_t q = 0; q < p.chain_first.size(); ++q)
            for (std::int64_t f = p.chain_first[q]; f <= p.chain_last[q]; ++f) {
              ++seen[f];
              item_of[f] = static_cast<std::int64_t>(q);
            }
          std::vector<int> expected(nf, 0);
          for (std::size_t q = 0; q < p.subtree_first.size(); ++q)
            for (std::int64_t f = p.subtree_first[q]; f <= p.subtree_last[q]; ++f) expected[f] = 1;
          for (std::int64_t q = p.small_offsets[0]; q < p.small_offsets[p.chain_levels]; ++q)
            expected[p.small_fronts[q]] = 1;
          for (index_t f = 0; f < nf; ++f) {
            EXPECT_EQ(seen[f], expected[f]) << "front " << f;
            if (!seen[f]) {
              EXPECT_EQ(p.chain_wait[f], 0);
              EXPECT_EQ(p.chain_parent[f], -1);
              continue;
            }
            const std::int64_t q = item_of[f];
            const bool level_front =
                p.chain_first[q] == p.chain_last[q] && s.level_of[f] < p.chain_levels &&
                std::find(p.small_fronts.begin(), p.small_fronts.end(), f) != p.small_fronts.end();
            EXPECT_EQ(p.chain_wait[f],
                      level_front ? t.child_offsets[f + 1] - t.child_offsets[f] : 0)
                << "front " << f;
            for (index_t c = t.child_offsets[f]; c < t.child_offsets[f + 1]; ++c) {
              const index_t child = t.children[c];
              if (!level_front) continue;
              EXPECT_EQ(p.chain_last[item_of[child]], child);
              EXPECT_LT(item_of[child], q);
              EXPECT_EQ(p.chain_parent[child], f);
            }
            if (p.chain_parent[f] >= 0) EXPECT_EQ(p.chain_parent[f], t.parent[f]);
          }
        }
  EXPECT_GT(with_chain, 0);
}

}  // namespace
}  // namespace strata
