// strata — the CPU executor: fronts of a batch on host threads, dense work in BLAS.
//
// Parallelism (no oversubscription): fronts whose factorization is large (more than
// kBigFrontFlops) are processed one after another with multithreaded OpenBLAS; the others
// are distributed over oneTBB worker threads with OpenBLAS restricted to one thread.
// Determinism: every front is computed by one thread from inputs (children's contribution
// blocks, summed in child order) that do not depend on the schedule, so the factor is
// bitwise the same for any thread count — except that multithreaded OpenBLAS rounds
// differently for different thread counts on the large fronts; Options::reproducible keeps
// those single-threaded too (docs/reliability.md, "Determinism"). TBB
// rather than OpenMP because idle OpenMP threads spin-wait (GOMP's default policy) and
// starve OpenBLAS's own threads on small machines (bench/history.md). Each worker owns a
// dense front
// workspace, reused from front to front and from factorization to factorization.
//
// Per front f with m rows and k pivots:
//   1. zero the m×m workspace, scatter the original entries (assembly map),
//   2. extend-add each child's contribution block (rows relative to f: the analysis's
//      ChildRowMap),
//   3. partial factorization (dense_front.hpp),
//   4. copy the first k columns (and U12 for LU) to the factor, the contribution block
//      F[k:m, k:m] to the CB arena, and the permuted pivot rows to the factor's rows.
// The schedule and the arena layout are those of the part being factored (ctx.part): the
// whole tree, or a subtree / the top part of a multi-worker factorization, whose
// subtree-root blocks cross between arenas by plain copies (export_cb / import_cb).
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <exception>
#include <mutex>
#include <thread>

#include "base/alloc.hpp"
#include "base/blas.hpp"
#include "numeric/assembly.hpp"
#include "numeric/cpu/dense_front.hpp"
#include "numeric/factor.hpp"
#include "strata/errors.hpp"

namespace strata::numeric {
namespace {

constexpr double kBigFrontFlops = 2e7;

struct Workspace {
  std::vector<double> front;
  std::vector<index_t> local_perm;
  std::vector<int> pivot_size;
};

class CpuExecutor final : public Executor {
 public:
  CpuExecutor(int threads, bool reproducible)
      : threads_(threads > 0 ? threads
                             : std::max(1, static_cast<int>(std::thread::hardware_concurrency()))),
        reproducible_(reproducible),
        arena_(threads_) {}
  const char* name() const override { return "cpu"; }

  void begin(const FactorContext& ctx) override {
    ws_.resize(threads_ + 1);  // TBB slot indices are < threads_; one spare
    blas_threads_ = -1;        // others (the solve) may have changed it since
  }

  std::size_t export_cb(const FactorContext& ctx, CbTransfer& t) override {
    const double* src = ctx.cb_arena->data() + ctx.part->cb_layout->cb_offset[t.front];
    std::memcpy(t.host_buffer(), src, sizeof(double) * t.size);
    t.on_host = true;
    return sizeof(double) * t.size;
  }

  std::size_t import_cb(const FactorContext& ctx, const CbTransfer& t) override {
    if (!t.on_host)
      throw InternalError("the CPU executor can only import a block from host memory");
    double* dst = ctx.cb_arena->data() + ctx.part->cb_layout->cb_offset[t.front];
    std::memcpy(dst, t.host, sizeof(double) * t.size);
    return sizeof(double) * t.size;
  }

  void factor_batch(const FactorContext& ctx, const BatchInfo& batch) override {
    const Analysis& an = *ctx.analysis;
    const auto& s = *ctx.part->schedule;
    std::vector<index_t> big, small;
    for (index_t p = batch.begin; p < batch.end; ++p) {
      const index_t f = s.fronts[p];
      (symbolic::front_flops(an.tree, f) > kBigFrontFlops ? big : small).push_back(f);
    }
    // small fronts: one BLAS thread each, fronts over the TBB workers
    if (!small.empty()) {
      set_blas_threads(1);
      std::exception_ptr error;
      std::mutex error_mutex;
      auto body = [&](std::size_t i) {
        try {
          const int slot = tbb::this_task_arena::current_thread_index();
          process_front(ctx, small[i], ws_[slot >= 0 ? slot : threads_]);
        } catch (...) {
          std::lock_guard<std::mutex> lock(error_mutex);
          if (!error) error = std::current_exception();
        }
      };
      if (small.size() == 1 || threads_ == 1) {
        for (std::size_t i = 0; i < small.size(); ++i) body(i);
      } else {
        arena_.execute([&] {
          tbb::parallel_for(tbb::blocked_range<std::size_t>(0, small.size(), 1),
                            [&](const tbb::blocked_range<std::size_t>& r) {
                              for (std::size_t i = r.begin(); i != r.end(); ++i) body(i);
                            });
        });
      }
      if (error) std::rethrow_exception(error);
    }
    // big fronts: one at a time, all threads inside BLAS — unless reproducible: OpenBLAS's
    // threaded kernels round differently for different thread counts (docs/reliability.md)
    if (!big.empty()) {
      set_blas_threads(reproducible_ ? 1 : threads_);
      for (index_t f : big) process_front(ctx, f, ws_[threads_]);
    }
  }

