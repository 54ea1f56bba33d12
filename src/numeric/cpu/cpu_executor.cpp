// strata — the CPU executor: fronts on host threads, dense work in BLAS.
//
// Order. A whole-tree factorization runs depth-first (factor_tree, the plan of
// schedule/stack_plan.hpp): the small subtrees of each step over the oneTBB threads, one
// BLAS thread each, every subtree in the stack region of its thread; the fronts of the
// top one after another on the calling thread, a large front (more than
// schedule::kLargeFrontFlops) with all threads inside OpenBLAS. The contribution blocks
// live on that stack: only the blocks of the path being climbed are alive, not those of a
// whole level. The parts of a multi-worker factorization go batch by batch through their
// level schedule (factor_batch) with the arena layout of the part, the same split of
// small and large fronts inside a batch, and subtree-root blocks crossing between arenas
// by plain copies (export_cb / import_cb).
// Determinism: every front is computed by one thread from inputs (children's contribution
// blocks, summed in child order) that do not depend on the schedule, so the factor is
// bitwise the same for any thread count — except that multithreaded OpenBLAS rounds
// differently for different thread counts on the large fronts; Options::reproducible keeps
// those single-threaded too (docs/reliability.md, "Determinism"). TBB rather than OpenMP
// because idle OpenMP threads spin-wait (GOMP's default policy) and starve OpenBLAS's own
// threads on small machines (bench/history.md).
//
// Per front f with m rows and k pivots, Cholesky (LLᵀ) with a parent:
//   1. zero the factor's panel for f (m × k) and f's block where it is formed (its lower
//      triangle: lower panels on the stack, base/lower_panels.hpp; a square in a level
//      arena), add the original entries (assembly map) into the two,
//   2. extend-add each child's block (rows relative to f: the analysis's ChildRowMap),
//   3. partial factorization on the two pieces (dense_front.hpp), no m × m workspace,
//   4. the rows to the factor's rows; the block moved down to where it stays (stack).
// Any other front (LDLᵀ, LU, a root) goes through the thread's dense workspace, reused
// from front to front and from factorization to factorization:
//   1. zero the m×m workspace, scatter the original entries,
//   2. extend-add each child's block,
//   3. partial factorization (dense_front.hpp),
//   4. copy the first k columns (and U12 for LU) to the factor, the contribution block
//      F[k:m, k:m] to where it stays, and the permuted pivot rows to the factor's rows.
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
#include "base/lower_panels.hpp"
#include "numeric/assembly.hpp"
#include "numeric/cpu/dense_front.hpp"
#include "numeric/factor.hpp"
#include "schedule/stack_plan.hpp"
#include "strata/errors.hpp"

namespace strata::numeric {
namespace {

struct Workspace {
  std::vector<double> front;
  std::vector<index_t> local_perm;
  std::vector<int> pivot_size;
};

// Where a front's contribution blocks are: its children's (read) and its own (written).
struct FrontBlocks {
  const std::vector<double>* arena = nullptr;
  // the level path: ctx.part->cb_layout; the depth-first path: the stack plan and the
  // region of the thread running the front
  const CbLayout* layout = nullptr;
  const schedule::StackPlan* plan = nullptr;
  std::size_t region = 0;  ///< doubles from the arena's start