 private:
  void process_front(const FactorContext& ctx, index_t f, Workspace& w) const;
  // OpenBLAS's thread count is global: change it only when it differs.
  void set_blas_threads(int n) {
    if (blas_threads_ != n) openblas_set_num_threads(n);
    blas_threads_ = n;
  }
  int threads_;
  bool reproducible_;
  int blas_threads_ = -1;
  tbb::task_arena arena_;
  std::vector<Workspace> ws_;
};

void CpuExecutor::process_front(const FactorContext& ctx, index_t f, Workspace& w) const {
  const Analysis& an = *ctx.analysis;
  const auto& t = an.tree;
  NumericFactor& fac = *ctx.factor;
  const bool lu = ctx.type == MatrixType::general;
  const index_t m = t.n_rows(f), k = t.n_pivots(f);
  const index_t* rows = t.rows_of(f);
  const std::size_t mm = static_cast<std::size_t>(m) * m;
  if (w.front.size() < mm) sized_resize(w.front, mm, "factorize: dense front workspace");
  double* F = w.front.data();
  std::fill(F, F + mm, 0.0);

  // 1. original entries
  const auto& am = an.assembly;
  add_entries(F, am.entry_dst.data(), am.entry_src.data(), ctx.values, am.entry_offsets[f],
              am.entry_offsets[f + 1], 0, static_cast<std::int64_t>(mm));

  // 2. extend-add of the children's contribution blocks (Analysis::child_rows: the
  // local positions of each child's contribution rows in f)
  const std::vector<double>& arena = *ctx.cb_arena;
  for (index_t q = t.child_offsets[f]; q < t.child_offsets[f + 1]; ++q) {
    const index_t c = t.children[q];
    const index_t mc = t.cb_size(c);
    if (mc == 0) continue;
    const double* cb = arena.data() + ctx.part->cb_layout->cb_offset[c];
    extend_add(F, m, cb, mc, an.child_rows.of(c), 0, mc, !lu);
  }

  // 3. partial factorization
  PivotStats& ps = fac.front_stats[f];
  ps = PivotStats{};
  w.local_perm.resize(k);
  w.pivot_size.resize(k);
  switch (ctx.type) {
    case MatrixType::spd: {
      const index_t bad = cpu::factor_front_llt(F, m, k, m, ps);
      if (bad >= 0) {
        const index_t pivot = t.first_pivot[f] + bad;
        throw NotPositiveDefinite(an.perm[pivot], F[bad * m + bad]);
      }
      for (index_t i = 0; i < k; ++i) w.local_perm[i] = i;
      break;
    }
    case MatrixType::symmetric_indefinite:
      cpu::factor_front_ldlt(F, m, k, m, ctx.static_pivot, w.local_perm.data(), w.pivot_size.data(),
                             ps);
      break;
    case MatrixType::general:
      cpu::factor_front_lu(F, m, k, m, ctx.static_pivot, w.local_perm.data(), ps);
      break;
    default:
      throw InternalError("unresolved matrix type in the CPU executor");
  }

  // 4. store the factor panel, the permuted pivot rows, D, and the contribution block
  double* panel = fac.panels.data() + an.factor_layout.panel_offset[f];
  std::memcpy(panel, F, sizeof(double) * m * k);
  if (lu)
    for (index_t j = k; j < m; ++j)  // U12: rows 0..k-1 of columns k..m-1
      std::memcpy(panel + m * k + (j - k) * k, F + j * m, sizeof(double) * k);
  if (ctx.type == MatrixType::symmetric_indefinite) {
    store_ldlt_front(an, f, w.local_perm.data(), w.pivot_size.data(), fac);
  } else {
    index_t* frows = fac.rows.data() + t.row_offsets[f];
    for (index_t i = 0; i < k; ++i) frows[i] = rows[w.local_perm[i]];
    for (index_t i = k; i < m; ++i) frows[i] = rows[i];
  }
  const index_t mc = m - k;
  if (mc > 0 && t.parent[f] >= 0) {
    double* cb = ctx.cb_arena->data() + ctx.part->cb_layout->cb_offset[f];
    for (index_t jj = 0; jj < mc; ++jj) {
      const index_t i0 = lu ? 0 : jj;
      std::memcpy(cb + jj * mc + i0, F + (k + jj) * m + k + i0, sizeof(double) * (mc - i0));
    }
  }
}

}  // namespace

std::unique_ptr<Executor> make_cpu_executor(int threads, bool reproducible) {
  return std::make_unique<CpuExecutor>(threads, reproducible);
}

}  // namespace strata::numeric