  std::size_t place(index_t f, bool build) const {
    if (layout) return layout->cb_offset[f];
    const std::size_t off = build ? plan->build_offset[f] : plan->cb_offset[f];
    return plan->in_region(f) ? region + off : off;
  }
  const double* child(index_t c) const { return arena->data() + place(c, false); }
  /// Front f's block (of a Cholesky factorization) at `data`: lower panels on the stack,
  /// the plain square in the level path's arena.
  LowerPanels block(const symbolic::AssemblyTree& t, index_t f, const double* data) const {
    if (plan) return plan->block(t, f, const_cast<double*>(data));
    const index_t c = t.cb_size(f);
    return LowerPanels{const_cast<double*>(data), c, c > 0 ? c : 1, c};
  }
};

// The memory-bound loops of a large front (zeroing, extend-add, block copies) split by
// columns over the executor's threads, which would otherwise wait for the next BLAS call;
// serial without an arena. Every element is still written by one thread in the same order
// (children one after another), so the result does not depend on the split.
struct ColumnSplit {
  tbb::task_arena* arena = nullptr;
  template <class Body>
  void operator()(index_t n, const Body& body) const {
    if (arena == nullptr || n < 256) {
      body(index_t{0}, n);
      return;
    }
    arena->execute([&] {
      tbb::parallel_for(tbb::blocked_range<index_t>(0, n, 32),
                        [&](const tbb::blocked_range<index_t>& r) { body(r.begin(), r.end()); });
    });
  }
};

// 1.–2. of the file header for the split Cholesky front: the original entries and the
// children's blocks added into the panel (the factor's storage, m × k, leading dimension
// m) and the contribution block (mc × mc, leading dimension mc; lower triangles only).
void assemble_split(const FactorContext& ctx, index_t f, const FrontBlocks& blocks, double* panel,
                    const LowerPanels& cb, const ColumnSplit& split) {
  const Analysis& an = *ctx.analysis;
  const auto& t = an.tree;
  const index_t m = t.n_rows(f), k = t.n_pivots(f);
  const auto& am = an.assembly;
  for (index_t e = am.entry_offsets[f]; e < am.entry_offsets[f + 1]; ++e) {
    const index_t d = am.entry_dst[e];
    const index_t i = d % m, j = d / m;
    if (j < k)
      panel[d] += ctx.values[am.entry_src[e]];
    else if (i >= j)
      cb.diag(j - k)[i - j] += ctx.values[am.entry_src[e]];
    else
      throw InternalError("assembly map: an entry above the diagonal of a Cholesky front");
  }
  for (index_t q = t.child_offsets[f]; q < t.child_offsets[f + 1]; ++q) {
    const index_t c = t.children[q];
    const index_t mcc = t.cb_size(c);
    if (mcc == 0) continue;
    const LowerPanels src = blocks.block(t, c, blocks.child(c));
    const index_t* rel = an.child_rows.of(c);
    split(mcc, [&](index_t j0, index_t j1) {
      for (index_t jj = j0; jj < j1; ++jj) {
        const double* col = src.diag(jj);  // col[ii − jj]: child element (ii, jj)
        const index_t pc = rel[jj];
        if (pc < k) {
          double* dst = panel + static_cast<std::size_t>(pc) * m;
          for (index_t ii = jj; ii < mcc; ++ii) dst[rel[ii]] += col[ii - jj];
        } else {
          double* dst = cb.diag(pc - k);  // dst[r − pc]: element (r − k, pc − k), r ≥ pc
          for (index_t ii = jj; ii < mcc; ++ii) dst[rel[ii] - pc] += col[ii - jj];
        }
      }
    });
  }
}

// A Cholesky front with its panel formed in the factor and its contribution block formed
// at `build` (the lower triangle of mc × mc doubles that overlap no block it reads), then
// moved to `keep` (which may overlap the children's blocks, all read by then).
void process_llt_split(const FactorContext& ctx, index_t f, const FrontBlocks& blocks,
                       double* build, double* keep, const ColumnSplit& split) {
  const Analysis& an = *ctx.analysis;
  const auto& t = an.tree;
  NumericFactor& fac = *ctx.factor;
  const index_t m = t.n_rows(f), k = t.n_pivots(f), mc = m - k;
  double* panel = fac.panels.data() + an.factor_layout.panel_offset[f];
  const LowerPanels cb = blocks.block(t, f, build);
  split(k, [&](index_t j0, index_t j1) {
    std::fill(panel + static_cast<std::size_t>(j0) * m, panel + static_cast<std::size_t>(j1) * m,
              0.0);
  });
  split(mc, [&](index_t j0, index_t j1) {
    for (index_t j = j0; j < j1; ++j) std::fill(cb.diag(j), cb.diag(j) + (mc - j), 0.0);
  });
  assemble_split(ctx, f, blocks, panel, cb, split);
  PivotStats& ps = fac.front_stats[f];
  ps = PivotStats{};
  const index_t bad = cpu::factor_front_llt(panel, m, k, m, cb, ps);
  if (bad >= 0) {
    const index_t pivot = t.first_pivot[f] + bad;
    throw NotPositiveDefinite(an.perm[pivot], panel[bad * m + bad]);
  }
  const index_t* rows = t.rows_of(f);
  std::copy(rows, rows + m, fac.rows.data() + t.row_offsets[f]);
  const std::size_t size = mc > 0 ? LowerPanels::size(mc, cb.width) : 0;
  if (size == 0 || keep == build) return;
  if (keep + size > build) {  // overlapping: one ordered move
    std::memmove(keep, build, sizeof(double) * size);
    return;
  }
  const auto chunks = static_cast<index_t>(std::min<std::size_t>(size / 4096 + 1, 1 << 20));
  split(chunks, [&](index_t c0, index_t c1) {
    const std::size_t b = size * c0 / chunks, e = size * c1 / chunks;
    std::memcpy(keep + b, build + b, sizeof(double) * (e - b));
  });
}

// A front in a dense m × m workspace (LDLᵀ, LU, or a Cholesky front without a parent):
// assembled, factored, its panel and rows stored, its contribution block copied to `cb`
// (nullptr: the front has no parent, the block is dropped).
void process_dense(const FactorContext& ctx, index_t f, const FrontBlocks& blocks, Workspace& w,
                   double* cb, const ColumnSplit& split) {
  const Analysis& an = *ctx.analysis;
  const auto& t = an.tree;
  NumericFactor& fac = *ctx.factor;
  const bool lu = ctx.type == MatrixType::general;
  const index_t m = t.n_rows(f), k = t.n_pivots(f);
  const index_t* rows = t.rows_of(f);
  const std::size_t mm = static_cast<std::size_t>(m) * m;
  if (w.front.size() < mm) sized_resize(w.front, mm, "factorize: dense front workspace");
  double* F = w.front.data();
  split(m, [&](index_t j0, index_t j1) {
    std::fill(F + static_cast<std::size_t>(j0) * m, F + static_cast<std::size_t>(j1) * m, 0.0);
  });

  // 1. original entries
  const auto& am = an.assembly;
  add_entries(F, am.entry_dst.data(), am.entry_src.data(), ctx.values, am.entry_offsets[f],
              am.entry_offsets[f + 1], 0, static_cast<std::int64_t>(mm));

  // 2. extend-add of the children's contribution blocks (Analysis::child_rows: the
  // local positions of each child's contribution rows in f)
  for (index_t q = t.child_offsets[f]; q < t.child_offsets[f + 1]; ++q) {
    const index_t c = t.children[q];
    const index_t mc = t.cb_size(c);
    if (mc == 0) continue;
    const index_t* rel = an.child_rows.of(c);
    if (lu) {
      const double* src = blocks.child(c);
      split(mc, [&](index_t j0, index_t j1) { extend_add(F, m, src, mc, rel, j0, j1, false); });
      continue;
    }
    const LowerPanels src = blocks.block(t, c, blocks.child(c));  // lower triangle only
    split(mc, [&](index_t j0, index_t j1) { extend_add_lower(F, m, src, rel, j0, j1); });
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
      cpu::factor_front_lu(F, m, k, m, ctx.static_pivot, ctx.diagonal_pivot_threshold,
                           w.local_perm.data(), ps);
      if (ps.perturbed > 0)  // which pivots: those now exactly ±static_pivot
        mark_static_pivots(F, m + 1, k, t.first_pivot[f], ctx.static_pivot, fac);
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
  if (mc > 0 && cb) {
    split(mc, [&](index_t j0, index_t j1) {
      for (index_t jj = j0; jj < j1; ++jj) {
        const index_t i0 = lu ? 0 : jj;
        std::memcpy(cb + static_cast<std::size_t>(jj) * mc + i0,
                    F + static_cast<std::size_t>(k + jj) * m + k + i0, sizeof(double) * (mc - i0));
      }
    });
  }
}

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
    FrontBlocks blocks;
    blocks.arena = ctx.cb_arena;
    blocks.layout = ctx.part->cb_layout;
    std::vector<index_t> big, small;
    for (index_t p = batch.begin; p < batch.end; ++p) {
      const index_t f = s.fronts[p];
      (symbolic::front_flops(an.tree, f) > schedule::kLargeFrontFlops ? big : small).push_back(f);
    }
    // small fronts: one BLAS thread each, fronts over the TBB workers
    if (!small.empty()) {
      set_blas_threads(1);
      std::exception_ptr error;
      std::mutex error_mutex;
      auto body = [&](std::size_t i) {
        try {
          const int slot = tbb::this_task_arena::current_thread_index();
          process_front(ctx, small[i], blocks, ws_[slot >= 0 ? slot : threads_]);
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
      for (index_t f : big) process_front(ctx, f, blocks, ws_[threads_], true);
    }
  }

  // The whole tree depth-first (schedule/stack_plan.hpp): steps in order, each running
  // its small subtrees over the threads, then its top front.
  bool factor_tree(const FactorContext& ctx) override {
    if (ctx.part == nullptr || ctx.part->id != -1) return false;  // parts: level by level
    const Analysis& an = *ctx.analysis;
    const schedule::StackPlan& plan = stack_plan(an, ctx.type == MatrixType::spd);
    if (ctx.cb_arena->size() < plan.arena_size())
      sized_resize(*ctx.cb_arena, plan.arena_size(), "factorize: contribution-block stack");
    FrontBlocks blocks;
    blocks.arena = ctx.cb_arena;
    blocks.plan = &plan;
    for (std::size_t i = 0; i < plan.step_front.size(); ++i) {
      const index_t* g = plan.group.data();
      if (plan.group_offsets[i] < plan.group_offsets[i + 1])
        run_subtrees(ctx, plan, g + plan.group_offsets[i], g + plan.group_offsets[i + 1]);
      const index_t f = plan.step_front[i];
      if (f < 0) continue;
      const bool large = symbolic::front_flops(an.tree, f) > schedule::kLargeFrontFlops;
      set_blas_threads(large && !reproducible_ ? threads_ : 1);
      process_front(ctx, f, blocks, ws_[threads_], large);
    }
    return true;
  }

 private:
  // `large`: a large front processed alone by the calling thread (its memory-bound loops
  // split over the threads, ColumnSplit).
  void process_front(const FactorContext& ctx, index_t f, const FrontBlocks& blocks, Workspace& w,
                     bool large = false);
  const schedule::StackPlan& stack_plan(const Analysis& an, bool lower_panels);
  void run_subtrees(const FactorContext& ctx, const schedule::StackPlan& plan, const index_t* first,
                    const index_t* last);
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
  // the plan of an analysis made for another thread count (or not carrying one)
  std::uint64_t own_plan_analysis_ = 0;
  schedule::StackPlan own_plan_;
};

void CpuExecutor::process_front(const FactorContext& ctx, index_t f, const FrontBlocks& blocks,
                                Workspace& w, bool large) {
  ColumnSplit split;
  if (large && threads_ > 1) split.arena = &arena_;
  const auto& t = ctx.analysis->tree;
  const bool has_cb = t.cb_size(f) > 0 && t.parent[f] >= 0;
  double* base = const_cast<double*>(blocks.arena->data());
  double* keep = has_cb ? base + blocks.place(f, false) : nullptr;
  if (ctx.type == MatrixType::spd && (has_cb || t.cb_size(f) == 0))
    process_llt_split(ctx, f, blocks, has_cb ? base + blocks.place(f, true) : keep, keep, split);
  else
    process_dense(ctx, f, blocks, w, keep, split);
}

const schedule::StackPlan& CpuExecutor::stack_plan(const Analysis& an, bool lower_panels) {
  const schedule::StackPlan& p = an.stack_plan;
  if (p.threads == threads_ && p.lower_panels == lower_panels &&
      p.subtree_of.size() == static_cast<std::size_t>(an.tree.n_fronts()))
    return p;
  if (own_plan_analysis_ != an.id || own_plan_.lower_panels != lower_panels) {
    own_plan_ = schedule::plan_stack(an.tree, threads_, lower_panels);
    own_plan_analysis_ = an.id;
  }
  return own_plan_;
}

// The subtrees [first, last) of one step, each on one thread (one BLAS thread each) in the
// region of that thread's slot; their roots write their blocks to the main stack.
void CpuExecutor::run_subtrees(const FactorContext& ctx, const schedule::StackPlan& plan,
                               const index_t* first, const index_t* last) {
  set_blas_threads(1);
  const auto count = static_cast<std::size_t>(last - first);
  std::exception_ptr error;
  std::mutex error_mutex;
  auto body = [&](std::size_t i) {
    try {
      const int slot = tbb::this_task_arena::current_thread_index();
      const int r = plan.regions == 1 ? 0 : (slot >= 0 && slot < threads_ ? slot : threads_);
      FrontBlocks blocks;
      blocks.arena = ctx.cb_arena;
      blocks.plan = &plan;
      blocks.region = plan.main_size + static_cast<std::size_t>(r) * plan.region_size;
      Workspace& w = ws_[slot >= 0 && slot < threads_ ? slot : threads_];
      const index_t s = first[i];
      for (index_t f = plan.subtree_first[s]; f <= plan.subtree_root[s]; ++f)
        process_front(ctx, f, blocks, w);
    } catch (...) {
      std::lock_guard<std::mutex> lock(error_mutex);
      if (!error) error = std::current_exception();
    }
  };
  if (count == 1 || threads_ == 1) {
    for (std::size_t i = 0; i < count; ++i) body(i);
  } else {
    arena_.execute([&] {
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, 1),
                        [&](const tbb::blocked_range<std::size_t>& r) {
                          for (std::size_t i = r.begin(); i != r.end(); ++i) body(i);
                        });
    });
  }
  if (error) std::rethrow_exception(error);
}

}  // namespace

std::unique_ptr<Executor> make_cpu_executor(int threads, bool reproducible) {
  return std::make_unique<CpuExecutor>(threads, reproducible);
}

}  // namespace strata::numeric
